"""Shared conventions of the ATO emulator.

Everything here except :mod:`ato_common.ros` is pure Python (numpy, PyYAML): units, train
presets, line descriptions, scenarios, tracking metrics and the topic/QoS table. The rclpy-facing
helpers (QoS profiles, message conversion) live in :mod:`ato_common.ros` so the cores can be used
and tested without ROS.
"""
