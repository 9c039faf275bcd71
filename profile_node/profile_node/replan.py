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

A train standing still more than ``planner.RESUME_GAP_M`` behind the reference (after an
emergency or watchdog brake) gets its leg planned again from where it stands
(``planner.resume_plan``, issue 13 defect 6). ``Replanner.decide`` makes both decisions, for
the real-time node (at each measurement) and for the lockstep schedule.

A measured position is the odometer's, and an odometer can err: one that places the train
outside the line (before its start, past its end) is taken as the nearest end of the line for
both decisions (``on_line``), and ``Replanner.note`` says so (issue 29: a bias of -200 m made
the planner fail on an empty stretch of line).

Lockstep (``LockstepPlans``): the measured state is read only at check instants, the first
control instant at or after each multiple of the check period, and a decision made from the
state of check instant t_c applies to the references from t_c + ``LAG_PERIODS`` control periods
on; the new plan starts there, from the measured position carried on at the measured speed. The
decisions are a function of the measured states at the check instants only, so a lockstep run
is reproducible bit for bit, and the offline loop (``ato_simulation.loop``, given a check
period) makes the same decisions as the node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ato_common.braking_curves import RunSupervision
from ato_common.line import Station
from ato_common.scenario import Scenario
from ato_common.types import seconds
from profile_node.planner import (
    RESUME_GAP_M,
    Plan,
    PlanningError,
    passing_time,
    plan_timetable,
    resume_plan,
)

# Below this speed the train is standing (a dwell, or a stop the resume handles), m/s.
MOVING_MPS = 1.0

#: lockstep: the simulated time between two checks of the measured state by default, s
CHECK_PERIOD_S = 1.0
#: lockstep: a decision from the measured state of check instant t_c applies to the references
#: from t_c + LAG_PERIODS control periods on. The profile sends each reference one period ahead
#: (at the tick before its own), so the reference of t_c + 2 periods is sent at t_c + 1 period,
#: when the state of t_c has been published (the plant publishes a step's state before it can
#: advance to the next one).
LAG_PERIODS = 2


def delay_s(plan: Plan, time_s: float, position_m: float) -> float:
    """How much later than ``plan`` a train at ``position_m`` is at ``time_s`` (negative:
    early)."""
    return time_s - passing_time(plan.trajectory, position_m)


def replan_from(scenario: Scenario, plan: Plan, time_s: float, position_m: float,
                speed_mps: float) -> Plan | None:
    """The rest of the run from a train at (position, speed) at ``time_s``, aimed at ``plan``'s
    arrival times, starting with ``plan``'s acceleration at ``time_s``; None where no station
    is left ahead."""
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


def on_line(scenario: Scenario, position_m: float) -> tuple[float, str]:
    """A measured position on the line: itself, or the nearest end of the line with a note
    naming the measured position (an odometer's error can place a train outside the line)."""
    line = scenario.line
    if 0.0 <= position_m <= line.length_m:
        return position_m, ''
    nearest = min(max(position_m, 0.0), line.length_m)
    return nearest, (f'the measured position {position_m:.1f} m is outside the line '
                     f'(0 to {line.length_m:g} m): taken as {nearest:g} m')


class Replanner:
    """Holds the plan in force and replans it when the train is late (module docstring).
    ``update`` is called with each measurement; it returns the new plan when it replanned."""

    def __init__(self, scenario: Scenario, plan: Plan):
        self.scenario = scenario
        self.plan = plan
        self.threshold_s = scenario.timetable.replan_delay_s
        self.replans: list[tuple[float, float, float]] = []  # (time, delay, expected delay)
        self.history: list[tuple[float, Plan]] = []          # (start time, the new plan)
        self.resumes: list[tuple[float, float]] = []         # (time, position)
        # The timetable's legs, kept across replans (a replan's legs start at the train).
        self.timetable_legs = plan.legs
        self.note = ''  # the last decision's measured position was outside the line: why

    @property
    def active(self) -> bool:
        return self.plan.strategy == 'timetable' and self.threshold_s > 0.0

    def update(self, time_s: float, position_m: float, speed_mps: float,
               start_s: float | None = None) -> Plan | None:
        """The replan of a train late at ``time_s`` (None: not late, or no curve). The new
        plan starts at ``start_s`` (default ``time_s``) from the measured position carried on
        at the measured speed."""
        if not self.active or not (math.isfinite(position_m) and math.isfinite(speed_mps)):
            return None
        position_m, self.note = on_line(self.scenario, position_m)
        if speed_mps < MOVING_MPS or time_s >= self.plan.stops[-1].arrival_s + self.threshold_s:
            return None
        stop = self.plan.next_stop(time_s)
        if position_m >= stop.station.position_m - RunSupervision.STOP_WINDOW_M:
            return None
        late = delay_s(self.plan, time_s, position_m)
        if late <= self.threshold_s:
            return None
        start_s = time_s if start_s is None else start_s
        original = replace(self.plan, legs=self.timetable_legs)
        try:
            plan = replan_from(self.scenario, original, start_s,
                               position_m + speed_mps * (start_s - time_s), speed_mps)
        except PlanningError:
            return None  # no curve from this state (keeps the old one; the ATP supervises)
        if plan is None:
            return None
        self.plan = plan
        self.replans.append((time_s, late, plan.expected_delay_s))
        self.history.append((start_s, plan))
        return plan

    def resume(self, time_s: float, position_m: float, speed_mps: float,
               start_s: float | None = None) -> Plan | None:
        """The leg planned again from a train standing still more than ``RESUME_GAP_M`` behind
        the plan's reference at ``time_s``, starting at ``start_s`` (default ``time_s``); None
        if it is not (or no station is left ahead)."""
        if not (math.isfinite(position_m) and math.isfinite(speed_mps)) \
                or abs(speed_mps) > RunSupervision.STANDSTILL_MPS:
            return None
        position_m, self.note = on_line(self.scenario, position_m)
        if self.plan.trajectory.at(time_s).position - position_m <= RESUME_GAP_M:
            return None
        start_s = time_s if start_s is None else start_s
        plan = resume_plan(self.scenario, position_m, start_s)
        if plan is None:
            return None
        self.plan = plan
        self.resumes.append((time_s, position_m))
        self.history.append((start_s, plan))
        return plan

    def decide(self, time_s: float, position_m: float, speed_mps: float,
               start_s: float | None = None) -> tuple[str, Plan] | None:
        """Replan a late moving train, else resume a standing one far behind: ('replanned',
        plan) or ('resumed', plan); None when the plan stays."""
        plan = self.update(time_s, position_m, speed_mps, start_s)
        if plan is not None:
            return 'replanned', plan
        plan = self.resume(time_s, position_m, speed_mps, start_s)
        return None if plan is None else ('resumed', plan)


@dataclass(frozen=True)
class Decision:
    """A change of plan in lockstep: made from the measured state of ``checked_ns``, the plan
    in force for the references from ``start_ns`` on."""

    kind: str            # 'replanned' or 'resumed'
    checked_ns: int
    start_ns: int
    position_m: float    # the measured state it was made from
    speed_mps: float
    plan: Plan


class LockstepPlans:
    """The plan in force at each control instant of a lockstep run (module docstring):
    ``schedule(t)`` says whether the control instant ``t`` is a check instant, ``check`` takes its
    measured state, ``plan_at(t)`` is the plan whose reference is streamed for ``t``."""

    def __init__(self, scenario: Scenario, plan: Plan, period_ns: int,
                 check_period_s: float = CHECK_PERIOD_S):
        if period_ns <= 0:
            raise ValueError(f'control period {period_ns} ns: must be positive')
        if not (math.isfinite(check_period_s) and check_period_s > 0.0):
            raise ValueError(f'replan check period {check_period_s!r} s: must be positive')
        self.replanner = Replanner(scenario, plan)
        self.period_ns = period_ns
        self.check_period_ns = max(round(check_period_s * 1e9), 1)
        self.next_check_ns = 0
        self.decisions: list[Decision] = []
        self._starts: list[int] = [-(2 ** 62)]
        self._plans: list[Plan] = [plan]

    def schedule(self, stamp_ns: int) -> bool:
        """Whether the control instant ``stamp_ns`` is a check instant (the first at or after
        the next multiple of the check period); True once per check instant."""
        if stamp_ns < self.next_check_ns:
            return False
        self.next_check_ns = (stamp_ns // self.check_period_ns + 1) * self.check_period_ns
        return True

    def start_of(self, checked_ns: int) -> int:
        """The first reference instant a decision at ``checked_ns`` applies to."""
        return checked_ns + LAG_PERIODS * self.period_ns

    def check(self, stamp_ns: int, position_m: float, speed_mps: float) -> Decision | None:
        """The measured state of the check instant ``stamp_ns``: a decision, or None."""
        start_ns = self.start_of(stamp_ns)
        decided = self.replanner.decide(seconds(stamp_ns), position_m, speed_mps,
                                        seconds(start_ns))
        if decided is None:
            return None
        kind, plan = decided
        decision = Decision(kind, stamp_ns, start_ns, position_m, speed_mps, plan)
        self.decisions.append(decision)
        self._starts.append(start_ns)
        self._plans.append(plan)
        return decision

    def plan_at(self, stamp_ns: int) -> Plan:
        starts = self._starts
        i = len(starts) - 1
        while starts[i] > stamp_ns:
            i -= 1
        return self._plans[i]

    @property
    def latest(self) -> Plan:
        """The newest plan (in force now or from a start instant still to come)."""
        return self._plans[-1]
