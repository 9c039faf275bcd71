"""The ``timetable`` driving strategy: on time, with the least traction energy.

The method is the structure optimal control theory gives for the energy-efficient train control
problem (Howlett & Pudney, *Energy-Efficient Train Control*, Springer 1995; Albrecht, Howlett,
Pudney, Vu & Zhou, "The key principles of optimal train control", Transportation Research
Part B 94, 2016, parts 1 and 2), applied as OSRD's MARECO energy-saving allowance applies it:
maximum traction, a cruise (speed holding, partial traction), a coast, and maximum braking.

In the distance domain, per unit mass, with speed v(x), time t(x), traction u_f >= 0, braking
u_b >= 0, resistance r(v) and grade g(x): dv/dx = (u_f - u_b - r(v) - g(x)) / v. The cost is
the traction work net of what regenerative braking recovers (efficiency eta),
J = integral (u_f - eta u_b) dx, and the running time is priced by a multiplier lambda: minimise
J + lambda T. Pontryagin's principle with the Hamiltonian
H = u_f - eta u_b + lambda / v + p (u_f - u_b - r - g) / v and theta = -p / v gives: full traction
for theta > 1, speed holding at theta = 1, coasting for eta < theta < 1, full braking for
theta < eta. Speed holding at V on level track needs dp/dx = 0, so

    lambda = psi(V),  psi(v) = v^2 r'(v)                                         (1)

(Albrecht et al. 2016, part 1, the speed-holding condition), and H is constant on level track:
H = r(V) + V r'(V) while holding; at the switch from coasting to braking (theta = eta, at speed
W), H = psi(V) / W + eta r(W). The coast therefore ends, and the braking starts, at the W with

    psi(V) / W + eta r(W) = r(V) + V r'(V)                                       (2)

(for eta = 0: W = psi(V) / (r(V) + V r'(V)), the braking speed OSRD's MARECO uses). Each leg is
then planned by the planner's jerk-limited builder (``planner.plan_leg`` with a ``LegCruise``):
traction at the train's capability up to min(level, V), cruise, coast down to W before every
braking, braking at the planning deceleration. V is found by bisection so that the leg arrives
at its target time (a running time that decreases with V). A passing window the single-V plan
misses splits the leg there: the stretches before and after get their own V (the multiplier
lambda jumps at an interior time constraint), each solved to meet its own time.

Simplified against the theory: (2) is taken on level track for every coast (on a grade the
coast simply follows the grade's force); steep descents (where the train would accelerate while
coasting) are held at V with the brake rather than entered by a coast from below V; the jerk
limit rounds every switch. The test (``profile_node/test/test_timetable_optimality.py``)
compares the resulting energy with a dynamic programme over distance and speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import brentq

from ato_common import units
from ato_common.scenario import Scenario
from profile_node.planner import (
    LegCruise,
    Plan,
    PlanningError,
    passing_time,
    plan_fastest,
    plan_leg,
    train_grade_sine,
)
from profile_node.trajectory import Trajectory, TrajectoryBuilder

# A window's time is aimed at this far inside the window (at most half its width), s: the
# closed loop follows the reference a little late or early.
WINDOW_MARGIN_S = 2.0
# Accuracy of the time each leg is solved to, s.
TIME_TOLERANCE_S = 0.05
# Accuracy of the cruise speed solved for, m/s (a few hundredths of a second on a leg).
SPEED_TOLERANCE_MPS = 0.005
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


def resistance_per_kg(scenario: Scenario):
    """r(v), r'(v): nominal Davis resistance over the mass and its derivative, m/s^2."""
    davis, mass = scenario.train.davis_nominal, scenario.train.mass_kg

    def r(v: float) -> float:
        return davis.force(v) / mass

    def dr(v: float) -> float:
        return (davis.b_n_s_per_m + 2.0 * davis.c_n_s2_per_m2 * v) / mass
    return r, dr


def coast_end_speed(scenario: Scenario, cruise_mps: float,
                    regenerative_efficiency: float = 0.0) -> float:
    """W of eq (2): the speed at which the coast ends and the braking starts, for a cruise at
    ``cruise_mps``; 0 where the resistance does not rise with speed (no coasting gain)."""
    r, dr = resistance_per_kg(scenario)
    v = cruise_mps
    psi = v * v * dr(v)                                          # eq (1)
    hold = r(v) + v * dr(v)
    if psi <= 0.0 or hold <= 0.0:
        return 0.0
    if regenerative_efficiency <= 0.0:
        return min(psi / hold, v)                               # eq (2), eta = 0
    eta = regenerative_efficiency

    def balance(w: float) -> float:
        return psi / w + eta * r(w) - hold                      # eq (2)
    if balance(v) >= 0.0:
        return v
    return brentq(balance, 1e-6, v)


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


def forecast_energy_j(scenario: Scenario, trajectory: Trajectory,
                      regenerative_efficiency: float = 0.0,
                      step_s: float = ENERGY_STEP_S) -> float:
    """Traction energy the nominal train needs to follow ``trajectory``, net of what its
    regenerative brake recovers (``regenerative_efficiency`` times the braking work), J.
    Force = m a* + Davis(v*) + m g sin(grade over the train's length) + curves and tunnels."""
    train, line = scenario.train, scenario.line
    times = np.arange(trajectory.start_time, trajectory.end_time + step_s, step_s)
    x, v, a = sample(trajectory, times)
    grade = np.array([train_grade_sine(line, p, train.length_m) for p in x])
    other = np.array([line.line_force_per_kg(p) - units.STANDARD_GRAVITY * line.grade_sine(p)
                      for p in x])
    davis = train.davis_nominal
    force = (train.mass_kg * (a + units.STANDARD_GRAVITY * grade + other)
             + davis.a_n + davis.b_n_s_per_m * v + davis.c_n_s2_per_m2 * v * v)
    power = force * v
    net = np.where(power > 0.0, power, regenerative_efficiency * power)
    return float(np.trapezoid(net, times))


def _window_target(earliest: float | None, latest: float | None) -> float | None:
    """The time aimed at in a window: as late as it allows (the least energy), a margin
    inside; None without an upper bound."""
    if latest is None:
        return None
    margin = WINDOW_MARGIN_S if earliest is None else min(WINDOW_MARGIN_S,
                                                          0.5 * (latest - earliest))
    return latest - margin


@dataclass(frozen=True)
class Conflict:
    """Two timing points whose windows cannot both be met."""

    first: str
    second: str
    shortest_s: float
    allowed_s: float

    def message(self) -> str:
        return (f'{self.second} cannot be reached from {self.first} in time: the shortest '
                f'running time between them is {self.shortest_s:.1f} s, the windows leave '
                f'{self.allowed_s:.1f} s')


def _point_name(index: int, point) -> str:
    kind = 'stop' if point.is_stopping_point else 'passing point'
    window = f'[{_fmt(point.earliest_s)}, {_fmt(point.latest_s)}] s'
    return f'timing point {index} ({kind} at {point.position_m:.0f} m, window {window})'


def _fmt(value: float | None) -> str:
    return '-' if value is None else f'{value:g}'


def window_conflicts(scenario: Scenario, fastest: Plan) -> list[Conflict]:
    """Pairs of timing points (i before j) where j's latest time minus i's earliest is shorter
    than the fastest curve's running time from i to j; i is also the start of the run."""
    if scenario.journey is None:
        return []
    points = scenario.journey.timing_points
    times = [check.planned_s for check in fastest.timing]
    start = fastest.trajectory.start_time + scenario.line.stations[0].dwell_s
    conflicts = []
    for j, later in enumerate(points):
        if later.latest_s is None:
            continue
        found = len(conflicts)
        for i in range(j):
            earlier = points[i]
            if earlier.earliest_s is None or earlier.position_m == later.position_m:
                continue
            shortest = times[j] - times[i]
            allowed = later.latest_s - earlier.earliest_s
            if allowed < shortest - 1e-6:
                conflicts.append(Conflict(_point_name(i, earlier), _point_name(j, later),
                                          shortest, allowed))
        if len(conflicts) == found and times[j] > later.latest_s + 1e-6:
            conflicts.append(Conflict('the start of the run', _point_name(j, later),
                                      times[j] - start, later.latest_s - start))
    return conflicts


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
                target = _window_target(arrival_point.earliest_s, arrival_point.latest_s)
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
                return point.position_m, _window_target(point.earliest_s, point.latest_s)
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
                   regenerative_efficiency: float = 0.0) -> Plan:
    """The ``timetable`` strategy's curve (module docstring). A journey whose windows cannot
    all be met is refused (PlanningError naming them and the shortest running time between
    them) unless ``scenario.timetable.run_infeasible``; then each time is aimed at as closely
    as the train allows. ``start_state`` and ``targets`` (leg -> arrival time): a replan."""
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


def shortest_running_time_s(scenario: Scenario) -> float:
    """The fastest curve's running time from the first departure to the last arrival, s."""
    fastest = plan_fastest(scenario)
    return fastest.stops[-1].arrival_s - fastest.trajectory.start_time \
        - scenario.line.stations[0].dwell_s


def energy_kwh(plan: Plan) -> float:
    return units.joules_to_kwh(plan.forecast_energy_j) if math.isfinite(
        plan.forecast_energy_j) else math.nan


def plan_summary(plan: Plan) -> dict[str, object]:
    """What the profile node reports of a plan on diagnostics (docs/guide/target-curve.md):
    the strategy, the forecast traction energy, the expected delay, and per stop its target
    and planned arrival, the shortest running time and the reserve; per journey timing point
    its planned time and whether it is within its window."""
    values: dict[str, object] = {
        'strategy': plan.strategy,
        'forecast_energy_kwh': (units.joules_to_kwh(plan.forecast_energy_j)
                                if math.isfinite(plan.forecast_energy_j) else math.nan),
        'expected_delay_s': plan.expected_delay_s,
        'plan_start_s': plan.trajectory.start_time,
        'plan_end_s': plan.trajectory.end_time}
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
