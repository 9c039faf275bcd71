"""Tracking metrics of a run, from sampled truth, reference and applied force.

The same definitions serve ``make demo``, the tests and reports from recordings:
- speed and position errors are reference minus truth of the lead car at each control instant;
- the stopping error at a stop is the lead car's position minus the station position at the end
  of the dwell (at the arrival for the last stop); a stop later than the run's end (a run over
  a window of the scenario) has none;
- traction energy is the work of the traction force: the sum over control intervals of
  max(F dx, 0), F the force applied (held) from one sample to the next and dx the distance run
  meanwhile (exact for a held force; braking work is not counted).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ato_common import units


@dataclass(frozen=True)
class StopSample:
    station: str
    station_position_m: float
    time_s: float       # when the stop error is read


@dataclass(frozen=True)
class RunMetrics:
    samples: int
    simulated_time_s: float
    rms_speed_error_kmh: float
    max_speed_error_kmh: float
    rms_position_error_m: float
    max_position_error_m: float
    stop_errors_m: dict[str, float]
    traction_energy_kwh: float


def compute_metrics(times_s, positions, speeds, forces, ref_positions, ref_speeds,
                    stops: list[StopSample]) -> RunMetrics:
    """``forces[k]``: the force applied from sample k to sample k+1."""
    t = np.asarray(times_s, dtype=float)
    x = np.asarray(positions, dtype=float)
    v = np.asarray(speeds, dtype=float)
    f = np.asarray(forces, dtype=float)
    ev = np.asarray(ref_speeds, dtype=float) - v
    ex = np.asarray(ref_positions, dtype=float) - x
    if t.size == 0:
        raise ValueError('no samples to compute metrics from')
    energy = float(np.sum(np.maximum(f[:-1] * np.diff(x), 0.0))) if t.size > 1 else 0.0
    stop_errors = {}
    for stop in stops:
        if stop.time_s > t[-1] + 1e-9:
            continue  # the run ended before this stop: no stopping error to read
        i = min(int(np.searchsorted(t, stop.time_s, side='right')) - 1, t.size - 1)
        stop_errors[stop.station] = float(x[max(i, 0)] - stop.station_position_m)
    return RunMetrics(
        samples=int(t.size), simulated_time_s=float(t[-1] - t[0]),
        rms_speed_error_kmh=units.mps_to_kmh(float(np.sqrt(np.mean(ev ** 2)))),
        max_speed_error_kmh=units.mps_to_kmh(float(np.max(np.abs(ev)))),
        rms_position_error_m=float(np.sqrt(np.mean(ex ** 2))),
        max_position_error_m=float(np.max(np.abs(ex))),
        stop_errors_m=stop_errors,
        traction_energy_kwh=units.joules_to_kwh(energy))


def format_summary(metrics: RunMetrics, scenario: str, controller: str,
                   wall_time_s: float | None = None) -> str:
    """The run summary; without a wall time (a report from a recording) the speed lines are
    left out."""
    lines = [
        f'scenario              {scenario}',
        f'controller            {controller}',
        f'speed error           RMS {metrics.rms_speed_error_kmh:.4f} km/h, '
        f'max {metrics.max_speed_error_kmh:.4f} km/h',
        f'position error        RMS {metrics.rms_position_error_m:.4f} m, '
        f'max {metrics.max_position_error_m:.4f} m',
    ]
    for station, error in metrics.stop_errors_m.items():
        lines.append(f'stopping error        {station}: {error:+.4f} m')
    lines += [
        f'traction energy       {metrics.traction_energy_kwh:.2f} kWh',
        f'simulated time        {metrics.simulated_time_s:.1f} s ({metrics.samples} steps)',
    ]
    if wall_time_s is not None and wall_time_s > 0.0:
        lines += [f'wall time             {wall_time_s:.2f} s',
                  f'real-time factor      {metrics.simulated_time_s / wall_time_s:.0f}x']
    return '\n'.join(lines)
