"""Plant models, one module each, behind one small interface (see :class:`PlantModel`).

A model owns the physics only: its state vector, the derivative for given actuator forces, an
integrator step with zero-order hold of the forces, and the per-car outputs. Actuator limits,
sensors and time keeping live in :mod:`train_plant_node.simulation`.
"""

from __future__ import annotations

from typing import Callable, Protocol, Sequence

import numpy as np

from ato_common.line import Line
from ato_common.trains import TrainParameters


class PlantModel(Protocol):
    @property
    def car_names(self) -> tuple[str, ...]: ...

    @property
    def actuator_names(self) -> tuple[str, ...]: ...

    @property
    def max_substep_s(self) -> float:
        """The longest integration step, s."""

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray: ...

    def lead_speed(self, state) -> float:
        """The lead car's speed in a state, m/s."""

    def step(self, state: np.ndarray, duration_s: float, forces: Sequence[float],
             time_s: float = 0.0, env=None) -> np.ndarray:
        """State after ``duration_s`` with the actuator forces held constant."""

    def outputs(self, state: np.ndarray, forces: Sequence[float], time_s: float = 0.0,
                env=None) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...],
                                   tuple[float, ...]]:
        """(positions, speeds, accelerations, applied forces) per car."""

    def kernel_inputs(self, env, duration_s: float) -> tuple:
        """What the model's compiled periods read (``periods.py``)."""


def _point_mass(train: TrainParameters, line: Line, **options) -> PlantModel:
    from train_plant_node.models.point_mass import PointMassModel
    return PointMassModel(train, line, **options)


def _multi_car(train: TrainParameters, line: Line, **options) -> PlantModel:
    from train_plant_node.models.multi_car import MultiCarModel
    return MultiCarModel(train, line, **options)


MODELS: dict[str, Callable[..., PlantModel]] = {
    'point_mass': _point_mass,
    'multi_car': _multi_car,
}


def make_model(name: str, train: TrainParameters, line: Line, **options) -> PlantModel:
    try:
        factory = MODELS[name]
    except KeyError:
        valid = ', '.join(sorted(MODELS))
        raise KeyError(f"unknown plant model '{name}'; valid: {valid}") from None
    return factory(train, line, **options)
