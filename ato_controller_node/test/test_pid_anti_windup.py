"""The PID's anti-windup (back-calculation of the position error, conditional integration):
after a long saturation it overshoots the reference speed far less than without, and while the
command is not saturated it is the same law."""

from __future__ import annotations

import math

import pytest

from ato_common.knowledge import TrainKnowledge
from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement

DT = 0.1


@pytest.fixture(scope='module')
def train():
    return TrainKnowledge.of(load_scenario('short_line').train)


def reference(t: float, accel: float, cruise: float) -> ReferencePoint:
    """Accelerate at ``accel`` from standstill to ``cruise``, then hold it."""
    ramp = cruise / accel
    if t < ramp:
        return ReferencePoint(t, 0.5 * accel * t * t, accel * t, accel)
    return ReferencePoint(t, 0.5 * accel * ramp * ramp + cruise * (t - ramp), cruise, 0.0)


def closed_loop(train, accel, cruise, settings=None, seconds=400.0):
    """The host and the PID on the nominal train itself (a point mass, the nominal Davis
    resistance, forces applied as commanded): (speed errors v - v*, forces, saturated steps)."""
    host = ControllerHost(train, DT, 'pid', {'pid': settings or {}})
    x, v = 0.0, 0.0
    errors, forces, saturated = [], [], 0
    for k in range(int(seconds / DT)):
        t = k * DT
        ref = reference(t, accel, cruise)
        result = host.step(Measurement(t, x, v), ref)
        force = result.total_force_n
        saturated += result.saturated
        accel_now = (force - train.nominal_davis.force(v)) / train.nominal_mass_kg
        x, v = x + v * DT + 0.5 * accel_now * DT * DT, max(v + accel_now * DT, 0.0)
        errors.append(v - ref.speed)
        forces.append(force)
    return errors, forces, saturated


def test_after_a_long_saturation_the_overspeed_is_far_smaller_with_anti_windup(train):
    # The reference asks 3x what the traction can give for over a minute: the train falls
    # hundreds of metres behind while the command is saturated.
    top = train.traction.max_traction_at(0.0) / train.nominal_mass_kg
    accel, cruise = 3.0 * top, 20.0
    with_aw, _, saturated = closed_loop(train, accel, cruise, seconds=600.0)
    without, _, saturated_without = closed_loop(train, accel, cruise, {'tracking_time_s': 0.0},
                                                seconds=600.0)
    assert saturated > 300 and saturated_without > 300   # a long saturation in both
    over_with, over_without = max(with_aw), max(without)
    assert over_without > 10.0                       # wound up: catches up at overspeed
    assert over_with < 0.2 * over_without            # with anti-windup, a fifth at most
    assert over_with < 1.0 + 0.5                     # about catch_up_speed_mps (1 m/s)
    # both still make up the distance: back on the reference speed at the end
    assert abs(with_aw[-1]) < 0.05 and abs(without[-1]) < 0.05


def test_unsaturated_the_anti_windup_changes_nothing(train):
    top = train.traction.max_traction_at(0.0) / train.nominal_mass_kg
    accel, cruise = 0.3 * top, 20.0   # well within the limits
    errors, forces, saturated = closed_loop(train, accel, cruise, seconds=200.0)
    off_errors, off_forces, _ = closed_loop(train, accel, cruise, {'tracking_time_s': 0.0},
                                            seconds=200.0)
    assert saturated == 0
    assert forces == off_forces and errors == off_errors   # bit for bit the same law
    assert max(map(abs, errors)) < 0.05


def test_the_grade_feedforward_is_the_known_grade_force_and_zero_when_hidden():
    scenario = load_scenario('short_line')
    from ato_common.knowledge import knowledge_of
    known, hidden = knowledge_of(scenario), knowledge_of(scenario, hide_gradient=True)
    m = Measurement(0.0, 18000.0, 30.0)   # on the 12 per mille grade
    r = ReferencePoint(0.0, 18000.0, 30.0, 0.0)
    forces = {}
    for name, train in (('known', known), ('hidden', hidden)):
        host = ControllerHost(train, DT, 'pid')
        forces[name] = host.step(m, r).wanted_force_n
    grade = known.nominal_mass_kg * 9.80665 * math.sin(math.atan(0.012))
    assert known.grade_force_n(18000.0) == pytest.approx(grade, rel=1e-3)
    assert forces['known'] - forces['hidden'] == pytest.approx(grade, rel=1e-3)
    off = ControllerHost(known, DT, 'pid', {'pid': {'grade_feedforward': False}})
    assert off.step(m, r).wanted_force_n == pytest.approx(forces['hidden'])
