import math

import pytest

from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost, LawRejected
from ato_controller_node.laws import LAWS, law_class
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.luo_xu import LuoXuLaw


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


def test_luo_xu_fix_changes_the_law_and_printed_switch_runs_it(train):
    m = Measurement(0.0, 10.0, 20.0)
    r = ReferencePoint(0.0, 0.0, 20.0, 0.0)
    fixed = LuoXuLaw(train, 0.1)
    settings = validated_settings(LuoXuLaw.Settings, {'paper_as_printed': True})
    printed = LuoXuLaw(train, 0.1, settings)
    # z1 = 10 m: the corrected varphi has (c1^2 - 1) z1, the printed one c1^2 z1
    diff = printed.step(m, r).force_n - fixed.step(m, r).force_n
    assert diff == pytest.approx(train.nominal_mass_kg * 10.0)


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
    host = ControllerHost(train, 0.1, first)
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
