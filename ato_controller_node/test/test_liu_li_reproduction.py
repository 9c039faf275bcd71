"""Liu & Li 2020 reproduction (offline loop, no ROS): with the speed sensor failed, the
observer and tracking errors reach the order of Table 3 (Value 10) / Table 4, and the traction
energy is of the order reported.

The paper's run is 561 km (about 6400 s); at the 200 Hz the Value-10 observer needs that is too
long for a unit test, so this runs a representative cut: the start of the trip (acceleration to
350 km/h), a 3 per-mille ramp and the curve (R = 200 m) inside a 1000 m tunnel of Table 1, moved
to the first 25 km. The full trip: `python ato_controller_node/test/test_liu_li_reproduction.py`
(its numbers are in README.md). No disturbance: the plant's disturbance arrives with the scenario's plant
section; Table 4 shows it changes the RMS errors by under 1 %.
"""

import dataclasses
import math

import numpy as np
import pytest

from ato_bringup.offline import run_offline
from ato_common.scenario import parse_scenario
from ato_common.types import TrainState
from train_plant_node.simulation import TrainSimulation

RATE_HZ = 200.0
CUT_S = 500.0
# Table 3, Value 10 (= Table 4 "fast", rows 2-4 read as x1e-4, shared/papers/README.md)
PAPER = {'s - s_hat': 5.3111e-5, 'v - v_hat': 0.0378, 's - s_d': 0.0075, 'v - v_d': 0.0366}
PAPER_ENERGY_KWH_PER_KM = 1.6696e4 / 561.37   # Table 3 V10, read as 1e4 kWh over 561.37 km


def liu_li_scenario(length_m=60000.0, ramp_m=14000.0, curve_m=24000.0, rate_hz=RATE_HZ):
    """The notes' reading of the paper's line (section 5): one 4 km ramp of 3 per mille, one
    curve (R = 200 m) inside a 1000 m tunnel; 350 km/h; CRH380AL 890 t."""
    return parse_scenario({
        'name': 'liu_li_line', 'train': {'preset': 'crh380al_liu_li'},
        'line': {'name': 'liu_li_line', 'length_m': length_m,
                 'stations': [{'name': 'start', 'position_m': 0},
                              {'name': 'end', 'position_m': length_m}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 350}],
                 'gradients': [{'start_m': 0, 'per_mille': 0}, {'start_m': ramp_m, 'per_mille': 3},
                               {'start_m': ramp_m + 4000, 'per_mille': 0}],
                 'curves': [{'start_m': curve_m, 'length_m': 1000, 'radius_m': 200}],
                 'tunnels': [{'start_m': curve_m, 'length_m': 1000}]},
        'planning': {'max_acceleration_mps2': 0.25, 'service_deceleration_mps2': 0.4,
                     'max_jerk_mps3': 0.05},
        'run': {'controller_rate_hz': rate_hz}})


def run_without_speed_sensor(scenario, end_time_s=None, settings=None):
    original = TrainSimulation.measured

    def speed_sensor_failed(self, truth=None):
        m = original(self, truth)
        return TrainState(m.stamp_ns, m.car_names, m.positions, (math.nan,) * len(m.speeds),
                          (math.nan,) * len(m.speeds), m.forces)
    TrainSimulation.measured = speed_sensor_failed
    try:
        return run_offline(scenario, 'liu_li', settings={'liu_li': settings or {}},
                           end_time_s=end_time_s)
    finally:
        TrainSimulation.measured = original


@pytest.fixture(scope='module')
def run():
    return run_without_speed_sensor(liu_li_scenario(), CUT_S)


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_runs_on_position_alone(run):
    assert not any(run.faults)
    assert run.positions[-1] > 25500.0             # through the ramp, the curve and the tunnel
    assert run.speeds.max() > 320 / 3.6            # the traction-limited climb to 350 km/h


def table_3_metrics(run):
    return {'s - s_hat': _rms(run.positions - run.estimate('position_hat_m')),
            'v - v_hat': _rms(run.speeds - run.estimate('speed_hat_mps')),
            's - s_d': _rms(run.positions - run.ref_positions),
            'v - v_d': _rms(run.speeds - run.ref_speeds),
            'energy_1e4_kwh': energy_kwh(run) / 1e4}


def energy_kwh(run):
    """Traction energy integral max(u v, 0) dt (the notes' reading of the paper's metric)."""
    dt = run.times_s[1] - run.times_s[0]
    return float(np.sum(np.maximum(run.forces * run.speeds, 0.0)) * dt / 3.6e6)


def test_errors_reach_the_order_of_table_3_value_10(run):
    measured = table_3_metrics(run)
    del measured['energy_1e4_kwh']
    # Measured on this cut: 2.6e-5 m, 3.5e-3 m/s, 1.5e-3 m, 3.8e-5 m/s, each at or below the
    # paper's order (5.3e-5 m, 0.038 m/s, 7.5e-3 m, 0.037 m/s). "Order of" = within 2x above.
    for key, value in measured.items():
        assert value < 2.0 * PAPER[key], (key, value)
    # and not trivially: the observer's speed error is not zero, the weights learned
    assert measured['v - v_hat'] > 1e-4
    assert run.estimate('resistance_hat_mps2')[-1] > 0.05


def test_energy_is_of_the_order_reported(run):
    per_km = energy_kwh(run) / (run.positions[-1] / 1000.0)
    # The cut includes the acceleration to 350 km/h (4.2e9 J of kinetic energy over 25 km), so
    # it costs more per km than the whole trip's average; same order: within 0.3x .. 3x.
    assert 0.3 * PAPER_ENERGY_KWH_PER_KM < per_km < 3.0 * PAPER_ENERGY_KWH_PER_KM


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
        run = run_without_speed_sensor(liu_li_scenario(rate_hz=20.0), 250.0, {
            'k1': k1, 'k2': k2, 'Gamma1': gamma1, 'lam': lam, 'K': gain})
        assert not any(run.faults), value
        metrics[value] = table_3_metrics(run)
    observer = [metrics[v]['s - s_hat'] for v in (1, 5, 7, 9)]
    assert all(a > 2 * b for a, b in zip(observer, observer[1:])), observer
    assert metrics[5]['s - s_d'] > 10 * metrics[6]['s - s_d']
    assert metrics[6]['s - s_hat'] == pytest.approx(metrics[5]['s - s_hat'], rel=0.5)


if __name__ == '__main__':
    # The full 561.37 km trip (ramp at km 100, curve in tunnel at km 300): Table 3 metrics.
    import sys
    import time
    settings = dict(arg.split('=') for arg in sys.argv[1:])
    settings = {k: (v == 'true') if v in ('true', 'false') else float(v) for k, v in settings.items()}
    started = time.time()
    full = run_without_speed_sensor(liu_li_scenario(561370.0, 100000.0, 300000.0),
                                    settings=settings)
    print(f'{len(full.times_s)} steps in {time.time() - started:.0f} s, faults: '
          f'{sum(1 for f in full.faults if f)}')
    for key, value in table_3_metrics(full).items():
        print(f'{key}: {value:.4g}' + (f'  (paper {PAPER[key]:.4g})' if key in PAPER else
                                       '  (paper 1.6696)'))
