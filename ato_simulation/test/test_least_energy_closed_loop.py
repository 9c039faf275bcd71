"""The ``timetable`` strategy's least-energy curve followed in closed loop (the PID law on the
nominal point-mass plant, ``loop.run_offline``) on the lines it is held against the oracle on
(tests/data/synthetic/least_energy_lines.yaml, profile_node/test/test_least_energy.py): the
run's energy at the wheel is within 3 % of the oracle's least energy for the running time the
run took, gross where the train regenerates nothing and net where it regenerates."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from ato_common.scenario import parse_scenario
from ato_simulation.loop import run_offline
from profile_node.oracle import LegOracle, Physics
from profile_node.planner import leg_limits

DATA = Path(__file__).resolve().parents[2] / 'tests' / 'data'
LINES = yaml.safe_load((DATA / 'synthetic' / 'least_energy_lines.yaml').read_text())
TRAINS = ('CH_Stadler_FLIRT_TPF', 'CH_Stadler_KISS_SBB')
# (objective, running-time supplement %): both energies, both supplements, in a modest number
# of runs.
CASES = (('gross', 7.0), ('net', 15.0))
# The oracle's grid (profile_node/test/test_oracle.py: its error there is under 0.5 %).
ORACLE_DX_M, ORACLE_DE = 100.0, 2.0
# Standing within this of the stopping point counts as arrived, m.
ARRIVED_WITHIN_M = 1.0


def scenario_for(line: str, train: str, supplement: float, objective: str):
    train_section = {'ttobench': str(DATA / 'ttobench' / 'trains' / f'{train}.json')}
    if objective == 'gross':
        train_section['regenerative_efficiency'] = 0.0
    return parse_scenario({
        'name': line, 'train': train_section, 'line': LINES['lines'][line],
        'planning': LINES['planning'],
        'timetable': {'strategy': 'timetable', 'supplement_percent': supplement}})


def cases():
    for line in sorted(LINES['lines']):
        for train in TRAINS:
            for objective, supplement in CASES:
                yield pytest.param(line, train, objective, supplement)


@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
@pytest.mark.parametrize('line, train, objective, supplement', list(cases()))
def test_the_closed_loop_run_is_within_3_percent_of_the_oracle(line, train, objective,
                                                               supplement):
    scenario = scenario_for(line, train, supplement, objective)
    run = run_offline(scenario, 'pid')
    assert not run.replans
    end = scenario.line.stations[-1].position_m
    at = (np.abs(run.positions - end) < ARRIVED_WITHIN_M) & (np.abs(run.speeds) < 0.01)
    assert at.any(), 'the train never stood at the end of the line'
    arrived = float(run.times_s[np.argmax(at)])
    leg = run.plan.legs[0]
    assert abs(arrived - leg.target_arrival_s) <= 1.0
    metrics = run.metrics()
    spent = metrics.traction_energy_kwh if objective == 'gross' else metrics.net_energy_kwh
    limits = leg_limits(scenario)
    oracle = LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m, objective,
                       ORACLE_DX_M, ORACLE_DE, scenario.planning.max_jerk_mps3)
    optimum = oracle.at_time(arrived - leg.departure_s).energy_j(objective) / 3.6e6
    assert spent == pytest.approx(optimum, rel=0.03), spent / optimum - 1.0
