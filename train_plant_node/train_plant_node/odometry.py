"""The ATP's odometry: where the train is and how fast it goes, as an EVC's odometry knows it
(SUBSET-026 3.6.4, SUBSET-041 5.3.1), with its confidence interval.

Knowledge side: it reads only the odometer (its count and its speed, each NaN where its sensor
has failed: :meth:`train_plant_node.sensors.Sensors.odometer`), the balise groups the train
passes with the count at each, the line's declared balise group positions and the train's
declared odometry accuracy (:class:`ato_common.braking_curves.SupervisionSettings`).

- **Relocation** at each balise group passed (the last relevant balise group, LRBG): the
  estimated front end is the group's position plus the distance counted since, so an error of
  the count (a wrong start position, a scale error, an integrated speed bias) does not outlive
  the next balise group.
- **Calibration**: the odometer's scale is the count between the last two balise groups passed
  over their declared distance (once they are ``CALIBRATION_MIN_M`` apart); distances and the
  speed are divided by it, as an EVC calibrates its wheel diameter against balise distances.
  Until two groups have been passed the scale is taken as 1.
- **Confidence interval**: ``location_accuracy_m`` plus ``odometry_accuracy`` times the distance
  counted since the LRBG (or since the start of the run), on each side of the estimate (min and
  max safe front end); the speed's accuracy ``speed_accuracy_mps`` plus ``speed_accuracy_share``
  times the speed, none while the wheel stands (it turns or it does not).
- **A failed channel**: without a speed the odometry differentiates its count over the cycle
  (and widens the speed's accuracy by what the train can gain in a cycle); without a count it
  integrates its speed; without both it is lost (``valid`` False) and the ATP brakes.

With an exact odometer the estimate is the truth to the last bit, its interval the declared
accuracy since the last balise group passed (``exact``: the compiled periods of ``periods.py``
compute the same in the same operations).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from typing import Sequence

from ato_common.braking_curves import SupervisionSettings

#: the shortest distance between two balise groups over which the odometry calibrates, m
CALIBRATION_MIN_M = 100.0


class Odometry:
    """The odometry of one run (module docstring). ``count_m`` and ``speed_mps``: the
    odometer's first reading (the start of mission); ``standstill_mps``: the speed up to which
    the train stands; ``acceleration_mps2``: the most the train can gain per second (a failed
    speed channel's accuracy); ``balise_groups_m``: the line's declared balise groups."""

    def __init__(self, settings: SupervisionSettings, count_m: float, speed_mps: float,
                 standstill_mps: float, acceleration_mps2: float,
                 balise_groups_m: Sequence[float] = ()):
        self.location_accuracy_m = settings.location_accuracy_m
        self.odometry_accuracy = settings.odometry_accuracy
        self.speed_accuracy_mps = settings.speed_accuracy_mps
        self.speed_accuracy_share = settings.speed_accuracy_share
        self.exact_accuracy = not (self.location_accuracy_m or self.odometry_accuracy
                                   or self.speed_accuracy_mps or self.speed_accuracy_share)
        self.standstill_mps = standstill_mps
        self.acceleration_mps2 = acceleration_mps2
        self.scale = 1.0          # the calibrated odometer scale (count per metre)
        self._correction = 0.0    # 1 / scale - 1
        self.lrbg_m: float | None = None   # the last relevant balise group's position
        self._fix = (count_m, count_m)     # (position, count) the estimate is counted from
        self.relocations = 0
        self.outside_interval = 0  # balise groups found outside the confidence interval
        self.last_discrepancy_m = 0.0
        # the balise groups ahead of the start, and how many of them the train has passed
        self.groups_ahead_m = tuple(x for x in balise_groups_m if x > count_m)
        self._passed = 0
        self._count = count_m
        self._raw_speed = speed_mps if math.isfinite(speed_mps) else 0.0
        self.position_m = self.min_safe_front_m = self.max_safe_front_m = count_m
        self.speed_mps = self.max_speed_mps = self._raw_speed
        self.standstill = abs(self._raw_speed) <= standstill_mps
        self.valid = True

    def exact(self, position_m: float, speed_mps: float) -> None:
        """This cycle's reading of an exact odometer: the estimate is the reading itself, the
        interval the declared accuracy since the last balise group passed, found from the
        line's groups (what ``update`` gives then, without its arithmetic: a relocation at a
        group the count places exactly finds no discrepancy and keeps the scale at 1)."""
        self.position_m, self.speed_mps = position_m, speed_mps
        self._count, self._raw_speed = position_m, speed_mps
        self.standstill = abs(speed_mps) <= self.standstill_mps
        self.valid = True
        if self.exact_accuracy:
            self.min_safe_front_m = self.max_safe_front_m = position_m
            self.max_speed_mps = speed_mps
            return
        groups = self.groups_ahead_m
        passed = bisect_right(groups, position_m)
        if passed > self._passed:
            self.relocations += passed - self._passed
            self._passed = passed
            self.lrbg_m = groups[passed - 1]
            self._fix = (self.lrbg_m, self.lrbg_m)
            self.last_discrepancy_m = 0.0
        half = self.location_accuracy_m + self.odometry_accuracy * abs(position_m - self._fix[1])
        self.min_safe_front_m = position_m - half
        self.max_safe_front_m = position_m + half
        accuracy = (self.speed_accuracy_mps + self.speed_accuracy_share * abs(speed_mps)
                    if speed_mps != 0.0 else 0.0)
        self.max_speed_mps = speed_mps + accuracy

    @property
    def fix_m(self) -> float:
        """The count the estimate is counted from (the last balise group's, or the start's)."""
        return self._fix[1]

    @property
    def passed(self) -> int:
        """How many of the balise groups ahead of the start the train has passed."""
        return self._passed

    def update(self, period_s: float, count_m: float, speed_mps: float,
               passed: Sequence[tuple[float, float]] = ()) -> None:
        """One cycle ``period_s`` after the last: the odometer's count and speed (NaN: that
        sensor failed) and the balise groups passed since, each (position, count there)."""
        count_ok, speed_ok = math.isfinite(count_m), math.isfinite(speed_mps)
        self.valid = count_ok or speed_ok
        if not self.valid:
            return
        widen = 0.0
        if not count_ok:     # integrate the speed
            count_m = self._count + 0.5 * (speed_mps + self._raw_speed) * period_s
        elif not speed_ok:   # differentiate the count
            speed_mps = (count_m - self._count) / period_s if period_s > 0.0 else 0.0
            widen = self.acceleration_mps2 * period_s
        self._count, self._raw_speed = count_m, speed_mps
        for position, at in passed:
            self._relocate(position, at if math.isfinite(at) else count_m)
        self._estimate(count_m, speed_mps, widen)

    def _relocate(self, position_m: float, count_m: float) -> None:
        """A balise group passed: note how far from it the odometry thought the train was,
        calibrate against the previous group, and count from it."""
        estimate = self._position(count_m)
        self.last_discrepancy_m = estimate - position_m
        if abs(self.last_discrepancy_m) > self._half_width(count_m) + 1e-9:
            self.outside_interval += 1
        previous = self._fix if self.lrbg_m is not None else None
        if previous is not None and position_m - previous[0] >= CALIBRATION_MIN_M:
            scale = (count_m - previous[1]) / (position_m - previous[0])
            if scale > 0.0:  # a count that ran backwards calibrates nothing
                self.scale = scale
                self._correction = 1.0 / scale - 1.0
        self._fix = (position_m, count_m)
        self.lrbg_m = position_m
        self.relocations += 1
        self._passed = max(self._passed, bisect_right(self.groups_ahead_m, position_m))

    def _position(self, count_m: float) -> float:
        """The estimated front end for a count: from the fix, the distance counted since it
        over the scale (written as a correction of the count, exact when there is none)."""
        fix_position, fix_count = self._fix
        return count_m + (fix_position - fix_count) + (count_m - fix_count) * self._correction

    def _half_width(self, count_m: float) -> float:
        """Half the confidence interval for a count, m."""
        since = abs(count_m - self._fix[1]) / self.scale
        return self.location_accuracy_m + self.odometry_accuracy * since

    def _estimate(self, count_m: float, speed_mps: float, widen: float) -> None:
        position = self._position(count_m)
        half = self._half_width(count_m)
        self.position_m = position
        self.min_safe_front_m = position - half
        self.max_safe_front_m = position + half
        speed = speed_mps / self.scale
        self.speed_mps = speed
        turning = speed_mps != 0.0
        accuracy = (self.speed_accuracy_mps + self.speed_accuracy_share * abs(speed)
                    if turning else 0.0) + widen
        self.max_speed_mps = speed + accuracy
        self.standstill = abs(speed) <= self.standstill_mps
