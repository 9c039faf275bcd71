"""Multi-car train (Mao, Tao, Jiang & Yan eqs 1-7): n cars joined by spring-damper couplers,
traction on the powered cars, resistance a_p + b_p v_p on every car, the aerodynamic c v^2 on
the lead car, and the line force (grade, curve, tunnel) of each car at its own position:

    M_p v_p' = F_p - M_p (a_p + b_p v_p + c_p v_p |v_p|) - M_p g_line(z_p)
               - k_p (y_p - y_p+1) - d_p (v_p - v_p+1) + k_p-1 (y_p-1 - y_p) + d_p-1 (v_p-1 - v_p)
               + M_p d(t) / M

with y_p = z_p + (p - 1) L the position of car p shifted by the rest spacing, so that a coupler's
extension is y_p - y_p+1. The disturbance d(t) is shared by the cars in proportion to their mass.
A mode (Mao et al. 2017) scales every car's mass and its a, b, c by the ratio of the mode's
whole-train values to the train's, and adds its grade and curve term to every car.

Numerics: the couplers (5e8-8e8 N/m on ~45 t cars) ring at tens of Hz with about 1 % damping.
The linear part x' = A x + B F (couplers, b_p v_p, forces) is integrated exactly by its matrix
exponential; the rest (constant and aerodynamic resistance, line forces, the time-varying parts,
the disturbance) by the fourth-order exponential Runge-Kutta scheme ETDRK4 of Cox & Matthews
(2002), whose phi-function matrices come from one augmented matrix exponential per step length
and mode (Van Loan 1978; Higham & Al-Mohy), cached. Steps are split where a car crosses a line
segment boundary (see line_segments.py).

The constant resistance a_p is applied as a_p tanh(v_p / 0.01 m/s): a smooth sign, so that the
coupler oscillation around standstill does not make it chatter.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.linalg import expm

from ato_common import units
from ato_common.line import Line
from ato_common.plant_setup import Mode
from ato_common.trains import TrainParameters
from train_plant_node.models.line_segments import LineSegments, crossing_time
from train_plant_node.surroundings import Surroundings, nominal_mode

STANDSTILL_SPEED_MPS = 0.01


def phi_functions(matrix: np.ndarray, order: int = 3) -> list[np.ndarray]:
    """[phi_0 .. phi_order](matrix), phi_0 = exp, phi_k(Z) = int_0^1 e^{(1-s)Z} s^(k-1)/(k-1)! ds,
    from the exponential of one block-companion matrix (Higham & Al-Mohy, Sidje 1998)."""
    m = matrix.shape[0]
    size = m * (order + 1)
    augmented = np.zeros((size, size))
    augmented[:m, :m] = matrix
    for k in range(order):
        augmented[m * k:m * (k + 1), m * (k + 1):m * (k + 2)] = np.eye(m)
    e = expm(augmented)
    return [e[:m, m * k:m * (k + 1)] for k in range(order + 1)]


class _ModeMatrices:
    """Per-mode car parameters and the linear dynamics."""

    def __init__(self, model: 'MultiCarModel', mode: Mode):
        train, cars, n = model.train, model.train.cars, model.n
        d, nominal = mode.davis, train.davis

        def ratio(new: float, old: float) -> float:
            return new / old if old else 0.0
        mass_ratio = mode.mass_kg / train.mass_kg
        self.masses = np.array([c.mass_kg for c in cars]) * mass_ratio
        # Resistance forces per car scale with the whole-train coefficients, then per kg.
        ra = ratio(d.a_n, nominal.a_n)
        rb = ratio(d.b_n_s_per_m, nominal.b_n_s_per_m)
        rc = ratio(d.c_n_s2_per_m2, nominal.c_n_s2_per_m2)
        self.a = [c.a_mps2 * c.mass_kg * ra / m for c, m in zip(cars, self.masses)]
        self.b = [c.b_per_s * c.mass_kg * rb / m for c, m in zip(cars, self.masses)]
        self.c = [c.c_per_m * c.mass_kg * rc / m for c, m in zip(cars, self.masses)]
        if not nominal.a_n and d.a_n:  # the train has none: share the mode's by mass
            self.a = [d.a_n / mode.mass_kg] * n
        if not nominal.b_n_s_per_m and d.b_n_s_per_m:
            self.b = [d.b_n_s_per_m / mode.mass_kg] * n
        if not nominal.c_n_s2_per_m2 and d.c_n_s2_per_m2:
            self.c = [d.c_n_s2_per_m2 / self.masses[0]] + [0.0] * (n - 1)
        self.extra = mode.grade_sine * model.gravity + mode.curve_accel_mps2
        stiffness = np.zeros((n, n))
        damping = np.zeros((n, n))
        for j, coupler in enumerate(train.couplers):
            for matrix, value in ((stiffness, coupler.stiffness_n_per_m),
                                  (damping, coupler.damping_n_s_per_m)):
                matrix[j, j] += value
                matrix[j + 1, j + 1] += value
                matrix[j, j + 1] -= value
                matrix[j + 1, j] -= value
        inverse_mass = np.diag(1.0 / self.masses)
        self.A = np.zeros((2 * n, 2 * n))
        self.A[:n, n:] = np.eye(n)
        self.A[n:, :n] = -inverse_mass @ stiffness
        self.A[n:, n:] = -inverse_mass @ damping - np.diag(self.b)
        self.inverse_mass = 1.0 / self.masses
        self.total_mass = float(np.sum(self.masses))
        self._propagators: dict[float, tuple] = {}

    def propagators(self, h: float, cache: bool = True):
        """ETDRK4 matrices for step h; only the velocity columns of the nonlinear-term maps are
        kept (the non-linear term has no position rows)."""
        found = self._propagators.get(h)
        if found is not None:
            return found
        n = self.A.shape[0] // 2
        # Balance positions against speeds (scale by the highest coupler frequency) so that the
        # exponential of the augmented matrix is computed to full relative accuracy:
        # phi_k(D^-1 A D h) = D^-1 phi_k(A h) D.
        omega = math.sqrt(float(np.max(np.abs(self.A[n:, :n])))) or 1.0
        scale = np.concatenate([np.full(n, 1.0 / omega), np.ones(n)])
        balanced = self.A * scale[None, :] / scale[:, None]

        def unbalanced(phis):
            return [p * scale[:, None] / scale[None, :] for p in phis]
        e_half, phi1_half = unbalanced(phi_functions(balanced * (h / 2), 1))
        e_full, phi1, phi2, phi3 = unbalanced(phi_functions(balanced * h, 3))
        v = slice(n, 2 * n)
        # Cox & Matthews (2002) eq (26): f1 = phi1 - 3 phi2 + 4 phi3, f2 = phi2 - 2 phi3,
        # f3 = -phi2 + 4 phi3 (their h^-2 L^-3 forms, written with phi functions).
        result = (e_half, (h / 2 * phi1_half)[:, v], e_full,
                  (h * (phi1 - 3 * phi2 + 4 * phi3))[:, v], (2 * h * (phi2 - 2 * phi3))[:, v],
                  (h * (4 * phi3 - phi2))[:, v])
        if cache:
            self._propagators[h] = result
        return result


class MultiCarModel:
    def __init__(self, train: TrainParameters, line: Line, gravity: float = units.STANDARD_GRAVITY,
                 max_substep_s: float = 0.1):
        if len(train.cars) < 2 or len(train.couplers) != len(train.cars) - 1:
            raise ValueError(f"train '{train.name}' has no multi-car description "
                             f'({len(train.cars)} cars, {len(train.couplers)} couplers)')
        if not max_substep_s > 0.0:
            raise ValueError(f'max_substep_s must be > 0, got {max_substep_s}')
        self.train, self.line, self.gravity = train, line, gravity
        self.max_substep_s = max_substep_s
        cars = train.cars
        n = self.n = len(cars)
        self.car_names = tuple(c.name for c in cars)
        self.actuator_names = tuple(c.name for c in cars if c.powered)
        if self.actuator_names != tuple(train.actuator_names):
            raise ValueError(f'actuators {train.actuator_names} are not the powered cars '
                             f'{self.actuator_names}')
        self.offsets = np.arange(n) * train.car_length_m
        self._offsets = [float(o) for o in self.offsets]
        self._powered = [i for i, c in enumerate(cars) if c.powered]
        self.segments = LineSegments(line, gravity)
        self.nominal = Surroundings(nominal_mode(train), 0)
        self._modes: dict[int, _ModeMatrices] = {}
        nominal = self.mode_matrices(self.nominal)
        self.A = nominal.A
        self.B = np.zeros((2 * n, len(self._powered)))
        for column, i in enumerate(self._powered):
            self.B[n + i, column] = 1.0 / nominal.masses[i]

    def mode_matrices(self, env: Surroundings) -> _ModeMatrices:
        found = self._modes.get(env.mode_key)
        if found is None or found.mode != env.mode:
            found = _ModeMatrices(self, env.mode)
            found.mode = env.mode
            self._modes[env.mode_key] = found
        return found

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray:
        return np.concatenate([np.full(self.n, position_m), np.full(self.n, speed_mps)])

    def lead_speed(self, state) -> float:
        return float(state[self.n])

    def positions(self, state: np.ndarray) -> np.ndarray:
        return state[:self.n] - self.offsets

    def _nonlinear(self, state, time_s: float, forces: Sequence[float], line_accels,
                   mm: _ModeMatrices, env: Surroundings) -> np.ndarray:
        """Specific forces outside the exact linear part (velocity rows), m/s^2; the actuator
        forces are included here (constant over the step, so phi_1 integrates them exactly)."""
        n = self.n
        fa, fb, fc, fl, dist = env.factors(time_s) if env.time_varying else (
            env.resistance_factor, env.resistance_factor, env.resistance_factor, 1.0, 0.0)
        specific_dist = dist / mm.total_mass
        out = [0.0] * n
        a, b, c, inv = mm.a, mm.b, mm.c, mm.inverse_mass
        extra = mm.extra
        for p in range(n):
            v = float(state[n + p])
            out[p] = (-fa * a[p] * math.tanh(v / STANDSTILL_SPEED_MPS) - (fb - 1.0) * b[p] * v
                      - fc * c[p] * v * abs(v) - fl * line_accels[p] - extra + specific_dist)
        for force, p in zip(forces, self._powered):
            out[p] += force * inv[p]
        return np.array(out)

    def _line_accels(self, indices, env: Surroundings) -> list[float]:
        return [self.segments.accel(i, env.grade_override_sine, 1.0) for i in indices]

    def _segment_indices(self, state) -> list[int]:
        n = self.n
        return [self.segments.index(float(state[p]) - self._offsets[p],
                                    float(state[n + p]) < 0.0) for p in range(n)]

    def _etdrk4(self, x, t: float, h: float, forces, line_accels, mm, env, cache: bool = True):
        """Cox & Matthews (2002) ETDRK4, eqs (26)."""
        e_half, p_half, e_full, f1, f2, f3 = mm.propagators(h, cache)
        nl = self._nonlinear
        n_x = nl(x, t, forces, line_accels, mm, env)
        ex = e_half @ x
        a = ex + p_half @ n_x
        n_a = nl(a, t + h / 2, forces, line_accels, mm, env)
        b = ex + p_half @ n_a
        n_b = nl(b, t + h / 2, forces, line_accels, mm, env)
        c = e_half @ a + p_half @ (2.0 * n_b - n_x)
        n_c = nl(c, t + h, forces, line_accels, mm, env)
        return e_full @ x + f1 @ n_x + f2 @ (n_a + n_b) + f3 @ n_c

    def step(self, state: np.ndarray, duration_s: float, forces: Sequence[float],
             time_s: float = 0.0, env: Surroundings | None = None) -> np.ndarray:
        """State after ``duration_s`` with the forces held (zero-order hold) from ``time_s``."""
        env = env or self.nominal
        mm = self.mode_matrices(env)
        forces = [float(f) for f in forces]
        substeps = max(1, math.ceil(duration_s / self.max_substep_s - 1e-9))
        h_max = duration_s / substeps
        x = np.asarray(state, dtype=float)
        t, end = time_s, time_s + duration_s
        n = self.n
        while end - t > 1e-12 * max(1.0, abs(end)):
            h = h_max if end - t > h_max * (1.0 - 1e-9) else end - t
            cached = h == h_max
            indices = self._segment_indices(x)
            accels = self._line_accels(indices, env)
            x1 = self._etdrk4(x, t, h, forces, accels, mm, env, cached)
            after = self._segment_indices(x1)
            if after != indices:  # a car reaches another segment: stop the step there
                crossings = []
                for p, (i0, i1) in enumerate(zip(indices, after)):
                    if i0 != i1:
                        boundary = self.segments.boundary_between(i0, i1) + self._offsets[p]
                        crossings.append((crossing_time(float(x[p]), float(x[n + p]),
                                                        float(x1[p]), float(x1[n + p]), h,
                                                        boundary), p, boundary))
                h, p, boundary = min(crossings)
                x1 = self._etdrk4(x, t, h, forces, accels, mm, env, cache=False)
                for _ in range(3):  # Newton on the crossing time, with the car's speed
                    miss = float(x1[p]) - boundary
                    if abs(miss) < 1e-8 or x1[n + p] == 0.0:
                        break
                    h = min(max(h - miss / float(x1[n + p]), 0.0), end - t)
                    x1 = self._etdrk4(x, t, h, forces, accels, mm, env, cache=False)
            x, t = x1, t + h
        return x

    def derivative(self, state: np.ndarray, forces: Sequence[float], time_s: float = 0.0,
                   env: Surroundings | None = None) -> np.ndarray:
        """x' at one instant (line forces looked up at the cars' positions)."""
        env = env or self.nominal
        mm = self.mode_matrices(env)
        n = self.n
        indices = self._segment_indices(state)
        out = mm.A @ state
        out[n:] += self._nonlinear(state, time_s, [float(f) for f in forces],
                                   self._line_accels(indices, env), mm, env)
        return out

    def outputs(self, state: np.ndarray, forces: Sequence[float], time_s: float = 0.0,
                env: Surroundings | None = None):
        n = self.n
        accelerations = self.derivative(state, forces, time_s, env)[n:]
        applied = [0.0] * n
        for force, i in zip(forces, self._powered):
            applied[i] = float(force)
        return (tuple(float(z) for z in self.positions(state)),
                tuple(float(v) for v in state[n:]),
                tuple(float(a) for a in accelerations), tuple(applied))
