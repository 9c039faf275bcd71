"""Mao et al. 2017 on the suite's plant: the built-in scenario mao_2017_modes in the offline closed
loop. (The law's equations and the reproduction on the paper's own model:
ato_controller_node/test/test_mao_2017.py.)"""

import numpy as np

from ato_common.evidence import Claim, record
from ato_common.scenario import load_scenario
from ato_simulation.loop import run_offline


def test_preset_mao_2017_modes_on_the_suite_plant():
    """The built-in scenario: same modes and failure, 200 km/h cruise, the mao_2017_500t
    limits (the healthy motors stay within them after the failure). The paper's result holds
    on the suite's plant: the position error goes back to about zero after every mode switch
    (400, 800, 1400 s) and every change of the failure (600, 1000, 1200 s)."""
    scenario = load_scenario('mao_2017_modes')
    run = run_offline(scenario, 'mao_2017')
    t, ex = run.times_s, run.ref_positions - run.positions
    assert not any(run.faults)
    for event in (400.0, 600.0, 800.0, 1000.0, 1200.0, 1400.0):   # measured at most 0.048 m
        window = (t > event + 100.0) & (t < event + 200.0)
        assert np.max(np.abs(ex[window])) < 0.15, event
    outage = (t > 1250.0) & (t < 1400.0)
    limits = np.array([scenario.train.traction.limits_at(v)[1] / 4 for v in run.speeds[outage]])
    assert np.all(run.actuator_forces[outage, 1:] < limits[:, None])  # measured 75 % at most
    assert np.all(run.actuator_forces[outage, 0] == 0.0)          # the failed motor
    assert np.max(np.abs(ex)) < 1.0                               # measured 0.30 m
    assert np.max(np.abs(ex[t > 1700.0])) < 0.05                  # measured 0.006 m
    stop = run.metrics().stop_errors_m['Stop']
    assert abs(stop) < 0.05                                       # measured 0.006 m
    after = max(np.max(np.abs(ex[(t > e + 100.0) & (t < e + 200.0)]))
                for e in (400.0, 600.0, 800.0, 1000.0, 1200.0, 1400.0))
    share = np.max(run.actuator_forces[outage, 1:] / limits[:, None])
    record(Claim(
        'mao_2017', "the paper's result on the suite's plant, with a train's traction limits",
        'error back to about zero after each event',
        f'peak {np.max(np.abs(ex)):.2f} m, at most {after:.3f} m 100-200 s after each event, '
        f'{np.max(np.abs(ex[t > 1700.0])):.4f} m after 1700 s, stop {stop:+.4f} m; healthy '
        f'motors at most {share * 100:.0f} % of their limit during the outage',
        'mao_2017_modes: the suite plant with the paper\'s modes and failure, 200 km/h cruise, '
        'the mao_2017_500t traction limits, 10 Hz', 'reproduced'))
