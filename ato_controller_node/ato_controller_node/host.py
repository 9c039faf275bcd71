"""Runs the selected law each period: switching with bumpless transfer, saturation to the
actuator limits, guard against missing or non-finite input and output, the check that the law
fits the train and the running plant, and the split over actuators.

The ATO envelope (:mod:`ato_controller_node.envelope`, ``envelope=True``, the default): the
saturation-aware anti-windup of the position error (the integral of the speed error), the same
for every law: the law is given a reference position shifted by the envelope, which winds it
from what the limits took away. Off (``envelope=False``) every law runs on the reference
itself.

Bumpless transfer: on a switch the new law is reset from the current state and told the last
command; whatever step remains between the last command and the new law's first output is
carried as an offset that decays with ``bumpless_time_constant_s``.

The host knows the train only through its :class:`~ato_common.knowledge.TrainKnowledge`
(nominal values, known modes); :meth:`ControllerHost.measurement` takes the known operating mode
from it, never from the plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import isfinite
from typing import Any, Mapping

from ato_common.knowledge import TrainKnowledge
from ato_common.types import ReferencePoint, TrainState
from ato_controller_node.envelope import Envelope, EnvelopeSettings
from ato_controller_node.laws import LAWS, law_class
from ato_controller_node.laws.base import ControlLaw, Measurement, validated_settings

#: the estimate under which a law that observes the speed reports it (m/s); used for the
#: traction limit when the speed is not measured
SPEED_ESTIMATE_KEY = 'speed_hat_mps'
#: the estimate under which the host reports the envelope's shift of the position reference, m
ENVELOPE_SHIFT_KEY = 'envelope_shift_m'


class LawRejected(ValueError):
    """A law that cannot be selected; the message says why and lists the valid ones."""


@dataclass(frozen=True)
class StepResult:
    total_force_n: float
    forces_n: tuple[float, ...]
    wanted_force_n: float
    saturated: bool
    law: str
    estimates: Mapping[str, float]
    speed_error_mps: float
    position_error_m: float
    fault: str


class ControllerHost:
    def __init__(self, train: TrainKnowledge, dt: float, law: str,
                 settings: Mapping[str, Mapping[str, Any]] | None = None,
                 bumpless_time_constant_s: float = 3.0, envelope: bool = True,
                 envelope_settings: Mapping[str, Any] | None = None):
        self.train = train
        self.dt = dt
        self.bumpless_time_constant_s = bumpless_time_constant_s
        #: the ATO envelope (None: off), the same for every law
        self.envelope = Envelope(validated_settings(EnvelopeSettings, envelope_settings or {})) \
            if envelope else None
        self._settings = {name: validated_settings(cls.Settings, (settings or {}).get(name, {}))
                          for name, cls in LAWS.items()}
        self.measured_cars: int | None = None  # cars the plant measures, once seen
        self.law: ControlLaw = self._make(law)
        self.started = False
        self.last_force_n = 0.0
        self.last_forces_n = (0.0,) * len(train.actuator_names)
        self._offset_n = 0.0
        self._has_commanded = False
        self.faults = 0
        self.mode = 0  # the known operating mode, kept while it cannot be determined
        self._actuators = len(train.actuator_names)  # the knowledge is frozen
        # (law, knowledge, cars, law.fits' reason) checked
        self._fit: tuple[Any, Any, Any, Any] = (None, None, None, None)
        # (dt, time constant, the offset's decay per step)
        self._decay: tuple[Any, Any, float] = (None, None, 1.0)
        # (law, its settings, law.feedback_gains()) asked
        self._gains: tuple[Any, Any, Any] = (None, None, None)

    def measurement(self, time_s: float, state: TrainState) -> Measurement:
        """The law's measurement of a measured ``state`` at run time ``time_s``, with the
        operating mode the on-board software takes as active: the knowledge's schedule at the
        lead car's measured position (Mao et al. 2017's known indicators chi_i; line data)."""
        self.mode = self.train.known_mode(time_s, state.positions[0], self.mode)
        return Measurement.from_state(time_s, state, self.mode)

    def _make(self, name: str) -> ControlLaw:
        try:
            cls = law_class(name)
        except KeyError as error:
            raise LawRejected(error.args[0]) from None
        law = cls(self.train, self.dt, self._settings[name])
        reason = law.fits(self.train, self.measured_cars)
        if reason:
            raise LawRejected(reason)
        return law

    def check(self, name: str) -> None:
        """Raise LawRejected if ``name`` cannot be selected (validate before apply)."""
        self._make(name)

    def select(self, name: str) -> None:
        """Switch to another law; it takes over at the next step from the current state."""
        if name == self.law.name:
            return
        self.law = self._make(name)
        self.started = False

    def update_settings(self, law: str, values: Mapping[str, Any]) -> None:
        """Validate and apply gains of one law (ValueError naming the field if invalid)."""
        new = validated_settings(LAWS[law].Settings, values, self._settings[law])
        self._settings[law] = new
        if self.law.name == law:
            self.law.update_settings(new)

    def settings(self, law: str):
        return self._settings[law]

    def _fits(self, law: ControlLaw) -> str | None:
        """``law.fits(self.train, self.measured_cars)``, asked again only when the law, the
        knowledge or the measured cars change (it depends on nothing else)."""
        cached_law, train, cars, reason = self._fit
        if cached_law is not law or train is not self.train or cars != self.measured_cars:
            reason = law.fits(self.train, self.measured_cars)
            self._fit = (law, self.train, self.measured_cars, reason)
        return reason

    def _feedback_gains(self, law: ControlLaw):
        """``law.feedback_gains()``, asked again only when the law or its settings change."""
        cached_law, settings, gains = self._gains
        if cached_law is not law or settings is not law.settings:
            gains = law.feedback_gains()
            self._gains = (law, law.settings, gains)
        return gains

    def _offset_decay(self) -> float:
        """exp(-dt / bumpless_time_constant_s), computed again when either changes (the node
        sets the time constant at run time)."""
        dt, time_constant, decay = self._decay
        if dt != self.dt or time_constant != self.bumpless_time_constant_s:
            dt, time_constant = self.dt, self.bumpless_time_constant_s
            decay = math.exp(-dt / time_constant)
            self._decay = (dt, time_constant, decay)
        return decay

    def step(self, measurement: Measurement, reference: ReferencePoint) -> StepResult:
        law = self.law
        if measurement.car_positions:
            self.measured_cars = measurement.car_count
        reason = self._fits(law)
        if reason:
            self.faults += 1
            return self._held(law, f'{reason}; holding the last command', reference,
                              measurement)
        missing = self._missing_input(law, measurement, reference)
        if missing:
            # Hold the last command and leave the law untouched: a non-finite value must not
            # reach its integrators or estimates.
            self.faults += 1
            return self._held(law, f'{missing}; holding the last command', reference,
                              measurement)
        envelope = self.envelope
        given = envelope.reference(reference, measurement.position) if envelope else reference
        if not self.started:
            law.reset(measurement, given, self.last_force_n if self._has_commanded else None)
        output = law.step(measurement, given)
        n = self._actuators
        law_forces = output.forces_n
        if law_forces is not None and len(law_forces) != n:
            self.faults += 1
            return self._held(law, f'{law.name} returned {len(law_forces)} forces for {n} '
                              'actuators; holding the last command', reference, measurement)
        if not (isfinite(output.force_n) and (not law_forces or all(map(isfinite, law_forces)))):
            self.faults += 1
            self.started = False  # restart the law from the current state at the next step
            return self._held(law, f'{law.name} produced a non-finite force; holding the last '
                              'command', reference, measurement)
        law_total = sum(law_forces) if law_forces is not None else output.force_n
        if not self.started:
            # Nothing to be bumpless to before the first command.
            self._offset_n = self.last_force_n - law_total if self._has_commanded else 0.0
            self.started = True
        else:
            self._offset_n *= self._offset_decay()
        offset = self._offset_n
        offset_each = offset / n
        law_each = law_forces if law_forces is not None else (law_total / n,) * n
        wanted_each = [f + offset_each for f in law_each]
        lowest, highest = self.train.actuator_limits_at(self._speed_for_limits(
            measurement, reference, output.estimates))
        forces = tuple([min(max(f, lowest), highest) for f in wanted_each])
        total = sum(forces)
        unlimited = output.unlimited_force_n
        # a law that limits its own shares wanted more than their sum: that is the wish
        wanted = sum(wanted_each) if unlimited is None else unlimited + offset
        law.after_saturation(wanted - offset, total - offset,
                             tuple([f - offset_each for f in forces]), applied_n=total)
        self.last_force_n, self.last_forces_n = total, forces
        self._has_commanded = True
        estimates = dict(output.estimates)
        if envelope:
            envelope.update(wanted - total, reference.speed, self.dt,
                            self.train.nominal_mass_kg, self._feedback_gains(law),
                            reference.speed - measurement.speed)
            estimates[ENVELOPE_SHIFT_KEY] = envelope.shift_m
        return self._result(total, forces, wanted, law, estimates, reference, measurement, '')

    @staticmethod
    def _missing_input(law: ControlLaw, measurement: Measurement,
                       reference: ReferencePoint) -> str:
        """Why the law cannot step on these inputs ('' if it can)."""
        if not (isfinite(reference.position) and isfinite(reference.speed)
                and isfinite(reference.acceleration) and isfinite(reference.jerk)):
            return 'non-finite reference'
        for quantity in law.requires:
            values = measurement.values_of(quantity)
            if not values or not all(map(isfinite, values)):
                return f'{law.name} needs the measured {quantity.replace("_", " ")}, which is ' \
                       'not available (NaN or missing)'
        return ''

    @staticmethod
    def _speed_for_limits(measurement: Measurement, reference: ReferencePoint,
                          estimates: Mapping[str, float]) -> float:
        """The speed at which the traction limit (power hyperbola) is taken: the measured one,
        else a law's own estimate, else the reference's."""
        for speed in (measurement.speed, estimates.get(SPEED_ESTIMATE_KEY, math.nan)):
            if math.isfinite(speed):
                return speed
        return reference.speed

    def _result(self, total, forces, wanted, law, estimates, reference, measurement, fault):
        return StepResult(total, forces, wanted, total != wanted, law.name, estimates,
                          reference.speed - measurement.speed,
                          reference.position - measurement.position, fault)

    def _held(self, law, fault, reference, measurement) -> StepResult:
        return self._result(self.last_force_n, self.last_forces_n, self.last_force_n, law, {},
                            reference, measurement, fault)
