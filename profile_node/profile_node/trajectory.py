"""Piecewise constant-jerk trajectories: exact, continuous in x, v and a, with bounded jerk.

A trajectory is a list of segments, each starting at (t0, x0, v0, a0) with constant jerk j;
within a segment x, v, a are the cubic, quadratic and linear polynomials of the elapsed time, so
v is exactly the derivative of x and a of v.
"""

from __future__ import annotations

import abc
import math
from bisect import bisect_right
from dataclasses import dataclass

from ato_common.types import ReferencePoint


@dataclass(frozen=True)
class Segment:
    t0: float
    duration: float
    x0: float
    v0: float
    a0: float
    jerk: float

    def at(self, t: float) -> tuple[float, float, float]:
        tau = t - self.t0
        j, a0, v0 = self.jerk, self.a0, self.v0
        return (self.x0 + tau * (v0 + tau * (a0 / 2.0 + tau * j / 6.0)),
                v0 + tau * (a0 + tau * j / 2.0),
                a0 + tau * j)


class TrajectoryBuilder:
    """Appends constant-jerk segments, carrying the end state of the last one forward."""

    def __init__(self, x0: float = 0.0, t0: float = 0.0):
        self.segments: list[Segment] = []
        self.t, self.x, self.v, self.a = t0, x0, 0.0, 0.0

    def add(self, duration: float, jerk: float = 0.0) -> None:
        if duration <= 0.0:
            return
        segment = Segment(self.t, duration, self.x, self.v, self.a, jerk)
        self.segments.append(segment)
        self.x, self.v, self.a = segment.at(self.t + duration)
        self.t += duration

    def snap(self, x: float, v: float = 0.0) -> None:
        """Remove the rounding drift at an exact target (a station stop)."""
        self.x, self.v, self.a = x, v, 0.0

    def speed_change(self, target_speed: float, max_accel: float, jerk: float) -> None:
        """S-curve from the current speed (with zero acceleration) to ``target_speed``."""
        dv = target_speed - self.v
        if dv == 0.0:
            return
        sign = 1.0 if dv > 0.0 else -1.0
        ramp, hold = speed_change_durations(abs(dv), max_accel, jerk)
        self.add(ramp, sign * jerk)
        self.add(hold, 0.0)
        self.add(ramp, -sign * jerk)
        self.v, self.a = target_speed, 0.0

    def accelerate_to(self, target_speed: float, capability, jerk: float,
                      min_acceleration: float, step_s: float = 1.0) -> None:
        """Traction phase from the current speed (zero acceleration) up to ``target_speed``,
        following the acceleration the train can deliver, ``capability(v)`` [m/s^2] but at least
        ``min_acceleration`` (the caller keeps the target where that is feasible), with
        |jerk| <= ``jerk``, ending with zero acceleration exactly at the target speed."""
        if target_speed <= self.v:
            return
        for _ in range(1_000_000):
            remaining = target_speed - self.v
            if remaining <= 1e-12:
                break
            if self.a > 0.0 and remaining <= self.a * self.a / (2.0 * jerk) + 1e-12:
                ramp_jerk = self.a * self.a / (2.0 * remaining)
                self.add(self.a / ramp_jerk, -ramp_jerk)
                break
            predicted = self.v + self.a * step_s
            wanted = max(min(capability(predicted), capability(self.v)), min_acceleration)
            j = min(max((wanted - self.a) / step_s, -jerk), jerk)
            a_end = self.a + j * step_s
            v_end = self.v + step_s * (self.a + 0.5 * j * step_s)
            if target_speed - v_end <= a_end * a_end / (2.0 * jerk):
                # The ramp-down to zero acceleration must start within this step.
                if self.a <= 0.0:
                    # From zero acceleration: a symmetric triangle ends exactly at the target.
                    peak = math.sqrt(remaining * jerk)
                    self.add(peak / jerk, jerk)
                    self.add(peak / jerk, -jerk)
                else:
                    # Hold the acceleration until exactly that point, then ramp down.
                    hold = (remaining - self.a * self.a / (2.0 * jerk)) / self.a
                    self.add(max(hold, 0.0), 0.0)
                    self.add(self.a / jerk, -jerk)
                break
            self.add(step_s, j)
        self.v, self.a = target_speed, 0.0

    def follow(self, wanted, jerk: float, speed: float | None = None,
               position: float | None = None, cap=math.inf,
               step_s: float = 1.0, speed_from: float = -math.inf, until=None,
               ahead: bool = False) -> None:
        """Follow the acceleration ``wanted(v, x)`` [m/s^2] (the lower of its values at the
        step's start and at its predicted end: a limit never exceeded; with ``ahead``, its
        value at the predicted end: an acceleration tracked without a step's lag, as a coast's
        is) with |jerk| <= ``jerk``, from any acceleration,
        until the speed reaches ``speed`` (exactly, with zero acceleration; from above or
        below) or the position reaches ``position`` (exactly). The speed never exceeds
        ``cap``: it reaches it with zero acceleration and holds it while ``wanted`` is
        positive; ``cap`` may be a function of the position. The speed ends the phase only
        from the position ``speed_from`` on. ``until(builder)``: the phase also ends (exactly)
        where this function of the state rises through zero."""
        ceiling = cap if callable(cap) else (lambda x: cap)
        for _ in range(1_000_000):
            if position is not None and self.x >= position - 1e-9:
                return
            if self.v <= 0.0 and self.a <= 0.0 and wanted(self.v, self.x) <= 0.0:
                raise ValueError(f'the train stalls at {self.x:.0f} m')
            target = speed if self.x >= speed_from else None
            # the cap here and a step ahead (a lower cap ahead holds from here)
            top = min(ceiling(self.x), ceiling(self.x + self.v * step_s))
            if self.v >= top - 1e-9 and self.a > 0.0:
                self.ramp_acceleration_to_zero(jerk)   # at the cap: no more acceleration
                continue
            if self.v >= top - 1e-9 and self.a <= 1e-12 and wanted(self.v, self.x) >= 0.0:
                # held at the cap: to the position, or a step
                if target is not None and abs(target - self.v) <= 1e-9:
                    self.v, self.a = target, 0.0
                    return
                duration = step_s if position is None else min(
                    step_s, (position - self.x) / max(self.v, 1e-9))
                if abs(self.v - top) <= 1e-6:
                    self.v = top   # rounding only: the speed is continuous
                self.a = 0.0
                if until is not None and self._reaches(until, 0.0, duration):
                    return
                self.add(duration)
                continue
            if target is not None and self._ends_at_speed(target, jerk):
                return
            if top > self.v and self.a > 0.0 and self._ends_at_speed(top, jerk):
                continue
            predicted = self.v + self.a * step_s
            want = wanted(predicted, self.x + self.v * step_s)
            if not ahead:
                want = min(want, wanted(self.v, self.x))
            j = min(max((want - self.a) / step_s, -jerk), jerk)
            duration = step_s
            if target is not None:
                duration = self._before_speed(target, j, jerk, duration)
            if top > self.v and math.isfinite(top):
                duration = self._before_speed(top, j, jerk, duration)
            if position is not None:
                duration = self._before_position(position, j, duration)
            if duration <= 0.0:
                duration = min(step_s, 1e-3)
            if until is not None and self._reaches(until, j, duration):
                return
            self.add(duration, j)

    def _reaches(self, until, j: float, duration: float) -> bool:
        """If ``until`` rises through zero within the step (``j``, ``duration``), advance to
        exactly there (bisection) and say so; also if it is not below zero now."""
        def after(tau: float) -> float:
            state = StateBuilder(self.x, self.t)
            state.v, state.a = self.v, self.a
            state.add(tau, j)
            return until(state)
        if until(self) >= 0.0:
            return True
        if after(duration) < 0.0:
            return False
        low, high = 0.0, duration
        for _ in range(60):
            middle = 0.5 * (low + high)
            if after(middle) < 0.0:
                low = middle
            else:
                high = middle
        self.add(low, j)
        return True

    def brake_to(self, speed: float, deceleration: float, jerk: float,
                 acceleration: float = 0.0) -> None:
        """From the current speed and acceleration to ``speed`` at ``acceleration``, braking
        at most at ``deceleration`` with |jerk| <= ``jerk`` (``braking_steps``)."""
        steps = braking_steps(self.v, self.a, speed, deceleration, jerk, acceleration)
        if steps is None:
            self.ramp_acceleration_to_zero(jerk)
            self.speed_change(speed, deceleration, jerk)
            return
        for duration, j in steps:
            self.add(duration, j)
        self.v, self.a = speed, acceleration

    def _ends_at_speed(self, target: float, jerk: float) -> bool:
        """If the speed is within reach of ``target`` (the ramp of the acceleration to zero
        would pass it), end exactly at it with zero acceleration; True then."""
        remaining = target - self.v
        if abs(remaining) <= 1e-9 and abs(self.a) <= 1e-9:
            self.v, self.a = target, 0.0
            return True
        sign = 1.0 if remaining > 0.0 else -1.0
        if sign * self.a > 0.0 and abs(remaining) <= self.a * self.a / (2.0 * jerk) \
                * (1.0 + 1e-9) + 1e-12:
            ramp_jerk = self.a * self.a / (2.0 * abs(remaining))
            self.add(abs(self.a) / ramp_jerk, -sign * ramp_jerk)
            self.v, self.a = target, 0.0
            return True
        return False

    def _before_speed(self, target: float, j: float, jerk: float, step_s: float) -> float:
        """The step's duration, shortened so that its end leaves room for the ramp of the
        acceleration to zero at ``target`` (bisection)."""
        remaining = target - self.v
        sign = 1.0 if remaining > 0.0 else -1.0

        def overshoots(tau: float) -> bool:
            a_end = self.a + j * tau
            v_end = self.v + tau * (self.a + 0.5 * j * tau)
            left = sign * (target - v_end)
            return left < 0.0 or (sign * a_end > 0.0 and left < a_end * a_end / (2.0 * jerk))
        if not overshoots(step_s):
            return step_s
        low, high = 0.0, step_s
        for _ in range(50):
            middle = 0.5 * (low + high)
            if overshoots(middle):
                high = middle
            else:
                low = middle
        return low

    def _before_position(self, position: float, j: float, step_s: float) -> float:
        """The step's duration, shortened to end exactly at ``position`` (bisection)."""
        def x_after(tau: float) -> float:
            return self.x + tau * (self.v + tau * (self.a / 2.0 + tau * j / 6.0))
        if x_after(step_s) < position:
            return step_s
        low, high = 0.0, step_s
        for _ in range(60):
            middle = 0.5 * (low + high)
            if x_after(middle) < position:
                low = middle
            else:
                high = middle
        return high

    def ramp_acceleration_to_zero(self, jerk: float) -> None:
        """From a nonzero acceleration to zero at the jerk limit (the start of a replan)."""
        if self.a != 0.0:
            self.add(abs(self.a) / jerk, -math.copysign(jerk, self.a))
            self.a = 0.0

    def build(self) -> 'Trajectory':
        return Trajectory(self.segments, (self.t, self.x, self.v, self.a))


class StateBuilder(TrajectoryBuilder):
    """A builder that only carries the end state forward (no segments kept): for the planner's
    trial runs (where a coast ends), the end state of :class:`TrajectoryBuilder`'s, bit for
    bit, at a fraction of its cost."""

    def add(self, duration: float, jerk: float = 0.0) -> None:
        if duration <= 0.0:
            return
        t0 = self.t
        t = t0 + duration
        tau = t - t0  # as Segment.at computes it
        v0, a0 = self.v, self.a
        self.x, self.v, self.a = (self.x + tau * (v0 + tau * (a0 / 2.0 + tau * jerk / 6.0)),
                                  v0 + tau * (a0 + tau * jerk / 2.0),
                                  a0 + tau * jerk)
        self.t = t


class _ReplayedSteps(abc.ABC):
    """The whole steps of one builder phase from one start, computed once and replayed: the
    states after each step and the jerk of each (the phase's own wanted acceleration from
    :meth:`_wanted`, limited by the jerk), the same operations on the same values as the
    builder, so bit for bit its states."""

    def __init__(self, start: tuple[float, float, float, float], jerk: float, step_s: float):
        self.jerk, self.step_s = jerk, step_s
        self.states: list[tuple[float, float, float, float]] = [start]  # (t, x, v, a)
        self.jerks: list[float] = []  # the jerk of the whole step from each state

    @abc.abstractmethod
    def _wanted(self, x: float, v: float, a: float) -> float:
        """The acceleration the phase wants from state (x, v, a), before the jerk limit."""

    def _jerk(self, k: int) -> float:
        """The jerk of the whole step from state ``k`` (state k + 1 then exists)."""
        if k == len(self.jerks):
            t, x, v, a = self.states[k]
            step_s, jerk = self.step_s, self.jerk
            j = min(max((self._wanted(x, v, a) - a) / step_s, -jerk), jerk)
            builder = StateBuilder(x, t)
            builder.v, builder.a = v, a
            builder.add(step_s, j)
            self.jerks.append(j)
            self.states.append((builder.t, builder.x, builder.v, builder.a))
        return self.jerks[k]


class AccelerationSteps(_ReplayedSteps):
    """:meth:`TrajectoryBuilder.accelerate_to` from one start (standstill or a speed, zero
    acceleration, at x = 0, t = 0) towards many target speeds: its whole steps do not depend on
    the target (only where it stops stepping and ramps down does), so they are computed once
    and replayed. ``distance_to(v)`` is the distance the builder's phase to ``v`` covers, bit
    for bit (the same operations on the same values)."""

    def __init__(self, v_from: float, capability, jerk: float, min_acceleration: float,
                 step_s: float = 1.0):
        super().__init__((0.0, 0.0, v_from, 0.0), jerk, step_s)
        self.capability, self.min_acceleration = capability, min_acceleration

    def _wanted(self, x: float, v: float, a: float) -> float:
        capability = self.capability
        predicted = v + a * self.step_s
        return max(min(capability(predicted), capability(v)), self.min_acceleration)

    def distance_to(self, target_speed: float) -> float:
        jerk, step_s = self.jerk, self.step_s
        if target_speed <= self.states[0][2]:
            return self.states[0][1]
        for k in range(1_000_000):
            t, x, v, a = self.states[k]
            remaining = target_speed - v
            if remaining <= 1e-12:
                return x
            builder = None
            if a > 0.0 and remaining <= a * a / (2.0 * jerk) + 1e-12:
                builder = StateBuilder(x, t)
                builder.v, builder.a = v, a
                ramp_jerk = a * a / (2.0 * remaining)
                builder.add(a / ramp_jerk, -ramp_jerk)
                return builder.x
            j = self._jerk(k)
            a_end = a + j * step_s
            v_end = v + step_s * (a + 0.5 * j * step_s)
            if target_speed - v_end <= a_end * a_end / (2.0 * jerk):
                builder = StateBuilder(x, t)
                builder.v, builder.a = v, a
                if a <= 0.0:
                    peak = math.sqrt(remaining * jerk)
                    builder.add(peak / jerk, jerk)
                    builder.add(peak / jerk, -jerk)
                else:
                    hold = (remaining - a * a / (2.0 * jerk)) / a
                    builder.add(max(hold, 0.0), 0.0)
                    builder.add(a / jerk, -jerk)
                return builder.x
        return self.states[-1][1]


def braking_steps(v0: float, a0: float, v1: float, deceleration: float, jerk: float,
                  a1: float = 0.0) -> list[tuple[float, float]] | None:
    """(duration, jerk) of a braking from speed v0 at acceleration a0 to v1 < v0 at
    acceleration a1 (-deceleration <= a1 <= 0): the acceleration ramped at |jerk| = J to -p
    (p at most ``deceleration``), held, then ramped to a1. None where that cannot end at v1
    (the speed to lose is less than the ramps lose)."""
    J, d = jerk, deceleration
    if v1 >= v0 or a1 > 0.0 or a1 < -d - 1e-12:
        return None
    first = -d - a0
    t1, j1 = abs(first) / J, math.copysign(J, first)
    t3 = (a1 + d) / J
    left = (v0 - v1) + a0 * t1 + 0.5 * j1 * t1 * t1 - d * t3 + 0.5 * J * t3 * t3
    if left >= 0.0:
        return [(t1, j1), (left / d, 0.0), (t3, J)]
    # A lower peak p, not held: ramped down from a0 to -p and up to a1, the speed lost is
    # (2 p^2 - a0^2 - a1^2) / (2 J).
    p = math.sqrt(max(0.5 * (a0 * a0 + a1 * a1) + J * (v0 - v1), 0.0))
    if p < -a0 - 1e-12 or p < -a1 - 1e-12:
        return None
    return [((p + a0) / J, -J), (0.0, 0.0), ((a1 + p) / J, J)]


def braking_distance(v0: float, a0: float, v1: float, deceleration: float,
                     jerk: float, a1: float = 0.0) -> float:
    """The distance of ``braking_steps`` (inf where there are none)."""
    steps = braking_steps(v0, a0, v1, deceleration, jerk, a1)
    if steps is None:
        return math.inf
    state = StateBuilder()
    state.v, state.a = v0, a0
    for duration, j in steps:
        state.add(duration, j)
    return state.x


def speed_change_durations(dv: float, max_accel: float, jerk: float) -> tuple[float, float]:
    """(jerk ramp duration, constant-acceleration duration) of a symmetric S-curve changing the
    speed by ``dv`` >= 0 with |a| <= max_accel and |j| = jerk."""
    if dv >= max_accel * max_accel / jerk:
        return max_accel / jerk, dv / max_accel - max_accel / jerk
    return math.sqrt(dv / jerk), 0.0


def speed_change_distance(v_from: float, v_to: float, max_accel: float, jerk: float) -> float:
    """Distance covered by that S-curve; symmetric, so mean speed times duration."""
    ramp, hold = speed_change_durations(abs(v_to - v_from), max_accel, jerk)
    return 0.5 * (v_from + v_to) * (2.0 * ramp + hold)


class Trajectory:
    def __init__(self, segments: list[Segment], end_state: tuple[float, float, float, float]):
        if not segments:
            raise ValueError('a trajectory needs at least one segment')
        self.segments = segments
        self._starts = [s.t0 for s in segments]
        self.start_time = segments[0].t0
        self.end_time, self.end_position, self.end_speed, self.end_acceleration = end_state

    def at(self, t: float) -> ReferencePoint:
        """The reference at time t, with the segment's jerk (the derivative of a*; at a segment
        boundary the jerk of the segment starting there); before the start and after the end
        the train stands still at the first/last position."""
        if t >= self.end_time:
            return ReferencePoint(t, self.end_position, self.end_speed, self.end_acceleration)
        if t <= self.start_time:
            first = self.segments[0]
            return ReferencePoint(t, first.x0, first.v0, first.a0)
        segment = self.segments[bisect_right(self._starts, t) - 1]
        x, v, a = segment.at(t)
        return ReferencePoint(t, x, v, a, segment.jerk)


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
