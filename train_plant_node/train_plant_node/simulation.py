"""Lockstep plant simulation: the train's physics (the truth) and its on-board units around it,
with exact integer time.

``TrainSimulation`` is what the node drives: ``apply_command`` (validated), ``advance`` by one
control period with the command held, and ``truth``/``measured`` snapshots. It has no rclpy
dependency and is deterministic for a seed. The scenario's ``plant:`` section
(:mod:`ato_common.plant_setup`) supplies what varies, the actuators, the failures and the
sensors. Its collaborators, one module each:

- the plant model (``models/``): the physics, stepped with the forces held;
- :class:`~train_plant_node.actuators.Actuators`: limits, dead time, lag, rate limit, failures,
  the emergency brake and its build-up;
- :class:`~train_plant_node.sensors.Sensors`: what the sensors report of the truth, to the ATO
  (``measured``) and to the ATP's odometry;
- :class:`~train_plant_node.odometry.Odometry` and :class:`~train_plant_node.atp.OnboardATP`:
  the EVC, which knows only its odometry (with its confidence interval), the movement authority
  and the train data, and demands the emergency brake (with traction cut-off) and, while the
  train dwells at a stop, the holding brake;
- the command watchdog (here): after ``watchdog_periods`` control periods without a valid
  command the train is service-braked, after ``emergency_periods`` emergency-braked; a valid
  command ends it;
- :mod:`train_plant_node.batch` and ``periods.py``: many periods in one compiled call.

Truth and knowledge: the model's state is the truth; the plant uses it for the physics and the
sensors read it, and it is what judges the supervision (``truth()``). The ATP never reads it:
each period the sensors give the odometer's reading to the odometry, the odometry its estimate
to the ATP, and the ATP its demands to the actuators.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from typing import Sequence

from ato_common.braking_curves import RunSupervision
from ato_common.plant_setup import ActuatorFailure, PlantSetup
from ato_common.scenario import Scenario
from ato_common.types import NS_PER_S, TrainState, nanoseconds
from train_plant_node.actuators import (
    DRIVE,
    EMERGENCY,
    EVENT_TOLERANCE_S,
    PEAK_ADHESION,
    SERVICE,
    Actuators,
    CommandRejected,
    FailureRejected,
    check_failure,
    failure_force_bound,
)
from train_plant_node.atp import OnboardATP, highest_acceleration
from train_plant_node.batch import Trajectory, run_commands
from train_plant_node.models import PlantModel, make_model
from train_plant_node.odometry import Odometry
from train_plant_node.sensors import Sensors, SensorSettings, merged_sensors
from train_plant_node.surroundings import Surroundings, surroundings_at

__all__ = ['PEAK_ADHESION', 'CommandRejected', 'FailureRejected', 'SafetySettings',
           'SensorSettings', 'TrainSimulation', 'Trajectory', 'check_failure',
           'control_period_ns', 'failure_force_bound', 'merged_sensors']


@dataclass(frozen=True)
class SafetySettings:
    """What the plant's command watchdog does (see ``TrainSimulation``)."""

    watchdog_periods: int = 3      # control periods without a valid command before service braking
    emergency_periods: int = 10    # ... before emergency braking


NORMAL, SERVICE_BRAKE, EMERGENCY_BRAKE = 'normal', 'service brake', 'emergency brake'


def scheduled_times(setup: PlantSetup, failures: Sequence[ActuatorFailure]) -> list[float]:
    """Every time at which something switches, increasing (integration steps split there)."""
    times = set(setup.scheduled_times())
    for f in failures:
        times |= {f.start_s, f.end_s}
    return sorted(t for t in times if math.isfinite(t) and t > 0.0)


def event_within(events: list[float], start_s: float, end_s: float) -> bool:
    """A scheduled time strictly inside (start_s, end_s), beyond the tolerance."""
    i = bisect_right(events, start_s + EVENT_TOLERANCE_S)
    return i < len(events) and events[i] < end_s - EVENT_TOLERANCE_S


def onboard_units(scenario: Scenario, run: RunSupervision, model: PlantModel, model_name: str,
                  state, sensors: SensorSettings | None
                  ) -> tuple[Sensors, Odometry, OnboardATP, bool]:
    """The sensors (truth side), and the EVC's odometry and ATP (knowledge side) of a run from
    ``state``; and whether the odometer is exact (while its sensors work, the odometry's
    estimate is the truth and its interval the declared accuracy, cheaply: ``Odometry.exact``)."""
    setup = merged_sensors(scenario.plant.sensors, sensors)
    setup.check_cars(model.car_names, model_name)
    start, speed = float(state[0]), model.lead_speed(state)
    units = Sensors(setup, scenario.line.balise_groups_m, start, model.car_names[0],
                    run.STANDSTILL_MPS)
    acceleration = highest_acceleration(scenario.supervision, scenario.line)
    count, reading = units.odometer(0.0, start, speed)
    odometry = Odometry(scenario.supervision, count, reading, run.STANDSTILL_MPS, acceleration,
                        scenario.line.balise_groups_m)
    if start in units.balise_groups_m:  # the train stands on a balise group at its start
        odometry.update(0.0, count, reading, [(start, count)])
    atp = OnboardATP(run, acceleration, odometry.speed_mps)
    return units, odometry, atp, units.exact_odometer


class TrainSimulation:
    """The plant and the on-board units that override the ATO command (module docstring):
    the command watchdog; the ATP (``atp``, on the train's odometry ``odometry``), whose
    intervention is an emergency brake the ATO cannot override and whose holding brake holds a
    train dwelling at a stop; the emergency brake of the actuators (``actuators``),
    which cuts every drive's traction and builds up over T_be, and which no drive failure
    cancels. A failed actuator keeps delivering its failure force whatever the ATO commands;
    a failure force beyond what a drive can physically exert (``failure_force_bound``) is
    refused (``FailureRejected``)."""

    def __init__(self, scenario: Scenario, model_name: str = 'point_mass',
                 sensors: SensorSettings | None = None,
                 safety: SafetySettings = SafetySettings(), **model_options):
        self.scenario = scenario
        self.setup: PlantSetup = scenario.plant
        self.supervision = RunSupervision.for_scenario(scenario)
        self.model: PlantModel = make_model(model_name, scenario.train, scenario.line,
                                            **model_options)
        self.actuator_names: tuple[str, ...] = self.model.actuator_names
        self.stamp_ns = 0
        self.state = self.model.initial_state(scenario.run.initial_position_m)
        self.sensors, self.odometry, self.atp, self._exact_odometry = onboard_units(
            scenario, self.supervision, self.model, model_name, self.state, sensors)
        n = len(self.actuator_names)
        self.commanded = (0.0,) * n
        self.applied = (0.0,) * n          # what acts on the train (failures included)
        self.actuators = Actuators(self.setup.actuators, self.setup.failures, scenario.train,
                                   self.actuator_names,
                                   scenario.supervision.emergency_brake_build_up_s)
        self.rejected_commands = 0
        self.safety = safety
        self.missed_periods = 0
        self.level = DRIVE                 # what the safety functions make of the drives
        self.events = scheduled_times(self.setup, self.actuators.failures)
        self._env_key: tuple | None = None
        self._env: Surroundings | None = None
        # Nothing switches the surroundings during the run: one for all steps.
        self._constant_env = not self.setup.modes and not self.setup.abrupt_changes
        # One integration step per period is possible (see ``advance``).
        self._one_step_possible = self.actuators.instant and \
            self.setup.disturbance.kind != 'random'
        self._applied_for: object = None  # the state ``applied`` was last computed for
        self._update_applied()

    # --- time and state ----------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return self.stamp_ns / NS_PER_S  # ato_common.types.seconds, inlined: per step

    def lead_speed(self) -> float:
        return self.model.lead_speed(self.state)

    def lead_position(self) -> float:
        return float(self.state[0])

    def surroundings(self, time_s: float | None = None) -> Surroundings:
        """The mode, abrupt change, varying resistance and disturbance in force now."""
        if self._env is not None and self._constant_env:
            return self._env  # nothing switches: the same all run
        setup = self.setup
        t = self.time_s if time_s is None else time_s
        key = (setup.mode_index(t, self.lead_position()), setup.abrupt_change(t))
        env = self._env
        if key != self._env_key or env is None:
            self._env_key = key
            env = self._env = surroundings_at(setup, self.scenario.train, t,
                                              self.lead_position())
        return env

    # --- commands, failures and the watchdog ----------------------------------------------------
    def apply_command(self, forces: Sequence[float]) -> tuple[float, ...]:
        """Validate a command; it is then held until the next one (zero-order hold).

        A command of the wrong length or with a non-finite value raises CommandRejected and the
        previous command stays in force. Returns the forces applied now."""
        names = self.actuator_names
        if len(forces) != len(names):
            self.rejected_commands += 1
            raise CommandRejected(f'{len(forces)} forces for {len(names)} actuators {list(names)}')
        values = tuple(map(float, forces))
        if not all(map(math.isfinite, values)):
            self.rejected_commands += 1
            raise CommandRejected(f'non-finite force in {list(values)}')
        self.commanded = values      # in force from now on, and the watchdog is quiet
        self.missed_periods = 0
        self._update_applied()
        return self.applied

    def command_missed(self, periods: int | None = None) -> None:
        """A control period passed without a valid command (the watchdog counts it); or, with
        ``periods``, that many have passed since the last valid one."""
        self.missed_periods = self.missed_periods + 1 if periods is None else periods
        self._update_applied()

    def inject_failures(self, failures: Sequence[ActuatorFailure],
                        repaired: Sequence[str] = ()) -> None:
        """Run-time failures: each replaces any failure of its actuator from its start time on;
        the actuators in ``repaired`` become healthy now."""
        self.actuators.inject(failures, repaired, self.time_s)
        self.events = scheduled_times(self.setup, self.actuators.failures)
        self._update_applied()

    @property
    def watchdog(self) -> str:
        if self.missed_periods >= self.safety.emergency_periods:
            return EMERGENCY_BRAKE
        if self.missed_periods >= self.safety.watchdog_periods:
            return SERVICE_BRAKE
        return NORMAL

    @property
    def emergency_brake(self) -> bool:
        """The emergency brake is demanded (ATP intervention or the watchdog's last stage)."""
        return self.level == EMERGENCY

    @property
    def atp_intervention(self) -> bool:
        """The ATP's emergency brake intervention is in force."""
        return self.atp.emergency_brake

    @property
    def atp_interventions(self) -> int:
        """How many ATP interventions began so far."""
        return self.atp.interventions

    def _update_applied(self) -> None:
        """The safety functions' demand now, and the forces it leaves acting on the train."""
        missed, safety, atp = self.missed_periods, self.safety, self.atp
        level = (EMERGENCY if atp.emergency_brake or missed >= safety.emergency_periods
                 else SERVICE if missed >= safety.watchdog_periods
                 or atp.standing_since_s is not None else DRIVE)
        self.level = level
        actuators = self.actuators
        actuators.demand(level, self.time_s)
        if actuators.instant:
            actuators.drive = actuators.targets(self.commanded, level, self.lead_speed())
        self.applied = actuators.delivered(actuators.drive, level, self.time_s)
        self._applied_for = self.state

    # --- time goes on --------------------------------------------------------------------------
    def advance(self, duration_ns: int) -> None:
        """Integrate one period: steps of at most the model's ``max_substep_s``, split at every
        scheduled time (modes, abrupt changes, failures, disturbance jumps); then the on-board
        units take their cycle."""
        t = self.stamp_ns / NS_PER_S
        duration = duration_ns / NS_PER_S
        end = t + duration
        actuators = self.actuators
        if self._one_step_possible and duration <= self.model.max_substep_s and \
                not event_within(self.events, t, end):
            # One integration step and nothing switches within it: the general loop's result,
            # without its bookkeeping. Instant actuators deliver what ``_update_applied`` last
            # computed, if for this state (and no failure samples its force within the step).
            forces = (self.applied if self._applied_for is self.state and not actuators.failures
                      and actuators.brake_since_s is None
                      else actuators.forces(self.commanded, self.level, self.lead_speed(), t,
                                            duration))
            env = self._env if self._constant_env and self._env is not None \
                else self.surroundings(t)
            self.state = self.model.step(self.state, duration, forces, t, env)
        else:
            self._integrate(t, duration, end)
        self.stamp_ns += duration_ns
        self._supervise(duration)

    def _integrate(self, t: float, duration: float, end: float) -> None:
        """The general loop of ``advance``: integration steps of at most ``max_substep_s``,
        split at the scheduled times, at a random disturbance's jumps and where a delayed
        request takes effect."""
        actuators = self.actuators
        substeps = max(1, math.ceil(duration / self.model.max_substep_s - 1e-9))
        h_nominal = duration / substeps
        events = [e for e in self.events if t + EVENT_TOLERANCE_S < e < end - EVENT_TOLERANCE_S]
        if self.setup.disturbance.kind == 'random':
            events = sorted(set(events) | set(self.setup.disturbance.switch_times(t, end)))
        if actuators.settings.dead_time_s:
            events = sorted(set(events) | set(actuators.dead_time_events(
                t, end, self.commanded, self.level)))
        boundaries = sorted(set([t + k * h_nominal for k in range(1, substeps)] + events))
        boundaries = [b for b in boundaries if b < end - EVENT_TOLERANCE_S] + [end]
        for stop in boundaries:
            h = stop - t
            if h <= EVENT_TOLERANCE_S:
                continue
            if abs(h - h_nominal) < EVENT_TOLERANCE_S:
                h = h_nominal  # one step length: the multi-car propagators stay cached
            env = self.surroundings(t)
            forces = actuators.forces(self.commanded, self.level, self.lead_speed(), t, h)
            self.state = self.model.step(self.state, h, forces, t, env)
            t = stop

    def _supervise(self, period_s: float) -> None:
        """The on-board units' cycle after a period: the odometer's reading to the odometry,
        the odometry's estimate and the drives' fault report to the ATP, its demand to the
        actuators. The truth goes no further than the sensors."""
        odometry, sensors = self.odometry, self.sensors
        if self._exact_odometry and not (sensors.may_fail and sensors.odometer_failed(
                self.stamp_ns / NS_PER_S)):
            position = float(self.state[0])
            if sensors.may_fail:  # where the train is, should the odometer fail later
                sensors.follow(position, period_s)
            odometry.exact(position, self.model.lead_speed(self.state))
        else:
            position, speed = float(self.state[0]), self.model.lead_speed(self.state)
            passed = self.sensors.follow(position, period_s)
            count, reading = self.sensors.odometer(self.time_s, position, speed)
            odometry.update(period_s, count, reading, passed)
        actuators = self.actuators
        fault = bool(actuators.failures) and actuators.drive_fault(self.time_s)
        self.atp.cycle(self.time_s, period_s, odometry, fault)
        self._update_applied()

    def run_commands(self, commands, period_ns: int) -> Trajectory:
        """Hold each row of ``commands`` (one force per actuator, N) for one control period:
        the same as ``apply_command(row)``, ``advance(period_ns)`` and ``truth()`` for each
        row, to the last bit, and many times faster where the compiled path applies
        (:func:`train_plant_node.batch.run_commands`)."""
        return run_commands(self, commands, period_ns)

    # --- outputs -------------------------------------------------------------------------------
    def truth(self) -> TrainState:
        """The true state of every car now: positions, speeds, accelerations, applied forces."""
        env = self._env if self._constant_env and self._env is not None else self.surroundings()
        return TrainState(self.stamp_ns, self.model.car_names,
                          *self.model.outputs(self.state, self.applied,
                                              self.stamp_ns / NS_PER_S, env))

    def measured(self, truth: TrainState | None = None) -> TrainState:
        """What the on-board sensors report to the ATO; a missing measurement is NaN."""
        return self.sensors.measured(truth or self.truth(), self.time_s)


def control_period_ns(rate_hz: float) -> int:
    return nanoseconds(1.0 / rate_hz)

