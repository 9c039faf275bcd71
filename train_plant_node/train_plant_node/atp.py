"""The on-board ATP: the speed and distance supervision of an ETCS on-board unit (the EVC),
SUBSET-026 3.13 in spirit, as a unit of its own beside the plant.

**What it knows** (the line between truth and knowledge runs here): the movement authority of
each leg with its braking curves (:class:`ato_common.braking_curves.RunSupervision`, built from
the line's declared data and the train data), the train data of
:class:`~ato_common.braking_curves.SupervisionSettings` (its traction acceleration), the line's
declared gradients, and, each cycle, what the train's own odometry reports (an
:class:`OdometryReading`: the estimated front end with its confidence interval, the estimated
speed with its accuracy, whether the train stands) and the train interface's fault report of the
traction drives. It never reads the plant's true position or speed: the plant keeps those for
the physics and to judge the supervision.

**Interface** (an EVC's): ``cycle(time_s, period_s, odometry, drive_fault)`` once per control
cycle; the demands to the train ``emergency_brake`` (with traction cut-off) and
``holding_brake``; for the driver's
display and the diagnostics ``permitted_speed``, ``intervention_speed``, ``status``, the leg of
the run under supervision (``leg``) and the count of ``interventions``.

**Supervision**, each cycle:

- *Anticipated over-speed check*: the train could run one more cycle before the next check sees
  it, accelerating at up to A (the train's traction acceleration plus the line's steepest
  descent, or the acceleration the odometry measured over the last cycle if higher, at most
  the adhesion cap). The ATP intervenes when at the end of such a cycle the speed, from the
  upper end of the speed interval, would exceed the EBI at the max safe front end
  (V_est + V_acc + A T > EBI(max safe front + (V_est + V_acc) T + A T^2 / 2)), the ceiling taken
  as the lowest over the whole interval from the min safe front end (a speed increase applies
  once the whole interval has left the lower limit). So the speed is at the EBI or under it at
  every check, and a train released at standstill close to its EOA cannot hop past it in the
  cycle before the next check (issue 29's 1-15 mm past the EOA). Without odometry (both of its
  channels failed) the ATP intervenes.
- *Intervention*: an emergency brake with traction cut-off that the ATO cannot override. In
  ceiling supervision it is released once the speed interval is at or under the permitted speed;
  in target-speed monitoring (the stop's curve or its release speed is the EBI) at standstill
  once the check passes again (beyond the EOA, a trip, never: until the authority moves on).
  Neither is released while the train interface reports a traction drive that delivers force
  it is not asked for (a stuck drive): the cause of the intervention is still there, so the
  emergency brake and the traction cut-off hold until the failure is isolated.
- *Stops*: the authority of a leg moves on to the next leg only after a continuous standstill
  of the stop's dwell in the stop's zone (from ``STOP_WINDOW_M`` before the stopping point to
  the SvL), the train taken as in the zone if its confidence interval reaches into it (an
  odometry that errs by less than its interval does not strand the train). While the train
  stands there before the dwell is over it is held (``holding_brake``: traction cut off and the
  service brake applied, as a train standing with its doors open is): a train that arrived late
  cannot start off with its reference before it has dwelt, a descent does not roll it on, and no
  hop breaks its standstill.
"""

from __future__ import annotations

from bisect import bisect_right
from typing import Protocol

from ato_common.braking_curves import RunSupervision, SampledLimit, SupervisionSettings
from ato_common.line import Line
from ato_common.units import STANDARD_GRAVITY

#: no estimate of the train's acceleration is taken above this (m/s^2): no train accelerates
#: faster than the highest wheel-rail adhesion of dry rail (0.4) lets it
ACCELERATION_CAP_MPS2 = 0.4 * STANDARD_GRAVITY

NORMAL = 'normal'
#: a dwell this close to complete is complete (times are float seconds)
DWELL_TOLERANCE_S = 1e-9


class OdometryReading(Protocol):
    """What the ATP reads from the train's odometry each cycle (SUBSET-026 3.6.4): the
    estimated front end and the confidence interval around it, m; the estimated speed and its
    accuracy, m/s; standstill; and whether the odometry works at all."""

    position_m: float
    min_safe_front_m: float
    max_safe_front_m: float
    speed_mps: float
    max_speed_mps: float
    standstill: bool
    valid: bool


def highest_acceleration(settings: SupervisionSettings, line: Line) -> float:
    """The acceleration the ATP assumes a train may have during a cycle, m/s^2: its traction
    acceleration (train data) plus gravity on the line's steepest declared descent."""
    descent = max(0.0, -min(line.grade_sine.values, default=0.0))
    return settings.traction_acceleration_mps2 + STANDARD_GRAVITY * descent


class OnboardATP:
    """The EVC's supervision of one run (module docstring). ``run`` holds one authority per
    leg; ``acceleration_mps2`` is :func:`highest_acceleration`; ``start_speed_mps`` the speed
    the odometry reads before the first cycle."""

    def __init__(self, run: RunSupervision, acceleration_mps2: float,
                 start_speed_mps: float = 0.0):
        self.run = run
        self.acceleration_mps2 = acceleration_mps2
        self._leg(0)
        self.emergency_brake = False
        self.interventions = 0
        self.hold_to_standstill = False   # the intervention is target-speed monitoring's
        self.standing_since_s: float | None = None  # continuous standstill in the stop zone
        self.previous_speed_mps = start_speed_mps   # the odometry's speed at the last cycle
        self.odometry_lost = False

    def _leg(self, leg: int) -> None:
        """The leg ``leg`` is under supervision: its tables are looked up once."""
        self.leg = leg
        self._tables: dict[str, tuple[SampledLimit, list[float], list[float]]] = {}
        self._zone = self.run.stop_zone(leg)
        self._dwell_s = self.run.dwell_s(leg)

    @property
    def holding_brake(self) -> bool:
        """The train is held at standstill while it dwells at a stop (module docstring)."""
        return self.standing_since_s is not None

    # --- the limits ----------------------------------------------------------------------------
    def limit(self, name: str, low_m: float, high_m: float) -> float:
        """The named limit for a front end anywhere in [low_m, high_m]: the sampled limit at
        ``high_m`` (curves fall towards their targets) and the lowest ceiling over the
        interval (a higher limit applies once the whole interval has left the lower one)."""
        table = self._tables.get(name)
        if table is None:  # the leg's sampled limit and its ceiling, built once per leg
            authority = self.run.legs[self.leg]
            table = self._tables[name] = (authority.sampled(name), *authority.ceiling(name))
        sampled, starts, ceilings = table
        value = sampled(high_m)
        first = bisect_right(starts, low_m) - 1
        last = bisect_right(starts, high_m) - 1
        if last > first:
            value = min(value, min(ceilings[max(first, 0):last + 1]))
        return value

    def permitted_speed(self, odometry: OdometryReading) -> float:
        """The permitted speed for the train's confidence interval, m/s."""
        return self.limit('permitted', odometry.min_safe_front_m, odometry.max_safe_front_m)

    def intervention_speed(self, odometry: OdometryReading) -> float:
        """The EBI for the train's confidence interval (without the anticipated cycle), m/s."""
        return self.limit('ebi', odometry.min_safe_front_m, odometry.max_safe_front_m)

    # --- the cycle -----------------------------------------------------------------------------
    def over_speed(self, odometry: OdometryReading, period_s: float) -> bool:
        """The anticipated check (module docstring): one more cycle at up to the highest
        acceleration could take the speed interval over the EBI. (``periods.supervise`` does
        the same in compiled code, in the same operations.)"""
        speed = odometry.max_speed_mps
        measured = (odometry.speed_mps - self.previous_speed_mps) / period_s
        a = max(self.acceleration_mps2, min(measured, ACCELERATION_CAP_MPS2))
        ahead = odometry.max_safe_front_m + speed * period_s + 0.5 * a * period_s * period_s
        return speed + a * period_s > self.limit('ebi', odometry.min_safe_front_m, ahead)

    def cycle(self, time_s: float, period_s: float, odometry: OdometryReading,
              drive_fault: bool) -> None:
        """One supervision cycle at ``time_s``, ``period_s`` after the last: the check, the
        intervention and its release, the stop. ``drive_fault``: the train interface reports a
        traction drive delivering force it is not asked for."""
        self.odometry_lost = not odometry.valid
        if self.odometry_lost:
            over = True
        else:
            over = period_s > 0.0 and self.over_speed(odometry, period_s)
            self.previous_speed_mps = odometry.speed_mps
        if not self.emergency_brake:
            if over:
                self.begin(odometry)
        elif not drive_fault and self._released(odometry, over):
            self.emergency_brake = False
        self.track_stop(time_s, odometry)

    def begin(self, odometry: OdometryReading) -> None:
        """An intervention begins: target-speed monitoring's when the leg's stop sets the EBI
        at the max safe front end (or the odometry is lost)."""
        self.emergency_brake = True
        self.interventions += 1
        self.hold_to_standstill = self.odometry_lost or self.run.target_monitoring(
            self.leg, odometry.max_safe_front_m)

    def _released(self, odometry: OdometryReading, over: bool) -> bool:
        if self.hold_to_standstill:
            return odometry.standstill and not over
        return odometry.max_speed_mps <= self.permitted_speed(odometry)

    def track_stop(self, time_s: float, odometry: OdometryReading) -> None:
        """The authority moves on after a continuous standstill of the dwell in the stop zone
        (module docstring)."""
        low, high = self._zone
        if not (odometry.standstill and odometry.max_safe_front_m >= low
                and odometry.min_safe_front_m <= high and odometry.valid):
            self.standing_since_s = None
            return
        if self.standing_since_s is None:
            self.standing_since_s = time_s
        if time_s - self.standing_since_s >= self._dwell_s - DWELL_TOLERANCE_S:
            self._leg(self.leg + 1)
            self.standing_since_s = None

    def status(self, odometry: OdometryReading) -> str:
        """The supervision status in words ('normal' when nothing acts)."""
        if self.emergency_brake:
            kind = ('odometry lost' if self.odometry_lost else 'target-speed monitoring'
                    if self.hold_to_standstill else 'ceiling supervision')
            return f'intervention ({kind})'
        if self.standing_since_s is not None:
            return 'dwelling at the stop: held at standstill until the dwell is over'
        return NORMAL

