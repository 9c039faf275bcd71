"""Single mass point (Luo & Xu eq 3; Mao et al. 2017 eqs 5-12; Tan, Jiang & Chen eqs 1-8;
Liu & Li eq 9):

    s' = v
    M v' = F - r (fa a + fb b v + fc c v^2) - M fl g_line(s) - M (g sin(theta_mode) + 0.004 D)
           + d(t)

with M the equivalent mass and a, b, c the Davis coefficients of the active mode (the train's
without modes), fa, fb, fc the slowly varying factors of Luo & Xu eq (34), r an abrupt change's
resistance factor, g_line the specific force of grade, curve and tunnel at the train's position
(Liu & Li eqs 2-5; fl their l(t) variation, eq 6), the mode's extra grade and curve term (Mao et
al. 2017 eq 12) and the external disturbance d(t) (Liu & Li eq 9).

The train does not roll backwards: at standstill the running resistance acts as static friction
up to ``a`` and the brakes hold it, so the speed is kept at or above zero.

Integration: classical RK4 per step (the dynamics are smooth and slow: the resistance's time
constant is minutes), split where the train crosses a line segment boundary. The work done by
the traction, the resistance, the line, and the disturbance are integrated alongside (``work``),
for energy balances.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ato_common.line import Line
from ato_common.trains import TrainParameters
from ato_common import units
from train_plant_node.models.line_segments import LineSegments, crossing_time
from train_plant_node.surroundings import Surroundings, nominal_mode


class PointMassModel:
    car_names = ('train',)

    def __init__(self, train: TrainParameters, line: Line, max_substep_s: float = 0.1,
                 gravity: float = units.STANDARD_GRAVITY):
        if not max_substep_s > 0.0:
            raise ValueError(f'max_substep_s must be > 0, got {max_substep_s}')
        self.train = train
        self.line = line
        self.actuator_names = train.actuator_names
        self.max_substep_s = max_substep_s
        self.gravity = gravity
        self.segments = LineSegments(line, gravity)
        self.nominal = Surroundings(nominal_mode(train), 0)
        # Work done on the train since the start, J: by the actuators, against the running
        # resistance, against the line (grade, curve, tunnel, mode terms), by the disturbance.
        self.work = [0.0, 0.0, 0.0, 0.0]

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray:
        return np.array([position_m, speed_mps], dtype=float)

    def lead_speed(self, state) -> float:
        return float(state[1])

    def _parts(self, speed: float, force: float, line_accel: float, time_s: float,
               env: Surroundings) -> tuple[float, float, float, float]:
        """(acceleration, resistance force, line force, disturbance force) at one instant."""
        mode = env.mode
        mass, d = mode.mass_kg, mode.davis
        fa, fb, fc, fl, dist = env.factors(time_s) if env.time_varying else (
            env.resistance_factor, env.resistance_factor, env.resistance_factor, 1.0, 0.0)
        line_force = mass * (line_accel * fl + mode.grade_sine * self.gravity
                             + mode.curve_accel_mps2)
        if speed > 0.0:
            resistance = fa * d.a_n + (fb * d.b_n_s_per_m + fc * d.c_n_s2_per_m2 * speed) * speed
            return (force - resistance - line_force + dist) / mass, resistance, line_force, dist
        # Standstill: static friction (the constant Davis term) and brakes hold the train.
        driving = force - line_force + dist
        if driving <= fa * d.a_n:
            return 0.0, driving, line_force, dist
        return (driving - fa * d.a_n) / mass, fa * d.a_n, line_force, dist

    def acceleration(self, position: float, speed: float, force: float, time_s: float = 0.0,
                     env: Surroundings | None = None) -> float:
        env = env or self.nominal
        segment = self.segments.index(position)
        line_accel = self.segments.accel(segment, env.grade_override_sine, 1.0)
        return self._parts(speed, force, line_accel, time_s, env)[0]

    def _rk4(self, s: float, v: float, t: float, h: float, force: float, line_accel: float,
             env: Surroundings):
        """One classical RK4 step of (s, v) and of the work integrals (powers P v)."""
        parts = self._parts
        a1, r1, l1, d1 = parts(v, force, line_accel, t, env)
        v2 = max(v + 0.5 * h * a1, 0.0)
        a2, r2, l2, d2 = parts(v2, force, line_accel, t + 0.5 * h, env)
        v3 = max(v + 0.5 * h * a2, 0.0)
        a3, r3, l3, d3 = parts(v3, force, line_accel, t + 0.5 * h, env)
        v4 = max(v + h * a3, 0.0)
        a4, r4, l4, d4 = parts(v4, force, line_accel, t + h, env)
        w = h / 6.0
        s_new = s + w * (v + 2.0 * v2 + 2.0 * v3 + v4)
        v_new = max(v + w * (a1 + 2.0 * a2 + 2.0 * a3 + a4), 0.0)
        work = (force * w * (v + 2.0 * v2 + 2.0 * v3 + v4),
                w * (r1 * v + 2.0 * r2 * v2 + 2.0 * r3 * v3 + r4 * v4),
                w * (l1 * v + 2.0 * l2 * v2 + 2.0 * l3 * v3 + l4 * v4),
                w * (d1 * v + 2.0 * d2 * v2 + 2.0 * d3 * v3 + d4 * v4))
        return s_new, v_new, work

    def step(self, state, duration_s: float, forces: Sequence[float], time_s: float = 0.0,
             env: Surroundings | None = None) -> np.ndarray:
        """State after ``duration_s`` with the forces held (zero-order hold) from ``time_s``."""
        env = env or self.nominal
        force = math.fsum(forces)
        s, v = float(state[0]), float(state[1])
        segments = self.segments
        t, end = time_s, time_s + duration_s
        substeps = max(1, math.ceil(duration_s / self.max_substep_s - 1e-9))
        h_max = duration_s / substeps
        while end - t > 1e-12 * max(1.0, abs(end)):
            h = h_max if end - t > h_max * (1.0 - 1e-9) else end - t
            segment = segments.index(s)
            line_accel = segments.accel(segment, env.grade_override_sine, 1.0)
            s1, v1, work = self._rk4(s, v, t, h, force, line_accel, env)
            after = segments.index(s1)
            if after != segment:  # the train reaches the next segment within this step
                boundary = segments.boundary_between(segment, after)
                h = crossing_time(s, v, s1, v1, h, boundary)
                s1, v1, work = self._rk4(s, v, t, h, force, line_accel, env)
                s1 = boundary  # on it, within the step's error: continue in the next segment
            s, v, t = s1, v1, t + h
            for i, w in enumerate(work):
                self.work[i] += w
        return np.array([s, v])

    def outputs(self, state, forces: Sequence[float], time_s: float = 0.0,
                env: Surroundings | None = None):
        s, v = float(state[0]), float(state[1])
        force = math.fsum(forces)
        return (s,), (v,), (self.acceleration(s, v, force, time_s, env),), (force,)
