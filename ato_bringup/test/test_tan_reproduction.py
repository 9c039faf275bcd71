"""Tan, Jiang & Chen (2025), Section 4: reproduction on jinan_xuzhou through the offline loop.

- 4.2: the proposed second-level adaptation with fixed models tracks with a steady-state speed
  error below 0.02 km/h.
- 4.3: comparison with the three other multiple-model methods, same five models and initial
  parameters, with the grade raised to 30 per mille for 1000 <= t < 1100 s (the plant's
  abrupt change). The paper's plant has no actuator limits; with the CRH380A's 9.6 MW the
  30 per mille climb at 245 km/h is beyond the traction power (about 170 kN needed, 141 kN
  available) and every law loses the same 41 km/h, so the comparison lifts the traction limits
  to the paper's unconstrained actuator.
"""

from dataclasses import replace

import numpy as np
import pytest

from ato_bringup.offline import run_offline
from ato_common.evidence import Claim, record
from ato_common.plant_setup import parse_plant_setup
from ato_common.scenario import load_scenario

COMPARED = ('tan_second_level', 'tan_second_level_adaptive', 'tan_switching_mm',
            'tan_weighted_mm')
JUMP = (1000.0, 1100.0)


def speed_error_kmh(run) -> np.ndarray:
    return np.abs(run.ref_speeds - run.speeds) * 3.6


def steady_state_mask(run, min_cruise_s: float = 200.0) -> np.ndarray:
    """Steady state: the second half of every cruise (reference acceleration zero) that lasts
    at least ``min_cruise_s``; transients after changes of speed or grade are excluded."""
    cruising = np.abs(run.ref_accelerations) < 1e-6
    mask = np.zeros_like(cruising)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], cruising.astype(int), [0]))))
    dt = run.times_s[1] - run.times_s[0]
    for start, end in zip(edges[::2], edges[1::2]):
        if (end - start) * dt >= min_cruise_s:
            mask[(start + end) // 2:end] = True
    return mask


def unconstrained_with_grade_jump():
    scenario = load_scenario('jinan_xuzhou')
    traction = replace(scenario.train.traction, max_traction_power_w=1e9,
                       max_traction_force_n=2.0 * scenario.train.mass_kg)
    jump = {'abrupt_changes': [{'start_s': JUMP[0], 'end_s': JUMP[1], 'grade_per_mille': 30}]}
    return replace(scenario, train=replace(scenario.train, traction=traction),
                   plant=parse_plant_setup(jump, scenario.train, 'plant'))


@pytest.fixture(scope='module')
def comparison():
    scenario = unconstrained_with_grade_jump()
    return {law: run_offline(scenario, law, end_time_s=1400.0) for law in COMPARED}


def test_second_level_fixed_models_steady_state_speed_error_below_0_02_kmh():
    scenario = load_scenario('jinan_xuzhou')
    run = run_offline(scenario, 'tan_second_level')
    error = speed_error_kmh(run)
    steady = steady_state_mask(run)
    assert steady.sum() * 0.1 > 500.0          # measured 880 s of steady state
    assert error[steady].max() < 0.02           # measured 0.0002 km/h
    # measured 1.25 km/h where the 12 per mille climb ends as the reference accelerates again
    # (an abrupt parameter change, see the grade-jump test); 0.50 km/h while starting
    assert error.max() < 2.0
    # the convex combination finds the mass: measured 440.6 t for 442 t
    assert run.estimate('mass_hat_kg')[-1] == pytest.approx(scenario.train.mass_kg, rel=0.02)
    stop = run.metrics().stop_errors_m['Xuzhou East']
    assert abs(stop) < 0.1   # measured 0.04 m
    record(Claim(
        'tan_jiang_chen', 'Section 4.2: steady-state speed error of the second-level adaptation '
        'with fixed models', 'below 0.02 km/h',
        f'{error[steady].max():.4f} km/h over {steady.sum() * 0.1:.0f} s of steady cruise; '
        f'largest error {error.max():.2f} km/h; mass estimate '
        f'{run.estimate("mass_hat_kg")[-1] / 1000:.1f} t for {scenario.train.mass_kg / 1000:.0f} '
        f't; stop {stop:+.3f} m',
        'jinan_xuzhou (built from the stated length, time and top speed), point mass, 10 Hz, '
        'the CRH380A traction limits', 'reproduced'))


def test_comparison_start_and_steady_state_rank_as_the_paper_says(comparison):
    """Switching among five fixed models (3) and weighting them (4) start worse (the paper:
    too few models for switching; equal initial weights) and keep a position bias in cruise
    because neither can interpolate between the models; the second-level combination can."""
    fixed = comparison['tan_second_level']
    t = fixed.times_s
    start = t < 300.0
    cruise = (t > 300.0) & (t < JUMP[0])
    fixed_start = speed_error_kmh(fixed)[start].max()
    fixed_cruise = np.abs(fixed.ref_positions - fixed.positions)[cruise].max()
    for law in ('tan_switching_mm', 'tan_weighted_mm'):
        run = comparison[law]
        assert speed_error_kmh(run)[start].max() > 2.0 * fixed_start   # 1.4, 1.8 vs 0.50 km/h
        # measured 1.3 m against 0.06 m
        assert np.abs(run.ref_positions - run.positions)[cruise].max() > 5.0 * fixed_cruise
    others = {law: (speed_error_kmh(comparison[law])[start].max(),
                    np.abs(comparison[law].ref_positions - comparison[law].positions)[cruise].max())
              for law in ('tan_switching_mm', 'tan_weighted_mm')}
    record(Claim(
        'tan_jiang_chen', 'Section 4.3: the second-level adaptation starts better and has no '
        'position bias in cruise, against switching and weighting among the same fixed models',
        'the proposed method tracks best',
        f'start (first 300 s): peak {fixed_start:.2f} km/h against '
        + ', '.join(f'{v[0]:.2f} ({k})' for k, v in others.items())
        + f'; cruise position error {fixed_cruise:.3f} m against '
        + ', '.join(f'{v[1]:.2f} m ({k})' for k, v in others.items()),
        'jinan_xuzhou, traction limits lifted as the paper has none, 0-1400 s, 10 Hz',
        'reproduced'))


def test_grade_jump_transients_as_measured(comparison):
    """The paper's claim that the fixed-model method has the smallest transient during the
    grade jump does NOT reproduce here (README, Tan et al.): measured peaks 3.6 km/h (fixed
    models), 1.1 (adaptive models), 2.8 (switching), 2.8 (weighted). At constant speed a step
    of grade moves every identification error by the same signal, which the fixed models'
    errors can explain only through their slow, lightly damped Am filter; the combination swings
    (partly taking the grade for mass) until the old errors decay. Adaptive models move their
    own parameters at once. What holds: every method stays bounded, and the fixed-model method
    settles again under 0.02 km/h within 120 s of the grade's return."""
    window = {}
    for law, run in comparison.items():
        window[law] = speed_error_kmh(run)[run.times_s >= JUMP[0]].max()
        assert window[law] < 5.0
    fixed = comparison['tan_second_level']
    t = fixed.times_s
    settled = (t >= JUMP[1] + 120.0) & (t <= JUMP[1] + 180.0)   # before the 12 per mille climb
    assert speed_error_kmh(fixed)[settled].max() < 0.02          # measured 0.007 km/h
    assert window['tan_second_level'] == max(window.values())
    assert window['tan_second_level_adaptive'] == min(window.values())
    record(Claim(
        'tan_jiang_chen', 'Section 4.3: the smallest transient during the grade jump is the '
        'proposed method\'s', 'smallest of the four methods',
        'peak speed error from 1000 s: ' + ', '.join(f'{v:.2f} km/h ({k})'
                                                     for k, v in window.items())
        + f'; settled at {speed_error_kmh(fixed)[settled].max():.3f} km/h 120-180 s after the jump',
        'jinan_xuzhou, grade raised to 30 per mille for 1000-1100 s on the built line (not the '
        "paper's constant 12 per mille), traction limits lifted", 'not reproduced',
        'the fixed-model method has the largest transient here, the adaptive-model method the '
        'smallest; every method stays bounded (issue 16 rebuilds the paper\'s set-up)'))
