"""Mao, Tao, Jiang & Yan 4-car laws: the input-output form against the plant model, the [FIX]
switch, the sign/boundary-layer terms, saturation handling and the control-period check."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common import units
from ato_common.line import parse_line
from ato_common.trains import train_preset
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.mao_multibody import (
    GAIN_PRESETS,
    MaoAdaptiveLaw,
    MaoNominalLaw,
    MaoState,
    allocate,
    phi_regressors,
    quasi_static_extension,
    true_parameters,
)
from train_plant_node.models.multi_car import MultiCarModel

DT = 1e-4


@pytest.fixture(scope='module')
def preset():
    return train_preset('crh2_4car_mao')


@pytest.fixture(scope='module')
def train(preset):
    return TrainKnowledge.of(preset)


@pytest.fixture(scope='module')
def model(preset):
    line = parse_line({'name': 'flat', 'length_m': 10000,
                       'stations': [{'name': 'A', 'position_m': 0},
                                    {'name': 'B', 'position_m': 10000}],
                       'speed_limits': [{'start_m': 0, 'speed_kmh': 200}]}, 'line')
    return MultiCarModel(preset, line)


def _moving_state(model, seed=1):
    """A state of the plant in motion with the couplers deflected (paper state order)."""
    rng = np.random.default_rng(seed)
    x = model.initial_state(1000.0, 30.0)
    x[:4] += rng.normal(0.0, 1e-4, 4)
    x[4:] += rng.normal(0.0, 0.1, 4)
    return x


def _measure(model, x, forces):
    positions, speeds, accelerations, _ = model.outputs(x, forces)
    return Measurement(0.0, positions[0], speeds[0], accelerations[0], positions, speeds)


def test_input_output_form_matches_the_plant_model(train, model):
    # (15)-(16) corrected [FIX]: y1'' = Phi1 + F2/th11 and y2' = Phi2 + F3/th21, checked against
    # the multi-car plant (y1'' by a central difference along the flow).
    x, forces = _moving_state(model), np.array([1e4, 2e4])
    flow = model.derivative(x, forces)
    # h: positions of 1000 m carry 1e-13 m of round-off, which the couplers (k/m ~ 1e4 s^-2)
    # turn into 1e-9 m/s^2: at h = 1e-7 that alone is 1e-5 of y1''; the O(h^2) error at 1e-4
    # is below 1e-7.
    h = 1e-4
    y1_ddot = (model.derivative(x + h * flow, forces)[4]
               - model.derivative(x - h * flow, forces)[4]) / (2 * h)
    theta1, theta2 = true_parameters(train)
    w1, w2 = phi_regressors(MaoState.of(_measure(model, x, forces), train.car_length_m), False)
    phi1 = sum(t * w for t, w in zip(theta1[1:], w1))
    phi2 = sum(t * w for t, w in zip(theta2[1:], w2))
    # the plant's c v|v| and a tanh(v/0.01) equal c v^2 and a at 30 m/s
    assert phi1 + forces[0] / theta1[0] == pytest.approx(y1_ddot, rel=1e-5)
    assert phi2 + forces[1] / theta2[0] == pytest.approx(flow[6], rel=1e-9)


def test_printed_constants_change_the_nominal_forces_by_the_sign_slip(train, model):
    m = _measure(model, _moving_state(model), (0.0, 0.0))
    r = ReferencePoint(0.0, 1000.0, 30.0, 0.1, 0.0)
    fixed = MaoNominalLaw(train, DT).step(m, r).forces_n
    printed = MaoNominalLaw(train, DT, validated_settings(
        MaoNominalLaw.Settings, {'paper_as_printed': True})).step(m, r).forces_n
    cars = train.cars
    # printed +d11 a2 instead of -d11 a2 in (17): F2 shifts by -2 a2 M2; printed +th27 with
    # th27 = a4 in (18) instead of -a3: F3 shifts by -(a3 + a4) M3
    assert printed[0] - fixed[0] == pytest.approx(-2 * cars[1].a_mps2 * cars[1].mass_kg, rel=1e-6)
    assert printed[1] - fixed[1] == pytest.approx(
        -(cars[2].a_mps2 + cars[3].a_mps2) * cars[2].mass_kg, rel=1e-6)


def test_adaptive_law_at_the_true_values_is_the_nominal_law(train, model):
    m = _measure(model, _moving_state(model), (0.0, 0.0))
    r = ReferencePoint(0.0, 1000.0, 30.0, 0.1, 0.0)
    nominal = MaoNominalLaw(train, DT).step(m, r).forces_n
    adaptive = MaoAdaptiveLaw(train, DT, validated_settings(MaoAdaptiveLaw.Settings, {
        'initial_estimate_ratio': 1.0, 'beta1': 0.0, 'beta2': 0.0})).step(m, r).forces_n
    assert adaptive == pytest.approx(nominal, rel=1e-12)


def test_sign_terms_and_their_boundary_layer(train):
    r = ReferencePoint(0.0, 0.0, 10.0, 0.0, 0.0)
    at_rest = Measurement(0.0, 0.0, 10.0, 0.0, (0.0, -25.0, -50.0, -75.0), (10.0,) * 4)
    e6 = 0.002
    m = Measurement(0.0, 0.0, 10.0, 0.0, at_rest.car_positions, (10.0, 10.0, 10.0 + e6, 10.0))

    def f3_robust(values):
        law = MaoAdaptiveLaw(train, DT, validated_settings(MaoAdaptiveLaw.Settings, values))
        return law.step(m, r).forces_n[1] - law.step(at_rest, r).forces_n[1] \
            + law.theta2_hat[0] * law.settings.alpha3 * e6 \
            - law.theta2_hat[0] * law.theta2_hat[3] * e6  # remove the (55) and Phi2 parts
    # (71): -beta2 sign(e6); with the boundary layer -beta2 sat(e6 / width)
    assert f3_robust({'boundary_layer': False}) == pytest.approx(-1000.0, rel=1e-6)
    assert f3_robust({}) == pytest.approx(-1000.0 * e6 / 0.01, rel=1e-6)


def test_adaptation_follows_64_74_and_freezes_under_saturation(train, model):
    m = _measure(model, _moving_state(model), (0.0, 0.0))
    r = ReferencePoint(0.0, 1000.0, 30.2, 0.1, 0.0)
    law = MaoAdaptiveLaw(train, DT)
    before = (list(law.theta1_hat), list(law.theta2_hat))
    out = law.step(m, r)
    law.after_saturation(out.force_n, out.force_n - 1.0, (out.forces_n[0] - 1.0, out.forces_n[1]))
    assert (law.theta1_hat, law.theta2_hat) == before
    out = law.step(m, r)
    law.after_saturation(out.force_n, out.force_n, out.forces_n)
    e6 = m.car_speeds[2] - r.speed
    # (74), entry th22: Theta2' = -Gamma2 W2 e6 with W2[1] = -x4
    expected = before[1][1] - DT * law.settings.gamma2 * (-m.car_speeds[1]) * e6
    assert law.theta2_hat[1] == pytest.approx(expected, rel=1e-12)
    assert law.theta1_hat != before[0]


def test_refused_when_sampled_too_slowly_or_on_a_single_mass_train(train):
    reason = MaoAdaptiveLaw(train, 0.01).fits(train)
    assert 'control period of at most 0.0001 s' in reason
    assert MaoAdaptiveLaw(train, DT).fits(train, measured_cars=4) is None
    single = TrainKnowledge.of(train_preset('crh3_luo_xu'))
    for law in (MaoNominalLaw, MaoAdaptiveLaw):
        assert 'actuators' in law(single, DT).fits(single)


def test_parameters_of_table_2(train):
    theta1, theta2 = true_parameters(train)
    # th11 = 1/(d11 m2) = M1 M2 / d1
    assert theta1[0] == pytest.approx(42800 / 8e4 * 48000, rel=1e-12)
    assert theta1[4] == pytest.approx(8e4 / 42800 * 8e8 / 48000, rel=1e-12)   # d11 k12
    assert theta2[0] == 46500 and theta2[2] == pytest.approx(6e8 / 46500)      # 1/m3, k23
    assert theta2[6] == pytest.approx(9.03e-3) and not math.isclose(
        true_parameters(train, as_printed=True)[1][6], theta2[6])              # a3 vs a4


extreme = st.floats(allow_nan=True, allow_infinity=True) | st.floats(-1e6, 1e6) | \
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, -1e300])
cars = st.tuples(extreme, extreme, extreme, extreme)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(['mao_multibody_nominal', 'mao_multibody_adaptive']),
       st.lists(st.tuples(cars, cars, extreme, extreme, extreme), min_size=1, max_size=20))
def test_commands_and_estimates_stay_finite_and_within_limits(train, law, samples):
    host = ControllerHost(train, DT, law)
    lowest, highest = train.actuator_limits_at(0.0)
    for k, (positions, speeds, acceleration, v_ref, a_ref) in enumerate(samples):
        result = host.step(Measurement(DT * k, positions[0], speeds[0], acceleration, positions,
                                       speeds), ReferencePoint(DT * k, 0.0, v_ref, a_ref, 0.0))
        assert all(lowest - 1e-6 <= f <= highest + 1e-6 for f in result.forces_n)
        assert all(math.isfinite(value) for value in result.estimates.values())


def test_paper_gains_converted_from_the_adaptive_laws_dimensions():
    # Table II's tonnes with m and s: only the input gains th11 [t s] and th21 [t] carry a mass
    gamma1, gamma2 = units.mao_multibody_adaptation_gains_to_si(2.0, 2.0)
    assert gamma1 == pytest.approx((2000.0,) + (2.0,) * 8, rel=1e-12)
    assert gamma2 == pytest.approx((2000.0,) + (2.0,) * 6, rel=1e-12)
    # one Euler step of (64) for th11 in t s and in kg s is the same step: th11_SI = 1000 th11_t
    w, eps, dt = 0.3, 0.01, 1e-4          # nu2 - Phi1_hat [m/s^3], eps [m/s]
    step_t = -dt * 2.0 * w * eps          # t s
    assert -dt * gamma1[0] * w * eps == pytest.approx(1000.0 * step_t, rel=1e-12)
    # the c1 entry [1/m] has no mass: only a length or time unit would change its gain; in km
    # and h it would be 2 * 1000^-4 * 3600^3 (its dimension L^-4 T^3)
    kmh = units.mao_multibody_adaptation_gains_to_si(2.0, 2.0, 1000.0, 1000.0, 3600.0)
    assert kmh[0][3] == pytest.approx(2.0 * 1000.0 ** -4 * 3600.0 ** 3, rel=1e-12)
    with pytest.raises(ValueError, match='mass unit'):
        units.mao_multibody_adaptation_gains_to_si(2.0, 2.0, mass_unit_kg=0.0)
    # every product theta_k W_k is the output's derivative (the tables are consistent)
    for thetas, ws, output in ((units.MAO_MULTIBODY_THETA1_DIMENSIONS,
                                units.MAO_MULTIBODY_W1_DIMENSIONS, (0, 1, -3)),
                               (units.MAO_MULTIBODY_THETA2_DIMENSIONS,
                                units.MAO_MULTIBODY_W2_DIMENSIONS, (0, 1, -2))):
        products = [tuple(a + b for a, b in zip(t, w)) for t, w in zip(thetas, ws)]
        assert products[0] == (1, 1, -2)              # th11 (nu2 - Phi1_hat): a force
        assert set(products[1:]) == {output}


def test_default_gains_are_the_paper_preset(train):
    law = MaoAdaptiveLaw(train, DT)
    for name, value in GAIN_PRESETS['paper'].items():
        assert getattr(law.settings, name) == value
    assert GAIN_PRESETS['paper']['gamma11'] == pytest.approx(2000.0)
    assert set(GAIN_PRESETS['unscaled_si'].values()) == {2.0}


def _regulated(values=None):
    return {'regulate_internal_force': True, 'kappa': 2.0, **(values or {})}


def test_quasi_static_extension_is_rigid_motion_of_the_plant(train, model, preset):
    # With every car at one speed, the couplers at their quasi-static extensions and the forces
    # of the mass split, the plant accelerates every car alike at A
    speed, accel = 30.0, 0.3
    cars = train.cars
    masses = [c.mass_kg for c in cars]
    resist = [c.mass_kg * (c.a_mps2 + c.b_per_s * speed + c.c_per_m * speed ** 2) for c in cars]
    total = sum(masses) * accel + sum(resist)
    f2 = total * (masses[0] + masses[1]) / sum(masses)
    x3 = -(masses[0] * accel + resist[0]) / train.couplers[0].stiffness_n_per_m
    x5 = (f2 - (masses[0] + masses[1]) * accel - resist[0] - resist[1]) \
        / train.couplers[1].stiffness_n_per_m
    x7 = (masses[3] * accel + resist[3]) / train.couplers[2].stiffness_n_per_m
    assert quasi_static_extension(train, speed, accel) == pytest.approx(x3 + x5, rel=1e-12)
    x = model.initial_state(1000.0, speed)    # the plant's positions: at rest spacing, equal
    x[1:4] -= np.cumsum([x3, x5, x7])
    flow = model.derivative(x, np.array([f2, total - f2]))
    assert flow[4:] == pytest.approx([accel] * 4, abs=1e-6)
    # car 3's share beyond its limit: car 2 takes the rest, the coupler between them pushes
    lowest, highest = train.actuator_limits_at(speed)
    hard = (2.0 * highest - sum(resist)) / sum(masses) * 0.999
    shifted = quasi_static_extension(train, speed, hard) - (
        -(masses[0] * hard + resist[0]) / train.couplers[0].stiffness_n_per_m)
    assert abs(shifted) < 1e-3 and math.isfinite(shifted)


def test_allocation_moves_what_one_actuator_cannot_give_to_the_other():
    limits = (-80.0, 50.0)
    assert allocate(30.0, 40.0, limits) == (30.0, 40.0)
    assert allocate(30.0, 60.0, limits) == (40.0, 50.0)
    assert allocate(70.0, 10.0, limits) == (50.0, 30.0)
    assert allocate(70.0, 60.0, limits) == (50.0, 50.0)
    assert allocate(-100.0, 0.0, limits) == (-80.0, -20.0)


def test_regulated_second_output_is_tracked_as_55(train, model):
    # The regulated nominal law on the plant: y2 = x6 - kappa (x3 + x5 - X*) obeys
    # y2' = v_m' - alpha3 (y2 - v_m) (reference at constant speed: X*' = 0)
    # a state near the quasi-static one, so that the forces stay within the actuators' limits
    x = model.initial_state(1000.0, 10.0)
    x[1:4] -= np.cumsum([-2e-6, 3e-6, 2e-6])
    x[4:] += [1e-5, -2e-5, 1.5e-5, -1e-5]
    r = ReferencePoint(0.0, 1000.0, 10.0, 0.0, 0.0)
    law = MaoNominalLaw(train, DT, validated_settings(MaoNominalLaw.Settings, _regulated()))
    m = _measure(model, x, (0.0, 0.0))
    out = law.step(m, r)
    lowest, highest = train.actuator_limits_at(10.0)
    assert all(lowest < f < 0.9 * highest for f in out.forces_n)     # not reallocated
    flow = model.derivative(x, np.array(out.forces_n))
    state = MaoState.of(_measure(model, x, out.forces_n), train.car_length_m)
    deviation = state.x[2] + state.x[4] - quasi_static_extension(train, r.speed, 0.0)
    y2 = state.x[5] - 2.0 * deviation
    y2_dot = flow[6] - 2.0 * (state.x[1] - state.x[5])
    assert out.estimates['internal_extension_error_m'] == pytest.approx(deviation, rel=1e-9)
    assert out.estimates['y2_error_mps'] == pytest.approx(y2 - r.speed, rel=1e-9)
    assert y2_dot == pytest.approx(-1.0 * (y2 - r.speed), rel=1e-6, abs=1e-9)
    # off, the law is the paper's (18): y2 = x6
    plain = MaoNominalLaw(train, DT).step(m, r)
    assert 'y2_error_mps' not in plain.estimates
    assert plain.forces_n[1] != pytest.approx(out.forces_n[1], rel=1e-6)
