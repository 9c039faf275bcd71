"""The ATO target curve: a distance-to-go reference under the supervision's permitted speed.

For each leg between consecutive stations, the line is cut into sections of constant *level*,
the highest speed the target may hold there:

* the static limit minus the planning margin, a lower limit applying from the point where the
  supervision's permitted speed has come down to it (its start less the distance run at that
  speed during the service-brake build-up and driver reaction times), a higher one only once the
  whole train has left the lower limit (train length);
* no more than the train can sustain on the section's steepest climb: the speed at which the
  traction reserve (a share of the traction force left after the nominal resistance and the
  grade) still gives ``MIN_PLANNED_ACCELERATION_MPS2``.

A backward pass gives the highest speed allowed at the end of each section (its level, the next
level, and what the next section leaves room to brake from); a forward pass then builds, in each
section, a jerk-limited traction phase that follows the train's capability, a cruise, and a
jerk-limited service braking that ends exactly at the section's end, each phase starting and
ending with zero acceleration. The braking deceleration is the planning deceleration, lowered
on a descent if the service brake (less the same reserve share) cannot deliver it there. The
leg ends exactly at the station (0.01 m), then the dwell.

The plan is checked against the supervision (:mod:`ato_common.braking_curves`): the target must
never exceed the permitted speed. Where it would (high planning deceleration against long
supervision times), the braking into that target is planned further ahead and the check repeated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
from scipy.optimize import brentq

from ato_common import units
from ato_common.braking_curves import RunSupervision, Target
from ato_common.line import Station
from ato_common.scenario import Scenario
from ato_common.validation import ConfigError
from profile_node.timetable import (
    LOWEST_CRUISE_MPS,
    SPEED_TOLERANCE_MPS,
    TIME_TOLERANCE_S,
    WINDOW_MARGIN_S,
    LegTiming,
    coast_end_speed,
    forecast_energy_j,
    train_grade_sine,
    window_conflicts,
    window_target,
)
from profile_node.trajectory import (
    AccelerationSteps,
    CoastSteps,
    StateBuilder,
    Trajectory,
    TrajectoryBuilder,
    speed_change_distance,
)


class PlanningError(ConfigError):
    """The scenario admits no target curve (the train cannot start, or cannot stay under the
    permitted speed with its planning limits); the message says where and why."""


@dataclass(frozen=True)
class StopEvent:
    station: Station
    arrival_s: float
    departure_s: float


@dataclass(frozen=True)
class Plan:
    trajectory: Trajectory
    stops: tuple[StopEvent, ...]
    supervision: RunSupervision
    targets: tuple[Target, ...]   # every target of the run, by location
    timing: tuple = ()            # TimingCheck of each journey timing point, if any
    strategy: str = 'fastest'     # how it is driven (Scenario.timetable.strategy)
    legs: tuple = ()              # profile_node.timetable.LegTiming of each leg (timetable)
    forecast_energy_j: float = math.nan  # traction energy to follow it, nominal train, J
    expected_delay_s: float = 0.0  # at the last stop, against the timetable (after a replan)

    def next_stop(self, time_s: float) -> StopEvent:
        """The stop the reference is heading for or dwelling at; the last one at the end."""
        for stop in self.stops:
            if time_s < stop.departure_s:
                return stop
        return self.stops[-1]

    def next_target(self, position_m: float, time_s: float) -> Target:
        """The nearest target ahead of a reference at (time, position): a speed decrease
        strictly ahead, or the stop being approached or dwelt at."""
        stop = self.next_stop(time_s)
        for target in self.targets:
            if target.kind == 'speed_decrease' and position_m < target.location_m \
                    < stop.station.position_m:
                return target
        return next(t for t in self.targets if t.kind != 'speed_decrease'
                    and t.location_m == stop.station.position_m)

    def permitted_speed(self, position_m: float, time_s: float) -> float:
        """The supervision's permitted speed for a reference at (time, position): the authority
        is the leg of the stop being approached."""
        return self.supervision.permitted_speed(position_m, self.leg(time_s))

    def leg(self, time_s: float) -> int:
        index = self.stops.index(self.next_stop(time_s))
        # Before the first departure the train stands at the origin under the first leg.
        return min(index, len(self.supervision.legs) - 1)


# Share of the traction reserve (force left after resistance and grade) that the plan may use;
# the rest is the controller's margin to correct errors. The same share of the service brake.
TRACTION_RESERVE_SHARE = 0.8
# Below this planned acceleration the approach to a speed takes too long to be useful: a
# section's level is kept where the train can still accelerate at least this much.
MIN_PLANNED_ACCELERATION_MPS2 = 0.02
# Tolerance of the check against the permitted speed, m/s.
PERMITTED_SPEED_TOLERANCE_MPS = 1e-6
# Sampling of that check, s.
CHECK_STEP_S = 0.5


def traction_capability(scenario: Scenario, climb_sine: float):
    """capability(v): planning acceleration capped by the train's traction reserve [m/s^2]."""
    train, planning = scenario.train, scenario.planning
    mass = train.mass_kg
    # Looked up once (the same operands, so the same values, as per call): per traction step.
    traction_at, resistance = train.traction.max_traction_at, train.davis_nominal.force
    highest, climb = planning.max_acceleration_mps2, units.STANDARD_GRAVITY * max(climb_sine, 0.0)

    def capability(v: float) -> float:
        reserve = (traction_at(v) - resistance(v)) / mass
        return min(highest, TRACTION_RESERVE_SHARE * (reserve - climb))
    return capability


def braking_deceleration(scenario: Scenario, descent_sine: float) -> float:
    """The planning deceleration, lowered where the service brake, less its reserve, cannot
    deliver it on the steepest descent (gradient correction; uphill does not raise it)."""
    brake = scenario.train.traction.max_service_brake_force_n / scenario.train.mass_kg
    available = TRACTION_RESERVE_SHARE * brake + units.STANDARD_GRAVITY * min(descent_sine, 0.0)
    if available < MIN_PLANNED_ACCELERATION_MPS2:
        raise PlanningError(f'{scenario.origin}: a descent of '
                            f'{-1000 * math.tan(math.asin(descent_sine)):.0f} per mille leaves the '
                            'service brake less than '
                            f'{MIN_PLANNED_ACCELERATION_MPS2} m/s^2 of deceleration')
    return min(scenario.planning.service_deceleration_mps2, available)


class _TractionDistances:
    """traction_phase_distance for a train and a climb, remembered: the timetable strategy
    plans the same traction phases again for every cruise speed it tries, and phases from the
    same speed share their steps (``trajectory.AccelerationSteps``). ``cache_clear()`` forgets
    both (a planning from scratch)."""

    def __init__(self, size: int = 100_000):
        self.size = size
        self.distances: dict[tuple, float] = {}
        self.steps: dict[tuple, AccelerationSteps] = {}

    def cache_clear(self) -> None:
        self.distances.clear()
        self.steps.clear()

    def __call__(self, traction, davis, mass_kg: float, planning, climb_sine: float,
                 v_from: float, v_to: float) -> float:
        key = (traction, davis, mass_kg, planning, climb_sine, v_from, v_to)
        distance = self.distances.get(key)
        if distance is None:
            start = key[:-1]
            steps = self.steps.get(start)
            if steps is None:
                if len(self.steps) >= self.size:
                    self.steps.clear()
                train = SimpleNamespace(traction=traction, davis_nominal=davis, mass_kg=mass_kg)
                capability = traction_capability(
                    SimpleNamespace(train=train, planning=planning), climb_sine)
                steps = self.steps[start] = AccelerationSteps(
                    v_from, capability, planning.max_jerk_mps3, MIN_PLANNED_ACCELERATION_MPS2)
            if len(self.distances) >= self.size:
                self.distances.clear()
            distance = self.distances[key] = steps.distance_to(v_to)
        return distance


_traction_distance = _TractionDistances()


def section_traction_distance(scenario: Scenario, climb_sine: float, v_from: float,
                              v_to: float) -> float:
    train = scenario.train
    return _traction_distance(train.traction, train.davis_nominal, train.mass_kg,
                              scenario.planning, climb_sine, v_from, v_to)


def traction_phase_distance(v_from: float, v_to: float, capability, jerk: float) -> float:
    builder = StateBuilder()
    builder.v = v_from
    builder.accelerate_to(v_to, capability, jerk, MIN_PLANNED_ACCELERATION_MPS2)
    return builder.x


def highest_reachable_speed(capability, limit: float, where: str) -> float:
    """Highest speed <= limit at which capability(v) >= MIN_PLANNED_ACCELERATION_MPS2."""
    if capability(limit) >= MIN_PLANNED_ACCELERATION_MPS2:
        return limit
    low, high = 0.0, limit
    if capability(low) < MIN_PLANNED_ACCELERATION_MPS2:
        raise PlanningError(f'{where}: the train cannot start: its traction reserve gives less '
                            f'than {MIN_PLANNED_ACCELERATION_MPS2} m/s^2 at standstill')
    for _ in range(60):
        middle = 0.5 * (low + high)
        if capability(middle) >= MIN_PLANNED_ACCELERATION_MPS2:
            low = middle
        else:
            high = middle
    return low


@dataclass
class Section:
    start_m: float
    end_m: float
    level_mps: float
    climb_sine: float     # steepest climb (for the traction capability)
    descent_sine: float   # steepest descent (for the braking deceleration)

    @property
    def length_m(self) -> float:
        return self.end_m - self.start_m


def train_grade_extremes(line, start_m: float, end_m: float, length_m: float
                         ) -> tuple[float, float]:
    """(steepest climb, steepest descent) of ``train_grade_sine`` with the front in
    [start_m, end_m]: the average is piecewise linear in the front's position, with its kinks
    where the front or the rear crosses a change of grade, so the extremes are there or at the
    ends."""
    points = {start_m, end_m}
    for s in line.grade_sine.starts:
        for x in (s, s + length_m):
            if start_m < x < end_m:
                points.add(x)
    values = [train_grade_sine(line, x, length_m) for x in points]
    return max(values), min(values)


def _breakpoints(function, start: float, end: float) -> list[float]:
    return [s for s in function.starts if start < s < end]


def leg_sections(scenario: Scenario, mrsp, start: float, end: float,
                 anticipation_s: float, extra_m: dict[float, float]) -> list[Section]:
    """The leg [start, end] cut where the level or the grade changes, equal levels merged.

    ``anticipation_s``: a lower limit applies from its start less the distance run at it in
    that time; ``extra_m`` moves a given limit's application further ahead (by its start)."""
    line, margin = scenario.line, scenario.planning.speed_margin_mps
    # Where each MRSP value applies for the target: decreases brought forward.
    pieces = []
    for s, e, v in mrsp.segments(line.length_m):
        ahead = v * anticipation_s + extra_m.get(s, 0.0)
        pieces.append((s - ahead if s > 0.0 else s, e, v))

    def ceiling(a: float, b: float) -> float:
        return min(v for s, e, v in pieces if s < b and e > a) - margin

    cuts = {start, end}
    cuts.update(x for s, e, _ in pieces for x in (s, e) if start < x < end)
    cuts.update(_breakpoints(line.grade_sine, start, end))
    # Where the rear of the train leaves a grade: the grade it feels changes there too.
    length = scenario.train.length_m
    cuts.update(s + length for s in line.grade_sine.starts if start < s + length < end)
    cuts = sorted(cuts)
    sections: list[Section] = []
    for a, b in zip(cuts, cuts[1:]):
        if b - a < 1e-6:
            continue
        # Grades act over the train's length: the steepest climb and descent the whole train
        # feels while its front runs through the piece.
        climb, descent = train_grade_extremes(line, a, b, scenario.train.length_m)
        where = f'{scenario.origin}: line at {a:.0f}-{b:.0f} m'
        limit = ceiling(a, b)
        if limit <= 0.0:
            raise PlanningError(f'{where}: the speed limit is not above the planning margin '
                                f'({units.mps_to_kmh(margin):g} km/h)')
        level = highest_reachable_speed(traction_capability(scenario, climb), limit, where)
        if sections and sections[-1].level_mps == level:
            last = sections[-1]
            last.end_m = b
            last.climb_sine = max(last.climb_sine, climb)
            last.descent_sine = min(last.descent_sine, descent)
        else:
            sections.append(Section(a, b, level, climb, descent))
    return sections


def highest_speed_braking_within(distance: float, v_to: float, deceleration: float,
                                 jerk: float, top: float) -> float:
    """Highest speed <= top from which the S-curve braking to v_to fits into ``distance``."""
    if top <= v_to or speed_change_distance(top, v_to, deceleration, jerk) <= distance:
        return top
    low, high = v_to, top
    for _ in range(50):
        middle = 0.5 * (low + high)
        if speed_change_distance(middle, v_to, deceleration, jerk) <= distance:
            low = middle
        else:
            high = middle
    return low


@dataclass(frozen=True)
class LegCruise:
    """The ``timetable`` strategy's choice on one leg: from ``starts_m[i]`` on, the target
    cruises at no more than ``speeds_mps[i]``, and a coast before a braking there ends at
    ``coast_end_mps[i]`` (the braking speed of the optimal control, profile_node.timetable)."""

    starts_m: tuple[float, ...]
    speeds_mps: tuple[float, ...]
    coast_end_mps: tuple[float, ...]

    def stretch(self, position_m: float) -> int:
        return max(i for i, start in enumerate(self.starts_m)
                   if start <= position_m or i == 0)

    def capped(self, sections: list[Section]) -> list[Section]:
        """The sections cut where the cruise speed changes, each level capped by it."""
        out = []
        for section in sections:
            cuts = [section.start_m] + [x for x in self.starts_m
                                        if section.start_m < x < section.end_m] + [section.end_m]
            for a, b in zip(cuts, cuts[1:]):
                level = min(section.level_mps, self.speeds_mps[self.stretch(a)])
                out.append(Section(a, b, level, section.climb_sine, section.descent_sine))
        return out


def coasting_deceleration(scenario: Scenario):
    """deceleration(v, x) of the train coasting (no traction, no brake) with its front at x:
    nominal Davis resistance over the mass plus g sin(grade over the train's length) [m/s^2]."""
    train, line = scenario.train, scenario.line
    # Looked up once (the same values as per call): per coasting step.
    resistance, mass, length = train.davis_nominal.force, train.mass_kg, train.length_m
    gravity, grade = units.STANDARD_GRAVITY, train_grade_sine

    def deceleration(v: float, x: float) -> float:
        return resistance(v) / mass + gravity * grade(line, x, length)
    return deceleration


# Coasting simulations: step, s, and the accuracy of the point where a coast starts, m.
COAST_STEP_S = 3.0
COAST_TOLERANCE_M = 0.5


def _coast_end(scenario: Scenario, start_m: float, v_from: float, v_to: float, jerk: float,
               limit_m: float) -> float:
    """Where a coast from ``v_from`` at ``start_m`` reaches ``v_to`` (inf: not before
    ``limit_m``)."""
    builder = StateBuilder(x0=start_m)
    builder.v = v_from
    if not builder.coast_to(v_to, coasting_deceleration(scenario), jerk, COAST_STEP_S, limit_m):
        return math.inf
    return builder.x


def _coast_then_brake(builder: TrajectoryBuilder, scenario: Scenario, section: Section,
                      coast_end: float, exit_speed: float, deceleration: float,
                      jerk: float) -> None:
    """From the cruise at ``builder.v``: cruise, coast down to ``coast_end`` (or less far where
    the section is too short) and brake to ``exit_speed`` exactly at the section's end."""
    peak = builder.v
    low = max(coast_end, exit_speed)
    end = section.end_m

    def brake_start(speed: float) -> float:
        return end - speed_change_distance(speed, exit_speed, deceleration, jerk)
    # The coasts from here (to the speeds the bisection below tries) share their steps.
    here = CoastSteps(builder.x, peak, coasting_deceleration(scenario), jerk, COAST_STEP_S)

    def coast_end_from_here(speed: float) -> float:
        x = here.end_of(speed, end)
        return math.inf if x is None else x
    if coast_end_from_here(low) <= brake_start(low):
        # Room for the whole coast: cruise until the point from which it ends where the
        # braking starts (a later start ends later).
        first, last = builder.x, brake_start(low)
        while last - first > COAST_TOLERANCE_M:
            middle = 0.5 * (first + last)
            if _coast_end(scenario, middle, peak, low, jerk, end) <= brake_start(low):
                first = middle
            else:
                last = middle
        if peak > 0.0 and first > builder.x:
            builder.add((first - builder.x) / peak)
    else:
        # Coast from here to the lowest speed from which the braking still ends in time.
        lo, hi = low, peak
        for _ in range(20):
            middle = 0.5 * (lo + hi)
            if coast_end_from_here(middle) <= brake_start(middle):
                hi = middle
            else:
                lo = middle
        low = hi
    builder.coast_to(low, coasting_deceleration(scenario), jerk, COAST_STEP_S)
    # The coast ends at most the tolerance before the braking point: cruise there.
    gap = brake_start(low) - builder.x
    if gap > 0.0 and low > 0.0:
        builder.add(gap / low)
    builder.speed_change(exit_speed, deceleration, jerk)


def plan_leg(builder: TrajectoryBuilder, scenario: Scenario, sections: list[Section],
             leg_deceleration_factor: float, cruise: LegCruise | None = None) -> None:
    """Append one leg, from the builder's state (standstill, or the measured speed of a
    replan) at its first section's start to standstill at its last section's end.
    ``cruise``: the ``timetable`` strategy's cruise speeds and coasting (None: the fastest
    curve)."""
    planning = scenario.planning
    jerk = planning.max_jerk_mps3
    if cruise is not None:
        sections = cruise.capped(sections)
    decelerations = [leg_deceleration_factor * braking_deceleration(scenario, s.descent_sine)
                     for s in sections]
    # Backward pass: the highest speed allowed at each section's end.
    exit_speeds = [0.0] * len(sections)
    for i in range(len(sections) - 2, -1, -1):
        following = sections[i + 1]
        exit_speeds[i] = highest_speed_braking_within(
            following.length_m, exit_speeds[i + 1], decelerations[i + 1], jerk,
            min(sections[i].level_mps, following.level_mps))
    # Forward pass.
    for section, exit_speed, deceleration in zip(sections, exit_speeds, decelerations):
        if builder.v > section.level_mps + 1e-9:
            # A replan from a train faster than the level: down to it first.
            builder.speed_change(section.level_mps, deceleration, jerk)
        entry = builder.v
        capability = traction_capability(scenario, section.climb_sine)

        def needed(peak: float) -> float:
            return (section_traction_distance(scenario, section.climb_sine, entry, peak)
                    + speed_change_distance(peak, exit_speed, deceleration, jerk))
        if entry < exit_speed and needed(exit_speed) > section.length_m:
            # Too short to reach the highest exit speed: accelerate throughout.
            low, high = entry, exit_speed
            for _ in range(40):
                middle = 0.5 * (low + high)
                if section_traction_distance(scenario, section.climb_sine, entry,
                                             middle) <= section.length_m:
                    low = middle
                else:
                    high = middle
            exit_speed = low
        lowest = max(entry, exit_speed)
        peak = section.level_mps
        if needed(peak) > section.length_m:
            low, high = lowest, peak
            for _ in range(40):
                middle = 0.5 * (low + high)
                if needed(middle) <= section.length_m:
                    low = middle
                else:
                    high = middle
            peak = low
        builder.accelerate_to(peak, capability, jerk, MIN_PLANNED_ACCELERATION_MPS2)
        if cruise is not None and exit_speed < peak - 1e-6:
            coast_end = cruise.coast_end_mps[cruise.stretch(section.end_m - 1e-6)]
            if coast_end < peak - 1e-6:
                _coast_then_brake(builder, scenario, section, coast_end, exit_speed,
                                  deceleration, jerk)
                continue
        braking = speed_change_distance(peak, exit_speed, deceleration, jerk)
        cruise_m = section.end_m - braking - builder.x
        if peak > 0.0 and cruise_m > 0.0:
            builder.add(cruise_m / peak)
        builder.speed_change(exit_speed, deceleration, jerk)


def _build(scenario: Scenario, supervision: RunSupervision, stations: list[Station],
           anticipation_s: float, extra_m: dict[float, float], deceleration_factors: list[float],
           start_s: float = 0.0, leg_planner=None, start_state: tuple[float, float] | None = None):
    """The whole curve, leg by leg. ``leg_planner(leg, builder, sections, factor)`` appends a
    leg (the ``timetable`` strategy); None: :func:`plan_leg`, the fastest curve.
    ``start_state``: (speed, acceleration) the curve starts from (a replan), else rest."""
    builder = TrajectoryBuilder(x0=stations[0].position_m, t0=start_s)
    if start_state is not None:
        builder.v, builder.a = start_state
        builder.ramp_acceleration_to_zero(scenario.planning.max_jerk_mps3)
    builder.add(stations[0].dwell_s)
    stops = []
    for leg, destination in enumerate(stations[1:]):
        sections = leg_sections(scenario, supervision.legs[leg].mrsp, builder.x,
                                destination.position_m, anticipation_s, extra_m)
        if leg_planner is None:
            plan_leg(builder, scenario, sections, deceleration_factors[leg])
        else:
            leg_planner(leg, builder, sections, deceleration_factors[leg])
        builder.snap(destination.position_m)
        arrival = builder.t
        dwell = destination.dwell_s
        if scenario.journey is not None and destination is not stations[-1]:
            # A timetable: no departure before the journey's earliest departure time.
            earliest = scenario.journey.earliest_departure_s(destination.position_m)
            if earliest is not None:
                dwell = max(dwell, earliest - arrival)
        builder.add(dwell)
        stops.append(StopEvent(destination, arrival, builder.t))
    return builder.build(), tuple(stops)


@dataclass(frozen=True)
class TimingCheck:
    """A journey timing point and when the target curve is there."""

    point: object          # ato_common.ttobench.TimingPoint
    planned_s: float       # arrival (stopping point) or passage (passing point)
    within_window: bool


def timing_checks(scenario: Scenario, trajectory: Trajectory,
                  stops: tuple[StopEvent, ...]) -> tuple[TimingCheck, ...]:
    """Each timing point of the scenario's journey against the plan (its planned time and
    whether that is within the window): the ``fastest`` curve only reports the windows it
    misses, the ``timetable`` one plans to meet them."""
    if scenario.journey is None:
        return ()
    checks = []
    points = scenario.journey.timing_points
    origin_departure = trajectory.start_time + scenario.line.stations[0].dwell_s
    for i, point in enumerate(points):
        stop = next((s for s in stops if s.station.position_m == point.position_m), None)
        is_departure = i > 0 and points[i - 1].is_stopping_point and \
            points[i - 1].position_m == point.position_m
        if i == 0:
            planned = origin_departure
        elif point.is_stopping_point and stop is not None:
            planned = stop.departure_s if is_departure else stop.arrival_s
        else:
            planned = passing_time(trajectory, point.position_m)
        within = ((point.earliest_s is None or planned >= point.earliest_s - 1e-6)
                  and (point.latest_s is None or planned <= point.latest_s + 1e-6))
        checks.append(TimingCheck(point, planned, within))
    return tuple(checks)


def passing_time(trajectory: Trajectory, position_m: float) -> float:
    """First time the target reaches a position (bisection: the position never decreases)."""
    low, high = trajectory.start_time, trajectory.end_time
    for _ in range(60):
        middle = 0.5 * (low + high)
        if trajectory.at(middle).position < position_m:
            low = middle
        else:
            high = middle
    return high


def first_violation(trajectory: Trajectory, plan_stops, supervision: RunSupervision):
    """(time, position) of the first sample where the target exceeds the permitted speed."""
    times = np.arange(trajectory.start_time, trajectory.end_time, CHECK_STEP_S)
    stop_index = 0
    for t in times:
        while stop_index < len(plan_stops) - 1 and t >= plan_stops[stop_index].departure_s:
            stop_index += 1
        point = trajectory.at(t)
        leg = min(stop_index, len(supervision.legs) - 1)
        if point.speed > supervision.permitted_speed(point.position, leg) \
                + PERMITTED_SPEED_TOLERANCE_MPS:
            return t, point.position, leg
    return None


def plan_reference(scenario: Scenario, start_s: float = 0.0) -> Plan:
    """The target curve of a scenario, from its initial position at rest at run time
    ``start_s`` (0: the start of the run), driven as its ``timetable.strategy`` says:
    ``fastest`` (:func:`plan_fastest`) or ``timetable`` (:func:`plan_timetable`)."""
    if scenario.timetable.strategy == 'timetable':
        return plan_timetable(scenario, start_s)
    plan = plan_fastest(scenario, start_s)
    return replace(plan, forecast_energy_j=forecast_energy_j(scenario, plan.trajectory))


def plan_fastest(scenario: Scenario, start_s: float = 0.0, leg_planner=None,
                 start_state: tuple[float, float] | None = None) -> Plan:
    """The curve checked against the supervision: the fastest one, or with ``leg_planner``
    the legs that planner appends (``_build``)."""
    stations = [s for s in scenario.line.stations
                if s.position_m >= scenario.run.initial_position_m - 1e-9]
    supervision = RunSupervision.for_scenario(scenario)
    settings = scenario.supervision
    anticipation = settings.service_brake_build_up_s + settings.driver_reaction_s
    extra_m: dict[float, float] = {}
    factors = [1.0] * (len(stations) - 1)
    for _ in range(30):
        trajectory, stops = _build(scenario, supervision, stations, anticipation, extra_m, factors,
                                   start_s, leg_planner, start_state)
        violation = first_violation(trajectory, stops, supervision)
        if violation is None:
            targets = tuple(sorted({t for leg in supervision.legs for t in leg.targets},
                                   key=lambda t: (t.location_m, t.kind)))
            return Plan(trajectory, stops, supervision, targets,
                        timing_checks(scenario, trajectory, stops))
        _, position, leg = violation
        target = supervision.legs[leg].binding_target(position)
        if target is None:
            raise PlanningError(f'{scenario.origin}: the target exceeds the static limit near '
                                f'{position:.0f} m (leg {leg})')
        if target.kind == 'speed_decrease':
            extra_m[target.location_m] = max(100.0, 2.0 * extra_m.get(target.location_m, 0.0))
        else:
            factors[leg] *= 0.8
    raise PlanningError(f'{scenario.origin}: no target curve stays under the permitted speed '
                        f'near {position:.0f} m (leg {leg}): lower planning.'
                        'service_deceleration_mps2 or the supervision times')


# A reference this far ahead of a train standing still has lost it (an emergency or watchdog
# brake, a restart): the leg is planned again from where the train stands, m.
RESUME_GAP_M = 50.0


def resume_plan(scenario: Scenario, position_m: float, time_s: float) -> Plan | None:
    """The rest of the run planned again from a train standing at ``position_m`` at run time
    ``time_s``: the current leg restarted from there (a departure without dwell), then every
    later station as planned. None where no station is left ahead (beyond the stop window of
    the last one)."""
    ahead = [s for s in scenario.line.stations
             if s.position_m > position_m + RunSupervision.STOP_WINDOW_M]
    if not ahead:
        return None
    here = Station('resume', position_m, 0.0)
    line = replace(scenario.line, stations=(here, *ahead))
    resumed = replace(scenario, line=line, run=replace(scenario.run,
                                                       initial_position_m=position_m))
    return plan_reference(resumed, start_s=time_s)


# The timetable strategy (profile_node.timetable gives its theory, the energy and the windows):
# each leg's cruise speeds solved to its times.

class _LegSolver:
    """Appends each leg of the timetable strategy to the curve (``planner._build``'s
    ``leg_planner``), solving its cruise speeds to its times."""

    def __init__(self, scenario: Scenario, regenerative_efficiency: float = 0.0,
                 targets: dict[int, float] | None = None):
        self.scenario = scenario
        self.eta = regenerative_efficiency
        self.targets = targets or {}   # leg -> target arrival time (a replan's)
        self.timings: list[LegTiming] = []
        self.latest: dict[int, float] = {}   # leg -> latest arrival the later legs allow

    def _trial(self, builder: TrajectoryBuilder, sections, factor,
               cruise: LegCruise | None) -> TrajectoryBuilder:
        trial = TrajectoryBuilder(x0=builder.x, t0=builder.t)
        trial.v, trial.a = builder.v, builder.a
        plan_leg(trial, self.scenario, sections, factor, cruise)
        return trial

    def _cruise(self, starts, speeds, coast_share: float = 0.0) -> LegCruise:
        """``coast_share`` in [0, 1] raises every coast's end speed from eq (2)'s W towards
        the cruise speed (1: no coasting): the times between the fastest curve and the
        coasting curve at the highest cruise speed."""
        ends = []
        for v in speeds:
            w = coast_end_speed(self.scenario, v, self.eta)
            ends.append(w + coast_share * (v - w))
        return LegCruise(tuple(starts), tuple(speeds), tuple(ends))

    def _time_at(self, trial: TrajectoryBuilder, position: float | None) -> float:
        if position is None:
            return trial.t
        return passing_time(trial.build(), position)

    def _solve_speed(self, builder, sections, factor, starts, speeds, k, position, target,
                     top):
        """speeds[k] such that the curve reaches ``position`` (None: the leg's end) at
        ``target``; the fastest it can where even ``top`` is too slow. Returns (speeds[k],
        coast share): a target between the fastest curve and the coasting one at ``top``
        is met by coasting less (``_cruise``)."""
        memo = {}

        def time_with(v, share=0.0):
            if (v, share) not in memo:
                trial_speeds = list(speeds)
                trial_speeds[k] = v
                cruise = self._cruise(starts, trial_speeds, share)
                memo[v, share] = self._time_at(self._trial(builder, sections, factor, cruise),
                                               position)
            return memo[v, share]
        low, high = LOWEST_CRUISE_MPS, top
        if time_with(high) >= target:
            if time_with(high, 1.0) >= target:
                return high, 1.0
            share = brentq(lambda c: time_with(high, c) - target, 0.0, 1.0, xtol=1e-3,
                           maxiter=60)
            return high, share
        if time_with(low) <= target:
            return low, 0.0
        # The running time falls as the cruise speed rises: Brent's method on it.
        return brentq(lambda v: time_with(v) - target, low, high,
                      xtol=SPEED_TOLERANCE_MPS, maxiter=60), 0.0

    def __call__(self, leg: int, builder: TrajectoryBuilder, sections, factor) -> None:
        scenario = self.scenario
        origin_m, end_m = builder.x, sections[-1].end_m
        departure = builder.t
        fastest = self._trial(builder, sections, factor, None)
        shortest = fastest.t - departure
        journey = scenario.journey
        target = self.targets.get(leg)
        points = []
        if journey is not None:
            arrival_point = next((p for p in journey.timing_points if p.is_stopping_point
                                  and abs(p.position_m - end_m) < 1e-6), None)
            if target is None and arrival_point is not None:
                target = window_target(arrival_point.earliest_s, arrival_point.latest_s)
                if target is None and arrival_point.earliest_s is not None:
                    target = max(arrival_point.earliest_s,
                                 departure + shortest
                                 * (1.0 + scenario.timetable.supplement_percent / 100.0))
            points = [p for p in journey.timing_points if not p.is_stopping_point
                      and origin_m < p.position_m < end_m]
        if target is None:
            target = departure + shortest * (1.0 + scenario.timetable.supplement_percent / 100.0)
        # No later than what leaves the later legs their times (a later window's reserve).
        target = min(target, self.latest.get(leg, math.inf))
        top = max(s.level_mps for s in sections)
        starts, speeds = [origin_m], [top]
        splits: list[tuple[float, float]] = []   # (position, time aimed at) of active windows
        chosen = fastest
        if target > fastest.t + TIME_TOLERANCE_S:
            for _ in range(len(points) + 1):
                goals = splits + [(None, target)]
                share = 0.0
                for _sweep in range(2 if splits else 1):
                    for k, (position, goal) in enumerate(goals):
                        speeds[k], share = self._solve_speed(builder, sections, factor, starts,
                                                             speeds, k, position, goal, top)
                chosen = self._trial(builder, sections, factor,
                                     self._cruise(starts, speeds, share))
                missed = self._first_missed(chosen.build(), points, splits)
                if missed is None:
                    break
                position, goal = missed
                splits = sorted(splits + [(position, goal)], key=lambda s: s[0])
                starts = [origin_m] + [p for p, _ in splits]
                speeds = [top] * len(starts)
        builder.segments.extend(chosen.segments)
        builder.t, builder.x, builder.v, builder.a = chosen.t, chosen.x, chosen.v, chosen.a
        self.timings.append(LegTiming(f'{end_m:.0f} m', departure, target, chosen.t, shortest))

    @staticmethod
    def _first_missed(trajectory: Trajectory, points, splits):
        """The first passing point outside its window (not yet a split), with the time to
        aim at there."""
        fixed = {p for p, _ in splits}
        for point in points:
            if point.position_m in fixed:
                continue
            t = passing_time(trajectory, point.position_m)
            if point.earliest_s is not None and t < point.earliest_s - 1e-6:
                late = point.latest_s
                margin = WINDOW_MARGIN_S if late is None else min(
                    WINDOW_MARGIN_S, 0.5 * (late - point.earliest_s))
                return point.position_m, point.earliest_s + margin
            if point.latest_s is not None and t > point.latest_s + 1e-6:
                return point.position_m, window_target(point.earliest_s, point.latest_s)
        return None


def _latest_arrivals(scenario: Scenario, fastest: Plan) -> dict[int, float]:
    """leg -> the latest arrival at its stop from which every later stop's latest time is
    still reachable (after the stop's dwell, at the fastest curve's running times)."""
    journey, stops = scenario.journey, fastest.stops
    latest: dict[int, float] = {}
    bound = math.inf
    for leg in range(len(stops) - 1, 0, -1):
        stop = stops[leg]
        arrival = next((p for p in journey.timing_points if p.is_stopping_point
                        and abs(p.position_m - stop.station.position_m) < 1e-6), None)
        if arrival is not None and arrival.latest_s is not None:
            bound = min(bound, arrival.latest_s)
        previous = stops[leg - 1]
        running = stop.arrival_s - previous.departure_s
        # The departure waits for its earliest time anyway: no need to arrive before that.
        departure = bound - running
        earliest = journey.earliest_departure_s(previous.station.position_m)
        if earliest is not None:
            departure = max(departure, earliest)
        bound = departure - previous.station.dwell_s
        latest[leg - 1] = bound
    return latest


def plan_timetable(scenario: Scenario, start_s: float = 0.0, start_state=None,
                   targets: dict[int, float] | None = None,
                   regenerative_efficiency: float | None = None) -> Plan:
    """The ``timetable`` strategy's curve (:mod:`profile_node.timetable`). A journey whose
    windows cannot all be met is refused (PlanningError naming them and the shortest running
    time between them) unless ``scenario.timetable.run_infeasible``; then each time is aimed
    at as closely as the train allows. ``start_state`` and ``targets`` (leg -> arrival time):
    a replan."""
    if start_state is None and targets is None and scenario.journey is not None:
        fastest = plan_fastest(replace(scenario, timetable=replace(scenario.timetable,
                                                                   strategy='fastest')),
                               start_s)
        conflicts = window_conflicts(scenario, fastest)
        if conflicts and not scenario.timetable.run_infeasible:
            raise PlanningError(
                f'{scenario.origin}: the journey\'s windows cannot all be met: '
                + '; '.join(c.message() for c in conflicts)
                + ' (timetable.run_infeasible: true runs it anyway, as close as possible)')
    if regenerative_efficiency is None:
        regenerative_efficiency = scenario.timetable.regenerative_efficiency
    solver = _LegSolver(scenario, regenerative_efficiency, targets)
    if start_state is None and targets is None and scenario.journey is not None:
        solver.latest = _latest_arrivals(scenario, fastest)
    plan = plan_fastest(scenario, start_s, solver, start_state)
    # plan_fastest may build the curve again (a supervision check); the last build's legs.
    timings = tuple(solver.timings[-len(plan.stops):])
    timings = tuple(replace(t, destination=stop.station.name)
                    for t, stop in zip(timings, plan.stops))
    delay = timings[-1].expected_delay_s if timings else 0.0
    return replace(plan, strategy='timetable', legs=timings, expected_delay_s=delay,
                   forecast_energy_j=forecast_energy_j(scenario, plan.trajectory,
                                                       regenerative_efficiency))
