"""The least-energy speed profile of one leg for a price of time: the ``timetable`` strategy's
optimisation, in the distance domain (no jerk limit; ``planner`` builds the jerk-limited curve
that follows it).

The problem (``LegLimits``): from the leg's start at its initial speed to standstill at its end,
under the speed ceiling (the planner's section levels), the highest acceleration a(v, x) (the
planning acceleration, capped by 80 % of the traction reserve after the nominal resistance and
the line force), the highest deceleration d(x) (the planning deceleration, lowered where 80 % of
the service brake less the descent cannot give it) and the train's physics: per unit mass,
dv/dx = (u - r(v) - w(x)) / v with the resistance r and the line force w (the grade over the
train's length, curves, tunnels). The energy is the work of the force at the wheel, each braking
valued at the train's regenerative efficiency eta up to its regenerative power (0: gross energy
only); the running time is priced by a multiplier lambda.

The method: Pontryagin's principle (Howlett & Pudney, *Energy-Efficient Train Control*, 1995;
Albrecht, Howlett, Pudney, Vu & Zhou, "The key principles of optimal train control", Transp. Res.
Part B 94, 2016, parts 1 and 2) gives the structure: full traction, speed holding at V with
lambda = psi(V) = V^2 r'(V) (partial traction; at a lower ceiling, holding the ceiling, with
the brake on a steep descent), coasting, full braking. The profile holds h(x) = min(V, ceiling)
and leaves it only where the structure requires it:

* from a standstill, after a ceiling rises: full traction up to h (until the braking envelope);
* before a lower ceiling or the stop: a coast, then braking along the braking envelope (the
  backward braking curve of the ceilings at d(x));
* above h (a stretch after a passing window with a lower hold speed): a coast down to h, in
  such a stretch at least at the deceleration that reaches h at its end (it must lose time);
* before and over a steep descent (where coasting at h speeds the train up): a coast, the
  speed falling below h before it and rising above h on it (up to the ceiling, held there with
  the brake, released where it is cheapest before the descent's end), rejoining h after it
  (or the braking envelope);
* before and over a steep climb (where full traction cannot hold h): full traction, the speed
  rising above h before it (up to the ceiling) and falling on it, rejoining h after it.

Where each coast or full traction starts is where the local cost, energy + lambda x time from a
point before it to the point where the profile rejoins h, is least (the local energy
minimisation of Albrecht et al. 2016: at the optimum it is Pontryagin's switching condition).
The profile is computed on a grid of nodes about ``STEP_M`` apart (and at every change of the
ceiling, the grade under the train, a curve or a tunnel): over an interval, the acceleration is
held (e = v^2 / 2 linear in position), taken at the interval's middle.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from ato_common import units
from ato_common.line import Curve, PiecewiseConstant, Tunnel
from ato_common.scenario import Scenario
from profile_node.trajectory import TrajectoryBuilder, braking_distance

# Share of the traction reserve (force left after resistance and the line force) that the plan
# may use; the rest is the controller's margin to correct errors. The same share of the
# service brake.
TRACTION_RESERVE_SHARE = 0.8
# Spacing of the profile's grid, m (longer on a leg that would have more than MAX_NODES).
STEP_M = 25.0
MAX_NODES = 1200
# How far under the supervision's permitted speed the profile keeps, m/s.
PERMITTED_MARGIN_MPS = 0.1
# A braking's pieces of one deceleration: the envelope's slope within one varies by less than
# this share; at most this many pieces.
BRAKING_PIECE_SPREAD = 0.03
MAX_BRAKING_PIECES = 8
# The start of each excursion is first looked for at about this many points of its window.
SCAN_POINTS = 8

HOLD, POWER, COAST, BRAKE = 'hold', 'power', 'coast', 'brake'


def train_line_force(scenario: Scenario) -> Callable[[float], float]:
    """w(x): the line's specific force on the train with its front at x, m/s^2: g sin(the
    grade averaged over the train's length) + the curves and tunnels at its front."""
    # profile_node.timetable.train_grade_sine, imported late: timetable imports this module
    from profile_node.timetable import train_grade_sine
    line, length = scenario.line, scenario.train.length_m
    gravity = units.STANDARD_GRAVITY
    plain = not line.curves and not line.tunnels

    def force(front: float) -> float:
        grade = gravity * train_grade_sine(line, front, length)
        if plain:
            return grade
        return grade + line.line_force_per_kg(front) - gravity * line.grade_sine(front)
    return force


@dataclass(frozen=True)
class LegLimits:
    """What the planner plans within on one leg [start_m, end_m]: the problem that the
    planner and the oracle (``profile_node.oracle``) both solve."""

    scenario: Scenario
    start_m: float
    end_m: float
    ceiling: PiecewiseConstant           # the section levels (planner.leg_ceiling), m/s
    # the supervision's permitted speed at a position
    permitted: Callable[[float], float] | None = None
    deceleration_factor: float = 1.0      # lowered by the supervision check (planner)
    # w(x) (``train_line_force`` of the scenario unless given; read it with ``line_force_at``)
    line_force: Callable[[float], float] | None = field(default=None, compare=False,
                                                        repr=False)

    def __post_init__(self) -> None:
        if self.line_force is None:
            object.__setattr__(self, 'line_force', train_line_force(self.scenario))

    def line_force_at(self, position_m: float) -> float:
        """w at a position, m/s^2."""
        # __post_init__ sets line_force when it is not given: never None after construction
        assert self.line_force is not None
        return self.line_force(position_m)

    def ceiling_mps(self, position_m: float) -> float:
        """The highest target speed: the level, and never above the permitted speed (less
        ``PERMITTED_MARGIN_MPS``: the profile checks it at its nodes only)."""
        level = self.ceiling(position_m)
        if self.permitted is None:
            return level
        return min(level, max(self.permitted(position_m) - PERMITTED_MARGIN_MPS, 0.0))

    @property
    def ceiling_changes_m(self) -> tuple[float, ...]:
        return tuple(s for s in self.ceiling.starts if self.start_m < s < self.end_m)

    def acceleration_mps2(self, speed_mps: float, position_m: float) -> float:
        train, planning = self.scenario.train, self.scenario.planning
        reserve = (train.traction.max_traction_at(speed_mps)
                   - train.davis_nominal.force(speed_mps)) / train.mass_kg
        return min(planning.max_acceleration_mps2,
                   TRACTION_RESERVE_SHARE * (reserve - self.line_force_at(position_m)))

    def deceleration_mps2(self, position_m: float) -> float:
        train, planning = self.scenario.train, self.scenario.planning
        brake = train.traction.max_service_brake_force_n / train.mass_kg
        available = TRACTION_RESERVE_SHARE * brake + min(self.line_force_at(position_m), 0.0)
        return self.deceleration_factor * min(planning.service_deceleration_mps2, available)


def speed_of_price(scenario: Scenario, price: float) -> float:
    """The V with psi(V) = ``price`` (psi increases with the speed; inf for an infinite
    price)."""
    if not math.isfinite(price):
        return math.inf
    high = 10.0
    while hold_speed_price(scenario, high) < price:
        high *= 2.0
        if high > 1e4:
            return math.inf
    return brentq(lambda v: hold_speed_price(scenario, v) - price, 0.0, high, xtol=1e-6)


def hold_speed_price(scenario: Scenario, speed_mps: float) -> float:
    """lambda = psi(V) = V^2 r'(V) (per unit mass, m^2/s^3): the price of time at which
    holding ``speed_mps`` is optimal (Albrecht et al. 2016, part 1, the speed-holding
    condition)."""
    davis, mass = scenario.train.davis_nominal, scenario.train.mass_kg
    v = speed_mps
    return v * v * (davis.b_n_s_per_m + 2.0 * davis.c_n_s2_per_m2 * v) / mass


@dataclass
class Profile:
    """A leg's profile on its grid: e = v^2/2 at each node, the mode of each interval, and its
    running time."""

    e: list[float]
    modes: list[str]
    time_s: float
    choices: dict[int, int] = field(default_factory=dict)  # excursion region start -> start
    # (first, last) intervals of each coast released from its braking hold (``EcoProfile``)
    released: list[tuple[int, int]] = field(default_factory=list)
    # per interval: the deceleration a stretch after a passing window slows down at, at least
    # (``EcoProfile._slowing``; 0 elsewhere), m/s^2
    slowing: list[float] = field(default_factory=list)


class LegGrid:
    """The leg's grid and the physics on it (module docstring)."""

    def __init__(self, limits: LegLimits, step_m: float = STEP_M):
        scenario = limits.scenario
        train, line = scenario.train, scenario.line
        start, end = limits.start_m, limits.end_m
        step_m = max(step_m, (end - start) / MAX_NODES)
        cuts = set(np.linspace(start, end, max(int(math.ceil((end - start) / step_m)), 1) + 1))
        cuts.update(limits.ceiling_changes_m)
        for s in line.grade_sine.starts:
            cuts.update(x for x in (s, s + train.length_m) if start < x < end)
        features: tuple[Curve | Tunnel, ...] = (*line.curves, *line.tunnels)
        for feature in features:
            cuts.update(x for x in (feature.start_m, feature.start_m + feature.length_m)
                        if start < x < end)
        xs = sorted(cuts)
        self.xs = [x for i, x in enumerate(xs) if i == 0 or x - xs[i - 1] > 1e-6]
        self.xs[-1] = end
        self.n = len(self.xs) - 1
        self.dx = [b - a for a, b in zip(self.xs, self.xs[1:])]
        force = limits.line_force_at
        # w at both ends of each interval (linear between the cuts: the grade over the
        # train's length, a transition curve's force) and its mean over it
        self.w_ends = [(force(a + 1e-9), force(b - 1e-9)) for a, b in zip(self.xs, self.xs[1:])]
        self.w = [0.5 * (left + right) for left, right in self.w_ends]
        # the lowest over each interval: the level's, and the permitted speed's (which falls
        # towards a target: sampled at both ends and the middle)
        self.ceiling = [min(limits.ceiling_mps(x) for x in (a, 0.5 * (a + b), b - 1e-6))
                        for a, b in zip(self.xs, self.xs[1:])]
        self.top = [0.5 * c * c for c in self.ceiling]   # the highest e over each interval
        self.decel = [limits.deceleration_mps2(0.5 * (a + b))
                      for a, b in zip(self.xs, self.xs[1:])]
        davis, mass = train.davis_nominal, train.mass_kg
        self.ra, self.rb, self.rc = davis.a_n / mass, davis.b_n_s_per_m / mass, \
            davis.c_n_s2_per_m2 / mass
        self.fmax = train.traction.max_traction_force_n / mass
        self.power = train.traction.max_traction_power_w / mass
        self.amax = scenario.planning.max_acceleration_mps2
        self.eta = train.regenerative_efficiency
        self.regen_power = train.regenerative_power_w / mass
        self._envelope(limits)

    def capability(self, v: float, i: int, w: float | None = None) -> float:
        """The highest planned acceleration at speed v in interval i (at line force w: by
        default the interval's mean)."""
        traction = self.fmax if v <= 0.0 else min(self.fmax, self.power / v)
        reserve = traction - self.ra - self.rb * v - self.rc * v * v
        return min(self.amax, TRACTION_RESERVE_SHARE * (reserve - (self.w[i] if w is None
                                                                   else w)))

    def interval(self, x: float) -> int:
        return min(max(bisect_right(self.xs, x) - 1, 0), self.n - 1)

    def line_force(self, x: float) -> float:
        """w at a position: linear over its interval."""
        i = self.interval(x)
        a, b = self.xs[i], self.xs[i + 1]
        left, right = self.w_ends[i]
        return left + (right - left) * min(max((x - a) / (b - a), 0.0), 1.0)

    def _envelope(self, limits: LegLimits) -> None:
        """The braking envelope (``self.envelope``): the highest e at each node from which
        braking at d(x) keeps under every later ceiling (the level's and, at each node, the
        permitted speed's) and stops at the end."""
        n = self.n
        levels = [limits.ceiling(0.5 * (a + b)) for a, b in zip(self.xs, self.xs[1:])]
        top = [0.5 * min(levels[max(i - 1, 0)], levels[min(i, n - 1)],
                         limits.ceiling_mps(x)) ** 2 for i, x in enumerate(self.xs)]
        b = [0.0] * (n + 1)
        for i in range(n - 1, -1, -1):
            b[i] = min(top[i], b[i + 1] + self.decel[i] * self.dx[i])
        self.envelope = b

    def braking(self, first: int, last: int) -> list[tuple[float, float]]:
        """A braking along the envelope from node ``first`` to node ``last`` as pieces of
        constant deceleration, each braking (e linear in the position) under the envelope at
        every node: (e at the piece's end, deceleration) of each, in order. The envelope's
        slope over each interval is grouped where it varies by less than
        ``BRAKING_PIECE_SPREAD`` (the planning deceleration; the permitted speed near a stop,
        shifted by the supervision's reaction times, asks for less and less); from the end
        backwards, each piece's deceleration is the lowest chord from its end over its nodes
        (at most the planning deceleration there)."""
        envelope, xs = self.envelope, self.xs
        slopes = [(envelope[k] - envelope[k + 1]) / self.dx[k] for k in range(first, last)]
        groups: list[list[int]] = []
        low = high = math.nan
        for k, slope in zip(range(first, last), slopes):
            if groups and (len(groups) == MAX_BRAKING_PIECES or max(high, slope)
                           <= (1.0 + BRAKING_PIECE_SPREAD) * min(low, slope)):
                groups[-1].append(k)
                low, high = min(low, slope), max(high, slope)
                continue
            groups.append([k])
            low = high = slope
        pieces: list[tuple[float, float]] = []
        e_end, x_end = envelope[last], xs[last]
        for group in reversed(groups):
            d = min(min((envelope[k] - e_end) / (x_end - xs[k]) for k in group),
                    min(self.decel[k] for k in group))
            d = max(d, 1e-3)
            pieces.append((e_end, d))
            x_start = xs[group[0]]
            e_end, x_end = e_end + d * (x_end - x_start), x_start
        pieces.reverse()
        return pieces

    def cost(self, i: int, e0: float, e1: float) -> tuple[float, float]:
        """(objective energy, time) per unit mass of interval i from e0 to e1."""
        dx = self.dx[i]
        v0, v1 = math.sqrt(e0), math.sqrt(max(e1, 0.0))
        v0 *= math.sqrt(2.0)
        v1 *= math.sqrt(2.0)
        total = v0 + v1
        if total <= 0.0:
            return 0.0, math.inf
        time = 2.0 * dx / total
        mean = 0.5 * total
        u = (e1 - e0) / dx + self.ra + self.rb * mean + self.rc * (e0 + e1) + self.w[i]
        if u >= 0.0:
            return u * dx, time
        return -self.eta * min(-u * dx, self.regen_power * time), time

    def energies(self, e: list[float]) -> tuple[float, float, float]:
        """(gross, braking, regenerated) work per unit mass of a profile (e at each node)."""
        gross = braking = regenerated = 0.0
        for i, dx in enumerate(self.dx):
            e0, e1 = e[i], e[i + 1]
            total = math.sqrt(2.0 * e0) + math.sqrt(2.0 * max(e1, 0.0))
            u = (e1 - e0) / dx + self.ra + self.rb * 0.5 * total + self.rc * (e0 + e1) \
                + self.w[i]
            if u >= 0.0:
                gross += u * dx
            else:
                braking -= u * dx
                time = 2.0 * dx / total if total > 0.0 else math.inf
                regenerated += self.eta * min(-u * dx, self.regen_power * time)
        return gross, braking, regenerated

    def step(self, mode: str, i: int, e: float, cap: float = math.inf) -> float:
        """e at node i + 1 from e at node i in ``mode`` (POWER or COAST), capped at the
        interval's ceiling and at ``cap`` (held there: partial traction, or the brake on a
        descent)."""
        dx = self.dx[i]
        if mode == POWER:
            v = math.sqrt(2.0 * e)
            a = self.capability(v, i)
            middle = e + 0.5 * a * dx
            a = self.capability(math.sqrt(2.0 * max(middle, 0.0)), i)
        else:
            v = math.sqrt(2.0 * e)
            a = -(self.ra + self.rb * v + self.rc * 2.0 * e + self.w[i])
            middle = max(e + 0.5 * a * dx, 0.0)
            vm = math.sqrt(2.0 * middle)
            a = -(self.ra + self.rb * vm + self.rc * 2.0 * middle + self.w[i])
        return min(e + a * dx, self.top[i], cap)


class EcoProfile:
    """The profile of given hold speeds on a grid (module docstring): ``solve()``.

    ``holds``, ``prices``, ``caps``: per interval, the hold speed V, the price of time
    lambda = psi(V) and the speed at which a coast down a steep descent is held by the brake
    (the braking singular arc, theta = eta: eta psi(V_b) = lambda; inf without regeneration).
    A passing window splits a leg into stretches of their own V (``EcoLeg``).

    The reference is the fastest profile under the hold line h = min(V, ceiling)
    (``ref_e``): full traction below h, holding h, coasting down to it from above, braking
    along the envelope. Each excursion (a coast, or full traction) leaves the reference at a
    node and rejoins it after the region that asks for it; its start is chosen by the local
    cost, along the excursion and then along the reference (the same continuation for every
    start)."""

    def __init__(self, grid: LegGrid, holds: list[float], prices: list[float],
                 caps: list[float], start_mps: float = 0.0,
                 forced: dict[int, int] | None = None):
        self.grid, self.price = grid, prices
        self.forced = forced or {}   # region start -> excursion start, instead of the best
        self.h2 = [min(v, c) ** 2 / 2.0 for v, c in zip(holds, grid.ceiling)] + [0.0]
        self.slowing = [0.0] * grid.n
        self.coast_most = [math.inf] * grid.n    # the highest coasting acceleration: -slowing
        # each interval's stretch (first interval, end node): where its hold speed holds
        self.stretch: list[tuple[int, int]] = []
        first = 0
        for i in range(grid.n + 1):
            if i == grid.n or (i > 0 and holds[i] != holds[i - 1]):
                self.stretch.extend([(first, i)] * (i - first))
                first = i
        self.cap = [c * c / 2.0 for c in caps]
        self.e0 = start_mps * start_mps / 2.0
        self._reference()

    def _reference(self) -> None:
        """The reference: its e at each node, mode of each interval, cost before each node,
        and the intervals where an excursion may save (``self.region``: the mode of the
        excursion that would, or '')."""
        grid, h2, envelope, price = self.grid, self.h2, self.grid.envelope, self.price
        n = grid.n
        e = [min(self.e0, envelope[0])] + [0.0] * n
        modes, cost = [HOLD] * n, [0.0] * (n + 1)
        self.region = [''] * n
        for i in range(n):
            hold = h2[i]
            v = math.sqrt(2.0 * hold)
            if e[i] > hold + 1e-9:
                coast = grid.step(COAST, i, e[i])
                slowing = self._slowing(i, e)
                slowed = e[i] - slowing * grid.dx[i]
                if slowed < coast:
                    self.slowing[i], self.coast_most[i] = slowing, -slowing
                e1, mode = max(min(coast, slowed), hold), COAST   # down to h
            elif e[i] >= hold - 1e-9 and grid.capability(v, i) >= 0.0:
                e1, mode = hold, HOLD
                if grid.ra + grid.rb * v + 2.0 * grid.rc * hold + grid.w[i] < 0.0:
                    self.region[i] = COAST     # held by the brake: a coast may save
            else:
                e1, mode = min(grid.step(POWER, i, e[i]), hold), POWER
                if e[i] >= hold - 1e-9:
                    self.region[i] = POWER     # full traction cannot hold h: a steep climb
            if e1 > envelope[i + 1]:
                e1, mode = envelope[i + 1], BRAKE
            if e1 <= 0.0 and i + 1 < n:
                raise ValueError(f'the train stalls at {grid.xs[i + 1]:.0f} m')
            e[i + 1], modes[i] = e1, mode
            energy, time = grid.cost(i, e[i], e1)
            cost[i + 1] = cost[i] + energy + price[i] * time
        self.ref_e, self.ref_modes, self.ref_cost = e, modes, cost

    def _slowing(self, i: int, e: list[float]) -> float:
        """In a stretch after a passing window (a hold speed of its own) entered above its
        hold line: the deceleration that brings the speed from its entry to the hold line
        over the stretch (at most the planning deceleration), where a coast would not: a
        stretch that must lose time after passing its point fast (a coast comes down to a
        lower hold speed only slowly). 0 in the first stretch; continuous in the hold speed,
        so the running time is."""
        grid = self.grid
        first, last = self.stretch[i]
        if first == 0:
            return 0.0
        need = (e[first] - self.h2[i]) / (grid.xs[last] - grid.xs[first])
        return min(max(need, 0.0), grid.decel[i])

    # --- excursions ---------------------------------------------------------------------

    def run(self, i: int, e: float, mode: str, region_end: int, record=None,
            release: int | None = None) -> tuple[float, int]:
        """Cost and end node of an excursion from node i at e in ``mode`` (POWER or COAST)
        until it rejoins the reference after ``region_end``, braking along the envelope where
        it meets it (after which, below the reference, full traction takes it back); inf if
        it stalls or comes below a lower ceiling at its start. ``record``: (mode, e, cost so
        far) of each node appended. A coast is held by the brake at the braking-hold speed
        (``caps``) up to node ``release`` (by default to its end), then coasts above it; a
        coast slows at least at the stretch's ``slowing``. (``LegGrid.step`` and
        ``LegGrid.cost`` written out: the planner's hot loop.)"""
        grid, ref, envelope, ref_modes = self.grid, self.ref_e, self.grid.envelope, \
            self.ref_modes
        n, price, cap, dxs, ws, tops = grid.n, self.price, self.cap, grid.dx, grid.w, grid.top
        coast_most = self.coast_most
        ra, rb, rc, eta, regen, capability = grid.ra, grid.rb, grid.rc, grid.eta, \
            grid.regen_power, grid.capability
        sqrt = math.sqrt
        total = 0.0
        while i < n:
            dx = dxs[i]
            if mode == BRAKE:
                if envelope[i] <= ref[i] + 1e-9:
                    return total + self._snap(record, i), i
                if envelope[i + 1] > envelope[i] + 1e-12:
                    mode, region_end = POWER, i   # the envelope rises: the braking is over
                    continue
                e1 = envelope[i + 1]
            else:
                v = sqrt(2.0 * e)
                if mode == POWER:
                    a = capability(v, i)
                    middle = e + 0.5 * a * dx
                    a = capability(sqrt(2.0 * middle) if middle > 0.0 else 0.0, i)
                    top = tops[i]
                else:
                    middle = e - 0.5 * (ra + rb * v + 2.0 * rc * e + ws[i]) * dx
                    middle = middle if middle > 0.0 else 0.0
                    a = min(-(ra + rb * sqrt(2.0 * middle) + 2.0 * rc * middle + ws[i]),
                            coast_most[i])
                    top = tops[i] if release is not None and i >= release \
                        else min(tops[i], cap[i])
                e1 = e + a * dx
                if e1 > top:
                    e1 = top
            braking = mode != BRAKE and e1 > envelope[i + 1] + 1e-12   # not a hold at the top
            if braking:
                e1 = envelope[i + 1]
            elif e1 <= 0.0 and mode != BRAKE:
                return math.inf, n
            # the interval's cost (LegGrid.cost)
            v0, v1 = sqrt(2.0 * e), sqrt(2.0 * e1) if e1 > 0.0 else 0.0
            speed = v0 + v1
            time = 2.0 * dx / speed if speed > 0.0 else math.inf
            u = (e1 - e) / dx + ra + rb * 0.5 * speed + rc * (e + e1) + ws[i]
            energy = u * dx if u >= 0.0 else -eta * min(-u * dx, regen * time)
            total += energy + price[i] * time
            if record is not None:
                record.append((BRAKE if mode == BRAKE or (braking and e1 < e) else mode, e1,
                               total))
            i, previous, e = i + 1, e, e1
            if mode == BRAKE:
                continue
            if braking:
                mode = BRAKE
                continue
            if mode == COAST and ref_modes[i - 1] == BRAKE and e < ref[i] - 1e-9 \
                    and i < n and ref_modes[i] != BRAKE:
                return math.inf, n    # below a lower ceiling at its start: too slow
            if i < region_end:
                continue
            if mode == COAST:
                # Rejoining from above (theta back at 1); a coast below the reference goes
                # on to the braking (theta keeps falling under V: Pontryagin).
                if e <= ref[i] and previous >= ref[i - 1]:
                    return total + self._snap(record, i), i
            elif e >= ref[i]:
                if previous <= ref[i - 1]:
                    return total + self._snap(record, i), i
                mode = COAST       # still above the reference after the climb
        return total, n

    def _snap(self, record, i: int) -> float:
        """Rejoining the reference at node i (the node's e replaced by the reference's)."""
        if record is not None:
            mode, _, total = record[-1]
            record[-1] = (mode, self.ref_e[i], total)
        return 0.0

    def _best_start(self, low: int, high: int, mode: str, region_end: int
                    ) -> tuple[int, float]:
        """The start node in [low, high] of the excursion of least local cost (a coarse
        scan, then halving steps around the best), and that cost (inf: none is possible)."""
        def cost(p: int) -> float:
            after, end = self.run(p, self.ref_e[p], mode, region_end)
            return self.ref_cost[p] + after - self.ref_cost[end]
        return _least(low, high, cost)

    def _best_release(self, p: int, mode: str, region_end: int) -> int | None:
        """Where a coast from node ``p`` held by the brake at the braking-hold speed leaves
        it to coast on (above it: before the end of a steep descent, the speed rising to the
        ceiling at most, which the braking or the coast after it takes): the node in [p,
        region_end] of least local cost, or None (held to the excursion's end) where none is
        cheaper or the coast is never held."""
        caps, tops = self.cap, self.grid.top
        if mode != COAST or all(caps[k] >= tops[k] for k in range(p, region_end)):
            return None

        def release_cost(q: int | None) -> float:
            after, end = self.run(p, self.ref_e[p], mode, region_end, release=q)
            return after - self.ref_cost[end]
        q, least = _least(p, region_end, release_cost)
        return q if least < release_cost(None) - 1e-12 else None

    # --- the whole leg --------------------------------------------------------------------

    def _next_event(self, i: int) -> tuple[str, int, int] | None:
        """From node i on the reference: (mode, start, end) of the next region where an
        excursion may save: a braking of the reference (a coast before it), a steep descent
        held by the brake (a coast over it), a steep climb (full traction before it); None
        if none is left."""
        modes, region, n = self.ref_modes, self.region, self.grid.n
        for k in range(i, n):
            kind = COAST if modes[k] == BRAKE else region[k]
            if kind:
                end = k
                while end < n and (COAST if modes[end] == BRAKE else region[end]) == kind:
                    end += 1
                return kind, k, end
        return None

    def solve(self) -> Profile:
        grid = self.grid
        e, modes = [self.ref_e[0]], []
        choices: dict[int, int] = {}
        released: list[tuple[int, int]] = []
        i = 0
        while i < grid.n:
            event = self._next_event(i)
            if event is None:
                p, cost = grid.n, math.inf
            else:
                kind, k, end = event
                if k == i and self.ref_modes[k] == BRAKE:
                    p, cost = end, math.inf   # already braking: no coast before it
                elif k in self.forced:
                    p = min(max(self.forced[k], i), k)
                    cost = self.run(p, self.ref_e[p], kind, end)[0]
                else:
                    p, cost = self._best_start(i, k, kind, end)
                if not math.isfinite(cost):
                    p = end      # no excursion is possible there: the reference
                else:
                    choices[k] = p
            e.extend(self.ref_e[i + 1:p + 1])
            modes.extend(self.ref_modes[i:p])
            if not math.isfinite(cost):
                i = p
                continue
            release = self._best_release(p, kind, end)
            record: list = []
            _, i = self.run(p, self.ref_e[p], kind, end, record, release)
            if release is not None:
                released.append((release, i))
            e.extend(x for _, x, _ in record)
            modes.extend(m for m, _, _ in record)
        time = sum(grid.cost(k, e[k], e[k + 1])[1] for k in range(grid.n))
        return Profile(e, modes, time, choices, released, self.slowing)


def _least(low: int, high: int, cost: Callable[[int], float]) -> tuple[int, float]:
    """The node in [low, high] of least ``cost`` (a coarse scan of about ``SCAN_POINTS``,
    then halving steps around the best), and that cost."""
    memo: dict[int, float] = {}

    def remembered(p: int) -> float:
        if p not in memo:
            memo[p] = cost(p)
        return memo[p]
    step = max((high - low) // SCAN_POINTS, 1)
    best = min(range(low, high + 1, step), key=remembered)
    best = min((best, high), key=remembered)
    while step > 1:
        step //= 2
        best = min((p for p in (best - step, best, best + step) if low <= p <= high),
                   key=remembered)
    return best, remembered(best)


# --- the jerk-limited curve that follows a profile ------------------------------------------

def profile_runs(grid: LegGrid, profile: Profile) -> list[tuple[str, int, int]]:
    """The profile as runs (mode, first node, last node) of one mode; a braking that stops
    falling (along the envelope at a ceiling) is a hold there."""
    modes = [HOLD if m == BRAKE and profile.e[i + 1] >= profile.e[i] - 1e-12 else m
             for i, m in enumerate(profile.modes)]
    runs: list[tuple[str, int, int]] = []
    for i, mode in enumerate(modes):
        if runs and runs[-1][0] == mode:
            runs[-1] = (mode, runs[-1][1], i + 1)
        else:
            runs.append((mode, i, i + 1))
    return runs


class LegBuilder:
    """Builds the jerk-limited curve of a leg's profile: each run of the profile by the
    builder (``TrajectoryBuilder.follow``: full traction at the capability, coasting at the
    resistance and line force up to the ceiling and the braking-hold speed ``braking_hold(x)``,
    holding); each braking at the lowest planning deceleration of its stretch, ending exactly
    where the profile's braking ends (``TrajectoryBuilder.brake_to``)."""

    def __init__(self, limits: LegLimits, grid: LegGrid, jerk: float,
                 braking_hold=lambda x: math.inf):
        self.limits, self.grid, self.jerk = limits, grid, jerk
        force, interval, ceiling = grid.line_force, grid.interval, grid.ceiling
        ra, rb, rc, capability = grid.ra, grid.rb, grid.rc, grid.capability

        def power(v: float, x: float) -> float:
            return capability(v, interval(x), force(x))

        self.slowing: list[float] = []   # the profile's (``build``): none yet

        def coast(v: float, x: float) -> float:
            a = -(ra + rb * v + rc * v * v + force(x))
            slowing = self.slowing[interval(x)] if self.slowing else 0.0
            return -slowing if slowing > 0.0 and a > -slowing else a
        self.power, self.coast = power, coast

        def ceiling_at(x: float) -> float:
            return ceiling[interval(x)]
        self.ceiling_at = ceiling_at
        self.coast_cap = lambda x: min(ceiling_at(x), braking_hold(x))

    def build(self, builder: TrajectoryBuilder, profile: Profile) -> None:
        grid, jerk = self.grid, self.jerk
        self.slowing = profile.slowing
        runs = profile_runs(grid, profile)
        speeds = [math.sqrt(2.0 * max(e, 0.0)) for e in profile.e]
        for r, (mode, a, b) in enumerate(runs):
            following = runs[r + 1] if r + 1 < len(runs) else None
            if mode == BRAKE:
                self._brake(builder, grid.braking(a, b))
                continue
            if following is not None and following[0] == BRAKE:
                _, c, d = following
                self._to_braking(builder, mode, grid.xs[d], speeds[d], grid.braking(c, d))
                continue
            if mode == HOLD:
                self._settle(builder, speeds[a])
                if builder.v > 0.0:
                    builder.add((grid.xs[b] - builder.x) / builder.v)
                continue
            wanted, cap = (self.power, self.ceiling_at) if mode == POWER \
                else (self.coast, self.coast_cap)
            if following is not None and following[0] == HOLD:
                # the speed ends the run once it heads for the hold monotonically
                extremum = b
                rising = speeds[b] >= speeds[b - 1]
                while extremum > a and (speeds[extremum - 1] <= speeds[extremum]) == rising:
                    extremum -= 1
                builder.follow(wanted, jerk, speed=speeds[b], position=grid.xs[b] + 1e3,
                               cap=cap, speed_from=grid.xs[extremum], ahead=mode == COAST)
            else:
                builder.follow(wanted, jerk, position=self._switch(mode, following, b, speeds),
                               cap=cap, ahead=mode == COAST)

    def _switch(self, mode: str, following, b: int, speeds: list[float]) -> float:
        """Where a run ending at node b by position hands over: the ramp of the acceleration
        from this run's to the next one's centred on the node."""
        x, v = self.grid.xs[b], speeds[b]
        if following is None or following[0] not in (POWER, COAST):
            return x
        ours = self.power if mode == POWER else self.coast
        theirs = self.power if following[0] == POWER else self.coast
        return x - 0.5 * v * abs(ours(v, x) - theirs(v, x)) / self.jerk

    def _settle(self, builder: TrajectoryBuilder, speed: float) -> None:
        """To ``speed`` with zero acceleration (a hold after a run that ended by position)."""
        builder.ramp_acceleration_to_zero(self.jerk)
        if abs(builder.v - speed) > 1e-9:
            builder.speed_change(speed, self.limits.scenario.planning.max_acceleration_mps2,
                                 self.jerk)

    def _brake(self, builder: TrajectoryBuilder, pieces) -> None:
        """The braking along ``pieces`` (``LegGrid.braking``); ``_to_braking`` brought the
        builder to where it starts."""
        for k, (e_end, d) in enumerate(pieces):
            speed = math.sqrt(2.0 * max(e_end, 0.0))
            if builder.v > speed:
                following = -pieces[k + 1][1] if k + 1 < len(pieces) else 0.0
                builder.brake_to(speed, d, self.jerk, max(following, -d))

    def _braking_distance(self, v: float, a: float, pieces) -> float:
        """The distance of ``_brake`` from speed v at acceleration a."""
        total = 0.0
        for k, (e_end, d) in enumerate(pieces):
            speed = math.sqrt(2.0 * max(e_end, 0.0))
            if v <= speed:
                continue
            following = -pieces[k + 1][1] if k + 1 < len(pieces) else 0.0
            following = max(following, -d)
            total += braking_distance(v, a, speed, d, self.jerk, following)
            v, a = speed, following
        return total

    def _to_braking(self, builder: TrajectoryBuilder, mode: str, end_m: float, end_mps: float,
                    pieces) -> None:
        """The run before a braking (a hold, a coast, full traction), ending exactly where
        the braking (``_brake``) must start to end at ``end_m``."""
        jerk = self.jerk
        wanted, cap = {POWER: (self.power, self.ceiling_at), COAST: (self.coast, self.coast_cap),
                       HOLD: (lambda v, x: 0.0, self.ceiling_at)}[mode]
        if mode == HOLD:
            builder.ramp_acceleration_to_zero(jerk)

        lowest = min(d for _, d in pieces)
        ramps = (2.0 * max(d for _, d in pieces) + self.limits.scenario.planning.
                 max_acceleration_mps2) / jerk * len(pieces)

        def braking_starts(state) -> float:
            if state.v <= end_mps:
                return state.x - end_m
            # far from it (more than any of these brakings takes): no need to work it out
            bound = (state.v ** 2 - end_mps ** 2) / (2.0 * lowest) + state.v * ramps
            if state.x + bound < end_m:
                return -1.0
            return state.x + self._braking_distance(state.v, state.a, pieces) - end_m
        builder.follow(wanted, jerk, position=end_m, cap=cap, until=braking_starts,
                       ahead=mode == COAST)


class EcoLeg:
    """The ``timetable`` strategy on one leg: the profile of given hold speeds per stretch
    (``EcoProfile``) built as a jerk-limited curve (``LegBuilder``)."""

    def __init__(self, limits: LegLimits, jerk: float, start_mps: float = 0.0):
        self.limits, self.jerk, self.start_mps = limits, jerk, start_mps
        self.grid = LegGrid(limits)
        self.eta = limits.scenario.train.regenerative_efficiency
        self.highest = max(self.grid.ceiling)

    def profile(self, starts: list[float], speeds: list[float],
                forced: dict[int, int] | None = None) -> tuple[Profile, list[float]]:
        """The profile of hold speed ``speeds[k]`` from ``starts[k]`` on (a stretch), and
        the braking-hold speed of each interval; ``forced``: excursion starts
        (``EcoProfile``)."""
        scenario, grid = self.limits.scenario, self.grid
        stretch_prices = [hold_speed_price(scenario, speed) for speed in speeds]
        stretch_caps = [speed_of_price(scenario, price / self.eta) if self.eta > 0.0
                        else math.inf for price in stretch_prices]
        holds, prices, caps = [], [], []
        k = 0
        for a, b in zip(grid.xs, grid.xs[1:]):
            middle = 0.5 * (a + b)
            while k + 1 < len(starts) and starts[k + 1] <= middle:
                k += 1
            holds.append(speeds[k])
            prices.append(stretch_prices[k])
            caps.append(stretch_caps[k])
        profile = EcoProfile(grid, holds, prices, caps, self.start_mps, forced).solve()
        return profile, caps

    def build(self, builder: TrajectoryBuilder, starts: list[float], speeds: list[float],
              forced: dict[int, int] | None = None) -> dict[int, int]:
        """Append the leg to ``builder`` (at the leg's start, at ``start_mps``); the
        excursions' starts (``Profile.choices``)."""
        profile, caps = self.profile(starts, speeds, forced)
        grid = self.grid
        builder_caps = list(caps)
        for first, last in profile.released:   # coasting on above the braking-hold speed
            builder_caps[first:last] = [math.inf] * (last - first)

        def braking_hold(x: float) -> float:
            return builder_caps[min(max(bisect_right(grid.xs, x) - 1, 0), grid.n - 1)]
        LegBuilder(self.limits, grid, self.jerk, braking_hold).build(builder, profile)
        return profile.choices
