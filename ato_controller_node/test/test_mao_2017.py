"""Mao et al. 2017 (adaptive actuator-failure compensation): the law's equations, its [FIX]
switch, saturation and projection, and the paper's result on the paper's own model.

Two reproductions: one on the paper's plant (eq 8: piecewise-constant modes, four motors, the
failure pattern of Section 4) integrated here, exactly what the paper simulates; one on the
suite's plant with the built-in scenario mao_2017_modes (the same modes and failure, the
preset's traction limits), in ato_simulation/test/test_mao_2017_suite_plant.py."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest

from ato_common.evidence import Claim, record
from ato_common.trains import DavisResistance, train_preset
from ato_common.types import ReferencePoint
from ato_common.units import STANDARD_GRAVITY
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement, TrainKnowledge
from ato_controller_node.laws.mao_2017 import CURVE_COEFFICIENT, Mao2017Law, Mao2017Settings

MASS_KG = 500e3


@dataclass(frozen=True)
class Mode:
    """A mode record as the scenario's plant section gives it."""

    mass_kg: float
    davis: DavisResistance
    grade_sine: float
    curve_accel_mps2: float


def paper_modes() -> tuple[Mode, ...]:
    """Section 4, reading (A): whole-train kN with V in km/h."""
    open_air = DavisResistance.from_kn_kmh(2.25, -1.9e-3, 3.2e-4)
    tunnel = DavisResistance.from_kn_kmh(2.25, -1.9e-3, 9.2e-4)
    return (Mode(MASS_KG, open_air, 0.0, 0.0),                             # (i) accelerating
            Mode(MASS_KG, tunnel, 0.0, 0.0),                               # (ii) tunnel
            Mode(MASS_KG, open_air, 0.015, CURVE_COEFFICIENT * 0.34),      # (iii) slope + curve
            Mode(MASS_KG, open_air, 0.0, 0.0))                             # (iv) level, braking


MODE_STARTS_S = (0.0, 400.0, 800.0, 1400.0)


def mode_at(time_s: float) -> int:
    return sum(time_s >= start for start in MODE_STARTS_S) - 1


def failed_motor_force(time_s: float) -> float | None:
    """Section 4: motor 1 stuck at 2e5 N from 600 s, oscillating 1000-1200 s, out after."""
    if time_s < 600.0:
        return None
    if time_s < 1000.0:
        return 2e5
    if time_s < 1200.0:
        return 2e5 * (1.0 + math.sin(0.05 * time_s - 30.0))
    return 0.0


def knowledge(modes=()) -> TrainKnowledge:
    """The mao_2017_500t train (500 t, four motors, 300 kN, 8.8 MW)."""
    train = train_preset('mao_2017_500t')
    assert train.mass_kg == MASS_KG and train.davis == paper_modes()[0].davis
    return TrainKnowledge.of(train, modes)


CRUISE_MPS = 60.0


def reference_at(t: float) -> ReferencePoint:
    """Smooth distance-to-go profile as in docs/papers/mao_2017.md: raised-cosine acceleration to
    60 m/s over 0-400 s, cruise, raised-cosine braking to a stop over 1400-2000 s."""
    v, accel_s, brake_start, brake_s = CRUISE_MPS, 400.0, 1400.0, 600.0
    x_accel = v * accel_s / 2.0
    if t < accel_s:
        w = math.pi / accel_s
        return ReferencePoint(t, v / 2 * (t - math.sin(w * t) / w), v / 2 * (1 - math.cos(w * t)),
                              v / 2 * w * math.sin(w * t), v / 2 * w * w * math.cos(w * t))
    x_cruise = x_accel + v * (brake_start - accel_s)
    if t < brake_start:
        return ReferencePoint(t, x_accel + v * (t - accel_s), v, 0.0, 0.0)
    tau = min(t - brake_start, brake_s)
    w = math.pi / brake_s
    speed = v / 2 * (1 + math.cos(w * tau))
    accel = -v / 2 * w * math.sin(w * tau) if tau < brake_s else 0.0
    jerk = -v / 2 * w * w * math.cos(w * tau) if tau < brake_s else 0.0
    return ReferencePoint(t, x_cruise + v / 2 * (tau + math.sin(w * tau) / w), speed, accel, jerk)


def run_paper_model(settings: Mao2017Settings = Mao2017Settings(), end_s: float = 2000.0,
                    dt: float = 0.1, substeps: int = 10):
    """Closed loop on eq 8 with the true mode parameters and the failure of motor 1; returns
    times, position errors, speed errors, the host's results."""
    modes = paper_modes()
    host = ControllerHost(knowledge(modes), dt, 'mao_2017', {'mao_2017': settings.__dict__})
    x, v = 0.0, 0.0
    times, position_errors, speed_errors, results = [], [], [], []
    h = dt / substeps
    for k in range(int(round(end_s / dt)) + 1):
        t = k * dt
        i = mode_at(t)
        reference = reference_at(t)
        result = host.step(Measurement(t, x, v, mode=i, car_positions=(x,), car_speeds=(v,)),
                           reference)
        times.append(t)
        position_errors.append(reference.position - x)
        speed_errors.append(reference.speed - v)
        results.append(result)
        mode = modes[i]
        a, b, c = mode.davis.per_kg(mode.mass_kg)
        forces = list(result.forces_n)
        for j in range(substeps):
            tj = t + j * h
            stuck = failed_motor_force(tj)
            if stuck is not None:
                forces[0] = stuck
            def accel(speed):                                                      # eq 8
                return (sum(forces) / mode.mass_kg - a - b * speed - c * speed * speed
                        - STANDARD_GRAVITY * mode.grade_sine - mode.curve_accel_mps2)
            # Heun's method on the speed, trapezoid on the position
            k1 = accel(v)
            k2 = accel(v + h * k1)
            v_next = v + h * (k1 + k2) / 2
            x += h * (v + v_next) / 2
            v = v_next
    return np.array(times), np.array(position_errors), np.array(speed_errors), results


@pytest.fixture(scope='module')
def paper_run():
    return run_paper_model()


def test_position_error_converges_despite_mode_switches_and_failure(paper_run):
    times, ex, ev, results = paper_run
    # The paper's figures: the distance error converges to zero after each mode switch (400,
    # 800, 1400 s) and each change of the failure (600, 1000, 1200 s). Measured: peak 0.30 m
    # (at the failure), at most 0.05 m 100-200 s after each event, 0.003 m at the stop.
    assert np.max(np.abs(ex)) < 1.0
    for event in (400.0, 600.0, 800.0, 1000.0, 1200.0, 1400.0):
        window = (times > event + 100.0) & (times < event + 200.0)
        assert np.max(np.abs(ex[window])) < 0.15, event
    assert abs(ex[-1]) < 0.02
    assert abs(ev[-1]) < 0.01
    assert not any(r.fault for r in results)
    # The adaptation does it: k_nu^ = 1/rho_knu^ goes from 4/0.95 to the 3 healthy motors
    # while motor 1 is stuck (measured 3.02 at 800 s).
    k_nu = np.array([r.estimates['k_nu_hat'] for r in results])
    assert k_nu[0] == pytest.approx(4 / 0.95)
    assert k_nu[times.searchsorted(800.0)] == pytest.approx(3.0, abs=0.3)
    after = max(np.max(np.abs(ex[(times > e + 100.0) & (times < e + 200.0)]))
                for e in (400.0, 600.0, 800.0, 1000.0, 1200.0, 1400.0))
    record(Claim(
        'mao_2017', 'Section 4: the position error converges to zero after every mode switch '
        'and every change of the actuator failure',
        'error back to about zero after each event (figures)',
        f'peak {np.max(np.abs(ex)):.2f} m, at most {after:.3f} m 100-200 s after each event, '
        f'{abs(ex[-1]):.4f} m at the stop; k_nu_hat {k_nu[times.searchsorted(800.0)]:.2f} at '
        '800 s (3 healthy motors)',
        "the paper's own model (8)-(9), four modes switching at 400, 800, 1400 s, motor 1 "
        'stuck from 600 s, oscillating 1000-1200 s, out from 1200 s; raised-cosine reference; '
        '10 Hz; gains not in the paper (unit-scaled)', 'reproduced'))


def test_printed_sign_of_35_drives_k_nu_the_wrong_way(paper_run):
    """[FIX] (35): with the printed "-" the stuck motor's error drives rho_knu^ the wrong way
    (k_nu^ falls to about 1.3) and the error after the failure stays ~30 times larger."""
    times, ex, _, _ = paper_run
    t_printed, ex_printed, _, printed = run_paper_model(
        Mao2017Settings(paper_as_printed=True), end_s=800.0)
    window = (times > 700.0) & (times < 800.0)
    window_printed = (t_printed > 700.0) & (t_printed < 800.0)
    assert np.max(np.abs(ex_printed[window_printed])) > 5.0 * np.max(np.abs(ex[window]))
    assert printed[-1].estimates['k_nu_hat'] < 2.0
    record(Claim(
        'mao_2017', 'the adaptive law (35) of 1/k_nu as printed', 'estimates converge',
        f'printed sign: k_nu_hat {printed[-1].estimates["k_nu_hat"]:.2f} at 800 s (3 healthy '
        f'motors), position error 700-800 s {np.max(np.abs(ex_printed[window_printed])):.3f} m '
        f'against {np.max(np.abs(ex[window])):.3f} m with the corrected sign',
        "the paper's own model, as above, to 800 s", 'not reproduced',
        'the printed "-" sign of (35) drives k_nu_hat the wrong way; the suite runs "+", with '
        'which the terms of V2 cancel ([FIX], paper_as_printed runs the printed one)'))


def law(modes=paper_modes(), **settings) -> Mao2017Law:
    return Mao2017Law(knowledge(modes), 0.1, Mao2017Settings(**settings))


def test_control_34_with_true_parameters_gives_the_designed_error_dynamics():
    """With exact estimates and no failure, (34) makes z2' = -z1 - r2 z2 on eq 8."""
    controller = law(initial_estimate_ratio=1.0)
    mode = paper_modes()[2]
    x, v = 1000.0, 50.0
    reference = ReferencePoint(10.0, 1000.4, 50.3, 0.1, 0.0)
    out = controller.step(Measurement(10.0, x, v, mode=2), reference)
    assert out.forces_n == (out.force_n / 4,) * 4
    a, b, c = mode.davis.per_kg(mode.mass_kg)
    accel = (out.force_n / mode.mass_kg - a - b * v - c * v * v
             - STANDARD_GRAVITY * mode.grade_sine - mode.curve_accel_mps2)
    z1, r1, r2 = x - reference.position, 0.5, 1.0
    z2 = v - (-r1 * z1 + reference.speed)
    alpha1_dot = -r1 * (v - reference.speed) + reference.acceleration
    assert accel - alpha1_dot == pytest.approx(-z1 - r2 * z2, rel=1e-9)


def test_adaptive_laws_move_each_estimate_in_the_direction_of_the_proof():
    """One Euler step of (28)-(33), (35), (36) with z2 > 0 (train ahead of alpha1)."""
    controller = law()
    controller.xi_hat = [1e5, 0.0]
    before_rho_knu = controller.rho_knu_hat
    before = list(controller.theta_hat[1]), controller.rho_hat[1]
    out = controller.step(Measurement(100.0, 10.5, 40.0, mode=1),
                          ReferencePoint(100.0, 10.0, 40.0, 0.0))
    z2 = out.estimates['z2_mps']
    assert z2 > 0.0
    controller.after_saturation(out.force_n, out.force_n, out.forces_n)
    assert controller.xi_hat[0] == pytest.approx(1e5 + 0.1 * 2e5 * z2)               # (28)
    assert all(after < prior for after, prior in zip(controller.theta_hat[1], before[0]))
    assert controller.rho_knu_hat > before_rho_knu                                     # (35) fixed
    assert controller.theta_hat[0] == [0.95 * p for p in controller.modes[0].parameters]
    printed = law(paper_as_printed=True)
    printed.xi_hat = [1e5, 0.0]
    out = printed.step(Measurement(100.0, 10.5, 40.0, mode=1),
                       ReferencePoint(100.0, 10.0, 40.0, 0.0))
    printed.after_saturation(out.force_n, out.force_n, out.forces_n)
    assert printed.rho_knu_hat < before_rho_knu                                        # as printed


def test_adaptation_frozen_under_saturation_and_rho_projected():
    controller = law()
    start = (list(controller.xi_hat), controller.rho_knu_hat, list(controller.rho_hat))
    out = controller.step(Measurement(0.0, 0.0, 0.0, mode=0), ReferencePoint(0.0, 50.0, 10.0, 0.0))
    controller.after_saturation(out.force_n, 0.5 * out.force_n, (out.force_n / 8,) * 4)
    assert (controller.xi_hat, controller.rho_knu_hat, controller.rho_hat) == \
        (start[0], start[1], start[2])
    huge = law(gamma_m=1e9, gamma_knu=1.0)
    huge.xi_hat = [1e6, 0.0]
    for _ in range(50):
        out = huge.step(Measurement(0.0, 0.0, 30.0, mode=0), ReferencePoint(0.0, 100.0, 0.0, 0.0))
        huge.after_saturation(out.force_n, out.force_n, out.forces_n)
    assert 0.5 * MASS_KG / 4 <= huge.rho_hat[0] <= 2.0 * MASS_KG
    assert 0.5 / 4 <= huge.rho_knu_hat <= 2.0


def test_modes_and_fit():
    controller = law()
    with pytest.raises(ValueError, match='mode 4 is not one of the 4 known modes'):
        controller.step(Measurement(0.0, 0.0, 0.0, mode=4), ReferencePoint(0.0, 0.0, 0.0, 0.0))
    # Without known modes: one mode from the nominal train, whatever the measured mode.
    single = law(modes=())
    assert len(single.modes) == 1 and single.modes[0].mass_kg == MASS_KG
    single.step(Measurement(0.0, 0.0, 0.0, mode=3), ReferencePoint(0.0, 0.0, 0.0, 0.0))
    one_motor = replace(knowledge(), actuator_names=('traction',))
    assert 'drives 4 actuators but the train has 1' in single.fits(one_motor)
    assert single.fits(knowledge()) is None
