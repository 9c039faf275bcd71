"""The bytes of ato_ros.wire are the standard messages: every encoder is checked against
rclpy's own deserialisation, every decoder against rclpy's own serialisation (whose padding bytes
are undefined) and against the typed conversion in ato_ros, on random content."""

import math
import random
import struct

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from trajectory_msgs.msg import JointTrajectory

from ato_common.types import Command, Reference, ReferencePoint, TrainState
from ato_ros import wire
from ato_ros.messages import (
    MessageError,
    actuator_forces_to_msg,
    command_from_msg,
    command_to_msg,
    decoded,
    reference_from_msg,
    reference_to_msg,
    state_from_msg,
    state_to_msg,
    to_duration,
    to_time,
)

rng = random.Random(20261202)


def _value() -> float:
    return rng.choice([0.0, -0.0, 1e-300, -3.5e12, rng.uniform(-1e6, 1e6), math.pi])


def _state(cars: int) -> TrainState:
    names = tuple(f'car_{i}' * rng.randint(1, 3) for i in range(cars))
    return TrainState(rng.randint(0, 10**13), names, *(tuple(_value() for _ in names)
                                                       for _field in range(4)))


def _reference(points: int) -> Reference:
    t0 = rng.uniform(0, 5000)
    return Reference(rng.randint(0, 10**13), tuple(
        ReferencePoint(t0 + 0.1 * i, _value(), _value(), _value(), _value())
        for i in range(points)))


def _command(actuators: int) -> Command:
    return Command(rng.randint(0, 10**13), tuple(f'drive_{i}' for i in range(actuators)),
                   tuple(_value() for _ in range(actuators)), rng.choice(['pid', 'luo_xu', 'é']))


@pytest.mark.parametrize('cars', [1, 2, 4, 8])
def test_a_state_is_the_standard_message_both_ways(cars):
    for _ in range(20):
        state = _state(cars)
        run_time_s = rng.uniform(0, 1e4)
        expected = state_to_msg(state)
        expected.points[0].time_from_start = to_duration(run_time_s)
        assert deserialize_message(wire.encode_state(state, run_time_s=run_time_s),
                                   JointTrajectory) == expected
        data = serialize_message(expected)
        for _twice in range(2):  # read field by field, then by the layout it learnt
            assert wire.decode_state(data) == state_from_msg(expected) == state


def test_a_state_stamped_apart_from_its_content():
    state = _state(1)
    msg = deserialize_message(wire.encode_state(state, stamp_ns=42), JointTrajectory)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 42)


@pytest.mark.parametrize('points', [1, 3, 11])
def test_a_reference_is_the_standard_message_both_ways(points):
    for _ in range(20):
        reference = _reference(points)
        expected = reference_to_msg(reference)
        assert deserialize_message(wire.encode_reference(reference), JointTrajectory) == expected
        data = serialize_message(expected)
        origin = rng.choice([0.0, 1234.5])
        for _twice in range(2):
            assert wire.decode_reference(data, origin) == reference_from_msg(expected, origin)


@pytest.mark.parametrize('actuators', [1, 4])
def test_commands_and_actuator_forces_are_the_standard_message_both_ways(actuators):
    for _ in range(20):
        command = _command(actuators)
        expected = command_to_msg(command)
        assert deserialize_message(wire.encode_command(command), JointState) == expected
        data = serialize_message(expected)
        for _twice in range(2):
            assert wire.decode_command(data, command.actuator_names) == command
        forces = actuator_forces_to_msg(command.stamp_ns, command.actuator_names, command.forces)
        assert deserialize_message(wire.encode_joint_forces(
            command.stamp_ns, command.actuator_names, command.forces), JointState) == forces
        # the plant's encoder of its actuators: the same bytes, for every stamp and forces
        encode = wire.joint_forces_encoder(command.actuator_names)
        assert encode(command.stamp_ns, command.forces) == wire.encode_joint_forces(
            command.stamp_ns, command.actuator_names, command.forces)
        whole = [int(f) for f in command.forces]  # any real number, as encode_joint_forces
        assert encode(command.stamp_ns, whole) == wire.encode_joint_forces(
            command.stamp_ns, command.actuator_names, whole)


def test_clock_and_float64():
    for stamp in (0, 1, 999_999_999, 1_000_000_000, 123_456_789_012_345):
        data = wire.encode_clock(stamp)
        assert deserialize_message(data, Clock) == Clock(clock=to_time(stamp))
        assert wire.decode_clock(serialize_message(Clock(clock=to_time(stamp)))) == stamp
    for value in (0.0, -2.5, 1e308):
        assert deserialize_message(wire.encode_float64(value), Float64).data == value
        assert wire.decode_float64(serialize_message(Float64(data=value))) == value


def test_nan_and_infinities_pass_bit_for_bit():
    state = TrainState(5, ('train',), (math.nan,), (math.inf,), (-math.inf,), (math.nan,))
    back = wire.decode_state(wire.encode_state(state))
    assert all(math.isnan(v) for v in back.positions + back.forces)
    assert back.speeds == (math.inf,) and back.accelerations == (-math.inf,)


def test_messages_of_another_layout_after_a_learnt_one_are_read_field_by_field():
    """The learnt layout is only a fast path: names, counts and frame ids that differ from it
    are read correctly, not forced into it."""
    for cars in (1, 4, 1, 2, 4):
        state = _state(cars)
        assert wire.decode_state(serialize_message(state_to_msg(state))) == state
    for points in (3, 1, 3, 5):
        reference = _reference(points)
        msg = reference_to_msg(reference)
        assert wire.decode_reference(serialize_message(msg)) == reference_from_msg(msg)
    msg = reference_to_msg(_reference(3))
    msg.points[1].effort = []  # a point without a jerk: 0
    assert wire.decode_reference(serialize_message(msg)) == reference_from_msg(msg)
    for law in ('pid', 'luo_xu', 'pid'):
        command = Command(7, ('a', 'b'), (1.0, 2.0), law)
        assert wire.decode_command(serialize_message(command_to_msg(command)), ('a', 'b')) \
            == command


def _big_endian_state(state: TrainState) -> bytes:
    """The same message in big-endian CDR, written here independently of the module."""
    out = bytearray(b'\x00\x00\x00\x00')

    def put(fmt, *values):
        size = struct.calcsize('>' + fmt[-1])
        out.extend(b'\x00' * (-(len(out) - 4) % size))
        out.extend(struct.pack('>' + fmt, *values))

    def string(text):
        data = text.encode() + b'\x00'
        put('I', len(data))
        out.extend(data)

    put('i', state.stamp_ns // 10**9)
    put('I', state.stamp_ns % 10**9)
    string('')
    put('I', len(state.car_names))
    for name in state.car_names:
        string(name)
    put('I', 1)
    for values in (state.positions, state.speeds, state.accelerations, state.forces):
        put('I', len(values))
        put(f'{len(values)}d', *values)
    put('i', 0)
    put('I', 0)
    return bytes(out)


def test_big_endian_bytes_are_read():
    state = _state(3)
    assert wire.decode_state(_big_endian_state(state)) == state


def test_an_unknown_encapsulation_is_left_to_the_middleware(monkeypatch):
    state = _state(1)
    data = serialize_message(state_to_msg(state))
    with pytest.raises(wire.UnknownEncoding, match='encapsulation 0x0002'):
        wire.decode_state(b'\x00\x02' + data[2:])
    # the adapter's fallback: the middleware's type support reads what the module does not
    seen = []
    monkeypatch.setattr(wire, '_ENCAPSULATIONS', {})
    assert decoded(data, wire.decode_state, JointTrajectory,
                   lambda msg: seen.append(msg) or state_from_msg(msg)) == state
    assert len(seen) == 1


def test_malformed_bytes_are_a_message_error_naming_the_fault():
    state = _state(2)
    data = wire.encode_state(state)
    for cut in (2, 10, 30, len(data) - 3):
        with pytest.raises(MessageError):
            wire.decode_state(data[:cut])
    two_points = state_to_msg(state)
    two_points.points = two_points.points * 2
    with pytest.raises(MessageError, match='exactly one point, got 2'):
        wire.decode_state(serialize_message(two_points))
    short = state_to_msg(state)
    short.points[0].effort = [1.0]
    with pytest.raises(MessageError, match='effort has 1 values for 2 cars'):
        wire.decode_state(serialize_message(short))
    huge = bytearray(data)
    huge[4 + 8 + 8:4 + 8 + 12] = struct.pack('<I', 10**9)  # joint_names count
    with pytest.raises(MessageError, match='longer than the message'):
        wire.decode_state(bytes(huge))


def test_a_command_is_checked_as_the_typed_conversion_checks_it():
    for command, expected, reason in (
            (Command(1, ('a',), (math.nan,), 'pid'), ('a',), 'force of a is not finite'),
            (Command(1, ('b',), (1.0,), 'pid'), ('a',), "names \\['b'\\] do not match"),
    ):
        msg = command_to_msg(command)
        for read in (lambda: wire.decode_command(serialize_message(msg), expected),
                     lambda: command_from_msg(msg, expected)):
            with pytest.raises(MessageError, match=reason):
                read()
