"""Station-to-station reference planning.

Each leg between consecutive stations is a rest-to-rest profile: a jerk-limited traction phase
that follows what the train can deliver (the planning acceleration, capped by a share of the
traction force left after the nominal resistance and the steepest climb of the leg), cruise,
jerk-limited service braking that ends exactly at the station, then the dwell. The cruise speed
is the lowest static speed limit on the leg minus the planning margin, lowered further when the
leg is too short to reach it.

Braking curves to intermediate targets within a leg (lower speed limits, end of authority) and
their ETCS-style supervision are not planned here yet: a limit change inside a leg is respected
by cruising at the lowest limit of the whole leg.
"""

from __future__ import annotations

from dataclasses import dataclass

from ato_common.line import Line, Station
from ato_common.scenario import PlanningLimits, Scenario
from profile_node.trajectory import Trajectory, TrajectoryBuilder, speed_change_distance


@dataclass(frozen=True)
class StopEvent:
    station: Station
    arrival_s: float
    departure_s: float


@dataclass(frozen=True)
class Plan:
    trajectory: Trajectory
    stops: tuple[StopEvent, ...]

    def next_stop(self, time_s: float) -> StopEvent:
        """The stop the reference is heading for or dwelling at; the last one at the end."""
        for stop in self.stops:
            if time_s < stop.departure_s:
                return stop
        return self.stops[-1]


# Share of the traction reserve (force left after resistance and grade) that the plan may use;
# the rest is the controller's margin to correct errors.
TRACTION_RESERVE_SHARE = 0.8
# Below this planned acceleration the approach to a speed takes too long to be useful: the cruise
# speed of a leg is kept where the train can still accelerate at least this much.
MIN_PLANNED_ACCELERATION_MPS2 = 0.02


def traction_capability(scenario: Scenario, climb_sine: float):
    """capability(v): planning acceleration capped by the train's traction reserve [m/s^2]."""
    train, planning = scenario.train, scenario.planning
    mass, gravity = train.mass_kg, 9.80665

    def capability(v: float) -> float:
        reserve = (train.traction.max_traction_at(v) - train.davis_nominal.force(v)) / mass
        return min(planning.max_acceleration_mps2,
                   TRACTION_RESERVE_SHARE * (reserve - gravity * max(climb_sine, 0.0)))
    return capability


def traction_phase_distance(target: float, capability, jerk: float) -> float:
    builder = TrajectoryBuilder()
    builder.accelerate_to(target, capability, jerk, MIN_PLANNED_ACCELERATION_MPS2)
    return builder.x


def highest_reachable_speed(capability, limit: float) -> float:
    """Highest speed <= limit at which capability(v) >= MIN_PLANNED_ACCELERATION_MPS2."""
    if capability(limit) >= MIN_PLANNED_ACCELERATION_MPS2:
        return limit
    low, high = 0.0, limit
    if capability(low) < MIN_PLANNED_ACCELERATION_MPS2:
        raise ValueError('the train cannot start on this leg: its traction reserve gives less '
                         f'than {MIN_PLANNED_ACCELERATION_MPS2} m/s^2 at standstill')
    for _ in range(60):
        middle = 0.5 * (low + high)
        if capability(middle) >= MIN_PLANNED_ACCELERATION_MPS2:
            low = middle
        else:
            high = middle
    return low


def leg_cruise_speed(distance: float, limit: float, planning: PlanningLimits,
                     capability) -> float:
    """Highest cruise speed <= limit whose acceleration and braking fit into ``distance``."""
    def needed(v: float) -> float:
        return (traction_phase_distance(v, capability, planning.max_jerk_mps3)
                + speed_change_distance(v, 0.0, planning.service_deceleration_mps2,
                                        planning.max_jerk_mps3))
    if needed(limit) <= distance:
        return limit
    low, high = 0.0, limit
    for _ in range(40):
        middle = 0.5 * (low + high)
        if needed(middle) <= distance:
            low = middle
        else:
            high = middle
    return low


def lowest_limit(line: Line, start: float, end: float) -> float:
    return min(v for s, e, v in line.speed_limit_mps.segments(line.length_m) if e > start and s < end)


def plan_reference(scenario: Scenario) -> Plan:
    line, planning = scenario.line, scenario.planning
    stations = [s for s in line.stations if s.position_m >= scenario.run.initial_position_m - 1e-9]
    builder = TrajectoryBuilder(x0=stations[0].position_m)
    builder.add(stations[0].dwell_s)
    stops = []
    for origin, destination in zip(stations, stations[1:]):
        distance = destination.position_m - origin.position_m
        limit = lowest_limit(line, origin.position_m, destination.position_m)
        climb = max(v for s, e, v in line.grade_sine.segments(line.length_m)
                    if e > origin.position_m and s < destination.position_m)
        capability = traction_capability(scenario, climb)
        top = highest_reachable_speed(capability, max(limit - planning.speed_margin_mps, 0.1))
        cruise = leg_cruise_speed(distance, top, planning, capability)
        builder.accelerate_to(cruise, capability, planning.max_jerk_mps3,
                              MIN_PLANNED_ACCELERATION_MPS2)
        braking = speed_change_distance(cruise, 0.0, planning.service_deceleration_mps2,
                                        planning.max_jerk_mps3)
        builder.add((destination.position_m - braking - builder.x) / cruise)
        builder.speed_change(0.0, planning.service_deceleration_mps2, planning.max_jerk_mps3)
        builder.snap(destination.position_m)
        arrival = builder.t
        builder.add(destination.dwell_s)
        stops.append(StopEvent(destination, arrival, builder.t))
    return Plan(builder.build(), tuple(stops))
