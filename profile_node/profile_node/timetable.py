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
then planned by the planner's jerk-limited builder (``planner.plan_leg`` with a ``LegCruise``;
the solver is ``planner.plan_timetable``, this module gives its theory, energy and windows):
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
from bisect import bisect_left, bisect_right
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ato_common import units
from ato_common.scenario import Scenario
from profile_node.trajectory import Trajectory

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
                      regenerative_efficiency: float | None = None,
                      step_s: float = ENERGY_STEP_S) -> float:
    """Traction energy the nominal train needs to follow ``trajectory``, net of what its
    regenerative brake recovers (``regenerative_efficiency``, default the scenario's, times the
    braking power up to ``timetable.regenerative_power_w``), J.
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
    if regenerative_efficiency is None:
        regenerative_efficiency = scenario.timetable.regenerative_efficiency
    recovered = np.maximum(power, -scenario.timetable.regenerative_power_w)
    net = np.where(power > 0.0, power, regenerative_efficiency * recovered)
    return float(np.trapezoid(net, times))


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


def window_conflicts(scenario: Scenario, fastest) -> list[Conflict]:
    """Pairs of timing points (i before j) where j's latest time minus i's earliest is shorter
    than the fastest curve's running time from i to j (``fastest``: its Plan,
    profile_node.planner); i is also the start of the run."""
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


def energy_kwh(plan) -> float:
    return units.joules_to_kwh(plan.forecast_energy_j) if math.isfinite(
        plan.forecast_energy_j) else math.nan


def plan_summary(plan) -> dict[str, object]:
    """What the profile node reports of a plan (a profile_node.planner.Plan) on diagnostics
    (docs/guide/target-curve.md): the strategy, the forecast traction energy, the expected
    delay, and per stop its target and planned arrival, the shortest running time and the
    reserve; per journey timing point its planned time and whether it is within its window."""
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
