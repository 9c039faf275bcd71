"""Liu & Li 2020 [REC] law: observer structure, output feedback with no speed sensor,
saturation handling, and the control-period check."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common.trains import train_preset
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.liu_li import LiuLiLaw

DA = 0.125          # m/s^2: CRH380A(L) specific resistance near 300 km/h (docs/papers/liu_li.md)
CRUISE = 80.0       # m/s


@pytest.fixture(scope='module')
def train():
    return TrainKnowledge.of(train_preset('crh380al_liu_li'))


def _law(train, dt, **values):
    return LiuLiLaw(train, dt, validated_settings(LiuLiLaw.Settings, values))


def _observe_cruise(law, seconds):
    """Drive the observer alone: the train cruises at CRUISE with a force that balances the
    specific resistance DA exactly (so the true speed is constant); only its position is
    measured. Returns the last (s - s_hat, v - v_hat)."""
    force = law.mass * DA
    steps = round(seconds / law.dt)
    reference = ReferencePoint(0.0, 0.0, CRUISE, 0.0)
    law.reset(Measurement(0.0, 0.0, math.nan), reference, None)
    law.v_hat = CRUISE  # start on the true speed: the test isolates the steady state
    for k in range(steps + 1):
        t = k * law.dt
        out = law.step(Measurement(t, CRUISE * t, math.nan), reference)
        law.after_saturation(out.force_n, force)
    return out.estimates['position_innovation_m'], CRUISE - out.estimates['speed_hat_mps']


def test_unlearned_observer_settles_where_table_3_value_5_puts_it(train):
    # docs/papers/liu_li.md (evidence): without learning, s_t -> -Da/k2 and v_t -> -(k1/k2) Da;
    # with Value 5 (k1 = 0.88, k2 = 0.22) that is 0.57 m and 0.50 m/s, the paper's V5 RMS 0.626 m,
    # 0.513 m/s.
    law = _law(train, 0.02, k1=0.88, k2=0.22, Gamma1=0.0)
    s_t, v_t = _observe_cruise(law, 60.0)
    assert s_t == pytest.approx(-DA / 0.22, rel=0.02)
    assert v_t == pytest.approx(-0.88 / 0.22 * DA, rel=0.02)


def test_network_learns_the_resistance_and_the_errors_vanish_with_value_10(train):
    law = _law(train, 0.005)
    s_t, v_t = _observe_cruise(law, 20.0)
    # Unlearned they would be Da/k2 = 3.6 mm and 4 Da = 0.5 m/s; the sigma-leakage leaves a
    # residual (measured 1.1e-4 m, 0.015 m/s) of the order of Table 3's Value 10 (5.3e-5 m,
    # 0.038 m/s).
    assert abs(s_t) < 2e-4 and abs(v_t) < 0.03
    estimated = law.step(Measurement(0.0, 0.0, math.nan), ReferencePoint(0.0, 0.0, CRUISE, 0.0))
    assert estimated.estimates['resistance_hat_mps2'] == pytest.approx(DA, abs=5e-3)


def test_runs_with_the_speed_sensor_failed_and_reports_its_speed_estimate(train):
    host = ControllerHost(train, 0.005, 'liu_li')
    reference = ReferencePoint(0.0, 0.0, 0.0, 0.0)
    result = host.step(Measurement(0.0, 0.0, math.nan), reference)
    assert result.fault == ''
    assert result.estimates['speed_hat_mps'] == 0.0
    assert LiuLiLaw.requires == ('position',)


def test_refuses_a_control_period_too_long_for_the_observer_gain(train):
    reason = LiuLiLaw(train, 0.1).fits(train)
    assert 'k1 = 140' in reason and '0.00714 s' in reason
    assert LiuLiLaw(train, 0.005).fits(train) is None
    assert _law(train, 0.1, k1=0.88, k2=0.22, Gamma1=1.1).fits(train) is None  # Value 5


def test_controller_adaptation_freezes_into_saturation_but_the_observer_runs(train):
    law = _law(train, 0.005)
    reference = ReferencePoint(0.0, 0.0, 10.0, 0.0)
    law.reset(Measurement(0.0, 0.0, math.nan), reference, None)
    out = law.step(Measurement(0.0, 0.0, math.nan), reference)   # v_hat = 10, v_d = 10, e1 = 0
    out = law.step(Measurement(0.0, -1.0, math.nan), reference)  # 1 m behind: r = -28 m/s
    assert out.force_n > 8e7
    weights, rho2, v_hat = law.w2.copy(), law.rho2, law.v_hat
    law.after_saturation(out.force_n, 5e5)
    assert (law.w2 == weights).all() and law.rho2 == rho2
    assert law.v_hat != v_hat  # the observer integrated the commanded force
    out = law.step(Measurement(0.005, -0.95, math.nan), reference)
    law.after_saturation(out.force_n, out.force_n)
    assert (law.w2 != weights).any() and law.rho2 > rho2
    # saturated, but the update would lower the command toward the limit: it adapts
    # (directional freezing, so that the law cannot lock itself in saturation)
    law.reset(Measurement(0.0, 0.0, math.nan), reference, None)
    out = law.step(Measurement(0.0, 1.0, math.nan), reference)   # 1 m ahead: r = +28 m/s
    weights = law.w2.copy()
    law.after_saturation(out.force_n + 1e6, out.force_n)          # wanted more than allowed
    assert (law.w2 > weights).any()                               # W2' = Gamma2 S2 r > 0


extreme = st.floats(allow_nan=True, allow_infinity=True) | st.floats(-1e6, 1e6) | \
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, -1e300])


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(extreme, extreme, extreme, extreme), min_size=1, max_size=30))
def test_commands_and_estimates_stay_finite_and_within_limits(samples):
    train = TrainKnowledge.of(train_preset('crh380al_liu_li'))
    host = ControllerHost(train, 0.005, 'liu_li')
    for k, (x, x_ref, v_ref, a_ref) in enumerate(samples):
        result = host.step(Measurement(0.005 * k, x, math.nan),
                           ReferencePoint(0.005 * k, x_ref, v_ref, a_ref))
        assert all(math.isfinite(f) for f in result.forces_n)
        low, high = train.traction.limits_at(0.0)
        assert low - 1e-6 <= result.total_force_n <= high + 1e-6
        assert all(math.isfinite(value) for value in result.estimates.values())
