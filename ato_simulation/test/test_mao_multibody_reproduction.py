"""Mao, Tao, Jiang & Yan reproduction (offline loop on the multi-car plant, no ROS), on the
`mao_4car` preset: with the estimates starting at 95 % of the true values (Section VI), the
adaptive controllers (60), (71) drive the speed errors of cars 1 and 3 to about zero, and the
relative positions z1 - z2 and z3 - z4 (the paper's Figs. 13-14) stay bounded and settle.

Differences from Section VI: the train starts at rest at a station (x(0) has speeds 0.01 m/s and
z1 = 0.5 m; the plant starts every car at rest, and position offsets do not enter the speed
loop); v_m(t) is the preset's jerk-limited plan (the paper does not give v_m); the first 7 s
(the start and the rise to 0.48 m/s^2). The actuator limits are lifted, as in the paper: the law
leaves the split of force between cars 2 and 3 to the coupler, and with the preset's limit of
53.8 kN per car, car 3 saturates after 4 s (measured). The law runs at 10 kHz: sampled slower
it is unstable (last test).
"""

import dataclasses

import numpy as np
import pytest

from ato_common.evidence import SUITE_EXTENSION, Claim, record
from ato_common.knowledge import knowledge_of
from ato_common.scenario import load_scenario
from ato_controller_node.laws.mao_multibody import true_parameters
from ato_simulation.loop import run_offline

RATE_HZ = 10_000.0
END_S = 7.0


def mao_scenario(limits=False):
    scenario = load_scenario('mao_4car')
    if limits:
        return scenario
    unlimited = dataclasses.replace(scenario.train.traction, max_traction_force_n=1e8,
                                    max_traction_power_w=1e11, max_service_brake_force_n=1e8,
                                    max_emergency_brake_force_n=1e8)
    return dataclasses.replace(scenario, train=dataclasses.replace(scenario.train,
                                                                   traction=unlimited))


def _coupler_extensions(run):
    z = run.car_positions
    return z[:, :-1] - z[:, 1:] - run.scenario.train.car_length_m


@pytest.fixture(scope='module')
def run():
    return run_offline(mao_scenario(), 'mao_multibody_adaptive', model='multi_car',
                       controller_rate_hz=RATE_HZ, end_time_s=END_S)


def test_speed_errors_of_cars_1_and_3_go_to_about_zero(run):
    assert not any(run.faults)
    errors = run.car_speeds[:, [0, 2]] - run.ref_speeds[:, None]
    last = run.times_s > END_S - 0.5
    peak, final = np.abs(errors).max(), np.abs(errors[last]).max()
    # measured: peak 6.6e-3 m/s at 2.4 s (start from rest: the standstill resistance is not
    # the law's constant a_p; the reference jerk), 1.0e-4 m/s over the last 0.5 s
    assert 1e-3 < peak < 0.02
    assert final < 3e-4 and final < 0.05 * peak
    record(Claim(
        'mao_multibody', 'Theorem 2: the adaptive controllers (60), (71) drive the speed errors '
        'of cars 1 and 3 to about zero', 'errors go to about zero (figures)',
        f'peak {peak:.2e} m/s, {final:.1e} m/s over the last 0.5 s',
        'mao_4car (CRH2 4-car unit), the multi-car plant, 10 kHz, actuator limits lifted as in '
        f'the paper, estimates from 95 % of the truth, first {END_S:g} s from rest',
        'reproduced'))


def test_relative_positions_stay_bounded_and_settle(run):
    extensions = _coupler_extensions(run)
    # bounded: 2e-4 m of a coupler is a force of 1.2e5 - 1.6e5 N
    assert np.abs(extensions).max() < 2e-4
    # z1 - z2 and z3 - z4 settle at the constant that carries the accelerating cars 1 and 4
    # (measured -2.73e-5 and +2.67e-5 m; M1 a / k1 with a = 0.48 m/s^2 is 2.6e-5 m).
    # z2 - z3 does not settle within the run: it drifts at v1 - v3 (2e-5 m/s measured at 7 s),
    # and the stiff coupler turns that into an internal force cars 2 and 3 hold against each
    # other (README: Control laws).
    tail = run.times_s > END_S - 2.0
    for column in (0, 2):
        assert np.ptp(extensions[tail, column]) < 3e-7
        assert abs(extensions[-1, column]) == pytest.approx(42800 * 0.48 / 8e8, rel=0.1)


def test_estimates_under_the_paper_gains_converted_for_tonnes(run):
    # Gamma1 = Gamma2 = 2 I read in Table II's tonnes with m and s (the default, preset paper):
    # gamma11 = gamma21 = 2000 in SI, the per-unit-mass entries 2 (ato_common.units)
    theta1, theta2 = true_parameters(knowledge_of(run.scenario))
    final1 = [run.estimate(f'theta1{k + 1}_hat')[-1] / t for k, t in enumerate(theta1)]
    final2 = [run.estimate(f'theta2{k + 1}_hat')[-1] / t for k, t in enumerate(theta2)]
    # the input gains keep their sign and hardly move from 95 % (measured 0.953, 0.950): their
    # rate gamma W e is ~1e-3 of their value per second
    assert 0.9 < final1[0] < 1.0 and 0.9 < final2[0] < 1.0
    # the c1 estimate changes sign (measured -1.4e3 x the truth): c1 carries no mass, so no
    # reading of the mass unit changes its gain; with the stiff coupler entries (5 % off, hardly
    # adapting) it absorbs their error, as do the constants th19, th27 (measured ~5x)
    assert final1[3] < 0.0
    assert final1[8] > 2.0 and final2[6] > 2.0
    record(Claim(
        'mao_multibody', 'adaptive laws (64), (74) with Gamma1 = Gamma2 = 2 I: the estimates stay '
        'bounded (Theorem 2) and, from 95 %, near the truth',
        'Gamma = 2 I (Section VI); estimates not shown',
        f'th11 {final1[0]:.3f}, th21 {final2[0]:.3f} of the truth; c1 {final1[3]:.3g}, th19 '
        f'{final1[8]:.2f}, th27 {final2[6]:.2f} of the truth after {END_S:g} s',
        'as the first claim; Gamma converted for Table II\'s tonnes with m and s '
        '(gamma11 = gamma21 = 2000 SI, others 2)',
        'partly reproduced',
        'bounded, but the c1 estimate changes sign and the constants overshoot: Theorem 2 gives '
        'no parameter convergence, and with one gain for entries from 1.5e-5 to 3e4 the stiff '
        'coupler entries hardly adapt while c1 and the constants absorb their error; c1 has no '
        'mass in its unit, so the conversion cannot change it'))


def _drift_runs(limits, end_s, regulated_settings):
    runs = {}
    for name, extra in (('paper', {}), ('regulated', regulated_settings)):
        runs[name] = run_offline(mao_scenario(limits=limits), 'mao_multibody_adaptive',
                                 model='multi_car', controller_rate_hz=RATE_HZ,
                                 end_time_s=end_s,
                                 settings={'mao_multibody_adaptive': extra})
    return runs


def test_internal_force_drifts_without_regulation_and_is_held_with_it():
    """The paper's zero eigenvalue: x3 + x5 integrates v1 - v3, so the coupler between the
    powered cars drifts; with regulate_internal_force (kappa 1 1/s) it turns back. Actuator
    limits lifted as in the paper (under the preset's limits see the next test). Measured at
    15 s: x5 -2.37e-4 m and still falling (F2 -96 kN braking against F3 +187 kN), regulated
    x5 -1.39e-4 m and rising again."""
    end = 15.0
    runs = _drift_runs(False, end, {'regulate_internal_force': True, 'kappa': 1.0})
    x5 = {k: _coupler_extensions(r)[:, 1] for k, r in runs.items()}
    times = runs['paper'].times_s
    late = times > end - 3.0
    slope = {k: np.polyfit(times[late], v[late], 1)[0] for k, v in x5.items()}
    # the paper's: still drifting at the end, at v1 - v3 ~ -1.5e-5 m/s
    assert slope['paper'] < -5e-6
    # regulated: smaller and on its way back
    assert slope['regulated'] > 0.0
    assert np.abs(x5['regulated']).max() < 0.7 * np.abs(x5['paper']).max()
    internal = {k: float(v[-1]) * runs['paper'].scenario.train.couplers[1].stiffness_n_per_m
                for k, v in x5.items()}
    record(Claim(
        'mao_multibody', 'the internal force between the powered cars (the zero eigenvalue of '
        'the zero dynamics) without and with the suite\'s regulation y2 = v3 - kappa (x3 + x5 '
        '- X*)', 'not discussed (Figs. 13-14 show z1 - z2 and z3 - z4 only)',
        f'at {end:g} s: x5 {x5["paper"][-1]:.2e} m drifting at {slope["paper"]:.1e} m/s '
        f'({internal["paper"] / 1000:.0f} kN); regulated {x5["regulated"][-1]:.2e} m '
        f'({internal["regulated"] / 1000:.0f} kN), returning at {slope["regulated"]:.1e} m/s',
        f'mao_4car, 10 kHz, limits lifted, first {end:g} s from rest, kappa 1 1/s',
        SUITE_EXTENSION,
        'the regulation is the suite\'s option; the paper\'s design leaves this mode '
        'unregulated (it drifts with the history of '
        'v1 - v3); the regulation bounds it but only as fast as the adaptive loops track, '
        'whose transient errors (~3e-3 m/s) exceed kappa times the deviation'))


def test_under_the_preset_limits_the_regulation_does_not_prevent_divergence():
    """With the preset's limits (53.8 kN per car) car 3 saturates at about 4.5 s during the
    adaptive transient, with or without the regulation (measured: kappa 1, 5 and 20 alike).
    Measured within 9 s: the paper's design 0.060 m/s of speed error and growing (make compare
    records its divergence within 150 s); regulated (kappa 5) 1.5 m/s, swinging between the
    limits from about 7 s: the regulation does not make the 10 kHz law work at the limits."""
    end = 9.0
    runs = _drift_runs(True, end, {'regulate_internal_force': True, 'kappa': 5.0})
    peaks = {}
    for name, r in runs.items():
        errors = r.car_speeds[:, [0, 2]] - r.ref_speeds[:, None]
        peaks[name] = float(np.abs(errors).max())
        limit = r.scenario.train.traction.max_traction_force_n / 2
        assert np.abs(r.actuator_forces[:, 1]).max() >= limit * (1 - 1e-9)
    # the unlimited run's peak is 6.6e-3 m/s (first test)
    assert peaks['paper'] > 0.03 and peaks['regulated'] > 0.03
    record(Claim(
        'mao_multibody', 'the design under the preset\'s actuator limits, without and with the '
        'regulation of the internal force', 'no actuator limits in the paper',
        f'peak speed error within {end:g} s: {peaks["paper"]:.2f} m/s (paper\'s design), '
        f'{peaks["regulated"]:.2f} m/s (regulated, kappa 5 1/s)',
        f'mao_4car with its limits, 10 kHz, first {end:g} s from rest', SUITE_EXTENSION,
        'the paper has no actuator limits; car 3 saturates at about 4.5 s during the adaptive '
        'transient (the loops\' errors of '
        '~3e-3 m/s dominate the regulation), the adaptation freezes and the feedback '
        'linearisation, which cancels the coupler dynamics, no longer holds: at onboard '
        'limits use mao_multibody_rigid'))


def test_sampled_at_1_khz_the_same_law_goes_unstable():
    # Why the law refuses periods above 1e-4 s: it cancels the coupler zero at -k1/d1 = -1e4
    # 1/s, which a zero-order hold at 1 ms cannot follow (sampled closed-loop eigenvalue 8.9).
    slow = run_offline(mao_scenario(limits=True), 'mao_multibody_adaptive', model='multi_car',
                       controller_rate_hz=1000.0, end_time_s=1.0,
                       settings={'mao_multibody_adaptive': {'max_control_period_s': 1e-3}})
    # the forces hit an actuator limit (the braking limit is the larger one)...
    limit = slow.scenario.train.traction.max_traction_force_n / 2
    assert np.abs(slow.actuator_forces).max() >= limit * (1 - 1e-9)
    slow_errors = slow.car_speeds[:, [0, 2]] - slow.ref_speeds[:, None]
    record(Claim(
        'mao_multibody', 'the design as a sampled law at an onboard rate',
        'continuous time (not discussed)',
        f'at 1 kHz the forces reach the actuator limit and the speed error '
        f'{np.abs(slow_errors).max():.3f} m/s within 1 s',
        'mao_4car with its limits, 1 kHz', SUITE_EXTENSION,
        'the paper designs in continuous time; the feedback linearisation cancels the '
        'coupler zero at -k1/d1 = -1e4 1/s: it needs '
        'periods under about 1e-4 s, so it cannot run at a controller node\'s rate'))
    # ...and the errors exceed the 10 kHz run's peak (6.6e-3 m/s) several times
    errors = slow.car_speeds[:, [0, 2]] - slow.ref_speeds[:, None]
    assert np.abs(errors).max() > 0.02


@pytest.mark.parametrize('rate_hz', [10.0, 100.0])
def test_rigid_coupler_reduction_runs_at_onboard_rates_with_the_limits(rate_hz):
    """The onboard-rate version of the design (mao_multibody_rigid): the rigid-coupler
    reduction, adaptive as (71)-(74) on the whole unit, force split by mass, at 10 and 100 Hz
    on mao_4car with the preset's actuator limits, the whole run. Measured at 10 Hz: RMS speed
    error of cars 1 and 3 1.7e-3 m/s, the mass estimate 178.4 t for 179.3 t, stops within
    0.03 m; the couplers at their quasi-static extension."""
    scenario = mao_scenario(limits=True)
    run = run_offline(scenario, 'mao_multibody_rigid', model='multi_car',
                      controller_rate_hz=rate_hz)
    assert not any(run.faults)
    errors = run.car_speeds[:, [0, 2]] - run.ref_speeds[:, None]
    rms, peak = float(np.sqrt(np.mean(errors ** 2))), float(np.abs(errors).max())
    assert rms < 5e-3 and peak < 0.05                 # measured 10 Hz: 1.7e-3, 0.024 m/s
    train = scenario.train
    mass = sum(c.mass_kg for c in train.cars)
    assert run.estimate('mass_hat_kg')[-1] == pytest.approx(mass, rel=0.05)
    stops = run.metrics().stop_errors_m
    assert set(stops) == {'B', 'C'} and all(abs(e) < 0.5 for e in stops.values())
    # quasi-static: no coupler carries more than the force that moves its side of the unit at
    # the planning limits (0.5 m/s^2 up, 0.6 down) with its resistance: (M1 + .. + Mi) 0.7 / k_i
    extensions = _coupler_extensions(run)
    masses = [c.mass_kg for c in train.cars]
    for i, coupler in enumerate(train.couplers):
        bound = sum(masses[:i + 1]) * 0.7 / coupler.stiffness_n_per_m
        assert np.abs(extensions[:, i]).max() < bound
    assert np.abs(extensions[:, 1]).max() < 0.3 * np.abs(extensions[:, 0]).max()
    record(Claim(
        'mao_multibody', f'the design at an onboard rate ({rate_hz:g} Hz): the rigid-coupler '
        'reduction, adaptive as (71)-(74), force split by mass',
        'speed errors go to about zero (continuous time, 10 kHz in the suite)',
        f'RMS speed error of cars 1 and 3 {rms:.1e} m/s, peak {peak:.3f} m/s; mass estimate '
        f'{run.estimate("mass_hat_kg")[-1] / 1000:.1f} t for {mass / 1000:.1f} t; stops '
        + ', '.join(f'{k} {v:+.3f} m' for k, v in stops.items())
        + f'; couplers within {np.abs(extensions).max():.1e} m',
        f'mao_4car, the multi-car plant, the preset\'s actuator limits, the whole run, '
        f'{rate_hz:g} Hz', SUITE_EXTENSION,
        'the reduction is the suite\'s law: the paper\'s feedback linearisation needs 10 kHz; '
        'its singular-perturbation reduction '
        'tracks at onboard rates, with the couplers at quasi-static extension instead of '
        'regulated individually'))
