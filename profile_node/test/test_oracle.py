"""The oracle (``profile_node.oracle``) is independent of the planner and accurate: it imports
none of the planner's modules (checked on the import graph, with grimp), its grid error is
measured by refining the grid (under 0.5 % at the tests' grid, refining the stages and the
speeds together and each alone), and its jerk allowance is the time of the ramps at the start
and the stop."""

from __future__ import annotations

import grimp
import pytest
from test_least_energy import ORACLE_DE, ORACLE_DX_M, scenario_for

from profile_node.oracle import LegOracle, Physics
from profile_node.planner import leg_limits, plan_reference

PLANNER_MODULES = ('profile_node.planner', 'profile_node.timetable', 'profile_node.trajectory',
                   'profile_node.eco')


def test_the_oracle_imports_none_of_the_planners_modules():
    graph = grimp.build_graph('profile_node', 'ato_common', cache_dir=None)
    imported = graph.find_upstream_modules('profile_node.oracle')
    assert imported, 'the import graph has no modules under the oracle'
    assert not imported & set(PLANNER_MODULES), sorted(imported & set(PLANNER_MODULES))
    for module in PLANNER_MODULES:
        assert not graph.chain_exists(importer='profile_node.oracle', imported=module)


@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
def test_the_oracles_grid_error_is_under_half_a_percent_at_the_tests_grid():
    # the mixed line: every kind of limit; the heavy train, regenerating (net energy)
    scenario = scenario_for('mixed', 'CH_Stadler_KISS_SBB', 7.0, 'net')
    leg = plan_reference(scenario).legs[0]
    running = leg.planned_arrival_s - leg.departure_s
    limits = leg_limits(scenario)

    def optimum(dx_m: float, de: float) -> float:
        oracle = LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m, 'net',
                           dx_m, de, scenario.planning.max_jerk_mps3)
        return oracle.at_time(running).net_j
    fine = optimum(0.5 * ORACLE_DX_M, 0.5 * ORACLE_DE)
    # both steps refined together, and each alone: refining them together keeps de / dx, the
    # grid's resolution of an acceleration over a stage, and would not show an error that
    # depends on it (a deceleration that is not a multiple of it: 0.5 m/s^2 x 50 m / 2 m^2/s^2)
    grids = {'coarse': (2.0 * ORACLE_DX_M, 2.0 * ORACLE_DE), 'tests': (ORACLE_DX_M, ORACLE_DE),
             'finer stages': (0.5 * ORACLE_DX_M, ORACLE_DE),
             'finer speeds': (ORACLE_DX_M, 0.5 * ORACLE_DE)}
    for name, grid in grids.items():
        assert optimum(*grid) == pytest.approx(fine, rel=0.005), name


def test_the_jerk_allowance_is_the_time_of_the_ramps_at_the_start_and_the_stop():
    scenario = scenario_for('speed_drops', 'CH_Stadler_FLIRT_TPF', 7.0, 'gross')
    limits = leg_limits(scenario)
    jerk = scenario.planning.max_jerk_mps3
    oracle = LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m, 'gross',
                       ORACLE_DX_M, ORACLE_DE, jerk)
    start = limits.acceleration_mps2(0.0, limits.start_m)
    stop = limits.deceleration_mps2(limits.end_m)
    assert oracle.jerk_allowance_s == pytest.approx((start + stop) / (2.0 * jerk))
    assert LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m, 'gross',
                     ORACLE_DX_M, ORACLE_DE).jerk_allowance_s == 0.0
