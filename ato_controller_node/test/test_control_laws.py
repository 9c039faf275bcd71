import math

import numpy as np
import pytest
from scipy.linalg import expm

from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost, LawRejected
from ato_controller_node.laws import LAWS, law_class
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.luo_xu import GAIN_PRESETS, LuoXuLaw


@pytest.fixture(scope='module')
def scenario():
    return load_scenario('short_line')


@pytest.fixture
def train(scenario):
    return TrainKnowledge.of(scenario.train)


def test_registry_lists_the_laws_and_rejects_unknown_names():
    assert {'pid', 'luo_xu'} <= set(LAWS)
    with pytest.raises(KeyError, match='valid: (.*, )?luo_xu, (.*, )?pid'):
        law_class('mpc')


def test_luo_xu_runs_the_printed_varphi_by_default_and_the_former_fix_only_if_asked(train):
    m = Measurement(0.0, 10.0, 20.0)
    r = ReferencePoint(0.0, 0.0, 20.0, 0.0)
    printed = LuoXuLaw(train, 0.1)
    fixed = LuoXuLaw(train, 0.1, validated_settings(LuoXuLaw.Settings, {'fixed_varphi': True}))
    # z1 = 10 m, z2 = c1 z1 = 1 m/s: the printed varphi is c1^2 z1 - (c1 + c2) z2
    c1, c2 = printed.settings.c1, printed.settings.c2
    specific = train.nominal_davis.force(20.0) / train.nominal_mass_kg
    assert printed.step(m, r).force_n == pytest.approx(
        train.nominal_mass_kg * (specific + c1 * c1 * 10.0 - (c1 + c2) * c1 * 10.0))
    # the former [FIX] (c1^2 - 1) z1: 1 m/s^2 per metre less
    diff = printed.step(m, r).force_n - fixed.step(m, r).force_n
    assert diff == pytest.approx(train.nominal_mass_kg * 10.0)


@pytest.mark.parametrize('fixed_varphi', [False, True])
def test_luo_xu_augmented_error_model_is_the_error_dynamics_of_the_law_that_runs(
        train, fixed_varphi):
    """The auxiliary model of the augmented error must be the law's own error dynamics
    (z1, z2)' with exact parameters: measured here from the law's force itself, on the nominal
    plant x'' = F/m - theta^T phi, by finite differences of (z1, z2)."""
    law = LuoXuLaw(train, 0.1, validated_settings(
        LuoXuLaw.Settings, {'fixed_varphi': fixed_varphi, 'c1': 0.3, 'c2': 0.2}))
    mass, davis = train.nominal_mass_kg, train.nominal_davis
    r = ReferencePoint(0.0, 1000.0, 50.0, 0.1)
    columns = []
    for dz1, dz2 in ((1.0, 0.0), (0.0, 1.0)):
        # the state with z1 = dz1, z2 = dz2: x = x* + z1, v = x*' + z2 - c1 z1
        x, v = r.position + dz1, r.speed + dz2 - law.settings.c1 * dz1
        law.reset(Measurement(0.0, x, v), r, None)
        force = law.step(Measurement(0.0, x, v), r).force_n
        accel = (force - davis.force(v)) / mass
        # z1' = v - x*', z2' = v' - x*'' + c1 z1'
        z1_dot = v - r.speed
        columns.append((z1_dot, accel - r.acceleration + law.settings.c1 * z1_dot))
    measured = np.array([[columns[0][0], columns[1][0]], [columns[0][1], columns[1][1]]])
    # the auxiliary model steps exactly that matrix over a period
    assert np.allclose(law._aux_step, expm(measured * 0.1), rtol=0.0, atol=1e-9)
    assert np.allclose(law.error_dynamics(), measured, rtol=0.0, atol=1e-9)


def test_settings_of_another_law_are_refused_by_name(train):
    with pytest.raises(ValueError, match="printed_varphi.*not a setting of luo_xu|not a setting"):
        validated_settings(LuoXuLaw.Settings, {'printed_varphi': True})


def test_luo_xu_adaptation_freezes_under_saturation_if_asked(train):
    law = LuoXuLaw(train, 0.1, validated_settings(LuoXuLaw.Settings,
                                                  {'freeze_under_saturation': True}))
    before = (law.mass_hat, list(law.theta_hat))
    out = law.step(Measurement(0.0, 0.0, 0.0), ReferencePoint(0.0, 500.0, 30.0, 0.3))
    law.after_saturation(out.force_n, 0.5 * out.force_n)
    # the saturated period is not integrated at the next sample
    out = law.step(Measurement(0.1, 0.0, 0.0), ReferencePoint(0.1, 5.0, 0.1, 0.0))
    assert (law.mass_hat, law.theta_hat) == before
    law.after_saturation(out.force_n, out.force_n)
    law.step(Measurement(0.2, 0.0, 0.0), ReferencePoint(0.2, 5.0, 0.1, 0.0))
    assert (law.mass_hat, law.theta_hat) != before


def test_host_saturates_to_the_traction_characteristic(train):
    host = ControllerHost(train, 0.1, 'pid')
    result = host.step(Measurement(0.0, 0.0, 80.0), ReferencePoint(0.0, 5000.0, 90.0, 0.5))
    assert result.total_force_n == pytest.approx(train.traction.max_traction_at(80.0))
    assert result.saturated and result.wanted_force_n > result.total_force_n
    result = host.step(Measurement(0.1, 0.0, 80.0), ReferencePoint(0.1, -5000.0, 0.0, -1.0))
    assert result.total_force_n == -train.traction.max_service_brake_force_n


@pytest.mark.parametrize('first, second', [('pid', 'luo_xu'), ('luo_xu', 'pid')])
def test_switch_is_bumpless(train, first, second):
    # luo_xu with slow adaptation: at the paper's gamma its mass estimate would swing to a bound
    # on these frozen measurements, and the PID's integrator could not take that over alone
    host = ControllerHost(train, 0.1, first, {'luo_xu': GAIN_PRESETS['earlier_retuning']})
    m, r = Measurement(0.0, 1000.0, 50.0), ReferencePoint(0.0, 1000.2, 50.05, 0.0)
    for _ in range(50):
        before = host.step(m, r).total_force_n
    host.select(second)
    after = host.step(m, r)
    assert after.law == second
    assert after.total_force_n == pytest.approx(before, rel=1e-6, abs=1.0)
    if second == 'pid':  # the PID takes over through its integrator, with no offset to decay
        assert host._offset_n == pytest.approx(0.0, abs=1.0)


def test_host_rejects_unknown_law_and_keeps_the_running_one(train):
    host = ControllerHost(train, 0.1, 'pid')
    valid = "unknown controller 'bogus'; valid: (.*, )?luo_xu, (.*, )?pid"
    with pytest.raises(LawRejected, match=valid):
        host.select('bogus')
    assert host.law.name == 'pid'


def test_settings_are_validated_with_the_field_named(train):
    host = ControllerHost(train, 0.1, 'pid')
    with pytest.raises(ValueError, match=r'kd_speed must be within \[0, 100\]'):
        host.update_settings('pid', {'kd_speed': -1.0})
    with pytest.raises(ValueError, match='must be a number'):
        host.update_settings('pid', {'kd_speed': 'fast'})
    host.update_settings('pid', {'kd_speed': 2.0})
    assert host.law.settings.kd_speed == 2.0


@pytest.mark.parametrize('law', ['pid', 'luo_xu'])
@pytest.mark.parametrize('bad', [Measurement(0.0, math.nan, 10.0),
                                 Measurement(0.0, 0.0, math.inf),
                                 Measurement(0.0, -math.inf, math.nan)])
def test_non_finite_measurements_hold_the_command_and_do_not_poison_the_law(train, law, bad):
    host = ControllerHost(train, 0.1, law)
    good = Measurement(0.0, 100.0, 10.0)
    ref = ReferencePoint(0.0, 101.0, 10.0, 0.0)
    held = host.step(good, ref).total_force_n
    for _ in range(5):
        result = host.step(bad, ref)
        assert result.fault and result.total_force_n == held
        assert all(math.isfinite(f) for f in result.forces_n)
    recovered = host.step(good, ref)
    assert not recovered.fault and math.isfinite(recovered.total_force_n)
    assert all(math.isfinite(v) for v in recovered.estimates.values())


def test_pid_integral_does_not_wind_up_while_ki_is_zero(train):
    host = ControllerHost(train, 0.1, 'pid', {'pid': {'ki_position': 0.0}})
    m, r = Measurement(0.0, 100.0, 10.0), ReferencePoint(0.0, 100.5, 10.0, 0.0)
    for _ in range(3000):
        before = host.step(m, r).total_force_n
    host.update_settings('pid', {'ki_position': 0.064})
    assert host.step(m, r).total_force_n == pytest.approx(before, abs=0.01 * 510e3 * 0.1)


def test_pid_starts_without_a_preloaded_integral(train):
    host = ControllerHost(train, 0.1, 'pid')
    result = host.step(Measurement(0.0, 0.0, 0.0), ReferencePoint(0.0, 0.0, 0.0, 0.0))
    assert result.estimates['integral_action_mps2'] == 0.0


def test_luo_xu_adapts_on_the_augmented_error_under_saturation(train):
    """The part of z2 the limits caused is taken out: the auxiliary error is what the cut force
    does over one period (z2 changes by about dt x cut / m_hat), and a law told its command was
    cut adapts on z2 minus it, where one told it was applied adapts on z2."""
    cut, applied = LuoXuLaw(train, 0.1), LuoXuLaw(train, 0.1)
    reference = ReferencePoint(0.0, 0.0, 60.0, 0.0)
    measured = Measurement(0.0, 0.0, 59.9)   # z2 = -0.1 m/s: the law wants more force
    for law, share in ((cut, 0.5), (applied, 1.0)):
        out = law.step(measured, reference)
        law.after_saturation(out.force_n, share * out.force_n)
    removed = 0.5 * out.force_n
    assert cut._aux[1] == pytest.approx(-0.1 * removed / train.nominal_mass_kg, rel=0.02)
    before = list(cut.theta_hat)
    for law in (cut, applied):
        law.step(Measurement(0.1, 6.0, 59.9), ReferencePoint(0.1, 6.0, 60.0, 0.0))
    raised_cut = cut.theta_hat[0] - before[0]
    raised_applied = applied.theta_hat[0] - before[0]
    assert raised_applied > 0.0
    assert raised_cut / raised_applied == pytest.approx((-0.1 - cut._aux[1]) / -0.1, rel=1e-6)
