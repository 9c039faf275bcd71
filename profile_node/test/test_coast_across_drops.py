"""A coast across successive speed drops (issue 30): where the least-energy coast before a
drop passes the start of the lower limit below it, and the reference brakes again for a still
lower limit (or the stop) before any traction, the coast runs on into that braking, as the
optimum does. The planner used to refuse such a coast ("too slow" at the lower limit's start)
and started its coast kilometres later, from a lower hold speed: on ``jinan_xuzhou`` (drops
310 -> 282 -> 245 -> 155 km/h before the last stop) 1.4 % over the oracle at the bench's grid,
on ``luo_xu_crh3`` 2.6 %. Where the lower limit is followed by a higher one (the synthetic
speed_drops line), the coast still rejoins the lower limit's speed."""

from __future__ import annotations

import dataclasses

import numpy as np

from ato_common.scenario import load_scenario
from profile_node.planner import plan_reference


def speed_kmh_at(plan, position_m: float) -> float:
    trajectory = plan.trajectory
    times = np.arange(trajectory.start_time, trajectory.end_time, 0.5)
    states = [trajectory.at(t) for t in times]
    positions = np.array([s.position for s in states])
    speeds = np.array([s.speed for s in states])
    return 3.6 * float(np.interp(position_m, positions, speeds))


def test_the_coast_before_the_last_stop_runs_across_the_speed_drops():
    scenario = load_scenario('jinan_xuzhou')
    scenario = dataclasses.replace(scenario, timetable=dataclasses.replace(
        scenario.timetable, strategy='timetable', supplement_percent=7.0))
    plan = plan_reference(scenario)
    # the oracle (bench grid): 278.7 km/h held to about 198 km, coasting from there: 261.8 at
    # 201.6 km, 189.4 at 218.4 km (the start of the 245 km/h limit), 147.5 at 224 km
    assert speed_kmh_at(plan, 190_000.0) > 275.0
    assert speed_kmh_at(plan, 201_600.0) < 265.0
    assert speed_kmh_at(plan, 218_400.0) < 200.0
