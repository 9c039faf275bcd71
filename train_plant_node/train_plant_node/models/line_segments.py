"""The line's specific force is piecewise constant in position (grades, curves and tunnels start
and end at given positions). The models look it up once per segment and split an integration step
where a car crosses a segment boundary, so that no integration stage straddles a jump of the
force: the step stays at its full order on any line."""

from __future__ import annotations

from bisect import bisect_right

from ato_common.line import Line

# A car that has just been integrated onto a boundary is in the segment it is entering.
BOUNDARY_NUDGE_M = 1e-6


class LineSegments:
    def __init__(self, line: Line, gravity: float):
        bounds = set(line.grade_sine.starts[1:])
        for feature in (*line.curves, *line.tunnels):
            bounds.update((feature.start_m, feature.start_m + feature.length_m))
        self.bounds = sorted(bounds)
        samples = [self.bounds[0] - 1.0 if self.bounds else 0.0] + self.bounds
        # Per segment: g sin(grade) and the curve + tunnel part, m/s^2 (line.py's rules).
        self.grade = [gravity * line.grade_sine(s) for s in samples]
        self.other = [line.line_force_per_kg(s, gravity) - g for s, g in zip(samples, self.grade)]
        self.gravity = gravity

    def index(self, position: float, moving_back: bool = False) -> int:
        return bisect_right(self.bounds, position - BOUNDARY_NUDGE_M if moving_back
                            else position + BOUNDARY_NUDGE_M)

    def accel(self, index: int, grade_override_sine: float | None, line_factor: float) -> float:
        """Specific line force of a segment, m/s^2 (positive opposes forward motion)."""
        grade = (self.grade[index] if grade_override_sine is None
                 else self.gravity * grade_override_sine)
        return line_factor * (grade + self.other[index])

    def boundary_between(self, index_from: int, index_to: int) -> float:
        """The first boundary crossed going from one segment towards another."""
        return self.bounds[index_from] if index_to > index_from else self.bounds[index_from - 1]


def crossing_time(s0: float, v0: float, s1: float, v1: float, h: float, boundary: float) -> float:
    """When the cubic Hermite interpolant of a step (positions and speeds at both ends) reaches
    ``boundary``; the step's own error bounds its error (the position is 4th-order accurate)."""
    def position(tau: float) -> float:
        x = tau / h
        h00, h10 = (1 + 2 * x) * (1 - x) ** 2, x * (1 - x) ** 2
        h01, h11 = x * x * (3 - 2 * x), x * x * (x - 1)
        return h00 * s0 + h10 * h * v0 + h01 * s1 + h11 * h * v1
    low, high = 0.0, h
    rising = s1 > s0
    for _ in range(60):  # bisection: robust, and crossings are rare
        mid = 0.5 * (low + high)
        if (position(mid) < boundary) == rising:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)
