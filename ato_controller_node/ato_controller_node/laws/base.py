"""The one interface every control law implements, and what a law is told about the train.

A law sees sampled measurements and the reference at a fixed period ``dt``; it keeps its own
state (integrators, parameter estimates) and returns the total traction/brake force it wants.
Saturation to the actuator limits is applied by the host, which tells the law what was actually
commanded so that its adaptation or integrator does not wind up.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar, Mapping

from ato_common.trains import DavisResistance, TractionCharacteristic, TrainParameters
from ato_common.types import ReferencePoint


@dataclass(frozen=True)
class TrainKnowledge:
    """What the on-board software knows of its train: nominal values, not the truth."""

    nominal_mass_kg: float
    nominal_davis: DavisResistance
    traction: TractionCharacteristic
    actuator_names: tuple[str, ...]

    @classmethod
    def of(cls, train: TrainParameters) -> 'TrainKnowledge':
        return cls(train.mass_kg, train.davis_nominal, train.traction, train.actuator_names)


@dataclass(frozen=True)
class Measurement:
    """Sampled lead-car measurements used by single-mass laws (SI)."""

    time_s: float
    position: float
    speed: float


@dataclass(frozen=True)
class LawOutput:
    force_n: float
    estimates: Mapping[str, float] = field(default_factory=dict)


def setting(default: float, *, minimum: float, maximum: float, units: str, description: str):
    """A law gain: its default (the paper's value where it has one), range, units and meaning.
    The controller node declares one ROS parameter per setting from this metadata."""
    return field(default=default, metadata={'minimum': minimum, 'maximum': maximum,
                                            'units': units, 'description': description})


def setting_fields(settings_type) -> list:
    return [f for f in fields(settings_type) if 'minimum' in f.metadata]


def validated_settings(settings_type, values: Mapping[str, Any], base=None):
    """New settings from ``values``; ValueError naming the field if one is out of range."""
    base = base if base is not None else settings_type()
    changes = {}
    for f in setting_fields(settings_type):
        if f.name not in values:
            continue
        value = values[f.name]
        if isinstance(f.default, bool):
            if not isinstance(value, bool):
                raise ValueError(f'{f.name} must be true or false, got {value!r}')
        else:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f'{f.name} must be a number, got {value!r}')
            value = float(value)
            if not f.metadata['minimum'] <= value <= f.metadata['maximum']:
                raise ValueError(f"{f.name} must be within [{f.metadata['minimum']:g}, "
                                 f"{f.metadata['maximum']:g}] {f.metadata['units']}, got {value:g}")
        changes[f.name] = value
    return replace(base, **changes)


class ControlLaw(ABC):
    """Base class of every law. Subclasses set ``name``, ``Settings`` and implement
    ``reset`` and ``step``."""

    name: ClassVar[str]
    summary: ClassVar[str]
    Settings: ClassVar[type]
    #: number of actuators the law drives; None: one total force, shared by the host
    actuators: ClassVar[int | None] = None

    def __init__(self, train: TrainKnowledge, dt: float, settings=None):
        self.train = train
        self.dt = dt
        self.settings = settings if settings is not None else self.Settings()

    def fits(self, train: TrainKnowledge) -> str | None:
        """None if the law can drive this train, else the reason it cannot."""
        if self.actuators is not None and self.actuators != len(train.actuator_names):
            return (f'{self.name} drives {self.actuators} actuators but the train has '
                    f'{len(train.actuator_names)} ({", ".join(train.actuator_names)})')
        return None

    def update_settings(self, settings) -> None:
        self.settings = settings

    @abstractmethod
    def reset(self, measurement: Measurement, reference: ReferencePoint,
              last_force_n: float | None) -> None:
        """Start (or take over) control from this state; ``last_force_n`` is what was
        commanded last (None before the first command), so a law with an integrator can start
        from it (bumpless transfer)."""

    @abstractmethod
    def step(self, measurement: Measurement, reference: ReferencePoint) -> LawOutput:
        """The total force wanted now (N); what was actually commanded comes back through
        ``after_saturation`` in the same period."""

    def after_saturation(self, wanted_n: float, commanded_n: float) -> None:
        """Told what was actually commanded (after limits), once per step, after ``step``."""
