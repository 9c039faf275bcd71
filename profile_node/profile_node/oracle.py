"""The reference optimum of one leg: the least energy to drive it in a given running time, by
dynamic programming. The tests and ``make bench`` hold the planner (``profile_node.planner``)
against it; it shares nothing with the planner but the problem.

The problem: from standstill at ``start_m`` to standstill at ``end_m`` in ``running_time_s``,
under the limits the planner plans within (``Limits``: the highest speed at each position, the
highest acceleration at each speed and position, the highest deceleration at each position),
with the train's physics (``Physics``, read here from the scenario: the nominal Davis
resistance, the mass, the grade averaged over the train's length and the curves and tunnels at
its front, the regenerative brake's efficiency and power: the train and the line the planner is
given, as the plan's forecast takes them; not a scenario's ``plant:`` section, whose operating
modes, failures and variations only the plant simulates). The energy is the work of the force at
the wheel F = m a + R(v) + m w(x): gross = the integral of max(F, 0) dx, braking = of max(-F, 0)
dx, regenerated = the efficiency times the braking work within the regenerative power limit, net
= gross - regenerated (``ato_common.metrics``' definitions). ``objective`` 'gross' minimises the
gross energy (no regeneration valued), 'net' the net one.

The method (Bellman's principle; the time priced by a multiplier lambda, bisected): the leg is
cut into stages of about ``dx_m``; the state at each stage boundary is the kinetic energy per
unit mass e = v^2 / 2 on a grid of step ``de``. Over a stage the force is held, so e is linear
in the position: the stage's time is exactly 2 dx / (v0 + v1), the mean of v^2 over it is e0 +
e1 and the mean of v is (2/3) (v0^2 + v0 v1 + v1^2) / (v0 + v1). The controls from a grid state
are every change of e to a grid state within the limits, and three more whose end state falls
between grid points (coasting, the highest acceleration, the highest deceleration), the cost to
go interpolated linearly there. A stage's highest end state is the highest acceleration a(v)
followed over it (``_reach``): capping the held acceleration at the end speed's a, where the
traction's power limit lowers a as the speed rises, fell short by a share growing with the stage
(``mao_4car`` in ``profile_node/test/test_plan_against_oracle_physics.py``). Beside the grid,
each stage boundary has one more state: the braking envelope B (the highest e from which braking
at the highest deceleration keeps under every later ceiling and stops at the end; B = 0 at the
end). Without it, a braking into the stop or a lower ceiling could only take the grid's
decelerations, multiples of de / dx (the cost to go is infinite above B, so an end state between
the last grid state under B and the one above it has no finite interpolation): on
``mao_2017_modes`` a planning deceleration of 0.093 m/s^2 became 0.08 on the bench's grid, and
the oracle's optimum rose above the plan, which brakes at 0.093. With B, braking along the
envelope is exact, and an end state between the last grid state under B and B is interpolated
between the two. ``solve(lam)`` minimises energy + lam x time backwards over the stages; lambda
is bisected (geometrically) to the running time, and the energy at that time interpolated
between the two solutions that bracket it (a convex combination of two feasible solutions: an
upper bound of the grid's optimum at that time). The grid error is measured by refining the grid
(``profile_node/test/test_oracle.py``); without a jerk limit the oracle's optimum can only be
below a jerk-limited curve's. Given the planning jerk J, the oracle gives a jerk-limited curve
the time its unavoidable ramps cost: a curve that starts from rest with |jerk| <= J reaches the
acceleration a0 only after a0 / J and is a0 / (2 J) behind one that takes it at once; a braking
to rest at d ends d / (2 J) later; ``at_time`` solves for the running time less a0 / (2 J) + d /
(2 J) (the highest acceleration at rest and the highest deceleration at the stop). It has no
other jerk limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ato_common import units
from ato_common.scenario import Scenario

# The steps in which the highest acceleration is followed over a stage (``_reach``), at most, m.
REACH_STEP_M = 10.0


@dataclass(frozen=True)
class Limits:
    """What the planner may plan: speed ceiling (m/s) at a position, with the positions where
    it changes; highest acceleration (m/s^2) at a speed and position; highest deceleration
    (m/s^2, positive) at a position."""

    ceiling_mps: Callable[[float], float]
    ceiling_changes_m: tuple[float, ...]
    acceleration_mps2: Callable[[float, float], float]
    deceleration_mps2: Callable[[float], float]


@dataclass(frozen=True)
class Physics:
    """The train on the line, as the oracle computes it (its own code, from the scenario)."""

    mass_kg: float
    davis_n: tuple[float, float, float]          # R(v) = a + b v + c v^2, N
    line_force_per_kg: Callable[[float], float]  # grade over the length + curves, tunnels
    regenerative_efficiency: float
    regenerative_power_w: float

    @classmethod
    def of(cls, scenario: Scenario) -> 'Physics':
        train, line = scenario.train, scenario.line
        length = train.length_m
        starts = list(line.grade_sine.starts)
        values = list(line.grade_sine.values)
        gravity = units.STANDARD_GRAVITY

        def averaged_grade(front: float) -> float:
            if length <= 0.0:
                return line.grade_sine(front)
            rear, total = front - length, 0.0
            for i, value in enumerate(values):
                low = starts[i] if i > 0 else -math.inf
                high = starts[i + 1] if i + 1 < len(starts) else math.inf
                total += value * max(0.0, min(high, front) - max(low, rear))
            return total / length

        def force(front: float) -> float:
            others = line.line_force_per_kg(front) - gravity * line.grade_sine(front)
            return gravity * averaged_grade(front) + others
        davis = train.davis_nominal
        return cls(train.mass_kg, (davis.a_n, davis.b_n_s_per_m, davis.c_n_s2_per_m2), force,
                   train.regenerative_efficiency, train.regenerative_power_w)


@dataclass(frozen=True)
class Optimum:
    """A solution: its running time and energies (J), and lambda (J/s per kg of train)."""

    running_time_s: float
    gross_j: float
    braking_j: float
    regenerated_j: float
    lam: float

    @property
    def net_j(self) -> float:
        return self.gross_j - self.regenerated_j

    def energy_j(self, objective: str) -> float:
        return self.gross_j if objective == 'gross' else self.net_j


@dataclass
class _Stage:
    dx: float
    start_ceiling: float       # the highest speed at the stage's start, end and middle
    end_ceiling: float
    middle_ceiling: float
    deceleration: float
    line_force: float          # mean over the stage, m/s^2
    acceleration: np.ndarray   # the acceleration limit at each grid speed (mid-stage)


class LegOracle:
    """The dynamic programme of one leg on a grid (``dx_m``, ``de``: module docstring)."""

    def __init__(self, physics: Physics, limits: Limits, start_m: float, end_m: float,
                 objective: str = 'net', dx_m: float = 100.0, de: float = 1.0,
                 jerk: float = math.inf):
        if objective not in ('gross', 'net'):
            raise ValueError(f"objective {objective!r}: 'gross' or 'net'")
        self.physics, self.objective, self.de = physics, objective, de
        # The jerk allowance (module docstring): the ramps of the acceleration from rest to
        # the highest acceleration and from the highest deceleration to rest at the stop.
        self.jerk_allowance_s = (max(limits.acceleration_mps2(0.0, start_m), 0.0)
                                 + limits.deceleration_mps2(end_m)) / (2.0 * jerk)
        self.xs = self._stage_bounds(limits, start_m, end_m, dx_m)
        top = max(limits.ceiling_mps(x) for x in self.xs)
        self.e = np.arange(0.0, top * top / 2.0 + de, de)
        self.v = np.sqrt(2.0 * self.e)
        self.stages = [self._stage(limits, a, b) for a, b in zip(self.xs, self.xs[1:])]
        self.envelope = self._braking_envelope()
        # at each boundary: the grid state under B, and whether B falls inside its step
        under, shares = self._between(self.envelope)
        self._envelope_steps = [(int(b), bool(0.0 < f < 1.0)) for b, f in zip(under, shares)]
        self._tables: dict[tuple, tuple] = {}
        self._envelope_moves: dict[int, tuple] = {}

    @staticmethod
    def _stage_bounds(limits: Limits, start_m: float, end_m: float, dx_m: float) -> np.ndarray:
        """Stages of about ``dx_m``, cut at every change of the ceiling (a stage takes the
        lowest ceiling over it): the uniform cuts within dx / 2 of a change are left out."""
        count = max(int(math.ceil((end_m - start_m) / dx_m - 1e-9)), 1)
        changes = [x for x in limits.ceiling_changes_m if start_m < x < end_m]
        uniform = [x for x in np.linspace(start_m, end_m, count + 1)[1:-1]
                   if all(abs(x - c) >= 0.5 * dx_m for c in changes)]
        return np.array(sorted({start_m, end_m, *changes, *uniform}))

    def _stage(self, limits: Limits, a: float, b: float) -> _Stage:
        # The ceiling at both ends of the stage (either side of each: it changes at stage
        # ends) and at its middle, where the state's e is the mean of the ends'.
        inside = [x for x in limits.ceiling_changes_m if a < x < b]
        start_ceiling = min([limits.ceiling_mps(x) for x in (a, a - 1e-6, *inside)])
        end_ceiling = min([limits.ceiling_mps(x) for x in (b, b - 1e-6, *inside)])
        middle_ceiling = limits.ceiling_mps(0.5 * (a + b))
        samples = np.linspace(a, b, 9)
        deceleration = min(limits.deceleration_mps2(x) for x in samples)
        line_force = float(np.mean([self.physics.line_force_per_kg(x) for x in samples]))
        middle = 0.5 * (a + b)
        acceleration = np.array([limits.acceleration_mps2(v, middle) for v in self.v])
        return _Stage(b - a, start_ceiling, end_ceiling, middle_ceiling, deceleration,
                      line_force, acceleration)

    def _braking_envelope(self) -> np.ndarray:
        """B at each stage boundary (module docstring): 0 at the end; before, the least of the
        ceilings at the boundary, B after the stage + its highest deceleration x its length and
        what the ceiling at the stage's middle leaves (the mean of the ends' e under it)."""
        stages = self.stages
        envelope = np.zeros(len(stages) + 1)
        for k in range(len(stages) - 1, -1, -1):
            stage, after = stages[k], envelope[k + 1]
            top = 0.5 * stage.start_ceiling ** 2
            if k > 0:
                top = min(top, 0.5 * stages[k - 1].end_ceiling ** 2)
            envelope[k] = max(min(top, after + stage.deceleration * stage.dx,
                                  stage.middle_ceiling ** 2 - after), 0.0)
        return envelope

    def _costs(self, stage: _Stage, e0: np.ndarray, e1: np.ndarray):
        """Per unit mass: (objective energy, gross, braking, regenerated, time) of stages from
        e0 to e1 (arrays), and whether each is within the limits."""
        p = self.physics
        v0, v1 = np.sqrt(2.0 * e0), np.sqrt(2.0 * np.maximum(e1, 0.0))
        total = v0 + v1
        with np.errstate(divide='ignore', invalid='ignore'):
            mean_v = np.where(total > 0.0, (2.0 / 3.0) * (v0 * v0 + v0 * v1 + v1 * v1) / total,
                              0.0)
            time = np.where(total > 0.0, 2.0 * stage.dx / total, np.inf)
        a, b, c = p.davis_n
        force = (e1 - e0) / stage.dx + (a + b * mean_v + c * (e0 + e1)) / p.mass_kg \
            + stage.line_force
        gross = np.maximum(force, 0.0) * stage.dx
        braking = np.maximum(-force, 0.0) * stage.dx
        with np.errstate(divide='ignore'):
            taken = np.minimum(braking, p.regenerative_power_w / p.mass_kg * time)
        regenerated = p.regenerative_efficiency * taken
        energy = gross - regenerated if self.objective == 'net' else gross
        return energy, gross, braking, regenerated, time

    def _table(self, k: int):
        """The grid transitions of stage k: target indices, costs, feasibility (cached by the
        stage's figures: a line of constant pieces repeats them)."""
        stage = self.stages[k]
        key = (stage.dx, stage.start_ceiling, stage.end_ceiling, stage.middle_ceiling,
               stage.deceleration, stage.line_force, stage.acceleration.tobytes())
        if key in self._tables:
            return self._tables[key]
        n, de = len(self.e), self.de
        low = int(math.floor(-stage.deceleration * stage.dx / de)) - 1
        high = int(math.ceil(max(float(np.max(stage.acceleration)), 0.0) * stage.dx / de)) + 1
        offsets = np.arange(low, high + 1)
        i = np.arange(n)[:, None]
        j = i + offsets[None, :]
        inside = (j >= 0) & (j < n)
        j = np.clip(j, 0, n - 1)
        e0, e1 = self.e[i] + 0.0 * j, self.e[j]
        accel = (e1 - e0) / stage.dx
        reach = self._reach(stage, self.e)
        v = self.v
        ok = inside & (e1 <= reach[i] + 1e-9) & (accel >= -stage.deceleration - 1e-12) \
            & (v[j] <= stage.end_ceiling + 1e-9) & (v[i] <= stage.start_ceiling + 1e-9) \
            & (e0 + e1 <= stage.middle_ceiling ** 2 + 1e-9) \
            & ((v[i] + v[j]) > 0.0)
        costs = self._costs(stage, e0, e1)
        table = (j, ok, costs, self._extra(stage))
        self._tables[key] = table
        return table

    def _extra(self, stage: _Stage):
        """Coasting, the highest acceleration and the highest deceleration from each grid
        state: end states between grid points, one after the other in one array of three
        times the grid's (state i's by control c at c n + i): end e, feasible, costs and the
        grid states either side (``_between``)."""
        end = np.concatenate(self._ends(stage, self.e))
        return (end, *self._moves(stage, np.tile(self.e, 3), end), self._between(end))

    def _between(self, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grid state under each end state (an array) and the share of the step to the
        one above (0 on a grid state's own e)."""
        position = end / self.de
        nearest = np.rint(position)
        position = np.where(np.abs(position - nearest) < 1e-9, nearest, position)
        low = np.clip(np.floor(position).astype(int), 0, len(self.e) - 2)
        return low, np.clip(position - low, 0.0, 1.0)

    def _ends(self, stage: _Stage, e: np.ndarray) -> list[np.ndarray]:
        """The end states of coasting, the highest acceleration and the highest deceleration
        over the stage from the states ``e`` (an array)."""
        p, v = self.physics, np.sqrt(2.0 * e)
        a, b, c = p.davis_n
        coast = e - ((a + b * v + 2.0 * c * e) / p.mass_kg + stage.line_force) * stage.dx
        for _ in range(2):  # the resistance at the stage's mean speed
            v1 = np.sqrt(2.0 * np.maximum(coast, 0.0))
            total = v + v1
            with np.errstate(divide='ignore', invalid='ignore'):
                mean_v = np.where(total > 0, (2 / 3) * (v * v + v * v1 + v1 * v1) / total, 0.0)
            coast = e - ((a + b * mean_v + c * (e + np.maximum(coast, 0.0))) / p.mass_kg
                         + stage.line_force) * stage.dx
        return [coast, self._reach(stage, e), e - stage.deceleration * stage.dx]

    def _reach(self, stage: _Stage, e: np.ndarray) -> np.ndarray:
        """The highest e at the stage's end from the states ``e`` (an array): the highest
        acceleration a(v) followed over the stage (de/dx = a; midpoint steps of at most
        ``REACH_STEP_M``), never below 0. Under an acceleration that falls with the speed
        (the traction's power limit) the chord at the end speed's a would fall short of it
        by a share that grows with the stage's length."""
        count = max(int(math.ceil(stage.dx / REACH_STEP_M)), 1)
        h = stage.dx / count

        def highest(e: np.ndarray) -> np.ndarray:
            return np.interp(np.sqrt(2.0 * e), self.v, stage.acceleration)
        reached = np.array(e, dtype=float)
        for _ in range(count):
            half = np.maximum(reached + 0.5 * h * highest(reached), 0.0)
            reached = np.maximum(reached + h * highest(half), 0.0)
        return reached

    def _moves(self, stage: _Stage, e: np.ndarray, end: np.ndarray):
        """Whether each move from ``e`` to ``end`` over the stage (arrays, broadcast) is
        within the limits, and its costs (``_costs``)."""
        accel = (end - e) / stage.dx
        v, v_end = np.sqrt(2.0 * e), np.sqrt(2.0 * np.maximum(end, 0.0))
        ok = (end >= 0.0) & (v_end <= stage.end_ceiling + 1e-9) \
            & (v <= stage.start_ceiling + 1e-9) \
            & (e + end <= stage.middle_ceiling ** 2 + 1e-9) \
            & (end <= self._reach(stage, e) + 1e-9) & (accel >= -stage.deceleration - 1e-9) \
            & ((v + v_end) > 0.0)
        return ok, self._costs(stage, e, end)

    def _envelope_table(self, k: int):
        """The moves of stage k that start or end on the braking envelope: from the grid
        states within reach to B after the stage (their indices, feasible, costs), and from B
        before it to the grid states within reach, to B after it and by the three controls
        of ``_ends`` (end states, feasible, costs). Cached per stage."""
        if k in self._envelope_moves:
            return self._envelope_moves[k]
        stage, de, n = self.stages[k], self.de, len(self.e)
        before, after = self.envelope[k], self.envelope[k + 1]
        up = max(float(np.max(stage.acceleration)), 0.0) * stage.dx
        down = stage.deceleration * stage.dx

        def within(low: float, high: float) -> np.ndarray:
            return np.arange(max(int(math.floor(low / de)) - 1, 0),
                             min(int(math.ceil(high / de)) + 2, n))
        sources = within(after - up, after + down)
        to_envelope = (sources, *self._moves(stage, self.e[sources], np.full(len(sources), after)))
        targets = self.e[within(before - down, before + up)]
        ends = np.concatenate([targets, [after], *self._ends(stage, np.array([before]))])
        from_envelope = (ends, *self._moves(stage, np.full(len(ends), before), ends),
                         self._between(ends))
        self._envelope_moves[k] = (to_envelope, from_envelope)
        return self._envelope_moves[k]

    def _to_go(self, end: np.ndarray, between: tuple[np.ndarray, np.ndarray], after):
        """The cost to go from end states (an array) at a stage boundary, and a function
        giving its parts at some of them: linear between the grid states either side
        (``between``), or, in the step where B falls, between the last grid state under B and
        the envelope state; inf above B (every grid state above it is). ``after``: the grid
        states' values and parts there, the boundary, the envelope state's value and parts."""
        value, parts, boundary, envelope_value, envelope_parts = after
        low, share = between
        upper = low + 1
        with np.errstate(invalid='ignore'):   # 0 x inf where share is 0 or 1
            to_go = (1.0 - share) * value[low] + share * value[upper]
        to_go = np.where(share <= 0.0, value[low], np.where(share >= 1.0, value[upper], to_go))
        envelope = self.envelope[boundary]
        below, inside = self._envelope_steps[boundary]
        in_cell = (low == below) & (share > 0.0) & (end <= envelope + 1e-9) if inside \
            else np.zeros(len(end), dtype=bool)
        cell = np.flatnonzero(in_cell)
        lower_e = self.e[below]
        envelope_share = np.clip((end[cell] - lower_e) / (envelope - lower_e), 0.0, 1.0)
        with np.errstate(invalid='ignore'):
            to_go[cell] = np.where(envelope_share >= 1.0, envelope_value,
                                   (1.0 - envelope_share) * value[below]
                                   + envelope_share * envelope_value)

        def parts_at(rows: np.ndarray) -> np.ndarray:
            mixed = (1.0 - share[rows]) * parts[:, low[rows]] + share[rows] * parts[:, upper[rows]]
            on_envelope = in_cell[rows]
            if on_envelope.any():
                shares = np.clip((end[rows] - lower_e) / (envelope - lower_e), 0.0, 1.0)
                mixed = np.where(on_envelope, (1.0 - shares) * parts[:, [below]]
                                 + shares * envelope_parts[:, None], mixed)
            return mixed
        return to_go, parts_at

    def evaluate(self, speeds_mps: np.ndarray) -> Optimum:
        """The energies and the running time of a given curve in the oracle's physics: its
        speeds at the stage boundaries (``xs``), the force held over each stage as in the
        programme; lambda nan. A check that a curve's forecast uses the oracle's physics."""
        e = 0.5 * np.asarray(speeds_mps, dtype=float) ** 2
        if e.shape != self.xs.shape:
            raise ValueError(f'evaluate: one speed per stage boundary ({len(self.xs)}), got '
                             f'{e.shape}')
        sums = np.zeros(4)
        for k, stage in enumerate(self.stages):
            _, *parts = self._costs(stage, e[k:k + 1], e[k + 1:k + 2])
            sums += [float(part[0]) for part in parts]
        mass = self.physics.mass_kg
        return Optimum(float(sums[3]), mass * sums[0], mass * sums[1], mass * sums[2], math.nan)

    def solve(self, lam: float) -> Optimum:
        """The least energy + lam x time from standstill to standstill on the grid."""
        n = len(self.e)
        rows = np.arange(n)
        # the value and, along the chosen controls, gross, braking, regenerated and time to go,
        # of the grid states and of the envelope state (B = 0 at the end: the standstill)
        value = np.where(self.e == 0.0, 0.0, np.inf)
        parts = np.zeros((4, n))
        envelope_value, envelope_parts = 0.0, np.zeros(4)
        for k in range(len(self.stages) - 1, -1, -1):
            j, ok, costs, extra = self._table(k)
            energy, *accumulated = costs
            total = np.where(ok, energy + lam * accumulated[3] + value[j], np.inf)
            best = np.argmin(total, axis=1)
            best_value = total[rows, best]
            best_parts = np.stack([accumulated[m][rows, best] + parts[m][j[rows, best]]
                                   for m in range(4)])
            after = (value, parts, k + 1, envelope_value, envelope_parts)
            end, feasible, (e_energy, *e_parts), between = extra
            to_go, parts_at = self._to_go(end, between, after)
            candidate = np.where(feasible, e_energy + lam * e_parts[3] + to_go,
                                 np.inf).reshape(3, n)
            control = np.argmin(candidate, axis=0)
            better = np.flatnonzero(candidate[control, rows] < best_value)
            if len(better):
                chosen = control[better] * n + better    # in the controls' one array
                best_value[better] = candidate[control[better], better]
                best_parts[:, better] = np.stack(e_parts)[:, chosen] + parts_at(chosen)
            to_envelope, from_envelope = self._envelope_table(k)
            sources, feasible, (e_energy, *e_parts) = to_envelope
            candidate = np.where(feasible, e_energy + lam * e_parts[3] + envelope_value, np.inf)
            better = candidate < best_value[sources]
            best_value[sources[better]] = candidate[better]
            best_parts[:, sources[better]] = (np.stack(e_parts)[:, better]
                                              + envelope_parts[:, None])
            ends, feasible, (e_energy, *e_parts), between = from_envelope
            to_go, parts_at = self._to_go(ends, between, after)
            candidate = np.where(feasible, e_energy + lam * e_parts[3] + to_go, np.inf)
            chosen = int(np.argmin(candidate))
            envelope_value = float(candidate[chosen])
            envelope_parts = np.stack(e_parts)[:, chosen] + parts_at(np.array([chosen]))[:, 0]
            value, parts = best_value, best_parts
        if not math.isfinite(value[0]):
            raise ValueError('the oracle finds no way through the leg within the limits')
        mass = self.physics.mass_kg
        return Optimum(float(parts[3][0]), mass * float(parts[0][0]),
                       mass * float(parts[1][0]), mass * float(parts[2][0]), lam)

    def at_time(self, running_time_s: float, iterations: int = 24) -> Optimum:
        """The least energy at ``running_time_s`` less the jerk allowance (lambda bisected;
        module docstring)."""
        running_time_s -= self.jerk_allowance_s
        high = 1e-3
        fast = self.solve(high)
        while fast.running_time_s > running_time_s:
            high *= 4.0
            if high > 1e6:
                raise ValueError(f'the oracle cannot run the leg in {running_time_s:.1f} s '
                                 f'(fastest found {fast.running_time_s:.1f} s)')
            fast = self.solve(high)
        low = high / 4.0
        slow = self.solve(low)
        while slow.running_time_s <= running_time_s:
            low /= 4.0
            if low < 1e-9:
                return slow
            slow = self.solve(low)
        for _ in range(iterations):
            middle = math.sqrt(low * high)
            trial = self.solve(middle)
            if trial.running_time_s > running_time_s:
                low, slow = middle, trial
            else:
                high, fast = middle, trial
        span = slow.running_time_s - fast.running_time_s
        share = 0.0 if span <= 0.0 else (slow.running_time_s - running_time_s) / span

        def mix(a: float, b: float) -> float:
            return (1.0 - share) * a + share * b
        return Optimum(running_time_s, mix(slow.gross_j, fast.gross_j),
                       mix(slow.braking_j, fast.braking_j),
                       mix(slow.regenerated_j, fast.regenerated_j),
                       math.sqrt(low * high))
