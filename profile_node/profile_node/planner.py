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
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ato_common import units
from ato_common.braking_curves import RunSupervision, Target
from ato_common.line import PiecewiseConstant, Station
from ato_common.metrics import WheelEnergy
from ato_common.scenario import PlanningLimits, Scenario
from ato_common.trains import DavisResistance, TractionCharacteristic
from ato_common.validation import ConfigError
from profile_node.eco import TRACTION_RESERVE_SHARE, EcoLeg, LegLimits
from profile_node.timetable import (
    LOWEST_CRUISE_MPS,
    SPEED_TOLERANCE_MPS,
    TIME_TOLERANCE_S,
    WINDOW_MARGIN_S,
    JourneyTimes,
    LegTiming,
    forecast_energy,
    journey_times,
    point_times,
    train_grade_sine,
    window_target,
)
from profile_node.trajectory import (
    AccelerationSteps,
    StateBuilder,
    Trajectory,
    TrajectoryBuilder,
    passing_time,
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
    forecast: WheelEnergy | None = None  # energies at the wheel to follow it, nominal train
    expected_delay_s: float = 0.0  # at the last stop, against the timetable (after a replan)

    def next_stop(self, time_s: float) -> StopEvent:
        """The stop the reference is heading for or dwelling at; the last one at the end."""
        return self.stops[self.next_stop_index(time_s)]

    def next_stop_index(self, time_s: float) -> int:
        """The index in ``stops`` of :meth:`next_stop`."""
        index = 0
        for stop in self.stops:
            if time_s < stop.departure_s:
                return index
            index += 1
        return index - 1

    def next_target(self, position_m: float, time_s: float) -> Target:
        """The nearest target ahead of a reference at (time, position): a speed decrease
        strictly ahead, or the stop being approached or dwelt at."""
        decreases, stop_target = self._targets_of_stop[self.next_stop_index(time_s)]
        for target in decreases:
            if position_m < target.location_m:
                return target
        return stop_target

    @cached_property
    def _targets_of_stop(self) -> tuple[tuple[tuple[Target, ...], Target], ...]:
        """For each stop, what :meth:`next_target` chooses from while it is the next stop: the
        speed decreases before its station, by location, and the stop's own target. Built once
        per plan (its fields are frozen): the profile asks at every tick."""
        table = []
        for stop in self.stops:
            station_m = stop.station.position_m
            own = [t for t in self.targets
                   if t.kind != 'speed_decrease' and t.location_m == station_m]
            if not own:
                raise ValueError(f'the plan has no target at the stop {stop.station.name} '
                                 f'({station_m:g} m)')
            table.append((tuple(t for t in self.targets if t.kind == 'speed_decrease'
                                and t.location_m < station_m), own[0]))
        return tuple(table)

    def permitted_speed(self, position_m: float, time_s: float) -> float:
        """The supervision's permitted speed for a reference at (time, position): the authority
        is the leg of the stop being approached."""
        return self.supervision.permitted_speed(position_m, self.leg(time_s))

    def leg(self, time_s: float) -> int:
        index = self.next_stop_index(time_s)
        # Before the first departure the train stands at the origin under the first leg.
        return min(index, len(self.supervision.legs) - 1)


# Below this planned acceleration the approach to a speed takes too long to be useful: a
# section's level is kept where the train can still accelerate at least this much.
MIN_PLANNED_ACCELERATION_MPS2 = 0.02
# Tolerance of the check against the permitted speed, m/s.
PERMITTED_SPEED_TOLERANCE_MPS = 1e-6
# Sampling of that check, s.
CHECK_STEP_S = 0.5


def traction_capability(scenario: Scenario, climb_sine: float) -> Callable[[float], float]:
    """capability(v): planning acceleration capped by the train's traction reserve [m/s^2]."""
    train = scenario.train
    return _capability(train.traction, train.davis_nominal, train.mass_kg, scenario.planning,
                       climb_sine)


def _capability(traction: TractionCharacteristic, davis: DavisResistance, mass_kg: float,
                planning: PlanningLimits, climb_sine: float) -> Callable[[float], float]:
    """``traction_capability`` from the parts of the scenario it depends on."""
    # Looked up once (the same operands, so the same values, as per call): per traction step.
    traction_at, resistance = traction.max_traction_at, davis.force
    highest, climb = planning.max_acceleration_mps2, units.STANDARD_GRAVITY * max(climb_sine, 0.0)

    def capability(v: float) -> float:
        reserve = (traction_at(v) - resistance(v)) / mass_kg
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

    def __call__(self, traction: TractionCharacteristic, davis: DavisResistance, mass_kg: float,
                 planning: PlanningLimits, climb_sine: float, v_from: float,
                 v_to: float) -> float:
        key = (traction, davis, mass_kg, planning, climb_sine, v_from, v_to)
        distance = self.distances.get(key)
        if distance is None:
            start = key[:-1]
            steps = self.steps.get(start)
            if steps is None:
                if len(self.steps) >= self.size:
                    self.steps.clear()
                capability = _capability(traction, davis, mass_kg, planning, climb_sine)
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


def _limit_pieces(scenario: Scenario, mrsp, anticipation_s: float,
                  extra_m: dict[float, float]) -> list[tuple[float, float, float]]:
    """(start, end, speed) of each MRSP value where it applies for the target: a lower limit
    from its start less the distance run at it in ``anticipation_s``, and ``extra_m`` (by its
    start) further ahead."""
    pieces = []
    for s, e, v in mrsp.segments(scenario.line.length_m):
        ahead = v * anticipation_s + extra_m.get(s, 0.0)
        pieces.append((s - ahead if s > 0.0 else s, e, v))
    return pieces


def leg_ceiling(scenario: Scenario, mrsp, start: float, end: float, anticipation_s: float,
                extra_m: dict[float, float]) -> PiecewiseConstant:
    """The highest target speed over the leg [start, end]: the MRSP less the planning margin,
    its decreases brought forward as in ``leg_sections`` (without its cap where the train
    cannot accelerate: the ``timetable`` strategy plans with the traction capability at each
    position, ``profile_node.eco``)."""
    margin = scenario.planning.speed_margin_mps
    pieces = _limit_pieces(scenario, mrsp, anticipation_s, extra_m)
    cuts = sorted({start, *(x for s, e, _ in pieces for x in (s, e) if start < x < end)})
    starts: list[float] = []
    values: list[float] = []
    for a in cuts:
        b = min((x for x in cuts if x > a), default=end)
        value = min(v for s, e, v in pieces if s < b and e > a) - margin
        if value <= 0.0:
            raise PlanningError(f'{scenario.origin}: line at {a:.0f}-{b:.0f} m: the speed limit '
                                'is not above the planning margin '
                                f'({units.mps_to_kmh(margin):g} km/h)')
        if not values or value != values[-1]:
            starts.append(a)
            values.append(value)
    return PiecewiseConstant(starts, values)


def leg_sections(scenario: Scenario, mrsp, start: float, end: float,
                 anticipation_s: float, extra_m: dict[float, float]) -> list[Section]:
    """The leg [start, end] cut where the level or the grade changes, equal levels merged.

    ``anticipation_s``: a lower limit applies from its start less the distance run at it in
    that time; ``extra_m`` moves a given limit's application further ahead (by its start)."""
    line, margin = scenario.line, scenario.planning.speed_margin_mps
    pieces = _limit_pieces(scenario, mrsp, anticipation_s, extra_m)

    def ceiling(a: float, b: float) -> float:
        return min(v for s, e, v in pieces if s < b and e > a) - margin

    edges = {start, end}
    edges.update(x for s, e, _ in pieces for x in (s, e) if start < x < end)
    edges.update(_breakpoints(line.grade_sine, start, end))
    # Where the rear of the train leaves a grade: the grade it feels changes there too.
    length = scenario.train.length_m
    edges.update(s + length for s in line.grade_sine.starts if start < s + length < end)
    cuts = sorted(edges)
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


def plan_leg(builder: TrajectoryBuilder, scenario: Scenario, sections: list[Section],
             leg_deceleration_factor: float) -> None:
    """Append one leg of the fastest curve, from the builder's state (standstill, or the
    measured speed of a replan) at its first section's start to standstill at its last
    section's end."""
    planning = scenario.planning
    jerk = planning.max_jerk_mps3
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
        braking = speed_change_distance(peak, exit_speed, deceleration, jerk)
        cruise_m = section.end_m - braking - builder.x
        if peak > 0.0 and cruise_m > 0.0:
            builder.add(cruise_m / peak)
        builder.speed_change(exit_speed, deceleration, jerk)


def _build(scenario: Scenario, supervision: RunSupervision, stations: list[Station],
           anticipation_s: float, extra_m: dict[float, float], deceleration_factors: list[float],
           start_s: float = 0.0, leg_planner=None, start_state: tuple[float, float] | None = None):
    """The whole curve, leg by leg. ``leg_planner(leg, builder, sections, factor, ceiling,
    permitted)`` appends a leg (the ``timetable`` strategy; ``ceiling``: ``leg_ceiling``,
    ``permitted``: the leg's permitted speed at a position); None: :func:`plan_leg`, the
    fastest curve.
    ``start_state``: (speed, acceleration) the curve starts from (a replan), else rest."""
    builder = TrajectoryBuilder(x0=stations[0].position_m, t0=start_s)
    dwell = stations[0].dwell_s
    if start_state is not None:
        builder.v, builder.a = start_state
        builder.ramp_acceleration_to_zero(scenario.planning.max_jerk_mps3)
    elif scenario.journey is not None:
        # The origin's departure window: no departure before its earliest time.
        earliest = scenario.journey.earliest_departure_s(stations[0].position_m)
        if earliest is not None:
            dwell = max(dwell, earliest - start_s)
    builder.add(dwell)
    stops = []
    for leg, destination in enumerate(stations[1:]):
        sections = leg_sections(scenario, supervision.legs[leg].mrsp, builder.x,
                                destination.position_m, anticipation_s, extra_m)
        if leg_planner is None:
            plan_leg(builder, scenario, sections, deceleration_factors[leg])
        else:
            ceiling = leg_ceiling(scenario, supervision.legs[leg].mrsp, builder.x,
                                  destination.position_m, anticipation_s, extra_m)
            leg_planner(leg, builder, sections, deceleration_factors[leg], ceiling,
                        supervision.legs[leg].sampled('permitted'))
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
    """Each timing point of the scenario's journey against the plan (its planned time,
    ``timetable.point_times``, and whether that is within the window): the ``fastest`` curve
    only reports the windows it misses, the ``timetable`` one plans to meet them."""
    if scenario.journey is None:
        return ()
    points = scenario.journey.timing_points
    checks = []
    for point, planned in zip(points, point_times(scenario.journey, trajectory, stops)):
        within = ((point.earliest_s is None or planned >= point.earliest_s - 1e-6)
                  and (point.latest_s is None or planned <= point.latest_s + 1e-6))
        checks.append(TimingCheck(point, planned, within))
    return tuple(checks)


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


def leg_limits(scenario: Scenario, leg: int = 0) -> LegLimits:
    """The limits the ``timetable`` strategy plans leg ``leg`` of the scenario within, as the
    first build has them (the supervision check can move a braking ahead or lower a leg's
    deceleration): the problem that ``profile_node.oracle`` solves too."""
    stations = [s for s in scenario.line.stations
                if s.position_m >= scenario.run.initial_position_m - 1e-9]
    supervision = RunSupervision.for_scenario(scenario)
    settings = scenario.supervision
    anticipation = settings.service_brake_build_up_s + settings.driver_reaction_s
    start, end = stations[leg].position_m, stations[leg + 1].position_m
    ceiling = leg_ceiling(scenario, supervision.legs[leg].mrsp, start, end, anticipation, {})
    return LegLimits(scenario, start, end, ceiling, supervision.legs[leg].sampled('permitted'))


def plan_reference(scenario: Scenario, start_s: float = 0.0) -> Plan:
    """The target curve of a scenario, from its initial position at rest at run time
    ``start_s`` (0: the start of the run), driven as its ``timetable.strategy`` says:
    ``fastest`` (:func:`plan_fastest`) or ``timetable`` (:func:`plan_timetable`)."""
    if scenario.timetable.strategy == 'timetable':
        return plan_timetable(scenario, start_s)
    plan = plan_fastest(scenario, start_s)
    return replace(plan, forecast=forecast_energy(scenario, plan.trajectory))


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


# The timetable strategy (profile_node.eco gives its optimisation, profile_node.timetable the
# energy and the windows): each leg's hold speeds solved to its times.

# Where the running time jumps with the hold speed (the structure of the curve changes), a
# leg may arrive this much after its target time (half the margin a window's time is aimed at
# inside it), s.
LATE_TOLERANCE_S = 0.5 * WINDOW_MARGIN_S
# Bisection steps of an excursion's start between two places (_LegSolver._between).
BETWEEN_STEPS = 8
# The hold speed of the fastest least-energy curve, over the leg's highest ceiling: the price
# of time so high that no coast pays (the curve is then the fastest under the ceilings).
FASTEST_HOLD_FACTOR = 10.0


def hold_speed_for(time_with, target: float, low: float, high: float, guess: float) -> float:
    """The hold speed in [low, high] at which ``time_with(speed)`` (a running time that falls
    as the speed rises) is ``target``: a bracket grown from ``guess`` by 15 % steps, then
    regula falsi (the Illinois variant) until the time is within TIME_TOLERANCE_S or the
    bracket within SPEED_TOLERANCE_MPS. Where the time jumps (the structure of the curve
    changes), the late side if it is late by at most LATE_TOLERANCE_S, else the early one;
    ``high`` where even it is late, ``low`` where even it is early."""
    def late(v: float) -> float:
        return time_with(v) - target
    v = min(max(guess, low), high)
    f = late(v)
    if abs(f) <= TIME_TOLERANCE_S:
        return v
    slow: tuple[float, float] | None = (v, f)
    fast: tuple[float, float] | None = None
    if f < 0.0:
        slow, fast = None, (v, f)
    while slow is None:
        # slow is None only from an early guess on, and fast holds the last early point
        assert fast is not None
        v = max(fast[0] / 1.15, low)
        f = late(v)
        if f >= 0.0:
            slow = (v, f)
        elif v <= low:
            return low
        else:
            fast = (v, f)
    while fast is None:
        v = min(slow[0] * 1.15, high)
        f = late(v)
        if f <= 0.0:
            fast = (v, f)
        elif v >= high:
            return high
        else:
            slow = (v, f)
    side = 0
    for _ in range(60):
        (a, fa), (b, fb) = slow, fast
        if fa <= TIME_TOLERANCE_S or b - a <= SPEED_TOLERANCE_MPS:
            break
        if -fb <= TIME_TOLERANCE_S:
            return b
        wa, wb = (0.5 if side == -1 else 1.0), (0.5 if side == 1 else 1.0)
        v = (a * fb * wa - b * fa * wb) / (fb * wa - fa * wb)
        v = min(max(v, a + 0.1 * (b - a)), b - 0.1 * (b - a))
        f = late(v)
        if f > 0.0:
            slow, side = (v, f), 1
        else:
            fast, side = (v, f), -1
    return slow[0] if slow[1] <= LATE_TOLERANCE_S else fast[0]


class _LegSolver:
    """Appends each leg of the timetable strategy to the curve (``planner._build``'s
    ``leg_planner``): the least-energy curve (``profile_node.eco``) whose hold speeds, one per
    stretch between passing windows, meet the leg's times."""

    def __init__(self, scenario: Scenario, targets: dict[int, float] | None = None,
                 shortest_s: list[float] | None = None, windows: JourneyTimes | None = None):
        self.scenario = scenario
        self.targets = targets or {}   # leg -> target arrival time (a replan's)
        self.shortest_s = shortest_s or []   # leg -> the fastest curve's running time
        self.windows = windows         # what the journey's windows allow at each point
        self.timings: list[LegTiming] = []

    @staticmethod
    def _copy(builder: TrajectoryBuilder) -> TrajectoryBuilder:
        trial = TrajectoryBuilder(x0=builder.x, t0=builder.t)
        trial.v, trial.a = builder.v, builder.a
        return trial

    def _trial(self, builder: TrajectoryBuilder, eco: EcoLeg, starts, speeds,
               forced: dict[int, int] | None = None) -> tuple[TrajectoryBuilder, dict[int, int]]:
        """The leg appended to a copy of ``builder``, and its excursions' starts."""
        trial = self._copy(builder)
        return trial, eco.build(trial, starts, speeds, forced)

    def _solve_speed(self, builder, eco: EcoLeg, starts, speeds, k, position, target,
                     guess: float, forced: dict[int, int]) -> tuple[float, dict[int, int]]:
        """speeds[k] such that the curve reaches ``position`` (None: the leg's end) at
        ``target`` (``hold_speed_for``, from ``guess``); the fastest it can where even the
        fastest hold speed is too slow. Where the running time jumps with the hold speed
        further than LATE_TOLERANCE_S (an excursion's best start moves from one place to
        another), the starts that moved are set in between (``_between``). Returns the
        speed and the excursion starts set so (``forced``, updated)."""
        memo: dict[float, tuple[float, dict[int, int]]] = {}

        def time_with(v: float) -> float:
            if v not in memo:
                trial_speeds = list(speeds)
                trial_speeds[k] = v
                trial, choices = self._trial(builder, eco, starts, trial_speeds, forced)
                memo[v] = (trial.t if position is None
                           else passing_time(trial.build(), position), choices)
            return memo[v][0]
        speed = hold_speed_for(time_with, target, LOWEST_CRUISE_MPS,
                               FASTEST_HOLD_FACTOR * eco.highest, guess)
        if abs(time_with(speed) - target) <= LATE_TOLERANCE_S:
            return speed, forced
        late = [v for v, (t, _) in memo.items() if t > target]
        early = [v for v, (t, _) in memo.items() if t < target]
        if not late or not early:
            return speed, forced
        slow, fast = memo[max(late)][1], memo[min(early)][1]
        moved = {r: (slow[r], fast[r]) for r in slow.keys() & fast.keys() if slow[r] != fast[r]}
        if not moved:
            return speed, forced
        return min(early), self._between(builder, eco, starts, speeds, k, min(early), position,
                                         target, moved, forced)

    def _between(self, builder, eco: EcoLeg, starts, speeds, k, speed, position, target,
                 moved: dict[int, tuple[int, int]], forced: dict[int, int]) -> dict[int, int]:
        """The excursion starts that ``moved`` (region start -> (start on the late side,
        start on the early side)) set in between, a share tau of the way to the early side's,
        tau bisected (at ``speed``) so that the curve is on time."""
        trial_speeds = list(speeds)
        trial_speeds[k] = speed

        def starts_at(tau: float) -> dict[int, int]:
            return {**forced, **{r: round(a + tau * (b - a)) for r, (a, b) in moved.items()}}

        def late(tau: float) -> float:
            trial, _ = self._trial(builder, eco, starts, trial_speeds, starts_at(tau))
            return (trial.t if position is None else passing_time(trial.build(), position)) \
                - target
        low, high = 0.0, 1.0
        if late(low) <= 0.0:
            return starts_at(low)
        for _ in range(BETWEEN_STEPS):
            middle = 0.5 * (low + high)
            if late(middle) > 0.0:
                low = middle
            else:
                high = middle
        return starts_at(high)

    def _target(self, leg: int, builder: TrajectoryBuilder, end_m: float, shortest: float):
        """The leg's target arrival, and (point, lower bound, upper bound) of each passing
        window within it: each window as the journey's later windows allow it
        (``self.windows``: ``timetable.JourneyTimes``)."""
        scenario, journey = self.scenario, self.scenario.journey
        departure, target, points = builder.t, self.targets.get(leg), []
        supplement = 1.0 + scenario.timetable.supplement_percent / 100.0
        if journey is not None:
            allowed = self.windows.latest if self.windows is not None \
                else [p.latest_s for p in journey.timing_points]
            for k, point in enumerate(journey.timing_points):
                if not point.is_stopping_point and builder.x < point.position_m < end_m:
                    points.append((point, point.earliest_s, _bound(allowed[k])))
            arrival = next((k for k, p in enumerate(journey.timing_points)
                            if p.is_stopping_point and abs(p.position_m - end_m) < 1e-6),
                           None)
            if target is None and arrival is not None:
                point = journey.timing_points[arrival]
                target = window_target(point.earliest_s, _bound(allowed[arrival]))
                if target is None and point.earliest_s is not None:
                    target = max(point.earliest_s, departure + shortest * supplement)
        if target is None:
            target = departure + shortest * supplement
        return target, points

    def _least_energy(self, builder, eco: EcoLeg, target: float, points,
                      fastest_s: float) -> TrajectoryBuilder:
        """The curve of the hold speeds that meet the target and the passing windows: one
        hold speed, then the leg split at each window it misses (``_first_missed``).
        ``fastest_s``: the fastest curve's running time (the first guess: the highest level
        scaled by the running times)."""
        origin = builder.x
        first = eco.highest * fastest_s / max(target - builder.t, fastest_s)
        guesses: list[float] = []
        starts, speeds = [origin], [FASTEST_HOLD_FACTOR * eco.highest]
        splits: list[tuple[float, float]] = []   # (position, time aimed at) of active windows
        chosen = None
        for _ in range(len(points) + 1):
            goals = splits + [(None, target)]
            forced: dict[int, int] = {}
            for _sweep in range(2 if splits else 1):
                for k, (position, goal) in enumerate(goals):
                    guess = guesses[k] if k < len(guesses) else first
                    speeds[k], forced = self._solve_speed(builder, eco, starts, speeds, k,
                                                          position, goal, guess, forced)
                guesses = list(speeds)
            chosen, _ = self._trial(builder, eco, starts, speeds, forced)
            missed = self._first_missed(chosen.build(), points, splits)
            if missed is None:
                break
            splits = sorted(splits + [missed], key=lambda s: s[0])
            starts = [origin] + [p for p, _ in splits]
            speeds = [FASTEST_HOLD_FACTOR * eco.highest] * len(starts)
            guesses = [speeds_solved for speeds_solved in guesses[:1]]
        # the loop above runs at least once (len(points) + 1 >= 1 times) and sets it
        assert chosen is not None
        return chosen

    def __call__(self, leg: int, builder: TrajectoryBuilder, sections, factor,
                 ceiling: PiecewiseConstant, permitted) -> None:
        scenario = self.scenario
        end_m, departure = sections[-1].end_m, builder.t
        fastest = self._copy(builder)
        plan_leg(fastest, scenario, sections, factor)
        shortest = self.shortest_s[leg] if leg < len(self.shortest_s) else fastest.t - departure
        target, points = self._target(leg, builder, end_m, shortest)
        chosen = fastest
        if target > fastest.t + TIME_TOLERANCE_S:
            limits = LegLimits(scenario, builder.x, end_m, ceiling, permitted, factor)
            try:
                eco = EcoLeg(limits, scenario.planning.max_jerk_mps3, builder.v)
                candidate = self._least_energy(builder, eco, target, points,
                                               fastest.t - departure)
            except ValueError:
                candidate = None   # no least-energy curve from this state: the fastest
            # Where even the fastest least-energy curve is late, the fastest curve.
            if candidate is not None and (candidate.t <= target + LATE_TOLERANCE_S
                                          or candidate.t < fastest.t):
                chosen = candidate
        builder.segments.extend(chosen.segments)
        builder.t, builder.x, builder.v, builder.a = chosen.t, chosen.x, chosen.v, chosen.a
        # the least-energy curve at the fastest price can be a little faster than the fastest
        # builder's curve (its switches fall elsewhere under the jerk limit): the shorter
        shortest = min(shortest, chosen.t - departure)
        self.timings.append(LegTiming(f'{end_m:.0f} m', departure, target, chosen.t, shortest))

    @staticmethod
    def _first_missed(trajectory: Trajectory, points, splits):
        """The first passing window missed (not yet a split), with the time to aim at
        there; ``points``: (point, lower bound, upper bound)."""
        fixed = {p for p, _ in splits}
        for point, earliest, latest in points:
            if point.position_m in fixed:
                continue
            t = passing_time(trajectory, point.position_m)
            if earliest is not None and t < earliest - 1e-6:
                margin = WINDOW_MARGIN_S if latest is None else max(min(
                    WINDOW_MARGIN_S, 0.5 * (latest - earliest)), 0.0)
                return point.position_m, earliest + margin
            if latest is not None and t > latest + 1e-6:
                return point.position_m, window_target(earliest, latest)
        return None


def _bound(latest: float | None) -> float | None:
    return None if latest is None or not math.isfinite(latest) else latest


def _running_times(scenario: Scenario, fastest: Plan) -> list[float]:
    """Each leg's shortest running time: the fastest curve's (checked against the
    supervision), from its departure (waiting excluded) to its arrival."""
    origin = next(s for s in scenario.line.stations
                  if s.position_m >= scenario.run.initial_position_m - 1e-9)
    departure = fastest.trajectory.start_time + origin.dwell_s
    times = []
    for stop in fastest.stops:
        times.append(stop.arrival_s - departure)
        departure = stop.departure_s
    return times


def plan_timetable(scenario: Scenario, start_s: float = 0.0, start_state=None,
                   targets: dict[int, float] | None = None) -> Plan:
    """The ``timetable`` strategy's curve (:mod:`profile_node.eco`). A journey whose
    windows cannot all be met (``timetable.journey_times``) is refused (PlanningError naming
    them and the shortest running time between them) unless
    ``scenario.timetable.run_infeasible``; then every window that can be is met and the others
    as closely as the train allows. ``start_state`` and ``targets`` (leg -> arrival time):
    a replan."""
    # The fastest curve without waiting for earliest departures: the shortest running times.
    fastest = plan_fastest(replace(scenario, journey=None, timetable=replace(
        scenario.timetable, strategy='fastest')), start_s, start_state=start_state)
    windows = None
    if start_state is None and targets is None and scenario.journey is not None:
        windows = journey_times(scenario.journey, fastest.trajectory, fastest.stops)
        if windows.conflicts and not scenario.timetable.run_infeasible:
            raise PlanningError(
                f'{scenario.origin}: the journey\'s windows cannot all be met: '
                + '; '.join(c.message() for c in windows.conflicts)
                + ' (timetable.run_infeasible: true runs it anyway, meeting every window it '
                'can)')
    solver = _LegSolver(scenario, targets, _running_times(scenario, fastest), windows)
    plan = plan_fastest(scenario, start_s, solver, start_state)
    # plan_fastest may build the curve again (a supervision check); the last build's legs.
    timings = tuple(solver.timings[-len(plan.stops):])
    timings = tuple(replace(t, destination=stop.station.name)
                    for t, stop in zip(timings, plan.stops))
    delay = timings[-1].expected_delay_s if timings else 0.0
    return replace(plan, strategy='timetable', legs=timings, expected_delay_s=delay,
                   forecast=forecast_energy(scenario, plan.trajectory))
