"""Runs the selected law each period: switching with bumpless transfer, saturation to the
actuator limits, guard against non-finite output, and the split over actuators.

Bumpless transfer: on a switch the new law is reset from the current state and told the last
command; whatever step remains between the last command and the new law's first output is
carried as an offset that decays with ``bumpless_time_constant_s``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

from ato_common.types import ReferencePoint
from ato_controller_node.laws import LAWS, law_class
from ato_controller_node.laws.base import ControlLaw, Measurement, TrainKnowledge, validated_settings


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
                 bumpless_time_constant_s: float = 3.0):
        self.train = train
        self.dt = dt
        self.bumpless_time_constant_s = bumpless_time_constant_s
        self._settings = {name: validated_settings(cls.Settings, (settings or {}).get(name, {}))
                          for name, cls in LAWS.items()}
        self.law: ControlLaw = self._make(law)
        self.started = False
        self.last_force_n = 0.0
        self._offset_n = 0.0
        self._has_commanded = False
        self.faults = 0

    def _make(self, name: str) -> ControlLaw:
        try:
            cls = law_class(name)
        except KeyError as error:
            raise LawRejected(error.args[0]) from None
        law = cls(self.train, self.dt, self._settings[name])
        reason = law.fits(self.train)
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

    def step(self, measurement: Measurement, reference: ReferencePoint) -> StepResult:
        law = self.law
        inputs = (measurement.position, measurement.speed, reference.position, reference.speed,
                  reference.acceleration)
        if not all(math.isfinite(x) for x in inputs):
            # Hold the last command and leave the law untouched: a non-finite value must not
            # reach its integrators or estimates.
            self.faults += 1
            return self._held(law, 'non-finite measurement or reference; holding the last '
                              'command', reference, measurement)
        if not self.started:
            law.reset(measurement, reference,
                      self.last_force_n if self._has_commanded else None)
        output = law.step(measurement, reference)
        if not math.isfinite(output.force_n):
            self.faults += 1
            return self._held(law, f'{law.name} produced a non-finite force; holding the last '
                              'command', reference, measurement)
        fault = ''
        wanted = output.force_n
        if not self.started:
            # Nothing to be bumpless to before the first command.
            self._offset_n = self.last_force_n - wanted if self._has_commanded else 0.0
            self.started = True
        else:
            self._offset_n *= math.exp(-self.dt / self.bumpless_time_constant_s)
        wanted += self._offset_n
        lowest, highest = self.train.traction.limits_at(measurement.speed)
        total = min(max(wanted, lowest), highest)
        law.after_saturation(wanted - self._offset_n, total - self._offset_n)
        self.last_force_n = total
        self._has_commanded = True
        return self._result(total, wanted, law, dict(output.estimates), reference, measurement,
                            fault)

    def _result(self, total, wanted, law, estimates, reference, measurement, fault):
        share = total / len(self.train.actuator_names)
        return StepResult(total, (share,) * len(self.train.actuator_names), wanted,
                          total != wanted, law.name, estimates,
                          reference.speed - measurement.speed,
                          reference.position - measurement.position, fault)

    def _held(self, law, fault, reference, measurement) -> StepResult:
        return self._result(self.last_force_n, self.last_force_n, law, {}, reference,
                            measurement, fault)
