"""The line's specific force between consecutive feature boundaries (grade changes, curve and
tunnel ends) is constant, or linear in position inside a transition curve. The models look a
segment up once per step and split an integration step where a car crosses a boundary, so that
no integration stage straddles a jump of the force: the step keeps its full order on any line."""

from __future__ import annotations

import math

import numpy as np

from ato_common.line import Curve, Line, Tunnel
from train_plant_node.jit import kernel

# A car that has just been integrated onto a boundary is in the segment it is entering.
BOUNDARY_NUDGE_M = 1e-6


class LineSegments:
    def __init__(self, line: Line, gravity: float):
        bounds = set(line.grade_sine.starts[1:])
        features: list[Curve | Tunnel] = [*line.curves, *line.tunnels]
        for feature in features:
            bounds.update((feature.start_m, feature.start_m + feature.length_m))
        self.bounds = sorted(bounds)
        starts = [self.bounds[0] - 1.0 if self.bounds else 0.0] + self.bounds
        ends = self.bounds + [starts[-1] + 1.0]
        self.starts = starts
        # Per segment: g sin(grade), and the curve + tunnel part at the segment's start with its
        # slope per metre (non-zero in a transition curve), m/s^2 (line.py's rules).
        self.grade = [gravity * line.grade_sine(s) for s in starts]
        self.other = [line.line_force_per_kg(s, gravity) - g for s, g in zip(starts, self.grade)]
        self.slope = []
        for s, e, g, o in zip(starts, ends, self.grade, self.other):
            mid = 0.5 * (s + e)
            self.slope.append((line.line_force_per_kg(mid, gravity) - g - o) / (mid - s))
        self.slope = [0.0 if abs(k) < 1e-15 else k for k in self.slope]
        self.gravity = gravity
        # What the kernels read: one row per segment quantity, and the bounds closed by +inf
        # (so that a search needs no length check; one more bound than segments).
        self.table = np.array([starts, self.grade, self.other, self.slope,
                               self.bounds + [math.inf]], dtype=float)


# Rows of LineSegments.table.
START, GRADE, OTHER, SLOPE, BOUNDS = range(5)


@kernel
def segment_index(table, position, moving_back):
    """The segment holding ``position`` (``table``: LineSegments.table)."""
    nudged = position - BOUNDARY_NUDGE_M if moving_back else position + BOUNDARY_NUDGE_M
    return np.searchsorted(table[BOUNDS], nudged, side='right')


@kernel
def segment_accel(table, index, has_override, override_accel):
    """Specific line force at a segment's start, m/s^2 (positive opposes forward motion); an
    abrupt change's grade (``override_accel`` = g sin) replaces the line's."""
    grade = override_accel if has_override else table[GRADE, index]
    return grade + table[OTHER, index]


@kernel
def segment_accel_at(table, index, position, has_override, override_accel):
    """Specific line force at a position inside segment ``index``, m/s^2."""
    base = segment_accel(table, index, has_override, override_accel)
    slope = table[SLOPE, index]
    return base + slope * (position - table[START, index]) if slope != 0.0 else base


@kernel
def boundary_between(table, index_from, index_to):
    """The first boundary crossed going from one segment towards another."""
    return table[BOUNDS, index_from] if index_to > index_from else table[BOUNDS, index_from - 1]


@kernel
def crossing_time(s0, v0, s1, v1, h, boundary):
    """When the cubic Hermite interpolant of a step (positions and speeds at both ends) reaches
    ``boundary``; the step's own error bounds its error (the position is 4th-order accurate)."""
    low, high = 0.0, h
    rising = s1 > s0
    for _ in range(60):  # bisection: robust, and crossings are rare
        mid = 0.5 * (low + high)
        x = mid / h
        h00, h10 = (1 + 2 * x) * (1 - x) ** 2, x * (1 - x) ** 2
        h01, h11 = x * x * (3 - 2 * x), x * x * (x - 1)
        position = h00 * s0 + h10 * h * v0 + h01 * s1 + h11 * h * v1
        if (position < boundary) == rising:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)
