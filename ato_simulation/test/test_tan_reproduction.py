"""Tan, Jiang & Chen (2025), Section 4: reproduction through the offline loop.

- 4.2 (on jinan_xuzhou): the proposed second-level adaptation with fixed models tracks with a
  steady-state speed error below 0.02 km/h.
- 4.3 (on tan_2025_comparison, the paper's own plant): the CRH380A on a constant 12 per mille
  grade plus the curvature term 0.004 D (D = 0.35), cruising at steady speed when the grade
  steps 12 -> 30 per mille for 1000 <= t < 1100 s (the plant's abrupt change; the curve stays),
  with the actuator limits lifted as the paper's plant has none. Compared: the four methods,
  the proposed one both with the printed freeze of (25) and with the projection [FIX], a "no
  adaptation" reference (law (24) with the exact pre-step parameters, never updated), the
  reading in which methods (3) and (4) adapt their models, and the ranking's dependence on the
  adaptive-model gain (not in the paper).
"""

from dataclasses import replace

import numpy as np
import pytest

from ato_common import units
from ato_common.evidence import Claim, record
from ato_common.knowledge import knowledge_of
from ato_common.plant_setup import parse_plant_setup
from ato_common.scenario import load_scenario
from ato_controller_node.laws.tan import SecondLevelSettings, model_box
from ato_simulation.loop import run_offline

COMPARED = ('tan_second_level', 'tan_second_level_adaptive', 'tan_switching_mm',
            'tan_weighted_mm')
#: the settings of the four methods as the paper compares them: switching and weighting among
#: the same fixed models (tan_weighted_mm's models adapt by default: set them fixed here)
FIXED_MODELS = {'tan_weighted_mm': {'adaptive_models': False}}
JUMP = (1000.0, 1100.0)
END_S = 1400.0
SETUP = ('tan_2025_comparison (constant 12 per mille plus the curvature term 0.004 D, D = 0.35; '
         'steady cruise at 295 km/h through 1000-1100 s), grade 12 -> 30 per mille for '
         '1000-1100 s, no actuator limits as in the paper, point mass, 10 Hz, 0-1400 s')
#: the identification_gain values of the adaptive-model sweep (the gain is not in the paper)
GAIN_SWEEP = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0)


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


def paper_comparison_scenario():
    """tan_2025_comparison with the paper's grade step and no actuator limits."""
    scenario = load_scenario('tan_2025_comparison')
    traction = replace(scenario.train.traction, max_traction_power_w=1e9,
                       max_traction_force_n=2.0 * scenario.train.mass_kg)
    jump = {'abrupt_changes': [{'start_s': JUMP[0], 'end_s': JUMP[1], 'grade_per_mille': 30}]}
    return replace(scenario, train=replace(scenario.train, traction=traction),
                   plant=parse_plant_setup(jump, scenario.train, 'plant'))


def exact_pre_step_alphas(scenario) -> np.ndarray:
    """Barycentric coordinates alpha_1..4 of the true pre-step parameter vector
    theta = (1/M, a + line force, b, c) in the corner simplex of the default model box:
    theta_k = theta_min + 4 w_k e_k, so sum alpha_k theta_k = theta_min + 4 sum alpha_k w_k e_k."""
    low, high = model_box(knowledge_of(scenario), SecondLevelSettings())
    train = scenario.train
    a, b, c = train.davis.per_kg(train.mass_kg)
    line = scenario.line.line_force_per_kg(scenario.line.length_m / 2)   # constant on the line
    truth = np.array([1.0 / train.mass_kg, a + line, b, c])
    return (truth - low) / (4.0 * (high - low))


def no_adaptation_settings(scenario) -> dict:
    alphas = exact_pre_step_alphas(scenario)
    return {'tan_second_level': {'alpha_gain': 0.0, **{f'initial_alpha_{k + 1}': float(a)
                                                       for k, a in enumerate(alphas)}}}


def _run(scenario, law, values=None):
    return run_offline(scenario, law, settings={law: values} if values else None,
                       end_time_s=END_S)


@pytest.fixture(scope='module')
def comparison():
    scenario = paper_comparison_scenario()
    runs = {law: _run(scenario, law, FIXED_MODELS.get(law)) for law in COMPARED}
    runs['tan_second_level (printed freeze of (25))'] = _run(scenario, 'tan_second_level',
                                                              {'paper_freeze': True})
    runs['no adaptation'] = run_offline(scenario, 'tan_second_level',
                                        settings=no_adaptation_settings(scenario),
                                        end_time_s=END_S)
    for law in ('tan_switching_mm', 'tan_weighted_mm'):
        runs[f'{law} (adaptive models)'] = _run(scenario, law, {'adaptive_models': True})
    return runs


def jump_peak_kmh(run) -> float:
    return float(speed_error_kmh(run)[run.times_s >= JUMP[0]].max())


def test_the_comparison_scenario_is_the_papers_plant():
    scenario = load_scenario('tan_2025_comparison')
    line = scenario.line
    # 12 per mille plus 0.004 D with D = 0.35 (Table 1), everywhere on the line
    expected = (units.STANDARD_GRAVITY * units.per_mille_to_sine(12.0) + 0.004 * 0.35)
    for position in np.linspace(0.0, line.length_m - 1.0, 9):
        assert line.line_force_per_kg(position) == pytest.approx(expected, rel=1e-5)
    assert line.curves[0].radius_m == pytest.approx(
        units.curvature_term_to_curve_radius_m(0.35), rel=1e-6)
    # steady cruise through the grade step (reference acceleration zero from 800 s to 1400 s)
    run = _run(paper_comparison_scenario(), 'tan_second_level')
    cruise = (run.times_s >= 800.0) & (run.times_s <= END_S)
    assert np.abs(run.ref_accelerations[cruise]).max() < 1e-9
    # the no-adaptation reference is the exact pre-step model: its error before the step is
    # the reference model's response to nothing (measured 0.0000 km/h in cruise)
    exact = run_offline(paper_comparison_scenario(), 'tan_second_level',
                        settings=no_adaptation_settings(scenario), end_time_s=JUMP[0])
    before = exact.times_s > 700.0
    assert speed_error_kmh(exact)[before].max() < 1e-3
    assert exact.estimate('mass_hat_kg')[-1] == pytest.approx(scenario.train.mass_kg, rel=1e-9)


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
    others = {}
    for law in ('tan_switching_mm', 'tan_weighted_mm'):
        run = comparison[law]
        others[law] = (speed_error_kmh(run)[start].max(),
                       np.abs(run.ref_positions - run.positions)[cruise].max())
        assert others[law][0] > 5.0 * fixed_start   # measured 4.2, 2.7 against 0.31 km/h
        assert others[law][1] > 5.0 * fixed_cruise  # measured 0.74, 0.73 against 0.048 m
    steady = speed_error_kmh(fixed)[(t > 800.0) & (t < JUMP[0])].max()
    assert steady < 0.02                            # measured below 1e-4 km/h
    record(Claim(
        'tan_jiang_chen', 'Section 4.3: the second-level adaptation starts better and has no '
        'position bias in cruise, against switching and weighting among the same fixed models',
        'the proposed method tracks best; (3) worst, (4) large initial error',
        f'start (first 300 s): peak {fixed_start:.2f} km/h against '
        + ', '.join(f'{v[0]:.2f} ({k})' for k, v in others.items())
        + f'; cruise position error {fixed_cruise:.3f} m against '
        + ', '.join(f'{v[1]:.2f} m ({k})' for k, v in others.items())
        + f'; steady cruise speed error {steady:.4f} km/h', SETUP, 'reproduced'))


def test_grade_step_transients_freeze_projection_and_no_adaptation(comparison):
    """The paper: the proposed method has the smallest transient after the grade step. On the
    paper's own plant it does not: measured peaks 1.92 km/h (projection), 1.50 (printed
    freeze), 0.68 (adaptive models), 1.48 (switching), 1.48 (weighted) against 1.62 km/h
    without any adaptation. The fixed models can explain a step of grade only through their
    slow, lightly damped Am filter; the combination swings (partly taking the grade for mass)
    until the old errors decay, and the projection onto sum alpha_k G_k >= 1/M_max binds then
    (the freeze, which stops only at sum <= 0, does not), so the two variants differ. Every
    method stays bounded and the proposed one settles again under 0.02 km/h."""
    peaks = {law: jump_peak_kmh(comparison[law])
             for law in (*COMPARED, 'tan_second_level (printed freeze of (25))', 'no adaptation')}
    for peak in peaks.values():
        assert peak < 3.0
    reference = peaks['no adaptation']
    assert 1.0 < reference < 2.5                                      # measured 1.62 km/h
    # the two readings of (25) differ (the projection binds during the step)
    projection = peaks['tan_second_level']
    freeze = peaks['tan_second_level (printed freeze of (25))']
    assert abs(projection - freeze) > 0.1                             # measured 1.92, 1.50
    four = {law: peaks[law] for law in COMPARED}
    smallest = min(four, key=four.get)
    assert smallest == 'tan_second_level_adaptive'                    # measured 0.68 km/h
    fixed = comparison['tan_second_level']
    t = fixed.times_s
    settled = (t >= JUMP[1] + 120.0) & (t <= END_S)
    settled_error = speed_error_kmh(fixed)[settled].max()
    assert settled_error < 0.02                                       # measured 0.003 km/h
    listed = ', '.join(f'{v:.2f} km/h ({k})' for k, v in peaks.items())
    record(Claim(
        'tan_jiang_chen', 'Section 4.3: the smallest transient after the grade step is the '
        "proposed method's", 'smallest of the four methods',
        f'peak speed error from 1000 s: {listed}; the proposed method settled at '
        f'{settled_error:.3f} km/h from 120 s after the step', SETUP,
        'reproduced' if smallest == 'tan_second_level' else 'not reproduced',
        f'the smallest of the four is {smallest}\'s; the proposed method, with the projection '
        f'or with the printed freeze, is no better than law (24) with the exact pre-step '
        f'parameters never updated ({reference:.2f} km/h): its fixed models see a grade step '
        'only through the slow Am filter, and the combination swings until the old errors '
        'decay'))


def test_switching_and_weighting_with_adaptive_models(comparison):
    """The other reading of Section 4.3 (all four methods start their models from the same
    initial values): methods (3) and (4) adapt their models. Measured: the start improves
    (0.68, 0.84 km/h against 4.2, 2.7 with fixed models), the step's transient shrinks (0.42,
    0.44 against 1.48) but the cruise after it keeps an error of about 0.11 km/h (the index
    keeps moving among models whose parameters drift apart)."""
    t = comparison['tan_second_level'].times_s
    start, after = t < 300.0, (t > JUMP[1] + 120.0) & (t <= END_S)
    rows = {}
    for law in ('tan_switching_mm', 'tan_weighted_mm'):
        fixed, adaptive = comparison[law], comparison[f'{law} (adaptive models)']
        rows[law] = [(speed_error_kmh(r)[start].max(), jump_peak_kmh(r),
                      speed_error_kmh(r)[after].max()) for r in (fixed, adaptive)]
        assert rows[law][1][0] < 0.5 * rows[law][0][0]     # the start improves
        assert rows[law][1][1] < 0.5 * rows[law][0][1]     # the step's transient shrinks
    proposed = jump_peak_kmh(comparison['tan_second_level'])
    adaptive_best = min(rows[law][1][1] for law in rows)
    assert adaptive_best < proposed
    text = '; '.join(f'{law}: start {f[0]:.2f} -> {a[0]:.2f} km/h, step peak {f[1]:.2f} -> '
                     f'{a[1]:.2f} km/h, after the step {f[2]:.3f} -> {a[2]:.3f} km/h'
                     for law, (f, a) in rows.items())
    record(Claim(
        'tan_jiang_chen', 'Section 4.3, methods (3) and (4) read as adapting their models (the '
        'paper: all methods start their models from the same initial values)',
        'the proposed method tracks best after the step',
        f'fixed -> adaptive models, {text}; the proposed method\'s step peak {proposed:.2f} km/h',
        SETUP + '; identification_gain 0.1', 'not reproduced',
        'with adapting models, switching and weighting have a smaller step transient than the '
        'proposed method (but keep about 0.1 km/h of error after the step); with fixed models '
        'they lock onto one model within the first 200 s'))


def test_ranking_depends_on_the_adaptive_model_gain():
    """The adaptive-model gain of method (2) is not in the paper, and it decides whether (2)
    beats the proposed method after the step: measured, (2)'s step peak is 2.65 km/h at gain
    0.001, 1.28 at 0.003, 1.58 at 0.01 (not monotonic) and falls to 0.10 km/h at gain 3, against
    1.92 km/h for the proposed method."""
    scenario = paper_comparison_scenario()
    proposed = jump_peak_kmh(_run(scenario, 'tan_second_level'))
    peaks = {gain: jump_peak_kmh(_run(scenario, 'tan_second_level_adaptive',
                                      {'identification_gain': gain})) for gain in GAIN_SWEEP}
    values = [peaks[g] for g in GAIN_SWEEP]
    assert values[-1] < 0.2 * values[0]            # the peak falls with the gain overall
    assert values[0] > 0.9 * proposed              # a tiny gain is nearly the fixed models
    beaten = [g for g in GAIN_SWEEP if peaks[g] < proposed]
    assert beaten and beaten[0] > GAIN_SWEEP[0]    # the ranking changes inside the sweep
    record(Claim(
        'tan_jiang_chen', 'Section 4.3: the ranking of the fixed-model method against adaptive '
        'models (method (2)) after the step, as a function of the adaptive-model gain (not in '
        'the paper)', 'the proposed method is better',
        'step peak of (2) by identification_gain: '
        + ', '.join(f'{g:g}: {peaks[g]:.2f}' for g in GAIN_SWEEP)
        + f' km/h, against {proposed:.2f} km/h for the proposed method; (2) is better from '
        f'gain {beaten[0]:g} on', SETUP, 'partly reproduced',
        f'the proposed method beats (2) only for gains below {beaten[0]:g}: the ranking is set '
        'by a gain the paper does not give'))
