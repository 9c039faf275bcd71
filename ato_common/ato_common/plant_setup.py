"""The ``plant:`` section of a scenario: what of the train and its surroundings changes during a
run, how the actuators respond and fail, and what the sensors report.

Everything is optional; the default :class:`PlantSetup` is "nothing varies": nominal train, no
disturbance, ideal actuators (within the traction characteristic), perfect sensors. Paper units
are converted here, through :mod:`ato_common.units`. Schema (all keys optional)::

    plant:
      resistance_variation:  # Luo & Xu eq (34): coefficient(t) = nominal (1 + A sin(w t + phi))
        a: {amplitude: 0.3, omega_rad_per_s: 0.1, phase_rad: 0.0}
        b: {amplitude: 0.2, omega_rad_per_s: 0.1}
        c: {amplitude: 0.1, omega_rad_per_s: 0.1}
        line: {amplitude: 0.05, omega_rad_per_s: 0.02}   # Liu & Li l(t) = M g (1 + ...)
      modes:                 # Mao et al. 2017 Section 4.1; from_s (by time) or from_m (region)
        - {name: open air, from_s: 0, davis_kn_kmh: {a: 2.25, b: -1.9e-3, c: 3.2e-4}}
        - {name: tunnel, from_s: 400, davis_kn_kmh: {a: 2.25, b: -1.9e-3, c: 9.2e-4}}
        - {name: slope and curve, from_s: 800, grade_sine: 0.015, curvature: 0.34, ...}
      abrupt_changes:              # Tan et al. 4.3: the grade is 30 per mille for 1000 <= t < 1100
        - {start_s: 1000, end_s: 1100, grade_per_mille: 30}
      disturbance: {kind: fast, amplitude_n: 8900, omega_rad_per_s: 1.0}   # Liu & Li Case 3
      actuators: {time_constant_s: 0.5, dead_time_s: 0.3, rate_limit_n_per_s: 1.0e+5}
      failures:                    # Mao et al. 2017 eqs (13)-(20)
        - {actuator: motor_2, kind: stuck, start_s: 600, end_s: 1000, force_n: 2.0e+5}
      sensors:
        seed: 1
        speed: {noise_std: 0.01, bias: 0.0, quantum: 0.0, dropout_probability: 0.0,
                failed_from_s: 300, failed_cars: [train], scale_error: 0.002}
        position: {bias: 0.3, scale_error: 0.002, reset_positions_m: [13700, 14000]}
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Sequence

import numpy as np

from ato_common import units
from ato_common.mode_schedule import ModeSchedule
from ato_common.trains import DavisResistance, TrainParameters
from ato_common.validation import ConfigError, Fields

# Mao et al. 2017 eq (12) / Tan et al. eq (1): the curve term is 0.004 D in m/s^2.
CURVATURE_ACCEL_PER_D = 0.004


@dataclass(frozen=True)
class Sinusoid:
    """A factor 1 + amplitude sin(omega t + phase) around a nominal value."""

    amplitude: float
    omega_rad_per_s: float
    phase_rad: float = 0.0

    def factor(self, time_s: float) -> float:
        return 1.0 + self.amplitude * math.sin(self.omega_rad_per_s * time_s + self.phase_rad)


@dataclass(frozen=True)
class ResistanceVariation:
    """Luo & Xu eq (34): c0(t), cv(t), ca(t) vary around their nominal values; ``line`` is Liu &
    Li's l(t) = M g (1 + ...) applied to the line's grade, curve and tunnel forces (eq 6)."""

    a: Sinusoid | None = None
    b: Sinusoid | None = None
    c: Sinusoid | None = None
    line: Sinusoid | None = None

    def factors(self, time_s: float) -> tuple[float, float, float, float]:
        a, b, c, line = (1.0 if s is None else s.factor(time_s)
                         for s in (self.a, self.b, self.c, self.line))
        return a, b, c, line


@dataclass(frozen=True)
class Mode:
    """One piecewise-constant mode of Mao et al. 2017 (eqs 10-12): mass, whole-train Davis
    resistance (N), extra grade (sine of the angle, added to the line's) and curve term
    0.004 D (m/s^2), active from ``start`` (s or m, see :attr:`PlantSetup.mode_switch`)."""

    name: str
    start: float
    mass_kg: float
    davis: DavisResistance
    grade_sine: float = 0.0
    curve_accel_mps2: float = 0.0


@dataclass(frozen=True)
class AbruptChange:
    """For start_s <= t < end_s the line's grade is replaced by ``grade_sine`` (if given) and the
    running resistance is multiplied by ``resistance_factor`` (Tan et al. Section 4.3)."""

    start_s: float
    end_s: float
    grade_sine: float | None = None
    resistance_factor: float = 1.0

    def active(self, time_s: float) -> bool:
        return self.start_s <= time_s < self.end_s


DISTURBANCE_KINDS = ('none', 'fast', 'slow', 'random')
RANDOM_BLOCK = 1024


@dataclass(frozen=True)
class Disturbance:
    """External force d(t) in M v' = u - f_w + d (Liu & Li eq 9; +d: docs/papers/liu_li.md).

    none: 0; fast: A sin(w t + phi); slow: -A (1 + sin(w t + phi)) / 2 (mostly resisting; the
    forms recommended for Liu & Li Case 3); random: uniform in [-A, A], a new value every
    ``hold_s``, reproducible from ``seed``.
    """

    kind: str = 'none'
    amplitude_n: float = 0.0
    omega_rad_per_s: float = 1.0
    phase_rad: float = 0.0
    hold_s: float = 1.0
    seed: int = 0
    _values: list = field(default_factory=list, compare=False, repr=False)

    def force(self, time_s: float) -> float:
        if self.kind == 'none':
            return 0.0
        if self.kind == 'fast':
            return self.amplitude_n * math.sin(self.omega_rad_per_s * time_s + self.phase_rad)
        if self.kind == 'slow':
            return -0.5 * self.amplitude_n * (
                1.0 + math.sin(self.omega_rad_per_s * time_s + self.phase_rad))
        k = max(int(time_s // self.hold_s), 0)
        while k >= len(self._values):  # fixed blocks, each seeded by its index: order-independent
            block = len(self._values) // RANDOM_BLOCK
            rng = np.random.default_rng([self.seed, block])
            self._values.extend(rng.uniform(-1.0, 1.0, RANDOM_BLOCK).tolist())
        return self.amplitude_n * float(self._values[k])

    def switch_times(self, start_s: float, end_s: float) -> list[float]:
        """Times in (start_s, end_s) where d(t) jumps (integration steps are split there)."""
        if self.kind != 'random':
            return []
        first = math.floor(start_s / self.hold_s) + 1
        return [k * self.hold_s for k in range(first, math.ceil(end_s / self.hold_s))
                if start_s < k * self.hold_s < end_s]


@dataclass(frozen=True)
class ActuatorSettings:
    """Each actuated unit: dead time (0: none), then first-order lag (0: none), then rate limit
    of the applied force (0: none): the drive responds to what it was asked ``dead_time_s``
    earlier. Force, power and braking limits are the unit's equal share of the train's
    :class:`~ato_common.trains.TractionCharacteristic`."""

    time_constant_s: float = 0.0
    rate_limit_n_per_s: float = 0.0
    dead_time_s: float = 0.0


FAILURE_KINDS = ('stuck', 'stuck_signal', 'loss', 'partial')


@dataclass(frozen=True)
class ActuatorFailure:
    """Mao et al. 2017 eqs (13)-(20): from start_s to end_s the actuator delivers

    stuck:        force_n (F_j = Fbar_j0)
    stuck_signal: force_n + amplitude_n sin(omega t + phase) (F_j = Fbar_j0 + Fbar_j1 f_j1(t))
    loss:         0 (total loss of effectiveness)
    partial:      effectiveness * the healthy traction force (> 0), brake_effectiveness *
                  the healthy braking force (< 0); each share in (0, 1]
    whatever it is commanded; a stuck force is not limited by the traction characteristic.

    A partial loss scales traction and braking separately: a lost traction converter takes its
    share of the traction away while the friction brake still brakes (the brake control makes up
    for the lost electric brake), an isolated friction brake the other way round.
    ``brake_effectiveness`` None: the braking share equals ``effectiveness`` (one share for
    both, as a scenario with ``effectiveness`` alone gives).
    """

    actuator: str
    kind: str
    start_s: float
    end_s: float = math.inf
    force_n: float = 0.0
    amplitude_n: float = 0.0
    omega_rad_per_s: float = 0.0
    phase_rad: float = 0.0
    effectiveness: float = 1.0          # partial: the share of the healthy traction force
    brake_effectiveness: float | None = None  # partial: of the braking force (None: as above)

    @property
    def braking_share(self) -> float:
        """The share of the healthy braking force a partial loss delivers."""
        return self.effectiveness if self.brake_effectiveness is None \
            else self.brake_effectiveness

    def active(self, time_s: float) -> bool:
        return self.start_s <= time_s < self.end_s

    def force(self, time_s: float, healthy_force_n: float) -> float:
        if self.kind == 'stuck':
            return self.force_n
        if self.kind == 'stuck_signal':
            return self.force_n + self.amplitude_n * math.sin(
                self.omega_rad_per_s * time_s + self.phase_rad)
        if self.kind == 'loss':
            return 0.0
        if healthy_force_n < 0.0:
            return self.braking_share * healthy_force_n
        return self.effectiveness * healthy_force_n

    def describe(self) -> str:
        details = {'stuck': f'{self.force_n:g} N',
                   'stuck_signal': f'{self.force_n:g} + {self.amplitude_n:g} sin('
                                   f'{self.omega_rad_per_s:g} t + {self.phase_rad:g}) N',
                   'loss': '0 N', 'partial': (
                       f'{self.effectiveness:g} of the healthy force'
                       if self.braking_share == self.effectiveness else
                       f'{self.effectiveness:g} of the healthy traction, '
                       f'{self.braking_share:g} of the braking force')}
        end = '' if math.isinf(self.end_s) else f' until {self.end_s:g} s'
        return f'{self.actuator} {self.kind} ({details[self.kind]}) from {self.start_s:g} s{end}'


#: the speed from which a speed sensor's ``bias`` acts in full, m/s (30 km/h: SUBSET-041
#: 5.3.1.2's low-speed range, in which it asks +/-2 km/h). Below it the bias shrinks in
#: proportion to the speed (``speed_reading``): an odometer's speed error is a share of the
#: speed (wheel diameter, radar beam angle) plus a resolution error that vanishes with the
#: wheel's pulses, so it never reads a moving train as standing or running backwards.
SPEED_BIAS_FULL_MPS = 30.0 / 3.6
#: the largest speed bias a scenario may give, m/s: below SPEED_BIAS_FULL_MPS times the
#: smallest (1 + scale_error), 0.9, so the reading never changes the speed's sign
SPEED_BIAS_MAX_MPS = 5.0


def speed_reading(sensor: QuantitySensor, speed_mps: float) -> float:
    """What a speed sensor reads of a true speed, before noise: (1 + s) v plus the bias b,
    b v / SPEED_BIAS_FULL_MPS below that speed (module constant's note): the reading has the
    sign of the speed and is 0 only at true standstill."""
    bias = sensor.bias
    if speed_mps == 0.0 or not bias:
        return (1.0 + sensor.scale_error) * speed_mps
    share = min(1.0, abs(speed_mps) / SPEED_BIAS_FULL_MPS)
    return (1.0 + sensor.scale_error) * speed_mps + bias * math.copysign(share, speed_mps)


@dataclass(frozen=True)
class QuantitySensor:
    """One measured quantity of every car: truth + scale error + bias + white noise, then
    quantised; NaN when dropped out (probability per sample) or failed (from failed_from_s to
    failed_until_s on ``failed_cars``, all cars if empty). Units: m, m/s or m/s^2 as the
    quantity.

    ``scale_error`` s is an odometer's relative scale error (a wheel diameter taken as D while
    it is D (1 + s)): a speed reads v (1 + s); a position reads the odometer's last reset
    point r plus (1 + s) times the distance run since, x + s (x - r), where r is the largest of
    the run's initial position and ``reset_positions_m`` (balise groups) at or behind x.

    ``bias``: of a speed, an error that acts in full from SPEED_BIAS_FULL_MPS and in proportion
    to the speed below (``speed_reading``); of a position, the error of the position the train
    starts its mission with, which the first reset point (a balise group) corrects."""

    noise_std: float = 0.0
    bias: float = 0.0
    quantum: float = 0.0
    dropout_probability: float = 0.0
    failed_from_s: float = math.inf
    failed_until_s: float = math.inf
    failed_cars: tuple[str, ...] = ()
    scale_error: float = 0.0
    reset_positions_m: tuple[float, ...] = ()

    @property
    def ideal(self) -> bool:
        return (self.noise_std == 0.0 and self.bias == 0.0 and self.quantum == 0.0
                and self.dropout_probability == 0.0 and math.isinf(self.failed_from_s)
                and self.scale_error == 0.0)

    def failed(self, time_s: float, car: str) -> bool:
        return (self.failed_from_s <= time_s < self.failed_until_s
                and (not self.failed_cars or car in self.failed_cars))


@dataclass(frozen=True)
class SensorSetup:
    position: QuantitySensor = QuantitySensor()
    speed: QuantitySensor = QuantitySensor()
    acceleration: QuantitySensor = QuantitySensor()
    seed: int = 0

    @property
    def ideal(self) -> bool:
        return self.position.ideal and self.speed.ideal and self.acceleration.ideal

    def check_cars(self, car_names: Sequence[str], model_name: str) -> None:
        """ConfigError if a sensor's ``failed_cars`` names a car that the plant model
        ``model_name`` does not have: the scenario accepts the cars of every model ('train' and
        the train's cars), and a name of the other model would fail nothing."""
        for quantity in ('position', 'speed', 'acceleration'):
            for i, car in enumerate(getattr(self, quantity).failed_cars):
                if car not in car_names:
                    raise ConfigError(
                        f"plant.sensors.{quantity}.failed_cars[{i}]: car '{car}' is not a car "
                        f"of the {model_name} model; valid: {', '.join(car_names)}")


@dataclass(frozen=True)
class PlantSetup:
    resistance_variation: ResistanceVariation | None = None
    modes: tuple[Mode, ...] = ()
    mode_switch: str = 'time'          # modes start at a time (from_s) or a position (from_m)
    abrupt_changes: tuple[AbruptChange, ...] = ()
    disturbance: Disturbance = Disturbance()
    actuators: ActuatorSettings = ActuatorSettings()
    failures: tuple[ActuatorFailure, ...] = ()
    sensors: SensorSetup = SensorSetup()

    @cached_property
    def mode_schedule(self) -> ModeSchedule:
        """Which mode applies when (or where): the lookup the on-board knowledge shares
        (:meth:`ato_common.knowledge.TrainKnowledge.known_mode`). Built once: the plant looks
        the mode up every substep."""
        return ModeSchedule(self.mode_switch, tuple(m.start for m in self.modes))

    def mode_index(self, time_s: float, position_m: float) -> int:
        """Index of the active mode (Mao et al. 2017's known indicators chi_i); 0 without modes.
        Region modes need a finite position: a NaN one (not measured) raises ValueError."""
        return self.mode_schedule.index(time_s, position_m)

    def known_mode(self, time_s: float, measured_position_m: float, previous: int) -> int:
        """The mode on-board software takes as active from its measurements: ``mode_index``,
        or ``previous`` while modes switch by position and the position is not measured (the
        controller side asks its knowledge, which shares this lookup)."""
        return self.mode_schedule.known(time_s, measured_position_m, previous)

    def abrupt_change(self, time_s: float) -> AbruptChange | None:
        for change in self.abrupt_changes:
            if change.active(time_s):
                return change
        return None

    def scheduled_times(self) -> list[float]:
        """Every time at which something switches (integration steps are split there)."""
        times = {c.start_s for c in self.abrupt_changes} | {c.end_s for c in self.abrupt_changes}
        times |= {f.start_s for f in self.failures} | {f.end_s for f in self.failures}
        if self.mode_switch == 'time':
            times |= {m.start for m in self.modes}
        for s in (self.sensors.position, self.sensors.speed, self.sensors.acceleration):
            times |= {s.failed_from_s, s.failed_until_s}
        return sorted(t for t in times if math.isfinite(t) and t > 0.0)


# --- parsing ------------------------------------------------------------------------------------

def _sinusoid(f: Fields) -> Sinusoid:
    s = Sinusoid(f.number('amplitude', minimum=-1.0, maximum=1.0),
                 f.number('omega_rad_per_s', minimum=0.0), f.number('phase_rad', 0.0))
    f.reject_unknown()
    return s


def _optional_sinusoid(parent: Fields, key: str) -> Sinusoid | None:
    return _sinusoid(parent.section(key)) if parent.has(key) else None


def _davis(f: Fields, default: DavisResistance) -> DavisResistance:
    """``davis_n: {a, b, c}`` in N, N s/m, N s^2/m^2, or ``davis_kn_kmh: {a, b, c}`` in kN with V
    in km/h (Mao et al. 2017 reading (A)); the default when neither is given."""
    if f.has('davis_n') and f.has('davis_kn_kmh'):
        raise ConfigError(f'{f.where}: give davis_n or davis_kn_kmh, not both')
    for key in ('davis_n', 'davis_kn_kmh'):
        if f.has(key):
            d = f.section(key)
            a, b, c = d.number('a'), d.number('b'), d.number('c')
            d.reject_unknown()
            davis = (DavisResistance(a, b, c) if key == 'davis_n'
                     else DavisResistance.from_kn_kmh(a, b, c))
            if davis.a_n < 0.0 or davis.c_n_s2_per_m2 < 0.0:
                raise ConfigError(f'{d.where}: a and c must be >= 0')
            return davis
    return default


def _grade_sine(f: Fields, default: float | None) -> float | None:
    if f.has('grade_sine') and f.has('grade_per_mille'):
        raise ConfigError(f'{f.where}: give grade_sine or grade_per_mille, not both')
    if f.has('grade_sine'):
        return f.number('grade_sine', minimum=-0.1, maximum=0.1)
    if f.has('grade_per_mille'):
        return units.per_mille_to_sine(f.number('grade_per_mille', minimum=-100.0, maximum=100.0))
    return default


def _modes(f: Fields, train: TrainParameters) -> tuple[tuple[Mode, ...], str]:
    items = f.items('modes')
    if not items:
        return (), 'time'
    switch = 'time' if items[0].has('from_s') else 'position'
    key = 'from_s' if switch == 'time' else 'from_m'
    modes: list[Mode] = []
    for i, item in enumerate(items):
        if not item.has(key):
            raise ConfigError(f"{item.where}: every mode needs {key} (the first mode's switch "
                              'decides: by time or by position)')
        start = item.number(key, minimum=0.0)
        if i == 0 and start != 0.0:
            raise ConfigError(f'{item.where}.{key}: the first mode must start at 0')
        if modes and start <= modes[-1].start:
            raise ConfigError(f'{item.where}.{key}: must increase, got {modes[-1].start:g} '
                              f'then {start:g}')
        mass = item.number('mass_kg', train.mass_kg, minimum=0.0, exclusive_minimum=True)
        modes.append(Mode(
            name=item.text('name', f'mode {i + 1}'), start=start, mass_kg=mass,
            davis=_davis(item, train.davis), grade_sine=_grade_sine(item, 0.0) or 0.0,
            curve_accel_mps2=CURVATURE_ACCEL_PER_D * item.number('curvature', 0.0, minimum=0.0)))
        item.reject_unknown()
    return tuple(modes), switch


def _abrupt_changes(f: Fields) -> tuple[AbruptChange, ...]:
    changes: list[AbruptChange] = []
    for item in f.items('abrupt_changes'):
        start = item.number('start_s', minimum=0.0)
        end = item.number('end_s', minimum=start, exclusive_minimum=True)
        change = AbruptChange(start, end, _grade_sine(item, None),
                              item.number('resistance_factor', 1.0, minimum=0.0, maximum=10.0))
        item.reject_unknown()
        if any(c.start_s < end and start < c.end_s for c in changes):
            raise ConfigError(f'{item.where}: overlaps another abrupt change')
        changes.append(change)
    return tuple(changes)


def _disturbance(f: Fields) -> Disturbance:
    kind = f.text('kind', 'none')
    if kind not in DISTURBANCE_KINDS:
        raise ConfigError(f"{f.where}.kind: '{kind}' is not valid; valid: "
                          f"{', '.join(DISTURBANCE_KINDS)}")
    d = Disturbance(kind, f.number('amplitude_n', 0.0, minimum=0.0),
                    f.number('omega_rad_per_s', 1.0, minimum=0.0),
                    f.number('phase_rad', 0.0),
                    f.number('hold_s', 1.0, minimum=0.0, exclusive_minimum=True),
                    int(f.number('seed', 0.0, minimum=0.0, maximum=2**31 - 1)))
    f.reject_unknown()
    return d


#: the keys of a partial loss: one share for both, or a share of traction and one of braking
PARTIAL_KEYS = ('effectiveness', 'traction_effectiveness', 'brake_effectiveness')


def _partial(item: Fields, actuator: str, start: float, end: float) -> ActuatorFailure:
    """A partial loss: ``effectiveness`` (both shares), or ``traction_effectiveness`` and/or
    ``brake_effectiveness`` (each defaults to ``effectiveness`` if given, else 1); at least one
    of the keys."""
    given = [key for key in PARTIAL_KEYS if item.has(key)]
    if not given:
        raise ConfigError(f"{item.where}: a partial loss needs 'effectiveness' (one share for "
                          "traction and braking) or 'traction_effectiveness' and/or "
                          "'brake_effectiveness'")

    def share(key: str, default: float) -> float:
        return item.number(key, default, minimum=0.0, maximum=1.0, exclusive_minimum=True)

    both = share('effectiveness', 1.0)
    traction, brake = share('traction_effectiveness', both), share('brake_effectiveness', both)
    return ActuatorFailure(actuator, 'partial', start, end, effectiveness=traction,
                           brake_effectiveness=None if brake == traction else brake)


def parse_failures(items: Sequence[Fields], actuator_names: Sequence[str],
                   default_start_s: float | None = None) -> tuple[ActuatorFailure, ...]:
    """Failure records (also what the node accepts at run time, where start_s defaults to now)."""
    failures: list[ActuatorFailure] = []
    for item in items:
        actuator = item.text('actuator')
        if actuator not in actuator_names:
            raise ConfigError(f"{item.where}.actuator: unknown actuator '{actuator}'; valid: "
                              f"{', '.join(actuator_names)}")
        kind = item.text('kind')
        if kind not in FAILURE_KINDS:
            raise ConfigError(f"{item.where}.kind: '{kind}' is not valid; valid: "
                              f"{', '.join(FAILURE_KINDS)}")
        start = item.number('start_s', default_start_s, minimum=0.0)
        end = item.number('end_s', math.inf, minimum=start, exclusive_minimum=True)
        failure = ActuatorFailure(actuator, kind, start, end)
        if kind in ('stuck', 'stuck_signal'):
            failure = ActuatorFailure(actuator, kind, start, end, item.number('force_n'))
        if kind == 'stuck_signal':
            failure = ActuatorFailure(actuator, kind, start, end, failure.force_n,
                                      item.number('amplitude_n'),
                                      item.number('omega_rad_per_s', minimum=0.0),
                                      item.number('phase_rad', 0.0))
        if kind == 'partial':
            failure = _partial(item, actuator, start, end)
        item.reject_unknown()
        for other in failures:
            if other.actuator == actuator and other.start_s < end and start < other.end_s:
                raise ConfigError(f'{item.where}: overlaps another failure of {actuator}')
        failures.append(failure)
    return tuple(failures)


def _quantity_sensor(f: Fields, car_names: Sequence[str]) -> QuantitySensor:
    cars = []
    names = f.raw('failed_cars') or []
    if not isinstance(names, list):
        raise ConfigError(f'{f.where}.failed_cars: must be a list of car names, got {names!r}')
    for i, name in enumerate(names):
        if not isinstance(name, str) or name not in car_names:
            raise ConfigError(f"{f.where}.failed_cars[{i}]: unknown car {name!r}; valid: "
                              f"{', '.join(car_names)}")
        cars.append(name)
    failed_from = f.number('failed_from_s', math.inf, minimum=0.0)
    resets = f.raw('reset_positions_m') or []
    if not isinstance(resets, list) or any(
            isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r)
            or r < 0.0 for r in resets):
        raise ConfigError(f'{f.where}.reset_positions_m: must be a list of positions >= 0 (m), '
                          f'got {resets!r}')
    sensor = QuantitySensor(
        noise_std=f.number('noise_std', 0.0, minimum=0.0),
        bias=f.number('bias', 0.0),
        quantum=f.number('quantum', 0.0, minimum=0.0),
        dropout_probability=f.number('dropout_probability', 0.0, minimum=0.0, maximum=1.0),
        failed_from_s=failed_from,
        failed_until_s=(f.number('failed_until_s', minimum=failed_from, exclusive_minimum=True)
                        if f.has('failed_until_s') else math.inf),
        failed_cars=tuple(cars),
        scale_error=f.number('scale_error', 0.0, minimum=-0.1, maximum=0.1),
        reset_positions_m=tuple(sorted(float(r) for r in resets)))
    f.reject_unknown()
    return sensor


def _sensors(f: Fields, car_names: Sequence[str]) -> SensorSetup:
    position, speed, acceleration = (_quantity_sensor(f.section(q), car_names)
                                     for q in ('position', 'speed', 'acceleration'))
    setup = SensorSetup(position, speed, acceleration,
                        seed=int(f.number('seed', 0.0, minimum=0.0, maximum=2**31 - 1)))
    if abs(speed.bias) > SPEED_BIAS_MAX_MPS:
        raise ConfigError(f'{f.where}.speed.bias: at most {SPEED_BIAS_MAX_MPS:g} m/s either '
                          f'way (it acts in full from {SPEED_BIAS_FULL_MPS * 3.6:g} km/h and '
                          f'must not reverse the reading below), got {speed.bias:g}')
    f.reject_unknown()
    return setup


def car_names_of(train: TrainParameters) -> tuple[str, ...]:
    """Names of the cars a plant model publishes: the multi-car description, or one 'train'."""
    return tuple(c.name for c in train.cars) + ('train',)


def parse_plant_setup(data, train: TrainParameters, where: str = 'plant') -> PlantSetup:
    """Parse the ``plant:`` section (None or absent: nothing varies)."""
    if data is None:
        return PlantSetup()
    f = Fields(data, where)
    v = f.section('resistance_variation')
    variation = None
    if f.has('resistance_variation'):
        variation = ResistanceVariation(
            *(_optional_sinusoid(v, k) for k in ('a', 'b', 'c', 'line')))
        v.reject_unknown()
    modes, switch = _modes(f, train)
    a = f.section('actuators')
    actuators = ActuatorSettings(a.number('time_constant_s', 0.0, minimum=0.0, maximum=60.0),
                                 a.number('rate_limit_n_per_s', 0.0, minimum=0.0),
                                 a.number('dead_time_s', 0.0, minimum=0.0, maximum=10.0))
    a.reject_unknown()
    setup = PlantSetup(
        resistance_variation=variation, modes=modes, mode_switch=switch,
        abrupt_changes=_abrupt_changes(f), disturbance=_disturbance(f.section('disturbance')),
        actuators=actuators, failures=parse_failures(f.items('failures'), train.actuator_names),
        sensors=_sensors(f.section('sensors'), car_names_of(train)))
    f.reject_unknown()
    return setup


def parse_failure_injection(text: str, actuator_names: Sequence[str], now_s: float,
                            where: str = 'inject_failure'
                            ) -> tuple[tuple[ActuatorFailure, ...], tuple[str, ...]]:
    """A run-time failure injection: YAML (or JSON) text of one failure mapping or a list of
    them, as in ``plant.failures``; ``start_s`` defaults to now and must not be in the past;
    ``kind: healthy`` repairs the actuator now. Returns (failures, repaired actuators)."""
    from ato_common.files import load_yaml_text  # the limits of the suite's files
    data = load_yaml_text(text, where) if text.strip() else []
    items = Fields({'failures': data if isinstance(data, list) else [data]}, '').items('failures')
    repaired, rest = [], []
    for i, item in enumerate(items):
        item.where = f'{where}[{i}]'
        if item.has('kind') and item.text('kind') == 'healthy':
            name = item.text('actuator')
            if name not in actuator_names:
                raise ConfigError(f"{item.where}.actuator: unknown actuator '{name}'; valid: "
                                  f"{', '.join(actuator_names)}")
            item.reject_unknown()
            repaired.append(name)
        else:
            rest.append(item)
    failures = parse_failures(rest, actuator_names, default_start_s=now_s)
    late = [f for f in failures if f.start_s < now_s]
    if late:
        raise ConfigError(f'{where}: start_s {late[0].start_s:g} is in the past (now '
                          f'{now_s:g} s)')
    return failures, tuple(repaired)
