"""The ``timetable`` strategy is the least-energy curve for its running time: on lines of every
kind on which the earlier planner was not (a 120 m descent, speed drops, a steep climb, a mixed
profile; tests/data/synthetic/least_energy_lines.yaml), for two TTOBench trains (a light
single-deck and a heavy double-deck EMU) and two running-time supplements, its energy is within
2 % of the independent optimum (``profile_node.oracle``), gross where the train regenerates
nothing and net where it regenerates at its efficiency. The oracle's own grid error is checked
in test_oracle.py."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from ato_common.scenario import parse_scenario
from profile_node.oracle import LegOracle, Physics
from profile_node.planner import leg_limits, plan_reference

DATA = Path(__file__).resolve().parents[2] / 'tests' / 'data'
SAMPLES = DATA / 'ttobench'
LINES = yaml.safe_load((DATA / 'synthetic' / 'least_energy_lines.yaml').read_text())
TRAINS = ('CH_Stadler_FLIRT_TPF', 'CH_Stadler_KISS_SBB')
SUPPLEMENTS = (7.0, 15.0)
# The oracle's grid (test_oracle.py: its error there is well under 1 %).
ORACLE_DX_M, ORACLE_DE = 100.0, 2.0


def scenario_for(line: str, train: str, supplement: float, objective: str):
    """The line with the train; 'gross': the train regenerating nothing, 'net': at its
    efficiency (the file's, 0.9)."""
    train_section = {'ttobench': str(SAMPLES / 'trains' / f'{train}.json')}
    if objective == 'gross':
        train_section['regenerative_efficiency'] = 0.0
    return parse_scenario({
        'name': line, 'train': train_section, 'line': LINES['lines'][line],
        'planning': LINES['planning'],
        'timetable': {'strategy': 'timetable', 'supplement_percent': supplement}})


def oracle_energy_j(scenario, running_time_s: float, objective: str) -> float:
    """The oracle's least energy on the scenario's single leg at ``running_time_s``, within
    the limits the planner plans it within."""
    limits = leg_limits(scenario)
    oracle = LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m, objective,
                       ORACLE_DX_M, ORACLE_DE, scenario.planning.max_jerk_mps3)
    return oracle.at_time(running_time_s).energy_j(objective)


@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
@pytest.mark.parametrize('objective', ('gross', 'net'))
@pytest.mark.parametrize('supplement', SUPPLEMENTS)
@pytest.mark.parametrize('train', TRAINS)
@pytest.mark.parametrize('line', sorted(LINES['lines']))
def test_the_timetable_curve_is_within_2_percent_of_the_oracle(line, train, supplement,
                                                               objective):
    scenario = scenario_for(line, train, supplement, objective)
    assert (scenario.train.regenerative_efficiency > 0.0) == (objective == 'net')
    plan = plan_reference(scenario)
    leg = plan.legs[0]
    # on time: the shortest running time plus the supplement (within the tolerance of a jump
    # of the running time with the hold speed, planner.LATE_TOLERANCE_S)
    assert leg.target_arrival_s == pytest.approx(
        leg.departure_s + leg.shortest_running_s * (1.0 + supplement / 100.0), abs=1e-6)
    assert abs(leg.planned_arrival_s - leg.target_arrival_s) <= 1.0
    energy = plan.forecast.traction_j if objective == 'gross' else plan.forecast.net_j
    optimum = oracle_energy_j(scenario, leg.planned_arrival_s - leg.departure_s, objective)
    assert energy == pytest.approx(optimum, rel=0.02), (energy / optimum - 1.0)
