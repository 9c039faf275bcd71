"""The plant's actuators: one per actuated unit (per motor, or per power car), and the emergency
brake, a brake system of its own.

What a drive is asked for (the request) is the ATO's command unless a safety function overrides
it (``requests``: the ATP's or the watchdog's emergency brake cuts traction; the watchdog's
service brake and the ATP's holding brake at a stop apply the service brake). The request
passes a dead time, is limited to the unit's equal share of the train's traction
characteristic (force, power P/v, at the speed of that moment) and of its emergency brake, and
then passes a first-order lag and a rate limit. These run at the integration step: the drive
holds its force within a step, as a traction controller sampling at that rate does, so every
model step is a zero-order hold. The dead time delays what each drive is asked for (not the
emergency brake, which has its own build-up time): integration steps are split where a delayed
request takes effect (``dead_time_events``), so the delay is exact, not rounded to a step.

A failure (Mao et al. 2017 eqs 13-20) replaces what the unit delivers from its start time; a
stuck signal is sampled at the middle of each integration step. Under a traction cut-off (the
emergency brake's, the service brake's) every drive, healthy or failed,
delivers at most zero, and the emergency brake adds the train's ``max_emergency_brake_force_n``,
shared over the units and built up linearly from the demand over T_be: no drive failure cancels
it. The train interface reports a drive that delivers traction it is not asked for
(``drive_fault``): the ATP holds its brake while one does.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

from ato_common.plant_setup import ActuatorFailure, ActuatorSettings
from ato_common.trains import TrainParameters
from ato_common.units import STANDARD_GRAVITY

# The highest wheel-rail adhesion coefficient of dry rail: no drive, however it fails, pushes
# or brakes the train harder than the train's whole weight times it (the wheels slip).
PEAK_ADHESION = 0.4

#: what the safety functions make of the drives, in increasing order: the ATO's command
#: (DRIVE), the service brake with traction cut (SERVICE: the watchdog's first stage, the
#: ATP's holding brake at a stop), the emergency brake (EMERGENCY, traction cut)
DRIVE, SERVICE, EMERGENCY = 0, 1, 2

# A scheduled time this close to a step boundary is on it (time is float seconds here).
EVENT_TOLERANCE_S = 1e-9


class CommandRejected(ValueError):
    """A command that must not reach the actuators; the message says why."""


class FailureRejected(ValueError):
    """A failure no drive could physically produce; the message names the field and bound."""


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


class Actuators:
    """The drives and the emergency brake of a train (module docstring). ``drive`` is what each
    healthy drive delivers after its lag and limits; ``brake_since_s`` since when the emergency
    brake is demanded (None: it is not)."""

    def __init__(self, settings: ActuatorSettings, failures: Sequence[ActuatorFailure],
                 train: TrainParameters, names: tuple[str, ...], build_up_s: float):
        self.settings = settings
        self.train = train
        self.names = names
        n = len(names)
        for failure in failures:
            check_failure(failure, train)
        self.failures: list[ActuatorFailure] = list(failures)
        self.drive = [0.0] * n
        self.brake_since_s: float | None = None
        self.instant = settings.time_constant_s == 0.0 and \
            settings.rate_limit_n_per_s == 0.0 and settings.dead_time_s == 0.0
        self.build_up_s = build_up_s
        self._eb_share = train.traction.max_emergency_brake_force_n / n
        self._service_share = train.traction.max_service_brake_force_n / n
        # What the drives were asked for and since when, (time_s, targets), oldest first: the
        # requests still to take effect after the dead time, and the one in effect.
        self._asked: list[tuple[float, list[float]]] = [(-math.inf, [0.0] * n)]

    # --- failures ------------------------------------------------------------------------------
    def inject(self, failures: Sequence[ActuatorFailure], repaired: Sequence[str],
               now_s: float) -> None:
        """Run-time failures: each replaces any failure of its actuator from its start time on;
        the actuators in ``repaired`` become healthy now."""
        for failure in failures:
            check_failure(failure, self.train)
        current = self.failures
        for failure in failures:
            current = [f if f.actuator != failure.actuator or f.end_s <= failure.start_s
                       else replace(f, end_s=failure.start_s)
                       for f in current if not (f.actuator == failure.actuator
                                                and f.start_s >= failure.start_s)]
            current.append(failure)
        for name in repaired:
            current = [f if f.actuator != name or f.end_s <= now_s else replace(f, end_s=now_s)
                       for f in current if not (f.actuator == name and f.start_s > now_s)]
        self.failures = [f for f in current if f.end_s > f.start_s]

    def active(self, time_s: float) -> dict[str, ActuatorFailure]:
        return {f.actuator: f for f in self.failures if f.active(time_s)}

    def drive_fault(self, time_s: float) -> bool:
        """The train interface's fault report: a failed drive delivers traction although asked
        for none (a stuck drive pushing against the traction cut-off)."""
        return bool(self.failures) and any(
            f.force(time_s, 0.0) > 0.0 for f in self.active(time_s).values())

    # --- what the drives are asked for and deliver ----------------------------------------------
    def demand(self, level: int, time_s: float) -> None:
        """The safety functions' demand now (``DRIVE`` ... ``EMERGENCY``): the emergency brake
        builds up from the moment it is first demanded."""
        if level == EMERGENCY:
            if self.brake_since_s is None:
                self.brake_since_s = time_s
        else:
            self.brake_since_s = None

    def emergency_brake_share(self, time_s: float) -> float:
        """The emergency brake's force per actuated unit at a time, N (<= 0): linear from the
        demand to full over T_be, zero without a demand."""
        since = self.brake_since_s
        if since is None:
            return 0.0
        if self.build_up_s <= 0.0 or time_s - since >= self.build_up_s:
            return -self._eb_share
        return -self._eb_share * max(time_s - since, 0.0) / self.build_up_s

    def requests(self, commanded: Sequence[float], level: int) -> list[float]:
        """What each healthy drive is asked for at a safety level: the command, unless a
        safety function overrides it. It changes only when the command or a safety function
        does: this is what passes the dead time."""
        if level == DRIVE:
            return list(commanded)
        if level == EMERGENCY:
            return [0.0] * len(commanded)  # traction cut; the brake is added in ``delivered``
        return [-self._service_share] * len(commanded)  # SERVICE

    def limited(self, requests: list[float], speed_mps: float) -> list[float]:
        """Each request within its unit's share of the physical limits now: the traction
        characteristic at the lead car's speed (force, power P/v) and the emergency brake. The
        limit applies where the force is delivered, after the dead time: a drive asked for full
        traction a dead time ago delivers what the characteristic allows at today's speed."""
        traction = self.train.traction
        share = 1.0 / len(requests)
        highest = traction.max_traction_at(speed_mps) * share
        lowest = -traction.max_emergency_brake_force_n * share
        return [lowest if f < lowest else highest if f > highest else f for f in requests]

    def targets(self, commanded: Sequence[float], level: int, speed_mps: float) -> list[float]:
        """What each healthy drive delivers without actuator dynamics: its request within the
        physical limits now."""
        return self.limited(self.requests(commanded, level), speed_mps)

    def delivered(self, drive: Sequence[float], level: int, time_s: float,
                  h: float = 0.0) -> tuple:
        """What acts on the train: the drives (failures included), traction cut under any
        safety demand, plus the emergency brake (sampled at the middle of the step)."""
        failures = self.active(time_s) if self.failures else {}
        if failures:
            drive = [failures[name].force(time_s + 0.5 * h, f) if name in failures else f
                     for name, f in zip(self.names, drive)]
        if level == DRIVE:
            return tuple(drive)
        brake = self.emergency_brake_share(time_s + 0.5 * h)
        return tuple((f if f < 0.0 else 0.0) + brake for f in drive)

    def forces(self, commanded: Sequence[float], level: int, speed_mps: float, time_s: float,
               h: float) -> tuple:
        """The forces held during the integration step [time_s, time_s + h]."""
        settings = self.settings
        if self.instant:
            self.drive = self.targets(commanded, level, speed_mps)
        else:
            requests = self.requests(commanded, level)
            if settings.dead_time_s:
                requests = self._delayed(time_s, requests)
            targets = self.limited(requests, speed_mps)
            gain = 1.0 - math.exp(-h / settings.time_constant_s) if settings.time_constant_s \
                else 1.0
            max_change = settings.rate_limit_n_per_s * h if settings.rate_limit_n_per_s \
                else math.inf
            self.drive = [f + min(max(gain * (target - f), -max_change), max_change)
                          for f, target in zip(self.drive, targets)]
        return self.delivered(self.drive, level, time_s, h)

    # --- dead time -----------------------------------------------------------------------------
    def _ask(self, time_s: float, requests: list[float]) -> None:
        """Note what the drives are asked for from ``time_s`` on (dead time)."""
        if requests != self._asked[-1][1]:
            self._asked.append((time_s, requests))

    def _delayed(self, time_s: float, requests: list[float]) -> list[float]:
        """What the drives act on at ``time_s``: the request of ``dead_time_s`` earlier."""
        self._ask(time_s, requests)
        asked, then = self._asked, time_s - self.settings.dead_time_s + EVENT_TOLERANCE_S
        while len(asked) > 1 and asked[1][0] <= then:
            asked.pop(0)
        return asked[0][1]

    def dead_time_events(self, start_s: float, end_s: float, commanded: Sequence[float],
                         level: int) -> list[float]:
        """Times in (start_s, end_s) at which a delayed request takes effect."""
        self._ask(start_s, self.requests(commanded, level))
        delay = self.settings.dead_time_s
        return [t + delay for t, _ in self._asked
                if start_s + EVENT_TOLERANCE_S < t + delay < end_s - EVENT_TOLERANCE_S]
