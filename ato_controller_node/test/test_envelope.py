"""The host's ATO envelope (ato_controller_node.envelope), the same for every law: after a long
saturation every law overshoots the reference speed far less with it than without, and while the
command is not saturated it changes nothing; the PID's own conditional integration and its
grade feedforward."""

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


#: the laws that drive the single-mass train of short_line
SINGLE_MASS_LAWS = ('pid', 'luo_xu', 'luo_xu_projection', 'tan_second_level',
                    'tan_second_level_adaptive', 'tan_switching_mm', 'tan_weighted_mm')


def closed_loop(train, accel, cruise, law='pid', envelope=True, seconds=400.0):
    """The host and ``law`` on the nominal train itself (a point mass, the nominal Davis
    resistance, forces applied as commanded): (speed errors v - v*, forces, saturated steps)."""
    host = ControllerHost(train, DT, law, envelope=envelope)
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


@pytest.mark.parametrize('law', SINGLE_MASS_LAWS)
def test_after_a_long_saturation_every_law_overshoots_far_less_with_the_envelope(train, law):
    # The reference asks 3x what the traction can give for over a minute: the train falls
    # hundreds of metres behind while the command is saturated.
    top = train.traction.max_traction_at(0.0) / train.nominal_mass_kg
    accel, cruise = 3.0 * top, 20.0
    with_aw, _, saturated = closed_loop(train, accel, cruise, law, seconds=600.0)
    without, _, saturated_without = closed_loop(train, accel, cruise, law, envelope=False,
                                                seconds=600.0)
    assert saturated > 250 and saturated_without > 250   # a long saturation in both
    over_with, over_without = max(with_aw), max(without)
    assert over_without > 5.0                        # wound up: catches up at overspeed
    assert over_with < 0.4 * over_without            # with the envelope, 40 % at most
    assert over_with < 6.0                           # measured 1.2 (pid) to 5.6 m/s (Tan)
    # both still make up the distance: back on the reference speed at the end
    assert abs(with_aw[-1]) < 0.05 and abs(without[-1]) < 0.05


@pytest.mark.parametrize('law', SINGLE_MASS_LAWS)
def test_unsaturated_the_envelope_changes_nothing(train, law):
    top = train.traction.max_traction_at(0.0) / train.nominal_mass_kg
    accel, cruise = 0.3 * top, 20.0   # well within the limits
    errors, forces, saturated = closed_loop(train, accel, cruise, law, seconds=200.0)
    off_errors, off_forces, _ = closed_loop(train, accel, cruise, law, envelope=False,
                                            seconds=200.0)
    assert saturated == 0
    assert forces == off_forces and errors == off_errors   # bit for bit the same law


def test_the_envelope_is_the_hosts_no_law_keeps_one_of_its_own():
    """The PID's former private reference shift is gone: its settings are its gains, and the
    host's envelope settings are refused as a law's."""
    from ato_controller_node.laws.base import setting_fields
    from ato_controller_node.laws.pid import PidSettings
    names = {f.name for f in setting_fields(PidSettings)}
    assert not names & {'tracking_time_s', 'catch_up_speed_mps', 'catch_up_deceleration_mps2'}
    host = ControllerHost(TrainKnowledge.of(load_scenario('short_line').train), DT, 'pid',
                          envelope_settings={'tracking_time_s': 5.0})
    assert host.envelope.settings.tracking_time_s == 5.0
    with pytest.raises(ValueError, match='tracking_time_s must be within'):
        ControllerHost(TrainKnowledge.of(load_scenario('short_line').train), DT, 'pid',
                       envelope_settings={'tracking_time_s': -1.0})


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
