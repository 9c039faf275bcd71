"""The rclpy edge of the conventions: QoS profiles, time stamps, message conversion and
diagnostics.

Only the node adapters import this module; the cores use :mod:`ato_common.types`.
"""

from __future__ import annotations

from typing import Callable, Sequence

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ato_common.conventions import REFERENCE_JOINT, TOPICS, QosSpec, Topic
from ato_common.types import NS_PER_S, Command, Reference, TrainState
from ato_ros.wire import (
    MessageError,
    UnknownEncoding,
    command_from_fields,
    reference_from_fields,
    state_from_fields,
)

__all__ = ['MessageError']  # re-exported: the nodes catch it from here


def qos_profile(spec: QosSpec) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST if spec.depth else HistoryPolicy.KEEP_ALL,
        depth=spec.depth or 1000,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local
                    else DurabilityPolicy.VOLATILE))


def topic(key: str) -> Topic:
    return TOPICS[key]


def to_time(stamp_ns: int) -> Time:
    return Time(sec=stamp_ns // NS_PER_S, nanosec=stamp_ns % NS_PER_S)


def from_time(stamp: Time) -> int:
    return stamp.sec * NS_PER_S + stamp.nanosec


def to_duration(time_s: float) -> Duration:
    ns = int(round(time_s * NS_PER_S))
    return Duration(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def from_duration(duration: Duration) -> float:
    return duration.sec + duration.nanosec * 1e-9


def state_to_msg(state: TrainState) -> JointTrajectory:
    msg = JointTrajectory()
    msg.header.stamp = to_time(state.stamp_ns)
    msg.joint_names = list(state.car_names)
    point = JointTrajectoryPoint()
    point.positions = list(state.positions)
    point.velocities = list(state.speeds)
    point.accelerations = list(state.accelerations)
    point.effort = list(state.forces)
    msg.points = [point]
    return msg


def _points(msg: JointTrajectory) -> list[tuple]:
    return [(p.positions, p.velocities, p.accelerations, p.effort,
             from_duration(p.time_from_start)) for p in msg.points]


def state_from_msg(msg: JointTrajectory) -> TrainState:
    return state_from_fields(from_time(msg.header.stamp), msg.joint_names, _points(msg))


def reference_to_msg(reference: Reference) -> JointTrajectory:
    msg = JointTrajectory()
    msg.header.stamp = to_time(reference.stamp_ns)
    msg.joint_names = [REFERENCE_JOINT]
    t0 = reference.points[0].time_s
    points = []
    for r in reference.points:
        point = JointTrajectoryPoint()
        point.positions = [r.position]
        point.velocities = [r.speed]
        point.accelerations = [r.acceleration]
        point.effort = [r.jerk]  # the reference's jerk (m/s^3) rides in the effort field
        point.time_from_start = to_duration(r.time_s - t0)
        points.append(point)
    msg.points = points
    return msg


def reference_from_msg(msg: JointTrajectory, time_origin_s: float = 0.0) -> Reference:
    """``time_origin_s`` maps the stamp to the curve's own time (0 in lockstep)."""
    return reference_from_fields(from_time(msg.header.stamp), msg.joint_names, _points(msg),
                                 time_origin_s)


def command_to_msg(command: Command) -> JointState:
    msg = JointState()
    msg.header.stamp = to_time(command.stamp_ns)
    msg.header.frame_id = command.law
    msg.name = list(command.actuator_names)
    msg.effort = list(command.forces)
    return msg


def actuator_forces_to_msg(stamp_ns: int, names: Sequence[str],
                           forces: Sequence[float]) -> JointState:
    """Force per actuated unit (commanded or applied) in effort, N."""
    msg = JointState()
    msg.header.stamp = to_time(stamp_ns)
    msg.name = list(names)
    msg.effort = [float(f) for f in forces]
    return msg


def command_from_msg(msg: JointState, expected_actuators: Sequence[str]) -> Command:
    """Validate a command against the plant's actuators; raise MessageError with the reason."""
    return command_from_fields(from_time(msg.header.stamp), msg.header.frame_id, msg.name,
                               msg.effort, expected_actuators)


def decoded(data: bytes, decode: Callable, msg_type, from_msg: Callable, *args):
    """A message taken raw (``create_subscription(..., raw=True)``), read by ``decode`` (an
    :mod:`ato_ros.wire` decoder); bytes in an encoding it does not read are deserialised by
    the middleware's own type support (``msg_type``) and converted by ``from_msg``, so that a
    publisher of any encoding is understood. Raises MessageError naming what is wrong."""
    try:
        return decode(data, *args)
    except UnknownEncoding:
        from rclpy.serialization import deserialize_message
        return from_msg(deserialize_message(data, msg_type), *args)


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      values: dict[str, object]) -> DiagnosticStatus:
    status = DiagnosticStatus()
    status.name = name
    status.hardware_id = hardware_id
    status.level = level
    status.message = message
    status.values = [KeyValue(key=k, value=_format_value(v)) for k, v in values.items()]
    return status


def _format_value(value: object) -> str:
    if isinstance(value, float):
        return f'{value:.9g}'
    return str(value)


def status_name(node, part: str) -> str:
    """The name of a node's diagnostics status: the node's fully qualified name without its
    leading slash, and what the status is about (``train_plant_node: simulation`` in the root
    namespace, ``train1/train_plant_node: simulation`` in ``/train1``), so that the statuses of
    two stacks on the one ``/diagnostics`` are told apart."""
    return f'{node.get_fully_qualified_name().lstrip("/")}: {part}'
