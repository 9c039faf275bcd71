"""Liu & Li 2020 reproduction (offline loop, no ROS), on the `liu_li_2020` preset with the
speed sensor failed from the start (measured speed NaN; the law uses the position only): the
observer and tracking errors reach the order of Table 3 (Value 10) / Table 4, and the traction
energy is of the order reported.

Plant: the time-varying resistance of docs/papers/liu_li.md (a_i(t) = a_i (1 + 0.1 sin(0.01 t +
phi_i)), l(t) = M g (1 + 0.05 sin(0.02 t))) and the fast disturbance d = 0.01 M sin(t), the
default of Cases 1-2 (Table 3's Value 10 equals Table 4's "fast" column).

The paper's run is 561 km (about 6400 s); at the 200 Hz the Value-10 observer needs that is too
long for a unit test, so the tests run a representative cut: the first 500 s (start, station
throat limits, acceleration towards 350 km/h). The full trip, for each disturbance of Table 4:
`python ato_controller_node/test/test_liu_li_reproduction.py none|fast|slow` (numbers in
README.md).
"""

import dataclasses
import math
import sys
import time

import numpy as np
import pytest

from ato_common.evidence import NOT_COMPARABLE, Claim, incomparable, record
from ato_common.plant_setup import parse_plant_setup
from ato_common.scenario import load_scenario
from ato_simulation.loop import run_offline
from train_plant_node.simulation import TrainSimulation

RATE_HZ = 200.0
CUT_S = 500.0
# Table 3, Value 10 (= Table 4 "fast", rows 2-4 read as x1e-4, docs/papers/liu_li.md)
PAPER = {'s - s_hat': 5.3111e-5, 'v - v_hat': 0.0378, 's - s_d': 0.0075, 'v - v_d': 0.0366}
PAPER_ENERGY_KWH_PER_KM = 1.6696e4 / 561.37   # Table 3 V10, read as 1e4 kWh over 561.37 km
TRIP_S = 6400.0
DISTURBANCES = {    # Case 3, the forms of docs/papers/liu_li.md [REC]
    'none': {'kind': 'none'},
    'fast': {'kind': 'fast', 'amplitude_n': 8900.0, 'omega_rad_per_s': 1.0},
    # -A (1 + sin(w t)) / 2 with w = 2 pi / trip; A set so that the energy roughly doubles
    'slow': {'kind': 'slow', 'amplitude_n': 2.7e5, 'omega_rad_per_s': 2 * math.pi / TRIP_S},
}


def liu_li_2020(disturbance='fast'):
    scenario = load_scenario('liu_li_2020')
    plant = parse_plant_setup({
        'resistance_variation': {
            'a': {'amplitude': 0.1, 'omega_rad_per_s': 0.01},
            'b': {'amplitude': 0.1, 'omega_rad_per_s': 0.01, 'phase_rad': 2.0},
            'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.01, 'phase_rad': 4.0},
            'line': {'amplitude': 0.05, 'omega_rad_per_s': 0.02}},
        'disturbance': DISTURBANCES[disturbance],
        'sensors': {'speed': {'failed_from_s': 0.0}}}, scenario.train)
    return dataclasses.replace(scenario, plant=plant)


def run_liu_li(scenario, end_time_s=None, settings=None, rate_hz=RATE_HZ):
    return run_offline(scenario, 'liu_li', settings={'liu_li': settings or {}},
                       end_time_s=end_time_s, controller_rate_hz=rate_hz)


@pytest.fixture(scope='module')
def run():
    return run_liu_li(liu_li_2020(), CUT_S)


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_runs_on_position_alone(run):
    assert not any(run.faults)
    sensors = TrainSimulation(run.scenario).measured()
    assert math.isnan(sensors.speeds[0]) and math.isfinite(sensors.positions[0])
    assert run.speeds.max() > 300 / 3.6            # the traction-limited climb to 350 km/h


def table_3_metrics(run):
    return {'s - s_hat': _rms(run.positions - run.estimate('position_hat_m')),
            'v - v_hat': _rms(run.speeds - run.estimate('speed_hat_mps')),
            's - s_d': _rms(run.positions - run.ref_positions),
            'v - v_d': _rms(run.speeds - run.ref_speeds),
            'energy_1e4_kwh': energy_kwh(run) / 1e4}


def energy_kwh(run):
    """Traction energy integral max(u v, 0) dt (docs/papers/liu_li.md's reading of the metric)."""
    dt = run.times_s[1] - run.times_s[0]
    return float(np.sum(np.maximum(run.forces * run.speeds, 0.0)) * dt / 3.6e6)


def test_errors_reach_the_order_of_table_3_value_10(run):
    measured = table_3_metrics(run)
    del measured['energy_1e4_kwh']
    # Measured on this cut (fast disturbance): 1.5e-4 m, 0.021 m/s, 3.4e-3 m, 6.5e-4 m/s
    # against the paper's 5.3e-5 m, 0.038 m/s, 7.5e-3 m, 0.037 m/s: the observer's position
    # error is 2.8x the paper's, the others below it. "Order of" = at most 4x above.
    for key, value in measured.items():
        assert value < 4.0 * PAPER[key], (key, value)
    # and not trivially: the observer's speed error is not zero, the weights learned
    assert measured['v - v_hat'] > 1e-4
    assert run.estimate('resistance_hat_mps2')[-1] > 0.05
    above = [k for k, v in measured.items() if v > PAPER[k]]
    # figures more than 10x apart (either way) say nothing about the paper's: the equations
    # are reconstructions and the trip is cut and built, not the paper's GA-optimised one
    far = incomparable(PAPER, measured)
    if far:
        verdict = NOT_COMPARABLE
        reason = ('; '.join(f'{k} {ratio:.2g}x the paper\'s' for k, ratio in far.items())
                  + ': more than 10x apart, a reconstructed law on a cut and rebuilt trip')
    elif above:
        verdict, reason = 'partly reproduced', (
            f'of the same order, but {", ".join(above)} above the paper\'s (a cut of the trip; '
            'the equations are reconstructions)')
    else:
        verdict, reason = 'reproduced', ''
    record(Claim(
        'liu_li', 'Table 3 (Value 10) / Table 4 (fast): RMS observer and tracking errors',
        ', '.join(f'{k} {v:.3g}' for k, v in PAPER.items()),
        ', '.join(f'{k} {v:.3g}' for k, v in measured.items()),
        f'liu_li_2020 [REC], speed sensor failed (position only), the reconstructed varying '
        f'resistance and fast disturbance, {RATE_HZ:g} Hz, the first {CUT_S:g} s of the trip',
        verdict, reason))


def perfect_tracking_energy_kwh(run):
    """The traction energy max(u* v*, 0) dt of following the built reference exactly on the
    plant's truth (the varying resistance, the line, the disturbance): u* is the force that
    gives the plant the reference's acceleration at the reference's position and speed (the
    point-mass acceleration is affine in the force)."""
    sim = TrainSimulation(run.scenario)
    model, dt, work = sim.model, run.times_s[1] - run.times_s[0], 0.0
    for t, x, v, a in zip(run.times_s, run.ref_positions, run.ref_speeds, run.ref_accelerations):
        if v <= 0.0:
            continue   # standing: no work (and the resistance is not affine there)
        env = sim.surroundings(float(t))
        free = model.acceleration(x, v, 0.0, float(t), env)
        per_newton = model.acceleration(x, v, 1.0, float(t), env) - free
        work += max((a - free) / per_newton * v, 0.0) * dt
    return work / 3.6e6


def test_energy_is_of_the_order_reported(run):
    km = run.positions[-1] / 1000.0
    per_km = energy_kwh(run) / km
    ideal_per_km = perfect_tracking_energy_kwh(run) / km
    # The cut includes the acceleration to 350 km/h (4.2e9 J of kinetic energy over 25 km), so
    # it costs more per km than the whole trip's average; same order: within 0.3x .. 3x.
    assert 0.3 * PAPER_ENERGY_KWH_PER_KM < per_km < 3.0 * PAPER_ENERGY_KWH_PER_KM
    # the law spends about what following the built reference exactly costs: the gap to the
    # paper's figure is the reference's and the reconstructed resistance's, not the law's
    assert abs(per_km / ideal_per_km - 1.0) < 0.05
    record(Claim(
        'liu_li', 'Table 3 (Value 10): traction energy of the trip',
        f'{PAPER_ENERGY_KWH_PER_KM:.1f} kWh/km (1.6696e4 kWh over 561.37 km)',
        f'closed loop {per_km:.1f} kWh/km; perfect tracking of the built reference '
        f'{ideal_per_km:.1f} kWh/km (closed loop / perfect {per_km / ideal_per_km:.3f})',
        f'liu_li_2020 [REC], the first {CUT_S:g} s of the trip ({km:.1f} km, with the '
        f'acceleration to 350 km/h), {RATE_HZ:g} Hz, energy = integral of max(u v, 0)',
        'partly reproduced', 'same order; the closed loop spends what perfect tracking of the '
        'built reference on the reconstructed resistance costs, so the difference from the '
        "paper's figure belongs to the reference (the paper's is lost) and the resistance, "
        'not to the law; and this is a cut of the trip'))


# Table 2: (k1, k2, Gamma1, lambda, K) of Values 1, 5, 6, 7, 9
TABLE_2 = {1: (0.048, 0.012, 0.06, 0.08, 8900.0), 5: (0.88, 0.22, 1.1, 0.08, 8900.0),
           6: (0.88, 0.22, 1.1, 0.8, 89000.0), 7: (4.88, 1.22, 6.1, 0.08, 8900.0),
           9: (8.8, 2.2, 11.0, 0.8, 89000.0)}


def test_cases_1_and_2_bigger_gains_cut_the_errors():
    # Case 1: observer gains up (Values 1 -> 5 -> 7 -> 9), the observer error falls (paper: 52,
    # 0.63, 0.030, 0.011 m); Case 2: control gains x10 (Value 5 -> 6, same observer) cut the
    # position-tracking error (paper 89 -> 0.41 m). Values 1-9 run at 20 Hz (k1 dt <= 0.44);
    # 250 s of the trip. Measured: s - s_hat 78, 2.0, 3.1e-4, 1.2e-4 m; s - s_d 287 -> 4.2 m.
    metrics = {}
    for value, (k1, k2, gamma1, lam, gain) in TABLE_2.items():
        run = run_liu_li(liu_li_2020(), 250.0, {
            'k1': k1, 'k2': k2, 'Gamma1': gamma1, 'lam': lam, 'K': gain}, rate_hz=20.0)
        assert not any(run.faults), value
        metrics[value] = table_3_metrics(run)
    observer = [metrics[v]['s - s_hat'] for v in (1, 5, 7, 9)]
    assert all(a > 2 * b for a, b in zip(observer, observer[1:])), observer
    assert metrics[5]['s - s_d'] > 10 * metrics[6]['s - s_d']
    assert metrics[6]['s - s_hat'] == pytest.approx(metrics[5]['s - s_hat'], rel=0.5)
    record(Claim(
        'liu_li', 'Cases 1 and 2: bigger observer gains cut the observer error; bigger control '
        'gains cut the tracking error', 's - s_hat 52, 0.63, 0.030, 0.011 m (Values 1, 5, 7, 9); '
        's - s_d 89 -> 0.41 m (Value 5 -> 6)',
        's - s_hat ' + ', '.join(f'{v:.3g}' for v in observer) + ' m; s - s_d '
        f'{metrics[5]["s - s_d"]:.3g} -> {metrics[6]["s - s_d"]:.3g} m',
        'liu_li_2020 [REC], Table 2 gains, 20 Hz, the first 250 s of the trip',
        'reproduced'))


if __name__ == '__main__':
    # The full 561.37 km trip with one of Table 4's disturbances; "unlimited" lifts the
    # traction limits (the paper has none; the slow disturbance needs more than 20.44 MW).
    case = sys.argv[1] if len(sys.argv) > 1 else 'fast'
    scenario = liu_li_2020(case)
    if 'unlimited' in sys.argv:
        traction = dataclasses.replace(scenario.train.traction, max_traction_force_n=5e6,
                                       max_traction_power_w=1e9)
        scenario = dataclasses.replace(scenario, train=dataclasses.replace(scenario.train,
                                                                           traction=traction))
    started = time.time()
    full = run_liu_li(scenario)
    print(f'{case}: {len(full.times_s)} steps in {time.time() - started:.0f} s, faults: '
          f'{sum(1 for f in full.faults if f)}, end at {full.positions[-1]:.0f} m')
    for key, value in table_3_metrics(full).items():
        print(f'{key}: {value:.4g}' + (f'  (paper {PAPER[key]:.4g})' if key in PAPER else ''))
