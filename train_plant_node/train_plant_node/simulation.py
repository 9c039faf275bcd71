"""Lockstep plant simulation: model + actuators + failures + sensors + exact integer time.

``TrainSimulation`` is what the node drives: ``apply_command`` (validated), ``advance`` by one
control period with the command held, and ``truth``/``measured`` snapshots. It has no rclpy
dependency and is deterministic for a seed. The scenario's ``plant:`` section
(:mod:`ato_common.plant_setup`) supplies what varies, the actuators, the failures and the sensors.

Actuators (one per actuated unit: per motor, or per power car): the command is limited to the
unit's equal share of the train's traction characteristic (force and power) and of its
emergency brake, then passes a dead time, a first-order lag and a rate limit. These run at the
integration step (at most ``max_substep_s``): the drive holds its force within a step, as a traction
controller sampling at that rate does, so every model step is a zero-order hold. A failure
(Mao et al. 2017 eqs 13-20) replaces what the unit delivers from its start time; a stuck signal
is sampled at the middle of each integration step. The dead time delays what each drive is
asked for (the command, or the safety functions' traction cut and service brake; not the
emergency brake, which has its own build-up time): integration steps are split where a delayed
request takes effect, so the delay is exact, not rounded to a step.

Sensors: truth, times (1 + scale error) for a speed and for the distance run since the
odometer's last reset (``QuantitySensor``), plus bias and white noise, quantised.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from ato_common.braking_curves import RunSupervision
from ato_common.plant_setup import ActuatorFailure, PlantSetup, QuantitySensor, SensorSetup
from ato_common.scenario import Scenario
from ato_common.types import NS_PER_S, TrainState, nanoseconds
from ato_common.units import STANDARD_GRAVITY
from train_plant_node.models import PlantModel, make_model
from train_plant_node.surroundings import Surroundings, surroundings_at


class CommandRejected(ValueError):
    """A command that must not reach the actuators; the message says why."""


class FailureRejected(ValueError):
    """A failure no drive could physically produce; the message names the field and bound."""


# The highest wheel-rail adhesion coefficient of dry rail: no drive, however it fails, pushes
# or brakes the train harder than the train's whole weight times it (the wheels slip).
PEAK_ADHESION = 0.4


def failure_force_bound(train) -> float:
    """The largest force a failed drive can physically exert on the train, N: the train's
    weight (its mass, ``mass_kg``) times ``PEAK_ADHESION`` of dry rail."""
    return PEAK_ADHESION * train.mass_kg * STANDARD_GRAVITY


def check_failure(failure: ActuatorFailure, train) -> None:
    """Refuse a failure whose force no drive can exert: beyond ``failure_force_bound`` (the
    whole train's adhesion). A drive's rated share of the traction characteristic is lower, but
    the papers' failures exceed it (Mao et al. 2017: 2e5 (1 + sin) N on one of four 75 kN
    motors), so a fault up to adhesion is accepted as the scenario gives it."""
    fields = []
    if failure.kind in ('stuck', 'stuck_signal'):
        fields.append(('force_n', abs(failure.force_n)))
    if failure.kind == 'stuck_signal':
        fields.append(('force_n + amplitude_n', abs(failure.force_n) + abs(failure.amplitude_n)))
    bound = failure_force_bound(train)
    for name, reach in fields:
        if not math.isfinite(reach):
            raise FailureRejected(f'{failure.actuator} {failure.kind}: {name} must be finite')
        if reach > bound:
            raise FailureRejected(
                f'{failure.actuator} {failure.kind}: |{name}| = {reach:g} N exceeds what a drive '
                f'can physically exert on this train ({bound:g} N: weight times the peak '
                f'adhesion {PEAK_ADHESION:g} of dry rail)')


@dataclass(frozen=True)
class SafetySettings:
    """What the on-board safety functions of the plant do (see ``TrainSimulation``)."""

    watchdog_periods: int = 3      # control periods without a valid command before service braking
    emergency_periods: int = 10    # ... before emergency braking


NORMAL, SERVICE_BRAKE, EMERGENCY_BRAKE = 'normal', 'service brake', 'emergency brake'


@dataclass(frozen=True)
class SensorSettings:
    """Node-parameter overrides of the scenario's sensors: white noise on position and speed
    (used when > 0) and the seed (used when the scenario's is 0)."""

    position_noise_m: float = 0.0
    speed_noise_mps: float = 0.0
    seed: int = 0


def merged_sensors(setup: SensorSetup, overrides: SensorSettings | None) -> SensorSetup:
    if overrides is None:
        return setup
    position, speed = setup.position, setup.speed
    if overrides.position_noise_m > 0.0:
        position = replace(position, noise_std=overrides.position_noise_m)
    if overrides.speed_noise_mps > 0.0:
        speed = replace(speed, noise_std=overrides.speed_noise_mps)
    return replace(setup, position=position, speed=speed, seed=setup.seed or overrides.seed)


# A scheduled time this close to a step boundary is on it (time is float seconds here).
EVENT_TOLERANCE_S = 1e-9


@dataclass(frozen=True)
class Trajectory:
    """The truth after each control period of :meth:`TrainSimulation.run_commands`: row k is
    what ``truth()`` returns after the k-th period (columns: the cars, lead car first)."""

    car_names: tuple[str, ...]
    stamps_ns: np.ndarray          # (periods,) int64
    positions: np.ndarray          # (periods, cars), m
    speeds: np.ndarray             # m/s
    accelerations: np.ndarray      # m/s^2
    forces: np.ndarray             # applied longitudinal force per car, N
    atp_intervention: np.ndarray   # (periods,) bool: the ATP's emergency brake after the period

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def state(self, k: int) -> TrainState:
        return TrainState(int(self.stamps_ns[k]), self.car_names,
                          tuple(self.positions[k].tolist()), tuple(self.speeds[k].tolist()),
                          tuple(self.accelerations[k].tolist()), tuple(self.forces[k].tolist()))


class TrainSimulation:
    """The plant with its safety functions, which override the ATO command:

    - command watchdog: after ``watchdog_periods`` control periods without a valid command the
      train is service-braked, after ``emergency_periods`` emergency-braked; a valid command
      ends it;
    - ATP supervision (``ato_common.braking_curves``, ETCS-style): above the emergency brake
      intervention curve EBI (the static limits plus dV_ebi, and the braking curves to the
      run's targets) an emergency brake intervention that the ATO cannot override until the
      train is back at or under the permitted speed.
    - the emergency brake (of the ATP, and of the watchdog after ``emergency_periods``) is a
      brake system of its own: it cuts every drive's traction (each drive, healthy or failed,
      delivers at most zero) and applies the train's ``max_emergency_brake_force_n``, shared
      equally over the actuated units, building up linearly from the demand over the
      supervision's emergency brake build-up time T_be; no drive failure cancels it. The
      watchdog's service brake also cuts traction, and the healthy drives brake;
    - an ATP intervention in target-speed monitoring (the stop's curve or its release speed,
      not the ceiling, is the EBI) holds until standstill, and beyond the EOA (a trip) until the
      authority moves on; a ceiling intervention ends once the train is at or under the
      permitted speed;
    - the leg of the run under supervision moves on only once the train has stood still at the
      leg's stop (``RunSupervision.at_stop``) and the stop's dwell has passed since, the train
      staying within the stop's zone.
    A failed actuator keeps delivering its failure force whatever the ATO commands; a failure
    force beyond what a drive can physically exert (``failure_force_bound``) is refused
    (``FailureRejected``).
    """

    def __init__(self, scenario: Scenario, model_name: str = 'point_mass',
                 sensors: SensorSettings | None = None,
                 safety: SafetySettings = SafetySettings(), **model_options):
        self.scenario = scenario
        self.setup: PlantSetup = scenario.plant
        self.supervision = RunSupervision.for_scenario(scenario)
        self.model: PlantModel = make_model(model_name, scenario.train, scenario.line,
                                            **model_options)
        self.sensors = merged_sensors(self.setup.sensors, sensors)
        self.sensors.check_cars(self.model.car_names, model_name)
        self._rng = np.random.default_rng(self.sensors.seed)
        # The odometer misreads where the train stands (bias, scale error): the ATP's stop
        # check takes its reading (``_track_stop``).
        self._odometer_errs = self.sensors.position.bias != 0.0 or \
            self.sensors.position.scale_error != 0.0
        self.stamp_ns = 0
        self.state = self.model.initial_state(scenario.run.initial_position_m)
        n = len(self.model.actuator_names)
        self.commanded = (0.0,) * n
        self._drive = [0.0] * n          # what each healthy drive delivers (after lag, limits)
        self.applied = (0.0,) * n        # what acts on the train (failures included)
        self.failures: list[ActuatorFailure] = list(self.setup.failures)
        for failure in self.failures:
            check_failure(failure, scenario.train)
        self.rejected_commands = 0
        self.safety = safety
        self.missed_periods = 0
        self.atp_intervention = False
        self.atp_interventions = 0
        self._hold_to_standstill = False  # the intervention is target-speed monitoring's
        self.leg = 0                     # the run's leg under supervision
        self._standing_since_s = None    # since when the train stands at the leg's stop
        self.brake_since_s = None        # since when the emergency brake is demanded
        self._build_up_s = scenario.supervision.emergency_brake_build_up_s
        self._eb_share = scenario.train.traction.max_emergency_brake_force_n / \
            len(self.model.actuator_names)
        self._events = self._schedule()
        self._env_key = None
        self._env: Surroundings | None = None
        # Nothing switches the surroundings during the run: one for all steps.
        self._constant_env = not self.setup.modes and not self.setup.abrupt_changes
        settings = self.setup.actuators
        self._instant_actuators = settings.time_constant_s == 0.0 and \
            settings.rate_limit_n_per_s == 0.0 and settings.dead_time_s == 0.0
        self._dead_time_s = settings.dead_time_s
        # What the drives were asked for and since when, (time_s, targets), oldest first: the
        # requests still to take effect after the dead time, and the one in effect.
        self._asked: list[tuple[float, list[float]]] = [(-math.inf, [0.0] * n)]
        # One integration step per period is possible (see ``advance``).
        self._one_step_possible = self._instant_actuators and \
            self.setup.disturbance.kind != 'random'
        self._applied_for = None  # the state ``applied`` was last computed for
        self._packed_supervision = None  # the ATP's tables for ``periods.py``'s kernels
        self._leg_tables = (None, None, None, None)  # (supervision, leg, its EBI, stop zone)
        self._sensors_ideal = (None, False)    # (sensors, sensors.ideal): asked once per setup
        self._update_applied()

    # --- time and state ----------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return self.stamp_ns / NS_PER_S  # ato_common.types.seconds, inlined: per step

    @property
    def actuator_names(self) -> tuple[str, ...]:
        return self.model.actuator_names

    def lead_speed(self) -> float:
        return self.model.lead_speed(self.state)

    def lead_position(self) -> float:
        return float(self.state[0])

    def _schedule(self) -> list[float]:
        times = set(self.setup.scheduled_times())
        for f in self.failures:
            times |= {f.start_s, f.end_s}
        return sorted(t for t in times if math.isfinite(t) and t > 0.0)

    def surroundings(self, time_s: float | None = None) -> Surroundings:
        """The mode, abrupt change, varying resistance and disturbance in force now."""
        if self._env is not None and self._constant_env:
            return self._env  # nothing switches: the same all run
        setup = self.setup
        t = self.time_s if time_s is None else time_s
        key = (setup.mode_index(t, self.lead_position()), setup.abrupt_change(t))
        if key != self._env_key:
            self._env_key = key
            self._env = surroundings_at(setup, self.scenario.train, t, self.lead_position())
        return self._env

    def mode_index(self) -> int:
        return self.setup.mode_index(self.time_s, self.lead_position())

    # --- commands ------------------------------------------------------------------------------
    def apply_command(self, forces: Sequence[float]) -> tuple[float, ...]:
        """Validate a command; it is then held until the next one (zero-order hold).

        A command of the wrong length or with a non-finite value raises CommandRejected and the
        previous command stays in force. Returns the forces applied now."""
        names = self.model.actuator_names
        if len(forces) != len(names):
            self.rejected_commands += 1
            raise CommandRejected(f'{len(forces)} forces for {len(names)} actuators {list(names)}')
        values = tuple(map(float, forces))
        if not all(map(math.isfinite, values)):
            self.rejected_commands += 1
            raise CommandRejected(f'non-finite force in {list(values)}')
        self._hold(values)
        return self.applied

    def _hold(self, forces: tuple[float, ...]) -> None:
        """A valid command: in force from now on, and the watchdog is quiet."""
        self.commanded = forces
        self.missed_periods = 0
        self._update_applied()

    def command_missed(self, periods: int | None = None) -> None:
        """A control period passed without a valid command (the watchdog counts it); or, with
        ``periods``, that many have passed since the last valid one."""
        self.missed_periods = self.missed_periods + 1 if periods is None else periods
        self._update_applied()

    def inject_failures(self, failures: Sequence[ActuatorFailure],
                        repaired: Sequence[str] = ()) -> None:
        """Run-time failures: each replaces any failure of its actuator from its start time on;
        the actuators in ``repaired`` become healthy now."""
        now = self.time_s
        for failure in failures:
            check_failure(failure, self.scenario.train)
        for failure in failures:
            self.failures = [f if f.actuator != failure.actuator or f.end_s <= failure.start_s
                             else replace(f, end_s=failure.start_s)
                             for f in self.failures if not (f.actuator == failure.actuator
                                                            and f.start_s >= failure.start_s)]
            self.failures.append(failure)
        for name in repaired:
            self.failures = [f if f.actuator != name or f.end_s <= now
                             else replace(f, end_s=now)
                             for f in self.failures if not (f.actuator == name
                                                            and f.start_s > now)]
        self.failures = [f for f in self.failures if f.end_s > f.start_s]
        self._events = self._schedule()
        self._update_applied()

    def active_failures(self, time_s: float | None = None) -> dict[str, ActuatorFailure]:
        t = self.time_s if time_s is None else time_s
        return {f.actuator: f for f in self.failures if f.active(t)}

    @property
    def watchdog(self) -> str:
        if self.missed_periods >= self.safety.emergency_periods:
            return EMERGENCY_BRAKE
        if self.missed_periods >= self.safety.watchdog_periods:
            return SERVICE_BRAKE
        return NORMAL

    def permitted_speed(self) -> float:
        """The ATP's permitted speed at the lead car (static limits and braking curves), m/s."""
        return self.supervision.sampled_curve('permitted', self.lead_position(), self.leg)

    @property
    def atp_holds_to_standstill(self) -> bool:
        """The ATP's intervention is target-speed monitoring's: it holds until standstill."""
        return self.atp_intervention and self._hold_to_standstill

    @property
    def emergency_brake(self) -> bool:
        """The emergency brake is demanded (ATP intervention or the watchdog's last stage)."""
        return self.atp_intervention or self.missed_periods >= self.safety.emergency_periods

    def emergency_brake_share(self, time_s: float) -> float:
        """The emergency brake's force per actuated unit at a time, N (<= 0): linear from the
        demand to full over T_be, zero without a demand."""
        since = self.brake_since_s
        if since is None:
            return 0.0
        if self._build_up_s <= 0.0 or time_s - since >= self._build_up_s:
            return -self._eb_share
        return -self._eb_share * max(time_s - since, 0.0) / self._build_up_s

    def requests(self) -> list[float]:
        """What each healthy drive is asked for: the command, unless a safety function
        overrides it. It changes only when the command or a safety function does: this is what
        passes the dead time."""
        n = len(self.commanded)
        missed, safety = self.missed_periods, self.safety  # ``watchdog``, inlined: per step
        if self.atp_intervention or missed >= safety.emergency_periods:
            return [0.0] * n  # traction cut; the emergency brake is added in ``_failed``
        if missed >= safety.watchdog_periods:
            return [-self.scenario.train.traction.max_service_brake_force_n / n] * n
        return list(self.commanded)

    def _limited(self, requests: list[float]) -> list[float]:
        """Each request within its unit's share of the physical limits now: the traction
        characteristic at the lead car's speed (force, power P/v) and the emergency brake. The
        limit applies where the force is delivered, after the dead time: a drive asked for full
        traction a dead time ago delivers what the characteristic allows at today's speed."""
        traction = self.scenario.train.traction
        share = 1.0 / len(requests)
        highest = traction.max_traction_at(self.lead_speed()) * share
        lowest = -traction.max_emergency_brake_force_n * share
        return [lowest if f < lowest else highest if f > highest else f for f in requests]

    def targets(self) -> list[float]:
        """What each healthy drive delivers without actuator dynamics: its request within the
        physical limits now."""
        return self._limited(self.requests())

    def _failed(self, drive: Sequence[float], time_s: float, h: float = 0.0) -> tuple:
        """What acts on the train: the drives (failures included), traction cut under a
        brake demand, plus the emergency brake (sampled at the middle of the step)."""
        failures = self.active_failures(time_s) if self.failures else {}
        if failures:
            names = self.model.actuator_names
            drive = [failures[name].force(time_s + 0.5 * h, f) if name in failures else f
                     for name, f in zip(names, drive)]
        if self.brake_since_s is None and self.missed_periods < self.safety.watchdog_periods:
            return tuple(drive)
        brake = self.emergency_brake_share(time_s + 0.5 * h)
        return tuple((f if f < 0.0 else 0.0) + brake for f in drive)

    def _update_applied(self) -> None:
        if self.emergency_brake:
            if self.brake_since_s is None:
                self.brake_since_s = self.time_s
        else:
            self.brake_since_s = None
        if self._instant_actuators:
            self._drive = self.targets()
        self.applied = self._failed(self._drive, self.time_s)
        self._applied_for = self.state

    def _event_within(self, start_s: float, end_s: float) -> bool:
        """A scheduled time strictly inside (start_s, end_s), beyond the tolerance."""
        events = self._events
        i = bisect_right(events, start_s + EVENT_TOLERANCE_S)
        return i < len(events) and events[i] < end_s - EVENT_TOLERANCE_S

    def _actuate(self, time_s: float, h: float) -> tuple:
        """The forces held during the integration step [time_s, time_s + h]."""
        settings = self.setup.actuators
        if self._instant_actuators:
            self._drive = self.targets()
        else:
            requests = self.requests()
            if self._dead_time_s:
                requests = self._delayed(time_s, requests)
            targets = self._limited(requests)
            gain = 1.0 - math.exp(-h / settings.time_constant_s) if settings.time_constant_s \
                else 1.0
            max_change = settings.rate_limit_n_per_s * h if settings.rate_limit_n_per_s \
                else math.inf
            self._drive = [f + min(max(gain * (target - f), -max_change), max_change)
                           for f, target in zip(self._drive, targets)]
        return self._failed(self._drive, time_s, h)

    def _ask(self, time_s: float, requests: list[float]) -> None:
        """Note what the drives are asked for from ``time_s`` on (dead time)."""
        if requests != self._asked[-1][1]:
            self._asked.append((time_s, requests))

    def _delayed(self, time_s: float, requests: list[float]) -> list[float]:
        """What the drives act on at ``time_s``: the request of ``dead_time_s`` earlier."""
        self._ask(time_s, requests)
        asked, then = self._asked, time_s - self._dead_time_s + EVENT_TOLERANCE_S
        while len(asked) > 1 and asked[1][0] <= then:
            asked.pop(0)
        return asked[0][1]

    def _dead_time_events(self, start_s: float, end_s: float) -> list[float]:
        """Times in (start_s, end_s) at which a delayed request takes effect."""
        self._ask(start_s, self.requests())
        return [t + self._dead_time_s for t, _ in self._asked
                if start_s + EVENT_TOLERANCE_S < t + self._dead_time_s < end_s - EVENT_TOLERANCE_S]

    def intervention_speed(self) -> float:
        """The ATP's emergency brake intervention speed (EBI) at the lead car, m/s:
        ``supervision.sampled_curve('ebi', position, leg)``, the leg's table looked up once."""
        return self._leg_lookups()[0](self.lead_position())

    def _leg_lookups(self) -> tuple:
        """(the sampled EBI, the stop zone) of the leg under supervision, looked up again
        only when the leg moves on (the supervision's tables are built once and kept)."""
        run, leg, ebi, zone = self._leg_tables
        if leg != self.leg or run is not self.supervision:
            run, leg = self.supervision, self.leg
            ebi, zone = run.legs[leg].sampled('ebi'), run.stop_zone(leg)
            self._leg_tables = (run, leg, ebi, zone)
        return ebi, zone

    def _supervise(self) -> None:
        speed = self.lead_speed()
        if not self.atp_intervention and speed > self.intervention_speed():
            self.atp_intervention = True
            self.atp_interventions += 1
            self._hold_to_standstill = self.supervision.target_monitoring(
                self.leg, self.lead_position())
        elif self.atp_intervention and (self._standstill_release() if self._hold_to_standstill
                                        else speed <= self.permitted_speed()):
            self.atp_intervention = False
        self._track_stop()
        self._update_applied()

    def _standstill_release(self) -> bool:
        """Target-speed monitoring's brake ends at standstill short of the EOA; beyond it (a
        trip) it holds until the authority moves on."""
        return self.lead_speed() <= self.supervision.STANDSTILL_MPS and \
            self.lead_position() < self.supervision.legs[self.leg].end_of_authority_m

    def _track_stop(self) -> None:
        """The leg moves on once the stop's dwell has passed since the train first stood still
        at its stop (``RunSupervision.at_stop``), as long as it has stayed within the stop's
        zone: a train that starts off with the reference a moment before its own dwell is over
        (it arrived later than the reference) is still at the station. Where the train stands
        is what the on-board odometer reads (``odometer_error``): the ATO stops on that reading
        and the on-board unit reports it, so a biased odometer does not strand at a station a
        train that the ATO stopped there."""
        run = self.supervision
        low, high = self._leg_lookups()[1]
        position = self.lead_position()
        if self._odometer_errs:
            position += self.odometer_error(position)
        if not low <= position <= high:
            self._standing_since_s = None
            return
        now = self.time_s
        if self._standing_since_s is None:
            if abs(self.lead_speed()) > run.STANDSTILL_MPS:
                return
            self._standing_since_s = now
        if now - self._standing_since_s >= run.dwell_s(self.leg) - EVENT_TOLERANCE_S:
            self.leg += 1
            self._standing_since_s = None

    def advance(self, duration_ns: int) -> None:
        """Integrate one period: steps of at most the model's ``max_substep_s``, split at every
        scheduled time (modes, abrupt changes, failures, disturbance jumps)."""
        t = self.stamp_ns / NS_PER_S
        duration = duration_ns / NS_PER_S
        end = t + duration
        if self._one_step_possible and duration <= self.model.max_substep_s and \
                not self._event_within(t, end):
            # One integration step and nothing switches within it: the general loop's result,
            # without its bookkeeping. Instant actuators deliver what ``_update_applied`` last
            # computed, if for this state (and no failure samples its force within the step).
            forces = (self.applied if self._applied_for is self.state and not self.failures
                      and self.brake_since_s is None else self._actuate(t, duration))
            env = self._env if self._constant_env and self._env is not None \
                else self.surroundings(t)
            self.state = self.model.step(self.state, duration, forces, t, env)
            self.stamp_ns += duration_ns
            self._supervise()
            return
        substeps = max(1, math.ceil(duration / self.model.max_substep_s - 1e-9))
        h_nominal = duration / substeps
        events = [e for e in self._events if t + EVENT_TOLERANCE_S < e < end - EVENT_TOLERANCE_S]
        if self.setup.disturbance.kind == 'random':
            events = sorted(set(events) | set(self.setup.disturbance.switch_times(t, end)))
        if self._dead_time_s:
            events = sorted(set(events) | set(self._dead_time_events(t, end)))
        boundaries = sorted(set([t + k * h_nominal for k in range(1, substeps)] + events))
        boundaries = [b for b in boundaries if b < end - EVENT_TOLERANCE_S] + [end]
        for stop in boundaries:
            h = stop - t
            if h <= EVENT_TOLERANCE_S:
                continue
            if abs(h - h_nominal) < EVENT_TOLERANCE_S:
                h = h_nominal  # one step length: the multi-car propagators stay cached
            env = self.surroundings(t)
            forces = self._actuate(t, h)
            self.state = self.model.step(self.state, h, forces, t, env)
            t = stop
        self.stamp_ns += duration_ns
        self._supervise()

    def run_commands(self, commands, period_ns: int) -> Trajectory:
        """Hold each row of ``commands`` (one force per actuator, N) for one control period:
        the same as ``apply_command(row)``, ``advance(period_ns)`` and ``truth()`` for each
        row, to the last bit, and many times faster where the compiled path applies
        (``periods.py``: instant actuators, constant surroundings, no failure active, one
        integration step per period; elsewhere, around every scheduled time and in a period
        where a car of the multi-car model crosses a line boundary, period by period). For
        open-loop runs: commands from a file, identification, Monte Carlo. The sensors are not
        sampled on the way (``measured()`` afterwards reads the final state).

        Every row is checked before the first period: a wrong shape or a non-finite force
        raises CommandRejected naming the row, and the simulation is left as it was."""
        names = self.actuator_names
        try:
            forces = np.array(commands, dtype=float, ndmin=2)
        except (TypeError, ValueError) as error:
            raise CommandRejected(f'commands must be a table of forces: {error}') from None
        if forces.ndim != 2 or forces.shape[1] != len(names):
            raise CommandRejected(f'commands of shape {forces.shape}: need one row per period '
                                  f'of {len(names)} forces {list(names)}')
        finite = np.isfinite(forces).all(axis=1)
        if not finite.all():
            row = int(np.argmin(finite))
            raise CommandRejected(f'row {row}: non-finite force in {forces[row].tolist()}')
        if isinstance(period_ns, bool) or not isinstance(period_ns, (int, np.integer)) \
                or period_ns <= 0:
            raise ValueError(f'period_ns must be a positive integer, got {period_ns!r}')
        period_ns = int(period_ns)
        periods, cars = len(forces), len(self.model.car_names)
        stamps = self.stamp_ns + period_ns * np.arange(1, periods + 1, dtype=np.int64)
        quantities = [np.empty((periods, cars)) for _ in range(4)]
        interventions = np.empty(periods, dtype=bool)
        rows = None  # the commands as tuples of floats, once some periods run one by one
        k = 0
        while k < periods:
            batch = self._compiled_periods(periods - k, period_ns)
            if batch:
                done = self._run_compiled(forces[k:k + batch], period_ns,
                                          [q[k:k + batch] for q in quantities],
                                          interventions[k:k + batch])
                k += done
                if done:
                    continue
            end = k  # then at least one period by the interface
            outputs, held = [], []
            rows = rows or forces.tolist()
            while end < periods and (end == k or not self._compiled_periods(1, period_ns)):
                self._hold(tuple(rows[end]))  # ``apply_command``, checked above
                self.advance(period_ns)
                outputs.append(self._outputs())
                held.append(self.atp_intervention)
                end += 1
            for q, values in zip(quantities, zip(*outputs)):
                q[k:end] = values
            interventions[k:end] = held
            k = end
        return Trajectory(self.model.car_names, stamps, *quantities, interventions)

    def _compiled_periods(self, wanted: int, period_ns: int) -> int:
        """How many of the next ``wanted`` periods ``periods.py``'s kernels may run: those in
        which ``advance`` would take its one-step path with nothing switching, and that end
        before the next scheduled time, so that no failure acts at any of them."""
        # Imported here: it loads every model's module, which a node of one model need not.
        from train_plant_node.periods import period_kernel
        if not (self._one_step_possible and self._constant_env
                and period_kernel(self.model) is not None
                and period_ns / NS_PER_S <= self.model.max_substep_s):
            return 0
        if self.failures and self.active_failures():
            return 0
        if self.emergency_brake or self.missed_periods or self._standing_since_s is not None:
            return 0  # braking, or dwelling at a stop: period by period
        i = bisect_right(self._events, self.time_s + EVENT_TOLERANCE_S)
        if i == len(self._events):
            return wanted
        before = self._events[i] - EVENT_TOLERANCE_S
        count = max(0, int((before - self.time_s) * NS_PER_S / period_ns))
        while count > 0 and (self.stamp_ns + count * period_ns) / NS_PER_S >= before:
            count -= 1
        while count < wanted and (self.stamp_ns + (count + 1) * period_ns) / NS_PER_S < before:
            count += 1
        return min(count, wanted)

    def _run_compiled(self, forces: np.ndarray, period_ns: int, out: list[np.ndarray],
                      interventions: np.ndarray) -> int:
        """Up to ``len(forces)`` periods in ``periods``' kernel; returns how many ran."""
        from train_plant_node.periods import period_kernel
        run = self.supervision
        if self._packed_supervision is None:
            self._packed_supervision = (*run.packed_curve('ebi'), *run.packed_curve('permitted'))
        low, high = run.stop_zone(self.leg)
        if self._odometer_errs:  # the zone of the odometer's reading, in true positions
            low, high = self._true_position(low), self._true_position(high)
        atp = (np.int64(self.leg), low, high, run.STANDSTILL_MPS, *self._packed_supervision)
        traction = self.scenario.train.traction
        state = np.array(self.state, dtype=float)
        done, intervention, began = period_kernel(self.model)(
            state, self.stamp_ns, period_ns, forces,
            (traction.max_traction_force_n, traction.max_traction_power_w,
             traction.max_emergency_brake_force_n), atp,
            self.atp_intervention, *out, interventions,
            self.model.kernel_inputs(self.surroundings(), period_ns / NS_PER_S))
        if done:
            self.state = state
            self.stamp_ns += period_ns * done
            self.atp_intervention = bool(intervention)
            self.atp_interventions += began
            if began:
                self._hold_to_standstill = run.target_monitoring(self.leg, self.lead_position())
            self._track_stop()
            self._hold(tuple(forces[done - 1].tolist()))
        return done

    # --- outputs -------------------------------------------------------------------------------
    def truth(self) -> TrainState:
        return TrainState(self.stamp_ns, self.model.car_names, *self._outputs())

    def _outputs(self) -> tuple:
        """(positions, speeds, accelerations, forces) per car now."""
        env = self._env if self._constant_env and self._env is not None else self.surroundings()
        return self.model.outputs(self.state, self.applied, self.stamp_ns / NS_PER_S, env)

    def odometer_error(self, position_m: float) -> float:
        """The position sensor's systematic error at a true position, m: its bias plus its
        scale error times the distance run since the odometer's last reset point
        (``QuantitySensor``); no noise."""
        sensor = self.sensors.position
        if not sensor.scale_error:
            return sensor.bias
        return sensor.bias + sensor.scale_error * max(
            position_m - self._odometer_start(position_m), 0.0)

    def _odometer_start(self, position_m: float) -> float:
        """The odometer's last reset point at or behind a position: the run's initial position
        or the last of the position sensor's ``reset_positions_m``."""
        resets = self.sensors.position.reset_positions_m
        i = bisect_right(resets, position_m)
        return max(self.scenario.run.initial_position_m, resets[i - 1] if i else -math.inf)

    def _true_position(self, reading_m: float) -> float:
        """The true position at which the odometer reads ``reading_m``: x + s (x - r) + bias =
        reading, x = r + (reading - bias - r) / (1 + s) (exact unless a reset point lies
        within the error of the reading)."""
        bias, s = self.sensors.position.bias, self.sensors.position.scale_error
        x = reading_m - bias
        if not (s and math.isfinite(x)):
            return x
        start = self._odometer_start(x)
        return x if x <= start else start + (x - start) / (1.0 + s)

    def _scaled(self, values: Sequence[float], sensor: QuantitySensor,
                distance: bool) -> Sequence[float]:
        """The truth as the scale error reads it: (1 + s) v, or x + (the systematic error of
        ``odometer_error`` without its bias) for a position (``distance``)."""
        if not sensor.scale_error:
            return values
        if distance:
            bias = sensor.bias
            return [x + self.odometer_error(x) - bias for x in values]
        return [(1.0 + sensor.scale_error) * v for v in values]

    def _measure(self, values: Sequence[float], sensor: QuantitySensor,
                 cars: Sequence[str], distance: bool = False) -> tuple[float, ...]:
        """Truth with its scale error, + bias + white noise, quantised; NaN when dropped out
        or failed."""
        if sensor.ideal:
            return tuple(values)
        values = self._scaled(values, sensor, distance)
        n = len(values)
        noise = (self._rng.normal(0.0, sensor.noise_std, n) if sensor.noise_std
                 else np.zeros(n))
        dropped = (self._rng.random(n) < sensor.dropout_probability
                   if sensor.dropout_probability else np.zeros(n, dtype=bool))
        out = []
        for value, e, drop, car in zip(values, noise, dropped, cars):
            if drop or sensor.failed(self.time_s, car):
                out.append(math.nan)
                continue
            value = value + sensor.bias + float(e)
            if sensor.quantum:
                value = round(value / sensor.quantum) * sensor.quantum
            out.append(value)
        return tuple(out)

    def measured(self, truth: TrainState | None = None) -> TrainState:
        """What the on-board sensors report; a missing measurement is NaN."""
        truth = truth or self.truth()
        s = self.sensors
        sensors, ideal = self._sensors_ideal
        if sensors is not s:
            ideal = s.ideal
            self._sensors_ideal = (s, ideal)
        if ideal:
            return truth
        cars = truth.car_names
        return TrainState(truth.stamp_ns, cars,
                          self._measure(truth.positions, s.position, cars, distance=True),
                          self._measure(truth.speeds, s.speed, cars),
                          self._measure(truth.accelerations, s.acceleration, cars), truth.forces)


def control_period_ns(rate_hz: float) -> int:
    return nanoseconds(1.0 / rate_hz)
