"""The line between what the plant simulates (the truth) and what the controller may know.

The plant (``train_plant_node``) simulates the truth from the whole scenario: the train's
simulated running resistance, the line's grades, curves and tunnels, the ``plant:`` section
(resistance variation, modes, abrupt changes, disturbance, actuator lag and rate limits,
failures, sensor noise and faults) and the failures injected at run time. The on-board software
(``ato_controller_node``: the node, its host and every law) knows only a
:class:`TrainKnowledge`: the nominal train, the line's gradient profile as on-board track data
(:class:`KnownGradient`; hidden, a flat line, when a campaign says so) and, for the laws that
assume them known, the operating modes and their schedule. :func:`knowledge_of` is the only
bridge from a scenario to that knowledge; the controller side never reads ``scenario.plant``.

The gradient is where truth and knowledge can part on the line: the plant always runs the
line's grades (``scenario.line.grade_sine``); the knowledge holds a copy of them, or, with
``hide_gradient``, none (every known grade 0), while the plant's grade force is unchanged.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Iterable

from ato_common import units
from ato_common.mode_schedule import MODE_SWITCHES, ModeSchedule
from ato_common.trains import (
    CarParameters,
    Coupler,
    DavisResistance,
    TractionCharacteristic,
    TrainParameters,
)

if TYPE_CHECKING:
    from ato_common.scenario import Scenario


@dataclass(frozen=True)
class KnownMode:
    """One operating mode of a piecewise-constant plant as the on-board software knows it
    (Mao et al. 2017 eqs 10-12: mass, whole-train Davis resistance in N, extra grade as the sine
    of the angle, curve term 0.004 D in m/s^2), active from ``start`` (s or m, by the
    knowledge's ``mode_switch``; None: not scheduled, the caller gives the mode index)."""

    mass_kg: float
    davis: DavisResistance
    grade_sine: float = 0.0
    curve_accel_mps2: float = 0.0
    name: str = ''
    start: float | None = None

    @classmethod
    def of(cls, mode, index: int = 0) -> KnownMode:
        """A copy of a mode record (a scenario's ``plant.modes`` entry, or any record with
        mass_kg, davis, grade_sine, curve_accel_mps2 and optionally name and start): the
        knowledge holds no object of the plant's."""
        return cls(mode.mass_kg, mode.davis, mode.grade_sine, mode.curve_accel_mps2,
                   getattr(mode, 'name', f'mode {index + 1}'), getattr(mode, 'start', None))


@dataclass(frozen=True)
class KnownGradient:
    """The gradient profile as the on-board software knows it (track data: ETCS sends it to the
    train as the gradient profile, UNISIG SUBSET-026 packet 21): the sine of the grade, positive
    uphill, from each start (m) to the next. No starts: the profile is not known, the line is
    taken as flat (``hidden``: a campaign hid it, :func:`knowledge_of`)."""

    starts_m: tuple[float, ...] = ()
    sines: tuple[float, ...] = ()
    hidden: bool = False

    def __post_init__(self) -> None:
        if len(self.starts_m) != len(self.sines):
            raise ValueError(f'a gradient profile needs one sine per start, got '
                             f'{len(self.starts_m)} starts and {len(self.sines)} sines')

    @classmethod
    def of(cls, grade_sine) -> KnownGradient:
        """A copy of a line's gradient profile (``Line.grade_sine``: starts and values)."""
        return cls(tuple(map(float, grade_sine.starts)), tuple(map(float, grade_sine.values)))

    def sine_at(self, position_m: float) -> float:
        """The known sine of the grade at a position (0 where nothing is known)."""
        if not self.starts_m:
            return 0.0
        return self.sines[max(bisect_right(self.starts_m, position_m) - 1, 0)]

    def mean_sine(self, front_m: float, length_m: float) -> float:
        """The mean known sine of the grade under a train of ``length_m`` whose front is at
        ``front_m`` (over [front - length, front], exactly: the profile is piecewise
        constant); the sine at the front for a length of 0."""
        if not self.starts_m or length_m <= 0.0:
            return self.sine_at(front_m)
        starts, sines = self.starts_m, self.sines
        rear = front_m - length_m
        first = max(bisect_right(starts, rear) - 1, 0)
        last = max(bisect_right(starts, front_m) - 1, 0)
        if first == last:
            return sines[first]
        total, lower = 0.0, rear
        for i in range(first, last):
            total += sines[i] * (starts[i + 1] - lower)
            lower = starts[i + 1]
        return (total + sines[last] * (front_m - lower)) / length_m


#: the knowledge of a line whose gradient profile the controller is not given
HIDDEN_GRADIENT = KnownGradient(hidden=True)


@dataclass(frozen=True)
class TrainKnowledge:
    """What the on-board software knows of its train: nominal values, not the truth.

    The nominal train: mass, Davis resistance (the on-board prior ``davis_nominal``, not the
    simulated ``davis``), traction characteristic, actuator names, length, and for a multi-car
    train the nominal per-car data, couplers and car length. The line's gradient profile as
    track data (``gradient``, :meth:`grade_force_n`; empty when hidden). For the laws that
    assume them known (Mao et al. 2017's mode indicators chi_i): the operating modes and the
    schedule that says which one applies, by time or by region (:meth:`known_mode`). No
    failure, disturbance, resistance variation, sensor fault or noise, actuator lag: those are
    the plant's truth.
    """

    nominal_mass_kg: float
    nominal_davis: DavisResistance
    traction: TractionCharacteristic
    actuator_names: tuple[str, ...]
    cars: tuple[CarParameters, ...] = ()    # nominal per-car data of a multi-car train
    couplers: tuple[Coupler, ...] = ()
    car_length_m: float = 25.0  # rest spacing of consecutive cars (coupler extension = 0)
    #: known modes of a piecewise-constant plant, indexed by ``Measurement.mode``
    modes: tuple[KnownMode, ...] = ()
    #: the modes start at a time ('time') or a position ('position'); see ModeSchedule
    mode_switch: str = 'time'
    #: the line's gradient profile as on-board track data (empty: not known, a flat line)
    gradient: KnownGradient = KnownGradient()
    length_m: float = 200.0     # the train's length (the grade force acts along it)

    def __post_init__(self) -> None:
        if self.mode_switch not in MODE_SWITCHES:
            raise ValueError(f"mode switch '{self.mode_switch}' is not valid; valid: "
                             f"{', '.join(MODE_SWITCHES)}")

    @classmethod
    def of(cls, train: TrainParameters, modes: Iterable = (),
           mode_switch: str = 'time', gradient: KnownGradient = KnownGradient()
           ) -> TrainKnowledge:
        """The knowledge of a nominal ``train`` and, optionally, its known ``modes`` (mode
        records, copied: see :meth:`KnownMode.of`) switching by ``mode_switch`` and the known
        ``gradient`` profile. From a scenario, use :func:`knowledge_of`."""
        return cls(train.mass_kg, train.davis_nominal, train.traction, train.actuator_names,
                   train.cars, train.couplers, train.car_length_m,
                   tuple(KnownMode.of(m, i) for i, m in enumerate(modes)), mode_switch,
                   gradient, train.length_m)

    def grade_force_n(self, positions_m: tuple[float, ...] | float) -> float:
        """The known grade force on the nominal train, N (positive uphill: it opposes the
        motion): M g times the mean sine of the grade under the train (its front at the
        measured position, its mass spread over its length, so the force changes smoothly as
        the train runs over a change of grade), or, given one position per car of a multi-car
        train, the sum of each car's nominal mass times g sin(grade) at its position. 0
        everywhere when the gradient profile is not known."""
        gradient = self.gradient
        if not gradient.starts_m:
            return 0.0
        g = units.STANDARD_GRAVITY
        if isinstance(positions_m, tuple):
            if self.cars and len(positions_m) == len(self.cars):
                return g * sum(car.mass_kg * gradient.sine_at(x)
                               for car, x in zip(self.cars, positions_m))
            positions_m = positions_m[0]
        return g * self.nominal_mass_kg * gradient.mean_sine(positions_m, self.length_m)

    @cached_property
    def mode_schedule(self) -> ModeSchedule:
        """The schedule of the known modes: the same lookup as the plant's. ValueError if the
        modes have no start (records given without one: the caller gives the mode index)."""
        starts = tuple(m.start for m in self.modes if m.start is not None)
        if len(starts) != len(self.modes):
            raise ValueError('the known modes have no start: no schedule to look the mode up')
        return ModeSchedule(self.mode_switch, starts)

    def known_mode(self, time_s: float, measured_position_m: float, previous: int) -> int:
        """The mode the on-board software takes as active from its measurements (run time and
        the lead car's measured position): the scheduled mode, or ``previous`` while modes
        switch by position and the position is not measured; 0 without modes."""
        return self.mode_schedule.known(time_s, measured_position_m, previous)

    def actuator_limits_at(self, speed: float) -> tuple[float, float]:
        """(lowest, highest) force of one actuator: an equal share of the train's limits."""
        lowest, highest = self.traction.limits_at(speed)
        n = len(self.actuator_names)
        return lowest / n, highest / n


def knowledge_of(scenario: Scenario, *, hide_gradient: bool = False) -> TrainKnowledge:
    """What the on-board software knows of a scenario: the only bridge from a scenario to the
    controller's knowledge (the controller node, the offline loop, compare and run_scenario all
    build it here).

    Takes the nominal train (``scenario.train``: mass, ``davis_nominal``, traction
    characteristic, actuator names, per-car data, couplers, car length), the line's gradient
    profile (``scenario.line.grade_sine``, copied: on-board track data) unless
    ``hide_gradient`` (then :data:`HIDDEN_GRADIENT`: no profile, every known grade 0, while the
    plant still runs the line's grades) and, copied out of ``scenario.plant``, the known
    operating modes (``plant.modes``) with their schedule (``plant.mode_switch``: by time or by
    region), which Mao et al. 2017 assume known on board.

    Leaves out the truth that only the plant simulates: the train's simulated running
    resistance (``train.davis``), ``plant.resistance_variation``, ``plant.abrupt_changes``,
    ``plant.disturbance``, ``plant.actuators`` (lag, rate limit), ``plant.failures`` and the
    failures injected at run time, ``plant.sensors`` (noise, bias, quantisation, dropouts,
    failures); the line's curves and tunnels; and the speed limits, stations, the planning
    limits and the run settings, which reach the controller as the reference and its
    parameters, not as knowledge of the train.
    """
    gradient = HIDDEN_GRADIENT if hide_gradient else KnownGradient.of(scenario.line.grade_sine)
    return TrainKnowledge.of(scenario.train, scenario.plant.modes, scenario.plant.mode_switch,
                             gradient)
