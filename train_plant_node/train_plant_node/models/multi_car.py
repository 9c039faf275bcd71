"""Multi-car train (Mao, Tao, Jiang & Yan eqs 1-7): n cars joined by spring-damper couplers,
traction on the powered cars, resistance a_p + b_p v_p on every car, the aerodynamic c v^2 on
the lead car, and the line force (grade, curve, tunnel) of each car at its own position:

    M_p v_p' = F_p - M_p (a_p + b_p v_p + c_p v_p |v_p|) - M_p g_line(z_p)
               - k_p (y_p - y_p+1) - d_p (v_p - v_p+1) + k_p-1 (y_p-1 - y_p) + d_p-1 (v_p-1 - v_p)

with y_p = z_p + (p - 1) L the position of car p shifted by the rest spacing, so that a coupler's
extension is y_p - y_p+1. The couplers (6e8-8e8 N/m on ~45 t cars) ring at tens of Hz with about
1 % damping: the linear part x' = A x + B F is integrated exactly with its matrix exponential,
and the rest (constant and aerodynamic resistance, line forces) with the second-order
exponential Runge-Kutta scheme ETD2RK (Cox & Matthews 2002), whose matrices come from one
augmented matrix exponential (Van Loan 1978) per step length, cached.

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
from ato_common.trains import TrainParameters

STANDSTILL_SPEED_MPS = 0.01


class MultiCarModel:
    def __init__(self, train: TrainParameters, line: Line, gravity: float = units.STANDARD_GRAVITY,
                 max_substep_s: float = 0.1):
        if len(train.cars) < 2 or len(train.couplers) != len(train.cars) - 1:
            raise ValueError(f"train '{train.name}' has no multi-car description "
                             f'({len(train.cars)} cars, {len(train.couplers)} couplers)')
        self.train, self.line, self.gravity = train, line, gravity
        self.max_substep_s = max_substep_s
        cars = train.cars
        n = self.n = len(cars)
        self.car_names = tuple(c.name for c in cars)
        self.actuator_names = tuple(c.name for c in cars if c.powered)
        if self.actuator_names != tuple(train.actuator_names):
            raise ValueError(f'actuators {train.actuator_names} are not the powered cars '
                             f'{self.actuator_names}')
        self.masses = np.array([c.mass_kg for c in cars])
        self.a = np.array([c.a_mps2 for c in cars])
        self.c = np.array([c.c_per_m for c in cars])
        self.offsets = np.arange(n) * train.car_length_m
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
        self.A[n:, n:] = -inverse_mass @ damping - np.diag([c.b_per_s for c in cars])
        powered = [i for i, c in enumerate(cars) if c.powered]
        self.B = np.zeros((2 * n, len(powered)))
        for column, i in enumerate(powered):
            self.B[n + i, column] = 1.0 / self.masses[i]
        self._powered = powered
        self._propagators: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def propagators(self, h: float):
        """(Phi, Gamma1, Gamma2 / h) for step h: exp(A h), int_0^h exp(A s) ds and
        int_0^h exp(A s) (h - s) ds / h, from one augmented exponential."""
        cached = self._propagators.get(h)
        if cached is None:
            m = self.A.shape[0]
            augmented = np.zeros((3 * m, 3 * m))
            augmented[:m, :m] = self.A
            augmented[:m, m:2 * m] = np.eye(m)
            augmented[m:2 * m, 2 * m:] = np.eye(m)
            e = expm(augmented * h)
            cached = (e[:m, :m], e[:m, m:2 * m], e[:m, 2 * m:] / h)
            self._propagators[h] = cached
        return cached

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray:
        return np.concatenate([np.full(self.n, position_m), np.full(self.n, speed_mps)])

    def positions(self, state: np.ndarray) -> np.ndarray:
        return state[:self.n] - self.offsets

    def nonlinear(self, state: np.ndarray) -> np.ndarray:
        """The non-linear specific forces (velocity rows), m/s^2."""
        n = self.n
        v = state[n:]
        line = np.array([self.line.line_force_per_kg(float(z), self.gravity)
                         for z in self.positions(state)])
        out = np.zeros(2 * n)
        out[n:] = -self.a * np.tanh(v / STANDSTILL_SPEED_MPS) - self.c * v * np.abs(v) - line
        return out

    def step(self, state: np.ndarray, duration_s: float, forces: Sequence[float]) -> np.ndarray:
        u = self.B @ np.asarray(forces, dtype=float)
        substeps = max(1, math.ceil(duration_s / self.max_substep_s - 1e-9))
        h = duration_s / substeps
        phi, gamma1, gamma2 = self.propagators(h)
        x = state
        for _ in range(substeps):
            n0 = self.nonlinear(x)
            predictor = phi @ x + gamma1 @ (u + n0)
            x = predictor + gamma2 @ (self.nonlinear(predictor) - n0)   # ETD2RK
        return x

    def derivative(self, state: np.ndarray, forces: Sequence[float]) -> np.ndarray:
        return self.A @ state + self.B @ np.asarray(forces, dtype=float) + self.nonlinear(state)

    def outputs(self, state: np.ndarray, forces: Sequence[float]):
        n = self.n
        accelerations = self.derivative(state, forces)[n:]
        applied = [0.0] * n
        for force, i in zip(forces, self._powered):
            applied[i] = float(force)
        return (tuple(float(z) for z in self.positions(state)),
                tuple(float(v) for v in state[n:]),
                tuple(float(a) for a in accelerations), tuple(applied))
