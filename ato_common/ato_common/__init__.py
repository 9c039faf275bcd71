"""The domain model of the ATO emulator, without ROS.

Every module here is pure Python (numpy, scipy, PyYAML): units, train presets, lines, scenarios
and TTOBench files, braking curves, uncertainty, the controller's knowledge of its train,
tracking metrics, and the interface conventions (topic names, QoS described as data). Nothing
here imports rclpy or any ``rcl*`` module, a message package or the other packages of the suite
(``tools/test/test_import_graph.py`` keeps it so). The rclpy edge (QoS profiles, message
conversion, the nodes' start-up and teardown, parameters) is the package ``ato_ros``.
"""
