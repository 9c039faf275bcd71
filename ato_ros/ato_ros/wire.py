"""The per-step messages as bytes on the wire: CDR packed from templates and read back without
building rclpy message objects.

In lockstep on a 2-core machine the loop is CPU-bound, and most of a step's CPU is rclpy turning
Python message objects into the middleware's serialised form and back (each ``JointTrajectory``
is a tree of Python objects whose every field setter checks its type). The hot per-step topics
(``/clock``, the measured and true state, the reference, the command, the actuator forces, the
distance to go and the permitted speed) are therefore published as bytes already serialised
(``Publisher.publish(bytes)``) and taken raw (``create_subscription(..., raw=True)``). The types
on the wire stay the standard common_interfaces ones (``trajectory_msgs/msg/JointTrajectory``,
``sensor_msgs/msg/JointState``, ...), so ``ros2 topic echo``, a recorder or any other subscriber
sees ordinary messages (``ato_ros/test/test_wire.py`` checks every encoder against rclpy's own
serialisation and every decoder against rclpy's own messages).

The encoding is the one ROS 2's middlewares use for these types: the 4-byte encapsulation header
of the OMG DDS-XTypes specification (1.3, 7.6.3.1.2) followed by plain CDR, little-endian, each
primitive aligned to its size counted from the end of that header (``PLAIN_CDR``, the
``XCDR1`` of rmw_fastrtps and rmw_cyclonedds). A string is its length including the closing
NUL as uint32, its bytes and the NUL; a sequence is its length as uint32 and its elements;
``builtin_interfaces`` times are ``int32 sec, uint32 nanosec``. The padding bytes, which the
middleware leaves undefined, are written as zeros. The decoders read both byte orders and
``XCDR2`` plain encodings too (8-byte primitives aligned to 4); an encapsulation they do not know
raises :class:`UnknownEncoding`, and the node adapter then falls back to rclpy's deserialisation
(``ato_ros.Decoder``), so no publisher is refused for its encoding.

A message whose content breaks the suite's layout (two points in a state, a non-finite command
force) raises :class:`MessageError` with the same reason as the typed conversion in
:mod:`ato_ros`, because both end in the same checks (``*_from_fields`` here).
"""

from __future__ import annotations

import math
import struct
from functools import lru_cache
from typing import Callable, Sequence

from ato_common.conventions import REFERENCE_JOINT
from ato_common.types import NS_PER_S, Command, Reference, ReferencePoint, TrainState


class MessageError(ValueError):
    """A received message does not have the layout of the suite's conventions."""


class UnknownEncoding(MessageError):
    """Bytes in an encapsulation this module does not read (the caller deserialises them with
    the middleware's own type support instead)."""


# Encapsulation identifiers (DDS-XTypes 1.3, table 60): (little endian, largest alignment).
_ENCAPSULATIONS = {
    b'\x00\x00': (False, 8),  # CDR_BE (XCDR1)
    b'\x00\x01': (True, 8),   # CDR_LE (XCDR1)
    b'\x00\x06': (False, 4),  # CDR2_BE (plain XCDR2, final types)
    b'\x00\x07': (True, 4),   # CDR2_LE
}
_HEADER = b'\x00\x01\x00\x00'  # what the encoders write: CDR_LE, options 0


def _time_parts(stamp_ns: int) -> tuple[int, int]:
    return divmod(stamp_ns, NS_PER_S)


def _duration_parts(time_s: float) -> tuple[int, int]:
    """As ``ato_ros.messages.to_duration``: rounded to the nanosecond."""
    ns = int(round(time_s * NS_PER_S))
    return ns // NS_PER_S, ns % NS_PER_S


# --- templates ------------------------------------------------------------------------------

class _Layout:
    """One message layout as ``struct`` formats, built once per layout (names, counts): the
    constant parts (names, counts) and the padding at the offsets the alignment rule gives, and
    the variable slots (``i``, ``I``, ``d``) of the stamps and values.

    ``pack`` fills the slots in one ``Struct.pack`` (the padding written as zeros). ``unpack``
    reads bytes of the same layout in one ``unpack_from`` (the padding skipped, since the
    middleware leaves it undefined, and any bytes after the end) and returns the slots' values,
    or None when the bytes are not of this layout (shorter, another encoding or another
    constant part): the caller then reads them field by field."""

    def __init__(self):
        self.tokens: list[tuple] = []  # ('pad', n) | ('const', bytes) | ('var', code, count)
        self.offset = 0  # from the end of the encapsulation header

    def const(self, data: bytes) -> None:
        self.tokens.append(('const', data))
        self.offset += len(data)

    def pad(self, size: int) -> None:
        n = -self.offset % size
        if n:
            self.tokens.append(('pad', n))
            self.offset += n

    def u32(self, value: int) -> None:
        self.pad(4)
        self.const(struct.pack('<I', value))

    def string(self, text: str) -> None:
        data = text.encode() + b'\x00'
        self.u32(len(data))
        self.const(data)

    def var(self, code: str, count: int = 1) -> None:
        if count:
            size = struct.calcsize(code)
            self.pad(size)
            self.tokens.append(('var', code, count))
            self.offset += size * count

    def doubles(self, count: int) -> None:
        """A sequence of ``count`` doubles: its length, then the values (aligned to 8)."""
        self.u32(count)
        self.var('d', count)

    def build(self) -> '_Layout':
        pack_parts: list[str] = []
        self._order: list[bytes | None] = []  # None for a slot, bytes for a constant
        unpack_parts, constant_at, index = [], [], 0
        pending = b''
        for token in self.tokens + [('end',)]:
            if token[0] in ('pad', 'const'):
                pending += b'\x00' * token[1] if token[0] == 'pad' else token[1]
                if token[0] == 'pad':
                    unpack_parts.append(f'{token[1]}x')
                else:
                    unpack_parts.append(f'{len(token[1])}s')
                    constant_at.append((index, token[1]))
                    index += 1
                continue
            if pending:
                pack_parts.append(f'{len(pending)}s')
                self._order.append(pending)
                pending = b''
            if token[0] == 'var':
                _, code, count = token
                pack_parts.append(f'{count}{code}')
                unpack_parts.append(f'{count}{code}')
                self._order.extend([None] * count)
                index += count
        self._pack = struct.Struct('<' + ''.join(pack_parts))
        self._unpack = struct.Struct('<' + ''.join(unpack_parts))
        self._constants = tuple(constant_at)
        slots = [True] * index
        for i, _ in constant_at:
            slots[i] = False
        self._slots = tuple(i for i, is_slot in enumerate(slots) if is_slot)
        self.size = 4 + self._unpack.size
        self.pack_values = self._slots_packer()
        return self

    def _slots_packer(self):
        """A function of the slots' values, one argument each, that packs the message in one
        ``Struct.pack`` with the constant parts in between: generated once per layout, so a
        per-step message costs one call instead of a walk over the layout (the constants are
        the function's globals, never text in its source)."""
        arguments, parts, constants = [], [], {}
        for index, part in enumerate(self._order):
            if part is None:
                arguments.append(f'v{len(arguments)}')
                parts.append(arguments[-1])
            else:
                constants[f'c{index}'] = part
                parts.append(f'c{index}')
        source = (f'def pack_values({", ".join(arguments)}):\n'
                  f'    return HEADER + PACK({", ".join(parts)})\n')
        scope = {'HEADER': _HEADER, 'PACK': self._pack.pack, **constants}
        exec(source, scope)  # noqa: S102 - source built above from argument names only
        return scope['pack_values']

    def pack(self, values: Sequence) -> bytes:
        return self.pack_values(*values)

    def unpack(self, data: bytes) -> list | None:
        # (the middleware may pad the end: rmw_serialize gives up to 8 bytes more)
        if len(data) < self.size or data[:2] != _HEADER[:2]:
            return None
        fields = self._unpack.unpack_from(data, 4)
        for i, constant in self._constants:
            if fields[i] != constant:
                return None
        return [fields[i] for i in self._slots]


def _header(p: _Layout, frame_id: str) -> None:
    p.var('i')  # stamp.sec
    p.var('I')  # stamp.nanosec
    p.string(frame_id)


def _names(p: _Layout, names: Sequence[str]) -> None:
    p.u32(len(names))
    for name in names:
        p.string(name)


@lru_cache(maxsize=64)
def _trajectory_layout(frame_id: str, names: tuple[str, ...], points: int,
                       values_per_field: int, with_effort: bool):
    p = _Layout()
    _header(p, frame_id)
    _names(p, names)
    p.u32(points)
    for _ in range(points):
        for _field in range(3):
            p.doubles(values_per_field)
        p.doubles(values_per_field if with_effort else 0)
        p.var('i')  # time_from_start.sec
        p.var('I')  # time_from_start.nanosec
    return p.build()


@lru_cache(maxsize=64)
def _joint_state_layout(frame_id: str, names: tuple[str, ...]):
    p = _Layout()
    _header(p, frame_id)
    _names(p, names)
    p.doubles(0)  # position
    p.doubles(0)  # velocity
    p.doubles(len(names))  # effort
    return p.build()


_CLOCK = struct.Struct('<iI')
_FLOAT64 = struct.Struct('<d')


# --- encoders -------------------------------------------------------------------------------

def encode_clock(stamp_ns: int) -> bytes:
    """``rosgraph_msgs/msg/Clock``."""
    return _HEADER + _CLOCK.pack(*divmod(stamp_ns, NS_PER_S))


def encode_float64(value: float) -> bytes:
    """``std_msgs/msg/Float64``."""
    return _HEADER + _FLOAT64.pack(value)


def encode_state(state: TrainState, stamp_ns: int | None = None,
                 run_time_s: float = 0.0) -> bytes:
    """``trajectory_msgs/msg/JointTrajectory`` as :func:`ato_ros.messages.state_to_msg` lays it out
    (one point, one value per car), stamped ``stamp_ns`` (default: the state's own stamp), with
    ``run_time_s`` in the point's ``time_from_start``."""
    n = len(state.car_names)
    layout = _trajectory_layout('', tuple(state.car_names), 1, n, True)
    stamp = state.stamp_ns if stamp_ns is None else stamp_ns
    return layout.pack_values(*divmod(stamp, NS_PER_S), *state.positions, *state.speeds,
                              *state.accelerations, *state.forces, *_duration_parts(run_time_s))


def encode_reference(reference: Reference) -> bytes:
    """``trajectory_msgs/msg/JointTrajectory`` as :func:`ato_ros.messages.reference_to_msg` lays it
    out (joint ``train``, one point per preview instant, the jerk in ``effort``)."""
    points = reference.points
    layout = _trajectory_layout('', (REFERENCE_JOINT,), len(points), 1, True)
    t0 = points[0].time_s
    values: list = [*_time_parts(reference.stamp_ns)]
    for r in points:
        values += (r.position, r.speed, r.acceleration, r.jerk, *_duration_parts(r.time_s - t0))
    return layout.pack(values)


def encode_joint_forces(stamp_ns: int, names: Sequence[str], forces: Sequence[float],
                        frame_id: str = '') -> bytes:
    """``sensor_msgs/msg/JointState`` with one force (N) per name in ``effort``, empty
    ``position`` and ``velocity``: the command (``frame_id`` = the law) and the actuator forces
    (``ato_ros.messages.command_to_msg``, ``actuator_forces_to_msg``)."""
    layout = _joint_state_layout(frame_id, tuple(names))
    return layout.pack_values(*divmod(stamp_ns, NS_PER_S), *map(float, forces))


def joint_forces_encoder(names: Sequence[str],
                         frame_id: str = '') -> Callable[[int, Sequence[float]], bytes]:
    """:func:`encode_joint_forces` for one set of names, as a function of the stamp and the
    forces (real numbers): the layout looked up once, for a node that encodes the same
    actuators at every step (the plant's actuator forces)."""
    pack_values = _joint_state_layout(frame_id, tuple(names)).pack_values

    def encode(stamp_ns: int, forces: Sequence[float]) -> bytes:
        return pack_values(*divmod(stamp_ns, NS_PER_S), *forces)
    return encode


@lru_cache(maxsize=16)
def _header_layout(frame_id: str):
    p = _Layout()
    _header(p, frame_id)
    return p.build()


def encode_header(stamp_ns: int, frame_id: str) -> bytes:
    """``std_msgs/msg/Header``."""
    return _header_layout(frame_id).pack(_time_parts(stamp_ns))


def encode_command(command: Command) -> bytes:
    return encode_joint_forces(command.stamp_ns, command.actuator_names, command.forces,
                               command.law)


# --- decoders -------------------------------------------------------------------------------

class _Reader:
    def __init__(self, data: bytes):
        if len(data) < 4:
            raise MessageError(f'{len(data)} bytes: too short for a serialised message')
        encoding = _ENCAPSULATIONS.get(bytes(data[:2]))
        if encoding is None:
            raise UnknownEncoding(f'encapsulation 0x{bytes(data[:2]).hex()} is not plain CDR')
        little, self.max_align = encoding
        self.e = '<' if little else '>'
        self.data, self.offset = data, 4
        self.u32 = struct.Struct(self.e + 'I')
        self.i32 = struct.Struct(self.e + 'i')

    def _align(self, size: int) -> None:
        self.offset += -(self.offset - 4) % min(size, self.max_align)

    def uint32(self) -> int:
        self._align(4)
        (value,) = self.u32.unpack_from(self.data, self.offset)
        self.offset += 4
        return value

    def int32(self) -> int:
        self._align(4)
        (value,) = self.i32.unpack_from(self.data, self.offset)
        self.offset += 4
        return value

    def time_ns(self) -> int:
        sec = self.int32()
        return sec * NS_PER_S + self.uint32()

    def string(self) -> str:
        size = self.uint32()
        end = self.offset + size
        if size == 0 or end > len(self.data) or self.data[end - 1] != 0:
            raise MessageError('a string of the message is not NUL-terminated in its bytes')
        text = bytes(self.data[self.offset:end - 1]).decode()
        self.offset = end
        return text

    def strings(self) -> tuple[str, ...]:
        return tuple(self.string() for _ in range(self._count(4)))

    def doubles(self) -> tuple[float, ...]:
        count = self._count(8)
        if not count:
            return ()
        self._align(8)
        values = struct.unpack_from(f'{self.e}{count}d', self.data, self.offset)
        self.offset += 8 * count
        return values

    def float64(self) -> float:
        self._align(8)
        (value,) = struct.unpack_from(self.e + 'd', self.data, self.offset)
        self.offset += 8
        return value

    def _count(self, element_size: int) -> int:
        count = self.uint32()
        if count * element_size > len(self.data) - self.offset:
            raise MessageError(f'a sequence of {count} elements is longer than the message')
        return count


def _read(decode):
    """Turn a read past the end of the bytes into a MessageError."""
    def wrapper(data, *args, **kwargs):
        try:
            return decode(data, *args, **kwargs)
        except struct.error as error:
            raise MessageError(f'truncated message: {error}') from None
        except UnicodeDecodeError as error:
            raise MessageError(f'a string of the message is not UTF-8: {error}') from None
    wrapper.__doc__, wrapper.__name__ = decode.__doc__, decode.__name__
    return wrapper


TrajectoryPoint = tuple  # (positions, velocities, accelerations, effort, time_from_start_s)


def _trajectory(data: bytes):
    r = _Reader(data)
    stamp_ns = r.time_ns()
    frame_id = r.string()
    names = r.strings()
    points = []
    for _ in range(r._count(4)):
        fields = (r.doubles(), r.doubles(), r.doubles(), r.doubles())
        sec = r.int32()
        points.append((*fields, sec + r.uint32() * 1e-9))
    return stamp_ns, frame_id, names, points


@_read
def decode_trajectory(data: bytes) -> tuple[int, tuple[str, ...], list[TrajectoryPoint]]:
    """A ``JointTrajectory``: (stamp ns, joint names, points), each point (positions,
    velocities, accelerations, effort, time_from_start s)."""
    stamp_ns, _, names, points = _trajectory(data)
    return stamp_ns, names, points


def stamp_of(data: bytes) -> int | None:
    """The stamp of a stamped message (its ``std_msgs/Header`` comes first), ns, or None when
    even that cannot be read: what a node can still say of a message it refuses."""
    try:
        return _Reader(data).time_ns()
    except (MessageError, struct.error):
        return None


@_read
def decode_clock(data: bytes) -> int:
    """A ``rosgraph_msgs/msg/Clock``: its time, ns."""
    return _Reader(data).time_ns()


@_read
def decode_header(data: bytes) -> tuple[int, str]:
    """A ``std_msgs/msg/Header``: (stamp ns, frame_id)."""
    r = _Reader(data)
    return r.time_ns(), r.string()


@_read
def decode_float64(data: bytes) -> float:
    return _Reader(data).float64()


@_read
def decode_joint_state(data: bytes) -> tuple[int, str, tuple[str, ...], tuple[float, ...],
                                               tuple[float, ...], tuple[float, ...]]:
    """A ``sensor_msgs/msg/JointState``: (stamp ns, frame_id, names, position, velocity,
    effort)."""
    r = _Reader(data)
    stamp_ns = r.time_ns()
    frame_id = r.string()
    names = r.strings()
    return stamp_ns, frame_id, names, r.doubles(), r.doubles(), r.doubles()


class _Recent:
    """The layout of the last message a decoder read field by field, and what it held: the
    next message of that layout (the usual case: one publisher, fixed names) is read in one
    ``unpack`` (:meth:`_Layout.unpack`)."""

    def __init__(self):
        self.layout: _Layout | None = None
        self.names: tuple[str, ...] = ()
        self.frame_id = ''

    def values(self, data: bytes) -> list | None:
        return None if self.layout is None else self.layout.unpack(data)


_recent_state, _recent_reference, _recent_command = _Recent(), _Recent(), _Recent()


@_read
def decode_state(data: bytes) -> TrainState:
    """A measured or true state (``encode_state``'s layout, from any publisher)."""
    recent = _recent_state
    v = recent.values(data)
    if v is not None:
        n = len(recent.names)
        return TrainState(v[0] * NS_PER_S + v[1], recent.names, tuple(v[2:2 + n]),
                          tuple(v[2 + n:2 + 2 * n]), tuple(v[2 + 2 * n:2 + 3 * n]),
                          tuple(v[2 + 3 * n:2 + 4 * n]))
    stamp_ns, frame_id, names, points = _trajectory(data)
    state = state_from_fields(stamp_ns, names, points)
    recent.layout = _trajectory_layout(frame_id, names, 1, len(names), True)
    recent.names = names
    return state


@_read
def decode_reference(data: bytes, time_origin_s: float = 0.0) -> Reference:
    """A reference (``encode_reference``'s layout, from any publisher)."""
    recent = _recent_reference
    v = recent.values(data)
    if v is not None:
        stamp_ns = v[0] * NS_PER_S + v[1]
        t0 = stamp_ns / NS_PER_S - time_origin_s
        return Reference(stamp_ns, tuple(
            ReferencePoint(t0 + (v[i + 4] + v[i + 5] * 1e-9), v[i], v[i + 1], v[i + 2], v[i + 3])
            for i in range(2, len(v), 6)))
    stamp_ns, frame_id, names, points = _trajectory(data)
    reference = reference_from_fields(stamp_ns, names, points, time_origin_s)
    if all(len(p[3]) == 1 for p in points):  # a jerk in every point: the usual layout
        recent.layout = _trajectory_layout(frame_id, names, len(points), 1, True)
    return reference


@_read
def decode_command(data: bytes, expected_actuators: Sequence[str]) -> Command:
    """A command, checked against the plant's actuators (``command_from_fields``)."""
    recent = _recent_command
    v = recent.values(data)
    if v is not None:
        return command_from_fields(v[0] * NS_PER_S + v[1], recent.frame_id, recent.names,
                                   v[2:], expected_actuators)
    stamp_ns, law, names, position, velocity, effort = decode_joint_state(data)
    command = command_from_fields(stamp_ns, law, names, effort, expected_actuators)
    if not position and not velocity:
        recent.layout = _joint_state_layout(law, names)
        recent.names, recent.frame_id = names, law
    return command


# --- the suite's layout checks (shared with the typed conversion in ato_ros) ----------

def state_from_fields(stamp_ns: int, names: Sequence[str],
                      points: Sequence[TrajectoryPoint]) -> TrainState:
    n = len(names)
    if len(points) != 1:
        raise MessageError(f'train state must have exactly one point, got {len(points)}')
    p = points[0]
    for field, values in zip(('positions', 'velocities', 'accelerations', 'effort'), p):
        if len(values) != n:
            raise MessageError(f'train state {field} has {len(values)} values for {n} cars')
    return TrainState(stamp_ns, tuple(names), tuple(p[0]), tuple(p[1]), tuple(p[2]),
                      tuple(p[3]))


def reference_from_fields(stamp_ns: int, names: Sequence[str],
                          points: Sequence[TrajectoryPoint],
                          time_origin_s: float = 0.0) -> Reference:
    """``time_origin_s`` maps the stamp to the curve's own time (0 in lockstep)."""
    if list(names) != [REFERENCE_JOINT] or not points:
        raise MessageError(f'reference must have joint_names [{REFERENCE_JOINT!r}] and at least '
                           f'one point, got {list(names)} with {len(points)} points')
    t0 = stamp_ns / NS_PER_S - time_origin_s
    out = []
    for positions, velocities, accelerations, effort, time_s in points:
        if not (len(positions) == len(velocities) == len(accelerations) == 1):
            raise MessageError('each reference point needs one position, velocity and acceleration')
        if len(effort) > 1:
            raise MessageError(f'a reference point carries at most one jerk (effort), got '
                               f'{len(effort)}')
        out.append(ReferencePoint(t0 + time_s, positions[0], velocities[0], accelerations[0],
                                  effort[0] if effort else 0.0))
    return Reference(stamp_ns, tuple(out))


def command_from_fields(stamp_ns: int, law: str, names: Sequence[str], effort: Sequence[float],
                        expected_actuators: Sequence[str]) -> Command:
    """Validate a command against the plant's actuators; raise MessageError with the reason."""
    names = tuple(names)
    if names != tuple(expected_actuators):
        raise MessageError(f'command names {list(names)} do not match the actuators '
                           f'{list(expected_actuators)}')
    if len(effort) != len(names):
        raise MessageError(f'command has {len(effort)} efforts for {len(names)} actuators')
    forces = tuple(float(f) for f in effort)
    bad = [n for n, f in zip(names, forces) if not math.isfinite(f)]
    if bad:
        raise MessageError(f'command force of {", ".join(bad)} is not finite')
    return Command(stamp_ns, names, forces, law)
