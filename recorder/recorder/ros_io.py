"""The rclpy edge of the recorder: message classes from type names, QoS to and from the
``offered_qos_profiles`` that rosbag2 stores per topic (:mod:`recorder.rosbag2_format`)."""

from __future__ import annotations

import importlib

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from recorder.definitions import split_type
from recorder.rosbag2_format import (
    DURABILITY,
    HISTORY,
    INFINITE_NS,
    LIVELINESS,
    RELIABILITY,
    duration,
    duration_ns,
    parse_qos_profiles,
)


def message_class(type_name: str):
    package, name = split_type(type_name)
    try:
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError):
        raise LookupError(f'message type {type_name} is not installed') from None


def _ns(value: Duration) -> int:
    return min(int(value.nanoseconds), INFINITE_NS)


def offered_profile(q: QoSProfile) -> dict:
    """A publisher's profile as rosbag2 Jazzy records it: every policy as offered (the history
    and depth as rmw reports them for a remote endpoint, often unknown and 0)."""
    return {
        'history': HISTORY[int(q.history.value)], 'depth': int(q.depth),
        'reliability': RELIABILITY[int(q.reliability.value)],
        'durability': DURABILITY[int(q.durability.value)],
        'deadline': duration(_ns(q.deadline)), 'lifespan': duration(_ns(q.lifespan)),
        'liveliness': LIVELINESS[int(q.liveliness.value)],
        'liveliness_lease_duration': duration(_ns(q.liveliness_lease_duration)),
        'avoid_ros_namespace_conventions': bool(q.avoid_ros_namespace_conventions)}


def offered_profiles(profiles: list[QoSProfile]) -> list[dict]:
    return [offered_profile(q) for q in profiles]


def _duration(ns: int) -> Duration:
    # rclpy's "unspecified" (0) is what rmw takes as infinite for an offer; keep it so.
    return Duration(nanoseconds=0 if ns >= INFINITE_NS else ns)


# Replay keeps every message of a stream: a subscriber that lags slows the replay instead of
# losing messages.
STREAM_DEPTH = 1000


def replay_qos(recorded) -> QoSProfile:
    """The profile to publish a recorded topic with, from its recorded offers (version 8 or 9,
    a list or its YAML): reliable unless every publisher was best effort, transient local (a
    latched topic replays latched, with the recorded depth) when every publisher was; deadline,
    lifespan and liveliness as recorded when all publishers offered the same, as rosbag2 does.
    Without a record: reliable and volatile."""
    profiles = parse_qos_profiles(recorded) if not isinstance(recorded, list) else \
        parse_qos_profiles(list(recorded))
    best_effort = bool(profiles) and all(p['reliability'] == 'best_effort' for p in profiles)
    latched = bool(profiles) and all(p['durability'] == 'transient_local' for p in profiles)
    depth = max((p['depth'] for p in profiles), default=0)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST if latched else HistoryPolicy.KEEP_ALL,
                     depth=max(depth, 1) if latched else STREAM_DEPTH,
                     reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                     else ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                     else DurabilityPolicy.VOLATILE)
    same = {(tuple(sorted(p['deadline'].items())), tuple(sorted(p['lifespan'].items())),
             p['liveliness'], tuple(sorted(p['liveliness_lease_duration'].items())))
            for p in profiles}
    if len(same) == 1:
        p = profiles[0]
        qos.deadline = _duration(duration_ns(p['deadline']))
        qos.lifespan = _duration(duration_ns(p['lifespan']))
        qos.liveliness_lease_duration = _duration(duration_ns(p['liveliness_lease_duration']))
        if p['liveliness'] in ('automatic', 'manual_by_topic'):
            qos.liveliness = LivelinessPolicy[p['liveliness'].upper()]
    return qos


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
