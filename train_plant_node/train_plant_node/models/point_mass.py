"""Single mass point (Luo & Xu eq 3; Tan, Jiang & Chen eqs 1-8; Liu & Li eq 9):

    s' = v
    M v' = F - (a + b v + c v^2) - M g_line(s)

with M the equivalent mass, F the sum of the actuator forces, a + b v + c v^2 the Davis running
resistance and g_line the specific force of grade, curve and tunnel at the train's position.

The train does not roll backwards: at standstill the running resistance acts as static friction
up to ``a`` and the brakes hold it, so the speed is kept at or above zero.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ato_common.line import Line
from ato_common.trains import TrainParameters
from ato_common import units


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
        self._mass = train.mass_kg
        self._a = train.davis.a_n
        self._b = train.davis.b_n_s_per_m
        self._c = train.davis.c_n_s2_per_m2

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray:
        return np.array([position_m, speed_mps], dtype=float)

    def acceleration(self, position: float, speed: float, force: float) -> float:
        line_force = self._mass * self.line.line_force_per_kg(position, self.gravity)
        if speed > 0.0:
            resistance = self._a + self._b * speed + self._c * speed * speed
            return (force - resistance - line_force) / self._mass
        # Standstill: static friction (the constant Davis term) and brakes hold the train.
        driving = force - line_force
        if driving <= self._a:
            return 0.0
        return (driving - self._a) / self._mass

    def step(self, state: np.ndarray, duration_s: float, forces: Sequence[float]) -> np.ndarray:
        force = math.fsum(forces)
        s, v = float(state[0]), float(state[1])
        substeps = max(1, math.ceil(duration_s / self.max_substep_s - 1e-9))
        h = duration_s / substeps
        acc = self.acceleration
        for _ in range(substeps):
            # Classical RK4: the point-mass dynamics are smooth and slow (time constant of the
            # resistance is minutes), so one step per control period is accurate.
            k1v = acc(s, v, force)
            k1s = v
            k2v = acc(s + 0.5 * h * k1s, max(v + 0.5 * h * k1v, 0.0), force)
            k2s = max(v + 0.5 * h * k1v, 0.0)
            k3v = acc(s + 0.5 * h * k2s, max(v + 0.5 * h * k2v, 0.0), force)
            k3s = max(v + 0.5 * h * k2v, 0.0)
            k4v = acc(s + h * k3s, max(v + h * k3v, 0.0), force)
            k4s = max(v + h * k3v, 0.0)
            s += h / 6.0 * (k1s + 2.0 * k2s + 2.0 * k3s + k4s)
            v = max(v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v), 0.0)
        return np.array([s, v])

    def outputs(self, state: np.ndarray, forces: Sequence[float]):
        s, v = float(state[0]), float(state[1])
        force = math.fsum(forces)
        return (s,), (v,), (self.acceleration(s, v, force),), (force,)
