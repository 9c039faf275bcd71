"""Tan, Jiang & Chen: the model box and its corner simplex, the identification models (17), the
convex-combination law (23) with projection (25), and the three comparison methods' weights."""

import math

import numpy as np
import pytest

from ato_common import units
from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.tan import (
    IdentificationBank,
    SecondLevelAdaptiveLaw,
    SecondLevelFixedLaw,
    SwitchingMultipleModelLaw,
    WeightedMultipleModelLaw,
    corner_simplex,
    model_box,
)

DT = 0.1


@pytest.fixture(scope='module')
def train():
    return TrainKnowledge.of(load_scenario('jinan_xuzhou').train)


def true_theta(train, grade_per_mille, mass_ratio=1.0):
    """(1/M, a + g sin(grade), b, c) of the train at a grade (Tan et al. eq 7)."""
    mass = train.nominal_mass_kg * mass_ratio
    a, b, c = train.nominal_davis.per_kg(train.nominal_mass_kg)
    return np.array([1.0 / mass, a + units.STANDARD_GRAVITY * units.per_mille_to_sine(
        grade_per_mille), b, c])


def barycentric(thetas, theta):
    """Convex weights of theta in the simplex (rows of thetas), by solving the 5x5 system."""
    system = np.vstack([thetas.T, np.ones(len(thetas))])
    return np.linalg.solve(system, np.append(theta, 1.0))


def test_box_holds_the_base_run_the_30_per_mille_jump_and_mass_within_20_percent(train):
    settings = SecondLevelFixedLaw.Settings()
    low, high = model_box(train, settings)
    thetas = corner_simplex(low, high)
    for grade in (12.0, 30.0, 0.0):
        for mass_ratio in (0.8, 1.0, 1.2):
            weights = barycentric(thetas, true_theta(train, grade, mass_ratio))
            assert weights.min() >= -1e-12 and weights.sum() == pytest.approx(1.0)


def test_corner_simplex_contains_every_corner_of_the_box():
    low, high = np.array([1.0, -2.0, 0.5, 3.0]), np.array([2.0, 1.0, 0.7, 4.0])
    thetas = corner_simplex(low, high)
    assert thetas[4] == pytest.approx(low)
    for corner in range(16):
        point = np.where([(corner >> i) & 1 for i in range(4)], high, low)
        weights = barycentric(thetas, point)
        assert weights.min() >= -1e-12


def test_identification_models_are_integrated_exactly_for_linear_state_and_held_force():
    """(17) over one period against a fine RK4 with x and Z_k(v) linear in time, u held."""
    thetas = np.array([[2e-6, 0.1, 1e-4, 1e-5]] * 5) * np.linspace(0.5, 1.5, 5)[:, None]
    bank = IdentificationBank(-0.1, -0.1, DT, thetas)
    start, end, force = (1000.0, 60.0), (1006.2, 64.0), 1.5e5
    bank.reset((990.0, 55.0))
    bank.advance(start, end, force)

    def rate(xhat, tau):
        s = start[0] + (end[0] - start[0]) * tau / DT
        v = start[1] + (end[1] - start[1]) * tau / DT
        z_start = -thetas[:, 1] - thetas[:, 2] * start[1] - thetas[:, 3] * start[1] ** 2
        z_end = -thetas[:, 1] - thetas[:, 2] * end[1] - thetas[:, 3] * end[1] ** 2
        z = z_start + (z_end - z_start) * tau / DT
        accel = -0.1 * (xhat[:, 0] - s) - 0.1 * (xhat[:, 1] - v) + thetas[:, 0] * force + z
        return np.stack([xhat[:, 1], accel], axis=1)

    xhat, n = np.tile([990.0, 55.0], (5, 1)), 1000
    h = DT / n
    for k in range(n):
        tau = k * h
        k1 = rate(xhat, tau)
        k2 = rate(xhat + h / 2 * k1, tau + h / 2)
        k3 = rate(xhat + h / 2 * k2, tau + h / 2)
        k4 = rate(xhat + h * k3, tau + h)
        xhat = xhat + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert bank.xhat == pytest.approx(xhat, rel=1e-10, abs=1e-9)


def test_lemma3_true_combination_of_identification_errors_stays_zero(train):
    """A plant exactly of the model's form with theta in the simplex: sum alpha_k e_k = 0 for
    its barycentric alpha (Lemma 3), under a varying force."""
    low, high = model_box(train, SecondLevelFixedLaw.Settings())
    thetas = corner_simplex(low, high)
    theta = true_theta(train, 12.0, 1.1)
    alpha = barycentric(thetas, theta)
    bank = IdentificationBank(-0.1, -0.1, DT, thetas)
    x = np.array([0.0, 10.0])
    bank.reset(tuple(x))
    worst = 0.0
    for k in range(2000):
        force = 1e5 * (1.0 + math.sin(0.01 * k))
        start = tuple(x)
        for _ in range(20):   # the plant, RK4 in 20 substeps
            def f(state):
                v = state[1]
                return np.array([v, theta[0] * force - theta[1] - theta[2] * v - theta[3] * v * v])
            h = DT / 20
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            k4 = f(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        bank.advance(start, tuple(x), force)
        worst = max(worst, np.abs(alpha @ bank.errors(tuple(x))).max())
    single = np.abs(bank.errors(tuple(x))).max()
    assert single > 1.0          # each fixed model alone is metres off
    assert worst < 1e-3          # their true combination is not: measured 2.9e-4 m, the
    #                              first-order hold of x and Z(v) within each period


def drive(law, steps, speed=lambda k: 20.0 + 0.05 * k, offset=0.5):
    """Step a law on a train moving at ``speed`` behind a reference by ``offset`` m."""
    out = None
    for k in range(steps):
        t = k * DT
        v = speed(k)
        m = Measurement(t, 100.0 + v * t, v)
        r = ReferencePoint(t, 100.0 + v * t + offset, v, 0.05 / DT)
        out = law.step(m, r)
        law.after_saturation(out.force_n, out.force_n)
    return out


def test_alpha_law_is_stable_at_any_gain_and_projection_keeps_the_divisor(train):
    settings = validated_settings(SecondLevelFixedLaw.Settings, {'alpha_gain': 1e6})
    law = SecondLevelFixedLaw(train, DT, settings)
    law.reset(Measurement(0.0, 100.0, 20.0), ReferencePoint(0.0, 100.0, 20.0, 0.0), None)
    out = drive(law, 300)
    assert np.all(np.isfinite(law.alpha))
    gains = law.bank.thetas[:, 0]
    assert law.alphas() @ gains >= law.g_min * (1.0 - 1e-12)
    assert math.isfinite(out.force_n)
    # a state below the bound is projected back onto it at the next update
    law.alpha = np.array([-1.0, 0.5, 0.5, 0.5])
    assert law.alphas() @ gains < law.g_min
    drive(law, 1)
    assert law.alphas() @ gains == pytest.approx(law.g_min, rel=1e-9)


def test_paper_freeze_holds_alpha_when_the_divisor_is_not_positive(train):
    settings = validated_settings(SecondLevelFixedLaw.Settings, {'paper_freeze': True})
    law = SecondLevelFixedLaw(train, DT, settings)
    law.reset(Measurement(0.0, 100.0, 20.0), ReferencePoint(0.0, 100.0, 20.0, 0.0), None)
    drive(law, 50)
    law.alpha = np.array([-2.0, 0.5, 0.5, 0.5])    # sum alpha_k G_k < 0
    frozen = law.alpha.copy()
    out = drive(law, 20)
    assert law.alpha == pytest.approx(frozen)       # (25) as printed: deadlocked
    assert math.isfinite(out.force_n)


def test_switching_selects_the_model_with_the_smallest_index(train):
    law = SwitchingMultipleModelLaw(train, DT)
    law.reset(Measurement(0.0, 100.0, 20.0), ReferencePoint(0.0, 100.0, 20.0, 0.0), None)
    out = drive(law, 400)
    index = law.settings.index_instant * (law.bank.errors(law._last_x) ** 2).sum(axis=1) + \
        law.settings.index_memory * np.asarray(law.memory)
    assert law.selected == int(np.argmin(index))
    assert out.estimates['selected_model'] == law.selected + 1


def test_weighted_weights_are_a_convex_combination_above_the_floor(train):
    # with fixed models: the recursion concentrates on one of them (with the default adapting
    # models, on the one that learns the train best, more slowly)
    law = WeightedMultipleModelLaw(train, DT, WeightedMultipleModelLaw.Settings(
        adaptive_models=False))
    law.reset(Measurement(0.0, 100.0, 20.0), ReferencePoint(0.0, 100.0, 20.0, 0.0), None)
    assert law.weights == pytest.approx(np.full(5, 0.2))   # equal initial weights
    drive(law, 400)
    weights = np.asarray(law.weights)
    assert weights.sum() == pytest.approx(1.0)
    assert weights.min() >= law.settings.weight_floor * 0.99
    assert weights.max() > 0.9          # the recursion concentrates on one model


def test_adaptive_models_move_their_parameters_and_fixed_ones_do_not(train):
    adaptive, fixed = SecondLevelAdaptiveLaw(train, DT), SecondLevelFixedLaw(train, DT)
    for law in (adaptive, fixed):
        law.reset(Measurement(0.0, 100.0, 20.0), ReferencePoint(0.0, 100.0, 20.0, 0.0), None)
        drive(law, 200)
    assert fixed.bank.thetas == pytest.approx(fixed.initial_thetas, rel=0, abs=0)
    assert np.abs(adaptive.bank.thetas - adaptive.initial_thetas).max() > 0.0


def test_a_skipped_period_restarts_the_models_from_the_measured_state(train):
    law = SecondLevelFixedLaw(train, DT)
    law.reset(Measurement(0.0, 100.0, 20.0), ReferencePoint(0.0, 100.0, 20.0, 0.0), None)
    drive(law, 50)
    gap = Measurement(50 * DT + 0.5, 250.0, 25.0)
    law.step(gap, ReferencePoint(gap.time_s, 250.0, 25.0, 0.0))
    assert law.bank.errors((250.0, 25.0)) == pytest.approx(np.zeros((5, 2)))


@pytest.mark.parametrize('law', ['tan_second_level', 'tan_second_level_adaptive',
                                 'tan_switching_mm', 'tan_weighted_mm'])
def test_settings_change_of_the_box_rebuilds_the_models(train, law):
    host = ControllerHost(train, DT, law)
    host.step(Measurement(0.0, 0.0, 0.0), ReferencePoint(0.0, 0.0, 0.0, 0.0))
    before = host.law.bank.thetas.copy()
    host.update_settings(law, {'grade_max_per_mille': 40.0})
    assert host.law.bank.thetas[1, 1] > before[1, 1]
    result = host.step(Measurement(DT, 0.0, 0.0), ReferencePoint(DT, 0.0, 0.0, 0.0))
    assert math.isfinite(result.total_force_n)
