"""The timetable strategy's theory (profile_node.timetable): the braking speed of eq (2), the
regenerative efficiency a TTOBench train gives, and the energy net of regeneration."""

from dataclasses import replace
from pathlib import Path

import pytest

from ato_common.scenario import load_scenario, parse_scenario
from ato_common.ttobench import scenario_data
from profile_node.planner import plan_reference
from profile_node.timetable import coast_end_speed, forecast_energy_j, resistance_per_kg

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'


def test_the_braking_speed_solves_eq_2_and_rises_with_regeneration():
    scenario = load_scenario('short_line')
    r, dr = resistance_per_kg(scenario)
    v = 60.0
    psi, hold = v * v * dr(v), r(v) + v * dr(v)
    without = coast_end_speed(scenario, v)
    assert without == pytest.approx(psi / hold)
    assert 0.0 < without < v
    with_regeneration = coast_end_speed(scenario, v, 0.6)
    assert psi / with_regeneration + 0.6 * r(with_regeneration) == pytest.approx(hold)
    # recovering part of the braking energy makes braking cheaper: the coast ends sooner
    assert without < with_regeneration < v


@pytest.mark.filterwarnings('ignore::UserWarning')
def test_a_ttobench_train_gives_its_regeneration_and_the_energy_is_net_of_it():
    data = scenario_data(SAMPLES / 'tracks' / 'CH_Fribourg_Bern.json',
                         SAMPLES / 'trains' / 'CH_Stadler_FLIRT_TPF.json')
    scenario = parse_scenario(data)
    assert scenario.timetable.regenerative_efficiency == 0.9
    assert scenario.timetable.regenerative_power_w == 2.6e6
    plan = plan_reference(scenario)
    lost = replace(scenario, timetable=replace(scenario.timetable, regenerative_efficiency=0.0))
    assert forecast_energy_j(scenario, plan.trajectory) < forecast_energy_j(lost, plan.trajectory)
    # a preset gives none
    assert load_scenario('short_line').timetable.regenerative_efficiency == 0.0
