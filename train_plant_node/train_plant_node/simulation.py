"""Lockstep plant simulation: model + actuator limits + sensors + exact integer time.

``TrainSimulation`` is what the node drives: ``apply_command`` (validated, then saturated by the
traction characteristic), ``advance`` by one control period with the applied force held, and
``truth``/``measured`` snapshots. It has no rclpy dependency and is deterministic for a seed.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

from ato_common.scenario import Scenario
from ato_common.types import TrainState, nanoseconds, seconds
from train_plant_node.models import PlantModel, make_model


class CommandRejected(ValueError):
    """A command that must not reach the actuators; the message says why."""


@dataclass(frozen=True)
class SafetySettings:
    """What the on-board safety functions of the plant do (see ``TrainSimulation``)."""

    watchdog_periods: int = 3      # control periods without a valid command before service braking
    emergency_periods: int = 10    # ... before emergency braking
    overspeed_margin_mps: float = 5.0 / 3.6  # ATP intervention above the permitted speed + this


NORMAL, SERVICE_BRAKE, EMERGENCY_BRAKE = 'normal', 'service brake', 'emergency brake'


@dataclass(frozen=True)
class SensorSettings:
    position_noise_m: float = 0.0   # standard deviation of white noise on each measurement
    speed_noise_mps: float = 0.0
    seed: int = 0


class TrainSimulation:
    """The plant with its safety functions, which override the ATO command:

    - command watchdog: after ``watchdog_periods`` control periods without a valid command the
      train is service-braked, after ``emergency_periods`` emergency-braked; a valid command
      ends it;
    - ATP supervision: above the permitted speed (the line's static limit) plus the margin, an
      emergency brake intervention that the ATO cannot override until the train is back at or
      under the permitted speed.
    """

    def __init__(self, scenario: Scenario, model_name: str = 'point_mass',
                 sensors: SensorSettings = SensorSettings(),
                 safety: SafetySettings = SafetySettings(), **model_options):
        self.scenario = scenario
        self.model: PlantModel = make_model(model_name, scenario.train, scenario.line,
                                            **model_options)
        self.sensors = sensors
        self._rng = np.random.default_rng(sensors.seed)
        self.stamp_ns = 0
        self.state = self.model.initial_state(scenario.run.initial_position_m)
        n = len(self.model.actuator_names)
        self.commanded = (0.0,) * n
        self.applied = (0.0,) * n
        self.rejected_commands = 0
        self.safety = safety
        self.missed_periods = 0
        self.atp_intervention = False
        self.atp_interventions = 0

    @property
    def time_s(self) -> float:
        return seconds(self.stamp_ns)

    @property
    def actuator_names(self) -> tuple[str, ...]:
        return self.model.actuator_names

    def _speed(self) -> float:
        """The lead car's speed (the state's second half holds the speeds)."""
        return float(self.state[len(self.state) // 2])

    def apply_command(self, forces: Sequence[float]) -> tuple[float, ...]:
        """Validate and saturate a command; it is then held until the next one (zero-order hold).

        A command of the wrong length or with a non-finite value raises CommandRejected and the
        previous command stays in force."""
        names = self.model.actuator_names
        if len(forces) != len(names):
            self.rejected_commands += 1
            raise CommandRejected(f'{len(forces)} forces for {len(names)} actuators {list(names)}')
        values = tuple(float(f) for f in forces)
        if not all(math.isfinite(f) for f in values):
            self.rejected_commands += 1
            raise CommandRejected(f'non-finite force in {list(values)}')
        self.commanded = values
        self.missed_periods = 0
        self._update_applied()
        return self.applied

    def command_missed(self, periods: int | None = None) -> None:
        """A control period passed without a valid command (the watchdog counts it); or, with
        ``periods``, that many have passed since the last valid one."""
        self.missed_periods = self.missed_periods + 1 if periods is None else periods
        self._update_applied()

    @property
    def watchdog(self) -> str:
        if self.missed_periods >= self.safety.emergency_periods:
            return EMERGENCY_BRAKE
        if self.missed_periods >= self.safety.watchdog_periods:
            return SERVICE_BRAKE
        return NORMAL

    def permitted_speed(self) -> float:
        return self.scenario.line.speed_limit_mps(float(self.state[0]))  # at the lead car

    def _update_applied(self) -> None:
        """The force the actuators apply: the command within the physical limits (traction
        characteristic, emergency brake), unless a safety function overrides it."""
        traction = self.scenario.train.traction
        n = len(self.model.actuator_names)
        share = 1.0 / n
        if self.atp_intervention or self.watchdog == EMERGENCY_BRAKE:
            self.applied = (-traction.max_emergency_brake_force_n * share,) * n
        elif self.watchdog == SERVICE_BRAKE:
            self.applied = (-traction.max_service_brake_force_n * share,) * n
        else:
            highest = traction.max_traction_at(self._speed())
            lowest = -traction.max_emergency_brake_force_n
            self.applied = tuple(min(max(f, lowest * share), highest * share)
                                 for f in self.commanded)

    def _supervise(self) -> None:
        speed, permitted = self._speed(), self.permitted_speed()
        if not self.atp_intervention and speed > permitted + self.safety.overspeed_margin_mps:
            self.atp_intervention = True
            self.atp_interventions += 1
        elif self.atp_intervention and speed <= permitted:
            self.atp_intervention = False
        self._update_applied()

    def advance(self, duration_ns: int) -> None:
        self.state = self.model.step(self.state, seconds(duration_ns), self.applied)
        self.stamp_ns += duration_ns
        self._supervise()

    def truth(self) -> TrainState:
        positions, speeds, accelerations, forces = self.model.outputs(self.state, self.applied)
        return TrainState(self.stamp_ns, self.model.car_names, positions, speeds, accelerations,
                          forces)

    def measured(self, truth: TrainState | None = None) -> TrainState:
        truth = truth or self.truth()
        s = self.sensors
        if s.position_noise_m == 0.0 and s.speed_noise_mps == 0.0:
            return truth
        n = len(truth.positions)
        noise_s = self._rng.normal(0.0, s.position_noise_m, n) if s.position_noise_m else np.zeros(n)
        noise_v = self._rng.normal(0.0, s.speed_noise_mps, n) if s.speed_noise_mps else np.zeros(n)
        return TrainState(truth.stamp_ns, truth.car_names,
                          tuple(p + e for p, e in zip(truth.positions, noise_s)),
                          tuple(v + e for v, e in zip(truth.speeds, noise_v)),
                          truth.accelerations, truth.forces)


def control_period_ns(rate_hz: float) -> int:
    return nanoseconds(1.0 / rate_hz)
