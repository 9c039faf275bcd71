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

from ato_bringup.offline import run_offline
from ato_common.evidence import Claim, record
from ato_common.scenario import load_scenario

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
        'mao_4car with its limits, 1 kHz', 'not reproduced',
        'the feedback linearisation cancels the coupler zero at -k1/d1 = -1e4 1/s: it needs '
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
        f'{rate_hz:g} Hz', 'partly reproduced',
        'the paper\'s feedback linearisation needs 10 kHz; its singular-perturbation reduction '
        'tracks at onboard rates, with the couplers at quasi-static extension instead of '
        'regulated individually'))
