"""Mao, Tao, Jiang & Yan 4-car laws: the input-output form against the plant model, the [FIX]
switch, the sign/boundary-layer terms, saturation handling and the control-period check."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common.line import parse_line
from ato_common.trains import train_preset
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.mao_multibody import (
    MaoAdaptiveLaw,
    MaoNominalLaw,
    MaoState,
    phi_regressors,
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
    expected = before[1][1] - DT * 2.0 * (-m.car_speeds[1]) * e6
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
