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
for energy balances. The integration runs in compiled kernels (train_plant_node.jit) on the
parameter array ``PointMassModel.parameters`` (layout below).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ato_common import units
from ato_common.line import Line
from ato_common.trains import TrainParameters
from train_plant_node.jit import kernel
from train_plant_node.models.line_segments import (
    LineSegments,
    boundary_between,
    crossing_time,
    segment_accel_at,
    segment_index,
)
from train_plant_node.surroundings import (
    DISTURBANCE_VALUE,
    ENV_SIZE,
    HAS_OVERRIDE,
    OVERRIDE_SINE,
    Surroundings,
    env_factors,
    nominal_mode,
)

# The kernels' parameter array: the mode's mass (kg), Davis a (N), b (N s/m), c (N s^2/m^2), its
# extra grade and curve term (m/s^2), gravity, then the surroundings (surroundings.py).
MASS, DAVIS_A, DAVIS_B, DAVIS_C, MODE_ACCEL, GRAVITY, ENV = range(7)
PARAMETERS = ENV + ENV_SIZE


@kernel
def _line_accel(p, table, segment, position):
    return segment_accel_at(table, segment, position, p[ENV + HAS_OVERRIDE] != 0.0,
                            p[GRAVITY] * p[ENV + OVERRIDE_SINE])


@kernel
def _parts(p, speed, force, line_accel, time_s):
    """(acceleration, resistance force, line force, disturbance force) at one instant: the
    module's equation (Luo & Xu eq 3 with eq 34, Mao et al. 2017 eq 12, Liu & Li eqs 2-6, 9)."""
    fa, fb, fc, fl, dist = env_factors(p, ENV, time_s)
    mass, a_n = p[MASS], p[DAVIS_A]
    line_force = mass * (line_accel * fl + p[MODE_ACCEL])
    if speed > 0.0:
        resistance = fa * a_n + (fb * p[DAVIS_B] + fc * p[DAVIS_C] * speed) * speed
        return (force - resistance - line_force + dist) / mass, resistance, line_force, dist
    # Standstill: static friction (the constant Davis term) and brakes hold the train.
    driving = force - line_force + dist
    if driving <= fa * a_n:
        return 0.0, driving, line_force, dist
    return (driving - fa * a_n) / mass, fa * a_n, line_force, dist


@kernel
def acceleration_kernel(p, table, position, speed, force, time_s):
    segment = segment_index(table, position, False)
    return _parts(p, speed, force, _line_accel(p, table, segment, position), time_s)[0]


@kernel
def _rk4(p, table, s, v, t, h, force, segment):
    """One classical RK4 step of (s, v) and of the work integrals (powers P v)."""
    a1, r1, l1, d1 = _parts(p, v, force, _line_accel(p, table, segment, s), t)
    v2 = max(v + 0.5 * h * a1, 0.0)
    a2, r2, l2, d2 = _parts(p, v2, force, _line_accel(p, table, segment, s + 0.5 * h * v),
                            t + 0.5 * h)
    v3 = max(v + 0.5 * h * a2, 0.0)
    a3, r3, l3, d3 = _parts(p, v3, force, _line_accel(p, table, segment, s + 0.5 * h * v2),
                            t + 0.5 * h)
    v4 = max(v + h * a3, 0.0)
    a4, r4, l4, d4 = _parts(p, v4, force, _line_accel(p, table, segment, s + h * v3), t + h)
    w = h / 6.0
    s_new = s + w * (v + 2.0 * v2 + 2.0 * v3 + v4)
    v_new = max(v + w * (a1 + 2.0 * a2 + 2.0 * a3 + a4), 0.0)
    return (s_new, v_new, force * w * (v + 2.0 * v2 + 2.0 * v3 + v4),
            w * (r1 * v + 2.0 * r2 * v2 + 2.0 * r3 * v3 + r4 * v4),
            w * (l1 * v + 2.0 * l2 * v2 + 2.0 * l3 * v3 + l4 * v4),
            w * (d1 * v + 2.0 * d2 * v2 + 2.0 * d3 * v3 + d4 * v4))


@kernel
def step_kernel(p, table, work, s, v, time_s, duration_s, max_substep_s, force):
    """(s, v) after ``duration_s`` with the force held from ``time_s``, in RK4 steps of at most
    ``max_substep_s`` split at segment boundaries; adds the work integrals to ``work``."""
    t, end = time_s, time_s + duration_s
    substeps = max(1, math.ceil(duration_s / max_substep_s - 1e-9))
    h_max = duration_s / substeps
    while end - t > 1e-12 * max(1.0, abs(end)):
        h = h_max if end - t > h_max * (1.0 - 1e-9) else end - t
        segment = segment_index(table, s, False)
        s1, v1, w0, w1, w2, w3 = _rk4(p, table, s, v, t, h, force, segment)
        after = segment_index(table, s1, False)
        if after != segment:  # the train reaches the next segment within this step
            boundary = boundary_between(table, segment, after)
            h = crossing_time(s, v, s1, v1, h, boundary)
            s1, v1, w0, w1, w2, w3 = _rk4(p, table, s, v, t, h, force, segment)
            s1 = boundary  # on it, within the step's error: continue in the next segment
        s, v, t = s1, v1, t + h
        work[0] += w0
        work[1] += w1
        work[2] += w2
        work[3] += w3
    return s, v


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
        self.work = np.zeros(4)
        self.parameters = np.zeros(PARAMETERS)
        self._parameters_of: Surroundings | None = None  # the surroundings ``parameters`` holds
        # Compile the kernels, or load them from numba's cache, now rather than in a lockstep
        # step (from a tenth of a second to seconds on first use in a process).
        self.step(self.initial_state(0.0), self.max_substep_s, (0.0,) * len(self.actuator_names))
        self.outputs(self.initial_state(0.0), (0.0,) * len(self.actuator_names))
        self.work[:] = 0.0

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray:
        return np.array([position_m, speed_mps], dtype=float)

    def lead_speed(self, state) -> float:
        return float(state[1])

    def _parameters(self, env: Surroundings, time_s: float, duration_s: float) -> np.ndarray:
        p = self.parameters
        if env is not self._parameters_of:
            mode = env.mode
            p[:ENV] = (mode.mass_kg, mode.davis.a_n, mode.davis.b_n_s_per_m,
                       mode.davis.c_n_s2_per_m2,
                       mode.grade_sine * self.gravity + mode.curve_accel_mps2, self.gravity)
            env.write_parameters(p, ENV)
            self._parameters_of = env
        if env.disturbance is not None and env.held_disturbance:  # constant within the step
            p[ENV + DISTURBANCE_VALUE] = env.disturbance.force(time_s + 0.5 * duration_s)
        return p

    def kernel_inputs(self, env: Surroundings, duration_s: float) -> tuple:
        """What ``periods.run_point_mass_periods`` reads of the model under ``env`` (without a
        held disturbance: then the parameters do not change with time)."""
        return self._parameters(env, 0.0, 0.0), self.segments.table, self.work, \
            self.max_substep_s

    def acceleration(self, position: float, speed: float, force: float, time_s: float = 0.0,
                     env: Surroundings | None = None) -> float:
        p = self._parameters(env or self.nominal, time_s, 0.0)
        return acceleration_kernel(p, self.segments.table, float(position), float(speed),
                                   float(force), float(time_s))

    def step(self, state, duration_s: float, forces: Sequence[float], time_s: float = 0.0,
             env: Surroundings | None = None) -> np.ndarray:
        """State after ``duration_s`` with the forces held (zero-order hold) from ``time_s``."""
        p = self._parameters(env or self.nominal, time_s, duration_s)
        s, v = step_kernel(p, self.segments.table, self.work, float(state[0]),
                           float(state[1]), float(time_s), float(duration_s),
                           self.max_substep_s, math.fsum(forces))
        return np.array((s, v))

    def outputs(self, state, forces: Sequence[float], time_s: float = 0.0,
                env: Surroundings | None = None):
        s, v = float(state[0]), float(state[1])
        force = math.fsum(forces)
        return (s,), (v,), (self.acceleration(s, v, force, time_s, env),), (force,)
