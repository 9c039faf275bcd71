"""The plant's sensors: what the on-board sensors report of the truth (the scenario's
``plant.sensors``). Truth side: this module reads the true state; what it returns is all that
the ATO (``measured``) and the ATP's odometry (``odometer``) get.

One odometer (a wheel sensor) gives both the distance and the speed:

- speed: (1 + s_v) v + b_v (``speed.scale_error`` s_v, ``speed.bias`` b_v), the bias acting in
  full from 30 km/h and in proportion to the speed below
  (:func:`ato_common.plant_setup.speed_reading`): the reading has the sign of the speed and is
  0 only at true standstill (a wheel that does not turn gives no pulse);
- distance: (1 + s_x) times the distance run (``position.scale_error`` s_x), plus the
  integral of the speed's bias (the odometer integrates what it measures); the position the
  ATO reads is that distance since the odometer's last reset point r (the run's initial
  position, the position sensor's ``reset_positions_m`` or a balise group of the line), plus
  r, plus the position's ``bias`` b_x until the first reset point (b_x is the error of the
  position the train starts its mission with: the first balise group corrects it, as it
  corrects the odometry's):
  x + s_x (x - r) + integral of the bias since r (+ b_x before the first r);
- then white noise and quantisation, NaN when dropped out or failed (the ATO's reading only).

The ATP's odometry gets the odometer's count (``odometer``): the position it reads, without
noise, reset only where the odometer itself is (``reset_positions_m``: relocating at the line's
balise groups is the odometry's own work), and the speed, without noise and nil below the wheel
sensor's resolution (the odometry's standstill); and, at each balise group of the line the
train's front passes, the count at that moment (``follow``).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from ato_common.plant_setup import SPEED_BIAS_FULL_MPS, QuantitySensor, SensorSetup, speed_reading
from ato_common.types import TrainState


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


class Sensors:
    """The sensors of one run (module docstring). ``balise_groups_m``: where the line's balise
    groups lie; ``start_m``: the lead car's initial position; ``lead``: the lead car's name;
    ``resolution_mps``: the lowest speed the odometer's wheel sensor resolves in a control
    period (below it, it gives no pulse: the ATP's odometry reads standstill)."""

    def __init__(self, setup: SensorSetup, balise_groups_m: Sequence[float], start_m: float,
                 lead: str, resolution_mps: float = 0.0):
        self.setup = setup
        self.rng = np.random.default_rng(setup.seed)
        self.start_m = start_m
        self.lead = lead
        self.resolution_mps = resolution_mps
        self.balise_groups_m = tuple(balise_groups_m)
        self._balise_groups = set(balise_groups_m)
        self.sensor_resets_m = tuple(sorted(setup.position.reset_positions_m))
        self.resets_m = tuple(sorted(set(self.sensor_resets_m) | self._balise_groups))
        position, speed = setup.position, setup.speed
        self.ideal = setup.ideal
        # The odometer's count equals the truth (no systematic error: the odometry's exact case).
        self.exact_odometer = position.bias == 0.0 and position.scale_error == 0.0 and \
            speed.bias == 0.0 and speed.scale_error == 0.0
        # The ATO's position reading equals the truth before noise.
        self._exact_position = position.ideal and speed.bias == 0.0
        # The odometer's sensors fail at some time of the run (``odometer_failed``).
        self.may_fail = not (math.isinf(position.failed_from_s)
                             and math.isinf(speed.failed_from_s))
        # the time the speed's bias has acted in full so far, s: a period's time, or less
        # below SPEED_BIAS_FULL_MPS (the bias's integral over the time moved, over the bias)
        self.moving_s = 0.0
        self._moving_at: dict[float, float] = {start_m: 0.0}  # reset point -> moving_s there
        self._last_m = start_m

    # --- the run goes on -----------------------------------------------------------------------
    def follow(self, position_m: float, period_s: float) -> list[tuple[float, float]]:
        """The lead car is at ``position_m`` after a period: count the time it moved and note
        the reset points it passed. Returns each balise group of the line passed with the
        odometer's count there (the moving time at the crossing interpolated in the period),
        in order."""
        last, self._last_m = self._last_m, position_m
        if position_m == last:
            return []
        before = self.moving_s
        self.moving_s = before + min(period_s, abs(position_m - last) / SPEED_BIAS_FULL_MPS)
        points = self.resets_m
        if not points:
            return []
        first, end = bisect_right(points, last), bisect_right(points, position_m)
        passed = []
        for point in points[first:end]:
            moving = before + (self.moving_s - before) * (point - last) / (position_m - last)
            self._moving_at[point] = moving
            if point in self._balise_groups:
                passed.append((point, point + self._error(point, self.sensor_resets_m, moving)))
        return passed

    # --- what the sensors report ---------------------------------------------------------------
    def _error(self, position_m: float, resets: tuple[float, ...], moving_s: float) -> float:
        """A reading less the truth at a position, before noise: the start's bias until the
        first of ``resets``, the scale error since the last of them behind the position (or the
        start) and the speed's bias integrated since the train passed it."""
        s = self.setup
        reset = self.reset_point(position_m, resets)
        error = s.position.bias if self._from_start(position_m, resets) else 0.0
        if s.position.scale_error:
            error += s.position.scale_error * max(position_m - reset, 0.0)
        if s.speed.bias:
            error += s.speed.bias * (moving_s - self._moving_at.get(reset, moving_s))
        return error

    def odometer(self, time_s: float, position_m: float, speed_mps: float) -> tuple[float, float]:
        """(count, speed) of the lead car's odometer for the ATP's odometry, each NaN where its
        sensor has failed. The count is a position reading reset only where the odometer itself
        is (the position sensor's ``reset_positions_m``): relocating at the line's balise
        groups is the odometry's own work. The speed is nil below the wheel sensor's
        resolution."""
        s = self.setup
        if self.exact_odometer:
            count, speed = position_m, speed_mps
        else:
            count = position_m + self._error(position_m, self.sensor_resets_m, self.moving_s)
            speed = speed_reading(s.speed, speed_mps) \
                if abs(speed_mps) > self.resolution_mps else 0.0
        if s.position.failed(time_s, self.lead):
            count = math.nan
        if s.speed.failed(time_s, self.lead):
            speed = math.nan
        return count, speed

    def _from_start(self, position_m: float, resets: tuple[float, ...]) -> bool:
        """No reset point at or behind a position lies at or ahead of the run's start: the
        reading still counts from the start of mission."""
        i = bisect_right(resets, position_m)
        return i == 0 or resets[i - 1] < self.start_m

    def odometer_failed(self, time_s: float) -> bool:
        """The lead car's position or speed sensor has failed at ``time_s``."""
        s = self.setup
        return self.may_fail and (s.position.failed(time_s, self.lead)
                                  or s.speed.failed(time_s, self.lead))

    def reset_point(self, position_m: float, resets: tuple[float, ...] | None = None) -> float:
        """The odometer's last reset point at or behind a position: the run's initial position,
        or the last of ``resets`` (default: the position sensor's reset points and the line's
        balise groups, where the ATO's reading is reset)."""
        resets = self.resets_m if resets is None else resets
        i = bisect_right(resets, position_m)
        return max(self.start_m, resets[i - 1] if i else -math.inf)

    def position_error(self, position_m: float) -> float:
        """The ATO's position reading less the truth at a position, m, before noise: the
        start's bias until the first reset point or balise group, the scale error since the
        last one and the speed's bias integrated since the train passed it (module
        docstring)."""
        return self._error(position_m, self.resets_m, self.moving_s)

    def measured(self, truth: TrainState, time_s: float) -> TrainState:
        """What the on-board sensors report to the ATO; a missing measurement is NaN."""
        if self.ideal:
            return truth
        s = self.setup
        cars = truth.car_names
        positions: Sequence[float] = truth.positions
        if not self._exact_position:
            positions = [x + self.position_error(x) for x in positions]
        speeds: Sequence[float] = truth.speeds
        if s.speed.scale_error or s.speed.bias:
            speeds = [speed_reading(s.speed, v) for v in speeds]
        return TrainState(truth.stamp_ns, cars,
                          self._read(positions, s.position, cars, time_s, biased=False),
                          self._read(speeds, s.speed, cars, time_s, biased=False),
                          self._read(self._scaled(truth.accelerations, s.acceleration),
                                     s.acceleration, cars, time_s), truth.forces)

    @staticmethod
    def _scaled(values: Sequence[float], sensor: QuantitySensor) -> Sequence[float]:
        if not sensor.scale_error:
            return values
        return [(1.0 + sensor.scale_error) * v for v in values]

    def _read(self, values: Sequence[float], sensor: QuantitySensor, cars: Sequence[str],
              time_s: float, biased: bool = True) -> tuple[float, ...]:
        """The reading with its bias (unless ``biased`` is False: added already), white noise,
        quantised; NaN when dropped out or failed."""
        if sensor.ideal:
            return tuple(values)
        n = len(values)
        noise = (self.rng.normal(0.0, sensor.noise_std, n) if sensor.noise_std
                 else np.zeros(n))
        dropped = (self.rng.random(n) < sensor.dropout_probability
                   if sensor.dropout_probability else np.zeros(n, dtype=bool))
        bias = sensor.bias if biased else 0.0
        out = []
        for value, e, drop, car in zip(values, noise, dropped, cars):
            if drop or sensor.failed(time_s, car):
                out.append(math.nan)
                continue
            value = value + bias + float(e)
            if sensor.quantum:
                value = round(value / sensor.quantum) * sensor.quantum
            out.append(value)
        return tuple(out)
