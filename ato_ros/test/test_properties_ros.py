"""Property-based tests: random and extreme input to the message conversions gives either a
valid result or the documented error, never anything else; and the other node helpers."""

import gc
import math
import weakref

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common.types import Command, Reference, ReferencePoint, TrainState
from ato_ros.lifecycle import freeze_startup_objects
from ato_ros.messages import (
    MessageError,
    command_from_msg,
    command_to_msg,
    reference_from_msg,
    reference_to_msg,
    state_from_msg,
    state_to_msg,
)

numbers = st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10**6, 10**6)



floats = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**62), st.lists(st.tuples(floats, floats, floats, floats), min_size=1,
                                        max_size=8))
def test_state_conversion_round_trips(stamp, cars):
    state = TrainState(stamp, tuple(f'car_{i}' for i in range(len(cars))),
                       *(tuple(c[k] for c in cars) for k in range(4)))
    assert state_from_msg(state_to_msg(state)) == state


@settings(max_examples=200, deadline=None)
@given(st.lists(numbers, min_size=0, max_size=3), st.lists(st.text(max_size=5), max_size=3))
def test_command_conversion_accepts_only_finite_forces_for_the_actuators(efforts, names):
    msg = command_to_msg(Command(0, tuple(names), (), 'pid'))
    msg.effort = [float(e) for e in efforts]
    try:
        command = command_from_msg(msg, ('traction',))
    except MessageError:
        return
    assert command.actuator_names == ('traction',)
    assert all(math.isfinite(f) for f in command.forces)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(floats, floats, floats), min_size=1, max_size=5))
def test_reference_conversion_round_trips(points):
    reference = Reference(10**9, tuple(ReferencePoint(1.0 + i, *p) for i, p in enumerate(points)))
    back = reference_from_msg(reference_to_msg(reference))
    assert [(p.position, p.speed, p.acceleration) for p in back.points] == points
    assert back.points[-1].time_s == pytest.approx(len(points))


class _Cycle:
    pass


def test_freezing_the_start_up_objects_collects_the_garbage_and_freezes_the_rest():
    # The nodes call it at the end of their start-up (constructing a node here would need
    # rclpy.init in the test process, which no unit test does).
    garbage = _Cycle()
    garbage.itself = garbage  # only a cyclic collection frees it
    dead = weakref.ref(garbage)
    del garbage
    try:
        freeze_startup_objects()
        assert dead() is None                # collected, not frozen for good
        assert gc.get_freeze_count() > 0     # the rest is out of the collector's sight
    finally:
        gc.unfreeze()  # the other tests of this process run with a normal collector
