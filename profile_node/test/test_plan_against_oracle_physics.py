"""The plan's forecast and the oracle (``profile_node.oracle``) are computed on the same physics,
the one the planner is given (the nominal train on the line; not a scenario's ``plant:``
section, whose operating modes, failures and variations only the plant simulates), and on it
the plan is never below the oracle's optimum beyond the oracle's grid error.

``mao_2017_modes`` (a level line whose plant passes through a tunnel, a slope and a failed
motor by time) showed its plan's forecast below the oracle at the bench's grid: not the modes,
which neither models, but the oracle's grid, which could brake into the stop only at a multiple
of de / dx (0.08 m/s^2 for the plan's 0.093). ``mao_4car`` showed it below too: the oracle's
acceleration over a stage capped at the end speed's power-limited one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ato_common.scenario import load_scenario
from profile_node.oracle import LegOracle, Physics
from profile_node.planner import leg_limits, plan_reference
from profile_node.timetable import sample

# The bench's oracle grid (bench/bench.py oracle_kwh): a leg's length / 150 within 50-200 m,
# a step of v^2/2 of 0.02 m/s^2 x the stage.
STAGES, LOWEST_DX_M, HIGHEST_DX_M, DE_PER_M = 150, 50.0, 200.0, 0.02
# How far the plan may be below the oracle: the oracle's grid error there (test_oracle.py).
GRID_TOLERANCE = 0.002


def timetable_plan(name: str):
    scenario = load_scenario(name)
    scenario = dataclasses.replace(scenario, timetable=dataclasses.replace(
        scenario.timetable, strategy='timetable', supplement_percent=7.0))
    return scenario, plan_reference(scenario)


def leg_oracles(scenario, plan, objective: str):
    """Each leg's oracle on the bench's grid, with the leg's running time in the plan."""
    for k, leg in enumerate(plan.legs):
        limits = leg_limits(scenario, k)
        dx = min(max((limits.end_m - limits.start_m) / STAGES, LOWEST_DX_M), HIGHEST_DX_M)
        oracle = LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m,
                           objective, dx, DE_PER_M * dx, scenario.planning.max_jerk_mps3)
        yield oracle, leg


def test_the_planner_is_not_given_the_plants_modes():
    scenario, plan = timetable_plan('mao_2017_modes')
    assert scenario.plant.modes, 'the scenario has lost its modes: the test means nothing'
    without = dataclasses.replace(scenario, plant=dataclasses.replace(scenario.plant, modes=()))
    assert plan_reference(without).trajectory.segments == plan.trajectory.segments


@pytest.mark.parametrize('name', ('mao_2017_modes', 'mao_4car'))
def test_the_forecast_is_the_plans_energy_in_the_oracles_physics(name):
    scenario, plan = timetable_plan(name)
    times = np.linspace(plan.trajectory.start_time, plan.trajectory.end_time, 100_001)
    positions, speeds, _ = sample(plan.trajectory, times)
    gross = 0.0
    for oracle, leg in leg_oracles(scenario, plan, 'gross'):
        on_leg = (times >= leg.departure_s - 1e-9) & (times <= leg.planned_arrival_s + 1e-9)
        curve = oracle.evaluate(np.interp(oracle.xs, positions[on_leg], speeds[on_leg]))
        gross += curve.gross_j
    assert plan.forecast is not None
    assert plan.forecast.traction_j == pytest.approx(gross, rel=0.001)


@pytest.mark.parametrize('name', ('mao_2017_modes', 'mao_4car'))
def test_the_plan_is_not_below_the_oracle_at_the_benchs_grid(name):
    scenario, plan = timetable_plan(name)
    objective = 'net' if scenario.train.regenerative_efficiency > 0.0 else 'gross'
    optimum = sum(oracle.at_time(leg.planned_arrival_s - leg.departure_s).energy_j(objective)
                  for oracle, leg in leg_oracles(scenario, plan, objective))
    assert plan.forecast is not None
    planned = plan.forecast.net_j if objective == 'net' else plan.forecast.traction_j
    assert planned >= (1.0 - GRID_TOLERANCE) * optimum, planned / optimum - 1.0
