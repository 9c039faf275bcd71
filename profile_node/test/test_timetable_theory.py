"""The timetable strategy's theory: the price of time at which holding a speed is optimal
(``eco.hold_speed_price``, Albrecht et al. 2016) and its inverse, the regenerative efficiency and
power a TTOBench train gives, and the four energies at the wheel the plan forecasts and a run
reports (``ato_common.metrics``: gross traction, braking, regenerated, net), each labelled."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ato_common.metrics import ENERGY_LABELS, RunMetrics, format_summary, wheel_energy
from ato_common.scenario import load_scenario, parse_scenario
from ato_common.ttobench import scenario_data
from profile_node.eco import hold_speed_price, speed_of_price
from profile_node.planner import plan_reference
from profile_node.timetable import forecast_energy

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'


def test_the_price_of_holding_a_speed_rises_with_it_and_is_inverted():
    scenario = load_scenario('short_line')
    davis, mass = scenario.train.davis_nominal, scenario.train.mass_kg
    v = 60.0
    # psi(V) = V^2 r'(V), r the resistance per unit mass
    assert hold_speed_price(scenario, v) == pytest.approx(
        v * v * (davis.b_n_s_per_m + 2.0 * davis.c_n_s2_per_m2 * v) / mass)
    prices = [hold_speed_price(scenario, s) for s in (10.0, 30.0, 60.0, 90.0)]
    assert prices == sorted(prices) and prices[0] > 0.0
    assert speed_of_price(scenario, hold_speed_price(scenario, v)) == pytest.approx(v, abs=1e-5)
    assert speed_of_price(scenario, float('inf')) == float('inf')


def test_the_energies_at_the_wheel_follow_their_definitions():
    # 10 kN over 100 m, -20 kN over 50 m in 1 s, -20 kN over 50 m in 10 s
    forces, distances, durations = [1e4, -2e4, -2e4], [100.0, 50.0, 50.0], [5.0, 1.0, 10.0]
    none = wheel_energy(forces, distances, durations)
    assert (none.traction_j, none.braking_j, none.regenerated_j) == (1e6, 2e6, 0.0)
    assert none.net_j == none.traction_j
    # at 0.8 and at most 500 kW: 500 kJ of the first 1 MJ of braking, all of the second
    limited = wheel_energy(forces, distances, durations, 0.8, 5e5)
    assert limited.regenerated_j == pytest.approx(0.8 * (5e5 + 1e6))
    assert limited.net_j == pytest.approx(1e6 - 0.8 * 1.5e6)
    assert set(limited.kwh()) == set(ENERGY_LABELS)
    metrics = RunMetrics(1, 1.0, 0.0, 0.0, 0.0, 0.0, {}, **limited.kwh())
    assert metrics.net_energy_kwh == pytest.approx(metrics.traction_energy_kwh
                                                   - metrics.regenerated_energy_kwh)
    summary = format_summary(metrics, 's', 'c')
    for key, label in ENERGY_LABELS.items():
        assert f'{label:<22}{getattr(metrics, key):.2f} kWh' in summary


@pytest.mark.filterwarnings('ignore::UserWarning')
def test_a_ttobench_train_gives_its_regeneration_and_the_forecast_is_net_of_it():
    data = scenario_data(SAMPLES / 'tracks' / 'CH_Fribourg_Bern.json',
                         SAMPLES / 'trains' / 'CH_Stadler_FLIRT_TPF.json')
    scenario = parse_scenario(data)
    assert scenario.train.regenerative_efficiency == 0.9
    assert scenario.train.regenerative_power_w == 2.6e6
    plan = plan_reference(scenario)
    with_regeneration = forecast_energy(scenario, plan.trajectory)
    lost = replace(scenario, train=replace(scenario.train, regenerative_efficiency=0.0))
    without = forecast_energy(lost, plan.trajectory)
    assert plan.forecast == with_regeneration
    # the same gross and braking work; the regenerated share only where the train regenerates
    assert without.traction_j == with_regeneration.traction_j > 0.0
    assert without.braking_j == with_regeneration.braking_j > 0.0
    assert without.regenerated_j == 0.0 and without.net_j == without.traction_j
    assert 0.0 < with_regeneration.regenerated_j <= 0.9 * with_regeneration.braking_j
    assert with_regeneration.net_j < without.net_j
    assert np.isfinite(with_regeneration.net_j)
    # a preset gives none
    assert load_scenario('short_line').train.regenerative_efficiency == 0.0
