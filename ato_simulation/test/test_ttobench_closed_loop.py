"""A TTOBench track with a TTOBench train through the closed loop (the no-ROS loop on the same
cores as the nodes): the plant runs the track's line and the train's physics, the PID law
tracks the suite's target curve."""

from pathlib import Path

import numpy as np

from ato_common.scenario import parse_scenario
from ato_common.ttobench import scenario_data

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
TRACK = SAMPLES / 'tracks' / 'CH_Stadelhofen_Altstetten.json'
TRAIN = SAMPLES / 'trains' / 'CH_Stadler_KISS_SBB.json'


def test_a_ttobench_track_and_train_run_through_the_closed_loop():
    from ato_simulation.loop import run_offline
    scenario = parse_scenario(scenario_data(TRACK, TRAIN, dwell_s=20.0))
    run = run_offline(scenario, 'pid')
    metrics = run.metrics()
    # every stop of the track is served, within 0.5 m
    assert set(metrics.stop_errors_m) == {f'stop_{i}' for i in range(1, 4)}
    assert all(abs(e) < 0.5 for e in metrics.stop_errors_m.values()), metrics.stop_errors_m
    assert metrics.rms_speed_error_kmh < 1.0 and metrics.max_position_error_m < 2.0
    # the train itself stays under the supervision's permitted speed (with the tracking error)
    permitted = np.array([run.plan.permitted_speed(x, t)
                          for t, x in zip(run.times_s, run.positions)])
    assert np.all(run.speeds <= permitted + 0.5)
    assert run.times_s[-1] >= run.plan.trajectory.end_time
