"""The one interface every control law implements, and what a law is told about the train.

A law sees sampled measurements and the reference at a fixed period ``dt``; it keeps its own
state (integrators, parameter estimates) and returns the force it wants: one total force that
the host shares equally over the actuators, or one force per actuator. Saturation to the
actuator limits is applied by the host, which tells the law what was actually commanded so that
its adaptation or integrator does not wind up.

A law declares its loop about cruise (``feedback_gains``: its error feedback linearised with its
adaptation frozen at the nominal estimates), which the host's ATO envelope (anti-windup of the
position and speed errors, the same for every law) and the loop margins
(``ato_campaigns.margins``) use.

A law declares what it needs of the running plant: the measured quantities (``requires``), the
number of cars whose measurements it uses (``cars``) and the number of actuators it drives
(``actuators``); the host refuses a law that does not fit, with the reason.

What a law is told about the train is a :class:`~ato_common.knowledge.TrainKnowledge` (nominal
values and the known modes, never the plant's truth), built from a scenario only by
:func:`ato_common.knowledge.knowledge_of`; it is re-exported here.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar, Mapping

from ato_common.knowledge import TrainKnowledge  # re-exported: what a law is told
from ato_common.types import ReferencePoint, TrainState

#: the measured quantities a law may require (see ``ControlLaw.requires``)
MEASURED_QUANTITIES = ('position', 'speed', 'acceleration', 'car_positions', 'car_speeds')


@dataclass(frozen=True)
class Measurement:
    """One sample of what the sensors measured (SI). ``position``, ``speed`` and
    ``acceleration`` are the lead car's; NaN means not measured (a failed or dropped-out
    sensor). ``car_positions``/``car_speeds`` hold every car, lead first (one entry for a
    single-mass plant). ``mode`` is the index of the known operating mode of a piecewise-constant
    plant (the indicators chi_i of Mao et al. 2017), 0 when the plant has no modes."""

    time_s: float
    position: float
    speed: float
    acceleration: float = math.nan
    car_positions: tuple[float, ...] = ()
    car_speeds: tuple[float, ...] = ()
    mode: int = 0

    @classmethod
    def from_state(cls, time_s: float, state: TrainState, mode: int = 0) -> 'Measurement':
        return cls(time_s, state.positions[0], state.speeds[0], state.accelerations[0],
                   tuple(state.positions), tuple(state.speeds), mode)

    @property
    def car_count(self) -> int:
        return max(1, len(self.car_positions))

    def values_of(self, quantity: str) -> tuple[float, ...]:
        value = getattr(self, quantity)
        return value if isinstance(value, tuple) else (value,)


@dataclass(frozen=True)
class LawOutput:
    """The total force wanted (N) and, from a law that drives each actuator itself
    (``ControlLaw.actuators`` set), one force per actuator summing to it. A law that limits
    its per-actuator forces itself (sharing a force over actuators with limits) gives the
    total it wanted before that in ``unlimited_force_n``: the host counts the step as
    saturated, tells the law and winds its envelope from it, not from the limited forces."""

    force_n: float
    estimates: Mapping[str, float] = field(default_factory=dict)
    forces_n: tuple[float, ...] | None = None
    unlimited_force_n: float | None = None


@dataclass(frozen=True)
class FeedbackGains:
    """A law's loop about cruise: its feedback linearised with its adaptation frozen at the
    nominal estimates, as specific force (per kg of the nominal mass) per unit of the errors of
    the reference over the measurement, F / M_nom = kp e_x + kd e_v + ki int e_x (e_x = x* - x,
    e_v = v* - v), with the feedforward left out. ``note`` says how it was linearised."""

    position_per_s2: float             # kp, 1/s^2
    speed_per_s: float                 # kd, 1/s
    integral_per_s3: float = 0.0       # ki, 1/s^3
    note: str = ''


def setting(default: float, *, minimum: float, maximum: float, units: str, description: str,
            admissible: tuple[float, float] | None = None, scale: str = 'linear'):
    """A law gain: its default (the paper's value where it has one), range, units and meaning.
    The controller node declares one ROS parameter per setting from this metadata.
    ``admissible``: the range the law's stability conditions allow for it (the paper's, with the
    sampled loop's where the paper has none), within [minimum, maximum]: the settings the tuning
    (``ato_campaigns.tuning``) searches, ``scale`` 'log' or 'linear' over it; None: not
    tuned (a switch, a structural choice or a prior)."""
    if admissible is not None and not minimum <= admissible[0] < admissible[1] <= maximum:
        raise ValueError(f'admissible range {admissible} outside [{minimum}, {maximum}]')
    if scale not in ('linear', 'log') or (scale == 'log' and admissible is not None
                                           and not admissible[0] * admissible[1] > 0.0):
        raise ValueError(f"scale must be 'linear' or 'log' (log of the magnitude over a range "
                         f'of one sign), got {scale!r} over {admissible}')
    return field(default=default, metadata={'minimum': minimum, 'maximum': maximum,
                                            'units': units, 'description': description,
                                            'admissible': admissible, 'scale': scale})


def setting_fields(settings_type) -> list:
    return [f for f in fields(settings_type) if 'minimum' in f.metadata]


def admissible_fields(settings_type) -> list:
    """The settings of a law the tuning searches (those with an ``admissible`` range)."""
    return [f for f in setting_fields(settings_type) if f.metadata.get('admissible')]


def validated_settings(settings_type, values: Mapping[str, Any], base=None):
    """New settings from ``values``; ValueError naming the field if one is out of range or is
    not a setting of ``settings_type`` at all."""
    base = base if base is not None else settings_type()
    known = setting_fields(settings_type)
    unknown = sorted(set(values) - {f.name for f in known})
    if unknown:
        raise ValueError(f"{', '.join(unknown)}: not a setting ({settings_type.__name__}); "
                         f"valid: {', '.join(f.name for f in known)}")
    changes = {}
    for f in known:
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
    #: measured quantities the law uses (of MEASURED_QUANTITIES); a NaN in one of them makes
    #: the host hold the last command instead of stepping the law
    requires: ClassVar[tuple[str, ...]] = ('position', 'speed')
    #: number of cars whose measurements the law uses; None: the lead car only
    cars: ClassVar[int | None] = None
    #: the stem of the law's paper note, docs/papers/<paper>.md; None for a law with no paper
    paper: ClassVar[str | None] = None

    def __init__(self, train: TrainKnowledge, dt: float, settings=None):
        self.train = train
        self.dt = dt
        self.settings = settings if settings is not None else self.Settings()

    def fits(self, train: TrainKnowledge, measured_cars: int | None = None) -> str | None:
        """None if the law can drive this train (and the running plant, which measures
        ``measured_cars`` cars; None before its first measurement), else the reason."""
        unknown = [q for q in self.requires if q not in MEASURED_QUANTITIES]
        if unknown:
            return f'{self.name} requires unknown measurements {unknown}; valid: ' \
                   f'{", ".join(MEASURED_QUANTITIES)}'
        if self.actuators is not None and self.actuators != len(train.actuator_names):
            return (f'{self.name} drives {self.actuators} actuators but the train has '
                    f'{len(train.actuator_names)} ({", ".join(train.actuator_names)})')
        if self.cars is not None:
            if len(train.cars) != self.cars:
                return (f'{self.name} needs a {self.cars}-car train model but the train has '
                        f'{len(train.cars) or "no"} per-car data')
            if measured_cars is not None and measured_cars != self.cars:
                return (f'{self.name} needs the measurements of {self.cars} cars but the plant '
                        f'publishes {measured_cars} (run the plant with model:=multi_car)')
        return None

    def update_settings(self, settings) -> None:
        self.settings = settings

    @classmethod
    def inadmissible(cls, settings) -> str | None:
        """Why ``settings`` lie outside what the law's stability conditions allow jointly
        (a condition coupling several settings, e.g. Routh-Hurwitz), None if they do not.
        Each setting's own range is its ``admissible`` metadata."""
        return None

    @abstractmethod
    def feedback_gains(self) -> FeedbackGains:
        """The law's error feedback about cruise with its adaptation frozen at the nominal
        estimates (:class:`FeedbackGains`): the host's envelope scales its reference shift by
        it, ``ato_campaigns.margins`` builds the loop from it."""

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

    def after_saturation(self, wanted_n: float, commanded_n: float,  # noqa: B027 (optional hook)
                         commanded_forces_n: tuple[float, ...] = (),
                         applied_n: float | None = None) -> None:
        """Told what was actually commanded (after limits), once per step, after ``step``:
        the total and the force of each actuator, both net of the host's bumpless offset (so
        that wanted and commanded compare for anti-windup), and ``applied_n``, the total the
        actuators are really asked for (offset included: what a law's plant model must use)."""
