"""Replanning a ``timetable`` plan when the train falls behind it (no ROS).

The delay of a train is how much later than the plan it is where it is: the run time now minus
the time the plan passes the train's measured position. Once that exceeds the scenario's
``timetable.replan_delay_s`` while the train is moving on a leg, the rest of the run is planned
again from the train's measured position and speed at that time, aimed at the timetable's
arrival times (each leg's original target): on time if the remaining reserve allows, else as
early as possible, and the expected delay at the last stop is the plan's ``expected_delay_s``.

The new curve starts where the train is (its position and speed: the tracking error steps to
zero, which is the point) with the old reference's acceleration, brought to zero at the jerk
limit, so a* stays continuous and the jerk bounded across the replan.
"""

from __future__ import annotations

import math
from dataclasses import replace

from ato_common.braking_curves import RunSupervision
from ato_common.line import Station
from ato_common.scenario import Scenario
from profile_node.planner import Plan, PlanningError, passing_time, plan_timetable

# Below this speed the train is standing (a dwell, or a stop the resume handles), m/s.
MOVING_MPS = 1.0


def delay_s(plan: Plan, time_s: float, position_m: float) -> float:
    """How much later than ``plan`` a train at ``position_m`` is at ``time_s`` (negative:
    early)."""
    return time_s - passing_time(plan.trajectory, position_m)


def replan_from(scenario: Scenario, plan: Plan, time_s: float, position_m: float,
                speed_mps: float) -> Plan | None:
    """The rest of the run from a train at (position, speed) at ``time_s``, aimed at ``plan``'s
    arrival times; None where no station is left ahead."""
    ahead = [s for s in scenario.line.stations
             if s.position_m > position_m + RunSupervision.STOP_WINDOW_M]
    if not ahead:
        return None
    line = replace(scenario.line, stations=(Station('replan', position_m, 0.0), *ahead))
    resumed = replace(scenario, line=line,
                      run=replace(scenario.run, initial_position_m=position_m))
    targets = {}
    for leg, station in enumerate(ahead):
        timing = next((t for t in plan.legs if t.destination == station.name), None)
        if timing is not None:
            targets[leg] = timing.target_arrival_s
    acceleration = plan.trajectory.at(time_s).acceleration
    return plan_timetable(resumed, time_s, (speed_mps, acceleration), targets)


class Replanner:
    """Holds the plan in force and replans it when the train is late (module docstring).
    ``update`` is called with each measurement; it returns the new plan when it replanned."""

    def __init__(self, scenario: Scenario, plan: Plan):
        self.scenario = scenario
        self.plan = plan
        self.threshold_s = scenario.timetable.replan_delay_s
        self.replans: list[tuple[float, float, float]] = []  # (time, delay, expected delay)
        self.history: list[tuple[float, Plan]] = []          # (time, the new plan)
        # The timetable's legs, kept across replans (a replan's legs start at the train).
        self.timetable_legs = plan.legs

    @property
    def active(self) -> bool:
        return self.plan.strategy == 'timetable' and self.threshold_s > 0.0

    def update(self, time_s: float, position_m: float, speed_mps: float) -> Plan | None:
        if not self.active or not (math.isfinite(position_m) and math.isfinite(speed_mps)):
            return None
        if speed_mps < MOVING_MPS or time_s >= self.plan.stops[-1].arrival_s + self.threshold_s:
            return None
        stop = self.plan.next_stop(time_s)
        if position_m >= stop.station.position_m - RunSupervision.STOP_WINDOW_M:
            return None
        late = delay_s(self.plan, time_s, position_m)
        if late <= self.threshold_s:
            return None
        original = replace(self.plan, legs=self.timetable_legs)
        try:
            plan = replan_from(self.scenario, original, time_s, position_m, speed_mps)
        except PlanningError:
            return None  # no curve from this state (keeps the old one; the ATP supervises)
        if plan is None:
            return None
        self.plan = plan
        self.replans.append((time_s, late, plan.expected_delay_s))
        self.history.append((time_s, plan))
        return plan
