"""The ``timetable`` driving strategy's energy and journey windows (its optimisation is
``profile_node.eco``; its solver ``planner.plan_timetable``): the grade under the train, the
energies at the wheel a plan forecasts (``forecast_energy``, the definitions of
``ato_common.metrics``), the time aimed at in a window, what a journey's windows allow at each
timing point and which cannot be met (``journey_times``) and what the profile node reports of
a plan (``plan_summary``).
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from dataclasses import dataclass

import numpy as np

from ato_common import units
from ato_common.metrics import WheelEnergy, wheel_energy
from ato_common.scenario import Scenario
from profile_node.trajectory import Trajectory, passing_time

# A window's time is aimed at this far inside the window (at most half its width), s: the
# closed loop follows the reference a little late or early.
WINDOW_MARGIN_S = 2.0
# Accuracy of the time each leg is solved to, s.
TIME_TOLERANCE_S = 0.05
# Accuracy of the hold speed solved for, m/s (where the running time jumps with it).
SPEED_TOLERANCE_MPS = 0.02
# The lowest cruise speed the solver tries, m/s.
LOWEST_CRUISE_MPS = 2.0
# Sampling of the energy forecast, s.
ENERGY_STEP_S = 1.0


@dataclass(frozen=True)
class LegTiming:
    """One leg of a timetable plan: its destination, the arrival it aims at, the arrival
    planned, the shortest running time (the fastest curve's) and the reserve left."""

    destination: str
    departure_s: float
    target_arrival_s: float
    planned_arrival_s: float
    shortest_running_s: float

    @property
    def reserve_s(self) -> float:
        """Running time beyond the shortest one the plan spends (saving energy)."""
        return self.planned_arrival_s - self.departure_s - self.shortest_running_s

    @property
    def expected_delay_s(self) -> float:
        return max(self.planned_arrival_s - self.target_arrival_s, 0.0)


def train_grade_sine(line, front_m: float, length_m: float) -> float:
    """The grade the whole train feels with its front at ``front_m``: sin(theta) averaged over
    its length [front - length, front] (exact for piecewise-constant grades; before the line's
    start the first grade holds)."""
    if length_m <= 0.0:
        return line.grade_sine(front_m)
    rear = front_m - length_m
    starts, values = line.grade_sine.starts, line.grade_sine.values
    # Only the grades from the one under the rear to the one under the front overlap the train
    # (the others' overlap is <= 0 and was never added): the same sum, in the same order.
    first = max(bisect_right(starts, rear) - 1, 0)
    last = min(max(bisect_left(starts, front_m) - 1, 0), len(values) - 1)
    count = len(starts)
    total = 0.0
    for i in range(first, last + 1):
        a = starts[i] if i > 0 else -math.inf
        b = starts[i + 1] if i + 1 < count else math.inf
        overlap = min(b, front_m) - max(a, rear)
        if overlap > 0.0:
            total += values[i] * overlap
    return total / length_m


def sample(trajectory: Trajectory, times: np.ndarray):
    """x*, v*, a* at many times at once (vectorised ``Trajectory.at``)."""
    starts = np.array([s.t0 for s in trajectory.segments])
    x0 = np.array([s.x0 for s in trajectory.segments])
    v0 = np.array([s.v0 for s in trajectory.segments])
    a0 = np.array([s.a0 for s in trajectory.segments])
    jerk = np.array([s.jerk for s in trajectory.segments])
    t = np.clip(times, trajectory.start_time, trajectory.end_time)
    i = np.clip(np.searchsorted(starts, t, side='right') - 1, 0, len(starts) - 1)
    tau = t - starts[i]
    x = x0[i] + tau * (v0[i] + tau * (a0[i] / 2.0 + tau * jerk[i] / 6.0))
    v = v0[i] + tau * (a0[i] + tau * jerk[i] / 2.0)
    a = a0[i] + tau * jerk[i]
    end = times >= trajectory.end_time
    x[end], v[end], a[end] = (trajectory.end_position, trajectory.end_speed,
                              trajectory.end_acceleration)
    return x, v, a


def forecast_energy(scenario: Scenario, trajectory: Trajectory,
                    step_s: float = ENERGY_STEP_S) -> WheelEnergy:
    """The energies at the wheel (``ato_common.metrics.wheel_energy``: gross traction, braking,
    regenerated at the train's efficiency and power, net) of the nominal train following
    ``trajectory``: the force m a* + Davis(v*) + m g sin(grade over the train's length) + curves
    and tunnels, taken at the middle of each step and held over it: steps of at most
    ``step_s``, cut at every segment's start, so that no step straddles a change of the jerk
    (a step across the start of a braking, sampled at its middle, takes its force as the
    step's: on a net energy that is a small difference of traction and regeneration, that
    error was several per cent)."""
    train, line = scenario.train, scenario.line
    uniform = np.arange(trajectory.start_time, trajectory.end_time, step_s)
    cuts = [s.t0 for s in trajectory.segments if trajectory.start_time < s.t0
            < trajectory.end_time]
    times = np.unique(np.concatenate([uniform, cuts, [trajectory.end_time]]))
    times = times[np.concatenate([[True], np.diff(times) > 1e-9])]
    x_ends, _, _ = sample(trajectory, times)
    middles = 0.5 * (times[1:] + times[:-1])
    x, v, a = sample(trajectory, middles)
    grade = np.array([train_grade_sine(line, p, train.length_m) for p in x])
    other = np.array([line.line_force_per_kg(p) - units.STANDARD_GRAVITY * line.grade_sine(p)
                      for p in x])
    davis = train.davis_nominal
    force = (train.mass_kg * (a + units.STANDARD_GRAVITY * grade + other)
             + davis.a_n + davis.b_n_s_per_m * v + davis.c_n_s2_per_m2 * v * v)
    return wheel_energy(force, np.diff(x_ends), np.diff(times), train.regenerative_efficiency,
                        train.regenerative_power_w)


def window_target(earliest: float | None, latest: float | None) -> float | None:
    """The time aimed at in a window: as late as it allows (the least energy), a margin
    inside; None without an upper bound."""
    if latest is None:
        return None
    margin = WINDOW_MARGIN_S if earliest is None else min(WINDOW_MARGIN_S,
                                                          0.5 * (latest - earliest))
    return latest - margin


@dataclass(frozen=True)
class Conflict:
    """A timing point whose window cannot be met after an earlier one's (or the start's)."""

    first: str
    second: str
    shortest_s: float
    allowed_s: float

    def message(self) -> str:
        return (f'{self.second} cannot be reached from {self.first} in time: the shortest '
                f'running time between them is {self.shortest_s:.1f} s (waiting excluded), '
                f'the windows leave {self.allowed_s:.1f} s')


def _point_name(index: int, point) -> str:
    kind = 'stop' if point.is_stopping_point else 'passing point'
    window = f'[{_fmt(point.earliest_s)}, {_fmt(point.latest_s)}] s'
    return f'timing point {index} ({kind} at {point.position_m:.0f} m, window {window})'


def _fmt(value: float | None) -> str:
    return '-' if value is None else f'{value:g}'


def origin_departure_s(trajectory: Trajectory) -> float:
    """When the curve leaves its origin: the end of its first segment if that is a dwell."""
    first = trajectory.segments[0]
    if first.v0 == 0.0 and first.a0 == 0.0 and first.jerk == 0.0:
        return first.t0 + first.duration
    return first.t0


def point_times(journey, trajectory: Trajectory, stops) -> list[float]:
    """The time of each of the journey's timing points on a curve (``stops``: its
    ``StopEvent``s): a stopping point's arrival or, the second of two at one station, its
    departure; at the origin the departure (an arrival there before it: the start); a passing
    point's first passage."""
    points = journey.timing_points
    origin = trajectory.segments[0].x0
    by_position = {stop.station.position_m: stop for stop in stops}
    times = []
    for i, point in enumerate(points):
        if not point.is_stopping_point:
            times.append(passing_time(trajectory, point.position_m))
            continue
        departing = i > 0 and points[i - 1].is_stopping_point \
            and points[i - 1].position_m == point.position_m
        departs_later = i + 1 < len(points) and points[i + 1].is_stopping_point \
            and points[i + 1].position_m == point.position_m
        if abs(point.position_m - origin) < 1e-6:
            times.append(trajectory.start_time if departs_later
                         else origin_departure_s(trajectory))
        elif point.position_m in by_position:
            stop = by_position[point.position_m]
            times.append(stop.departure_s if departing else stop.arrival_s)
        else:
            times.append(passing_time(trajectory, point.position_m))
    return times


@dataclass(frozen=True)
class JourneyTimes:
    """What a journey's windows allow at each timing point: the earliest time the train can
    be there (its window's lower bound, and the shortest running times from the earlier
    points, waiting excluded), the latest it may be there to meet every later window, and the
    windows that cannot be met (each conflict named once, at the first point it makes late;
    the latest time is never before the earliest: a conflict's later window is missed, the
    earlier ones are met)."""

    earliest: list[float]
    latest: list[float]
    conflicts: list[Conflict]


def journey_times(journey, trajectory: Trajectory, stops) -> JourneyTimes:
    """``JourneyTimes`` of a journey from the fastest curve without waiting (``trajectory``
    and its ``stops``: the shortest running time between consecutive timing points, a stop's
    dwell included). Forward, each point is reached no earlier than its window's lower bound
    and the previous point's earliest time plus the running time; a point whose upper bound
    is earlier is a conflict with the point that set that time (the start of the run, or the
    last point whose lower bound did), unless an earlier conflict made it late. Backward, each
    point's latest time is its upper bound, and no later than the next point's latest time
    less the running time."""
    points = journey.timing_points
    times = point_times(journey, trajectory, stops)
    running = [b - a for a, b in zip(times, times[1:])]
    earliest: list[float] = []
    conflicts: list[Conflict] = []
    source, source_time, inherited = None, times[0], False
    for k, point in enumerate(points):
        reached = times[0] if k == 0 else earliest[-1] + running[k - 1]
        if point.earliest_s is not None and point.earliest_s >= reached:
            reached, source, source_time, inherited = point.earliest_s, k, point.earliest_s, False
        earliest.append(reached)
        if point.latest_s is not None and reached > point.latest_s + 1e-6:
            if not inherited:
                first = 'the start of the run' if source is None else \
                    _point_name(source, points[source])
                conflicts.append(Conflict(first, _point_name(k, point), reached - source_time,
                                          point.latest_s - source_time))
            inherited = True
    latest = [math.inf] * len(points)
    for k in range(len(points) - 1, -1, -1):
        bound = points[k].latest_s if points[k].latest_s is not None else math.inf
        if k + 1 < len(points):
            bound = min(bound, latest[k + 1] - running[k])
        # never before the earliest time (a later conflict is missed, not every window)
        latest[k] = max(bound, earliest[k])
    return JourneyTimes(earliest, latest, conflicts)


def plan_summary(plan) -> dict[str, object]:
    """What the profile node reports of a plan (a profile_node.planner.Plan) on diagnostics
    (docs/guide/target-curve.md): the strategy, the forecast energies (``forecast.<field>``,
    the fields and definitions of ``ato_common.metrics.RunMetrics``), the expected delay, and
    per stop its target and planned arrival, the shortest running time and the reserve; per
    journey timing point its planned time and whether it is within its window."""
    values: dict[str, object] = {'strategy': plan.strategy}
    if plan.forecast is not None:
        values.update((f'forecast.{key}', value) for key, value in plan.forecast.kwh().items())
    values.update({
        'expected_delay_s': plan.expected_delay_s,
        'plan_start_s': plan.trajectory.start_time,
        'plan_end_s': plan.trajectory.end_time})
    for stop in plan.stops:
        values[f'stop.{stop.station.name}.arrival_s'] = stop.arrival_s
        values[f'stop.{stop.station.name}.departure_s'] = stop.departure_s
    for leg in plan.legs:
        values[f'stop.{leg.destination}.target_arrival_s'] = leg.target_arrival_s
        values[f'stop.{leg.destination}.shortest_running_s'] = leg.shortest_running_s
        values[f'stop.{leg.destination}.reserve_s'] = leg.reserve_s
    for i, check in enumerate(plan.timing):
        values[f'timing_point.{i}.planned_s'] = check.planned_s
        values[f'timing_point.{i}.within_window'] = check.within_window
    return values
