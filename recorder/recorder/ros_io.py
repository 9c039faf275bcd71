"""The rclpy edge of the recorder: message classes from type names, QoS to and from the
``offered_qos_profiles`` YAML that rosbag2 stores per topic."""

from __future__ import annotations

import importlib

import yaml
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from recorder.definitions import split_type


def message_class(type_name: str):
    package, name = split_type(type_name)
    try:
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError):
        raise LookupError(f'message type {type_name} is not installed') from None


_INFINITE = {'sec': 2147483647, 'nsec': 4294967295}


def qos_to_yaml(profiles: list[QoSProfile]) -> str:
    """As rosbag2 writes offered_qos_profiles: a YAML list, policies as rmw enum numbers."""
    entries = []
    for q in profiles:
        entries.append({
            'history': int(q.history.value), 'depth': int(q.depth),
            'reliability': int(q.reliability.value), 'durability': int(q.durability.value),
            'deadline': dict(_INFINITE), 'lifespan': dict(_INFINITE),
            'liveliness': int(q.liveliness.value),
            'liveliness_lease_duration': dict(_INFINITE),
            'avoid_ros_namespace_conventions': False})
    return yaml.safe_dump(entries, sort_keys=False) if entries else ''


def qos_from_yaml(text: str) -> QoSProfile:
    """The profile to publish a recorded topic with: reliable and transient local when every
    recorded publisher offered them (a latched topic replays latched), else the defaults."""
    try:
        entries = yaml.safe_load(text) or []
    except yaml.YAMLError:
        entries = []
    reliable = bool(entries) and all(e.get('reliability') == ReliabilityPolicy.RELIABLE.value
                                     for e in entries)
    latched = bool(entries) and all(e.get('durability') == DurabilityPolicy.TRANSIENT_LOCAL.value
                                    for e in entries)
    # Keep-all for streams: a subscriber that lags slows the replay instead of losing messages.
    return QoSProfile(history=HistoryPolicy.KEEP_LAST if latched else HistoryPolicy.KEEP_ALL,
                      depth=1 if latched else 1000,
                      reliability=ReliabilityPolicy.RELIABLE if reliable or not entries
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


def subscription_qos(offered: list[QoSProfile]) -> QoSProfile:
    """What a recorder subscribes with so that it is compatible with every publisher and loses
    nothing a reliable publisher keeps: like rosbag2, reliable only if all publishers are, and
    transient local only if all publishers are (to get latched data)."""
    reliable = bool(offered) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    latched = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                                    for q in offered)
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)
