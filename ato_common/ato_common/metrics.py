"""Tracking metrics of a run, from sampled truth, reference and applied force.

The same definitions serve ``make demo``, the tests and reports from recordings:
- speed and position errors are reference minus truth of the lead car at each control instant;
- the stopping error at a stop is the lead car's position minus the station position at the end
  of the dwell (at the arrival for the last stop); a stop later than the run's end (a run over
  a window of the scenario) has none;
- the energies at the wheel (``wheel_energy``), F the force applied (held) from one sample to
  the next, dx the distance and dt the time run meanwhile (exact for a held force):
  **traction energy** (gross) = the sum of max(F dx, 0), the work of the traction force;
  **braking energy** = the sum of max(-F dx, 0), the work of the brake;
  **regenerated energy** = the train's regenerative efficiency times the braking work its
  regenerative brake takes, at most its power (``TrainParameters.regenerative_efficiency``
  and ``regenerative_power_w``) times dt in each interval;
  **net energy** = traction - regenerated.
  The plan's forecast (``profile_node``) and the bench use the same function and labels.
"""

from __future__ import annotations

import math
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
    traction_energy_kwh: float        # gross, at the wheel (module docstring)
    braking_energy_kwh: float = 0.0
    regenerated_energy_kwh: float = 0.0
    net_energy_kwh: float = math.nan  # traction - regenerated (computed when not given)

    def __post_init__(self) -> None:
        if math.isnan(self.net_energy_kwh):
            object.__setattr__(self, 'net_energy_kwh',
                               self.traction_energy_kwh - self.regenerated_energy_kwh)


@dataclass(frozen=True)
class WheelEnergy:
    """The energies at the wheel, J (module docstring)."""

    traction_j: float
    braking_j: float
    regenerated_j: float

    @property
    def net_j(self) -> float:
        return self.traction_j - self.regenerated_j

    def kwh(self) -> dict[str, float]:
        """The four energies in kWh, by their labels (``ENERGY_LABELS``)."""
        return {'traction_energy_kwh': units.joules_to_kwh(self.traction_j),
                'braking_energy_kwh': units.joules_to_kwh(self.braking_j),
                'regenerated_energy_kwh': units.joules_to_kwh(self.regenerated_j),
                'net_energy_kwh': units.joules_to_kwh(self.net_j)}


#: field name -> label of each energy, as the summary, the report and the bench print them
ENERGY_LABELS = {'traction_energy_kwh': 'gross traction energy',
                 'braking_energy_kwh': 'braking energy',
                 'regenerated_energy_kwh': 'regenerated energy',
                 'net_energy_kwh': 'net energy'}


def wheel_energy(forces, distances, durations, regenerative_efficiency: float = 0.0,
                 regenerative_power_w: float = math.inf) -> WheelEnergy:
    """The energies at the wheel of a force ``forces[k]`` (N) held over ``distances[k]`` (m)
    and ``durations[k]`` (s); module docstring."""
    work = np.asarray(forces, dtype=float) * np.asarray(distances, dtype=float)
    braking = np.maximum(-work, 0.0)
    taken = np.minimum(braking, regenerative_power_w * np.asarray(durations, dtype=float))
    return WheelEnergy(float(np.sum(np.maximum(work, 0.0))), float(np.sum(braking)),
                       regenerative_efficiency * float(np.sum(taken)))


def compute_metrics(times_s, positions, speeds, forces, ref_positions, ref_speeds,
                    stops: list[StopSample], regenerative_efficiency: float = 0.0,
                    regenerative_power_w: float = math.inf) -> RunMetrics:
    """``forces[k]``: the force applied from sample k to sample k+1; the regenerative brake's
    efficiency and power: the train's (``TrainParameters``; 0: none)."""
    t = np.asarray(times_s, dtype=float)
    x = np.asarray(positions, dtype=float)
    v = np.asarray(speeds, dtype=float)
    f = np.asarray(forces, dtype=float)
    ev = np.asarray(ref_speeds, dtype=float) - v
    ex = np.asarray(ref_positions, dtype=float) - x
    if t.size == 0:
        raise ValueError('no samples to compute metrics from')
    energy = wheel_energy(f[:-1], np.diff(x), np.diff(t), regenerative_efficiency,
                          regenerative_power_w).kwh()
    stop_errors = read_stop_errors(t, x, stops)
    return RunMetrics(
        samples=int(t.size), simulated_time_s=float(t[-1] - t[0]),
        rms_speed_error_kmh=units.mps_to_kmh(float(np.sqrt(np.mean(ev ** 2)))),
        max_speed_error_kmh=units.mps_to_kmh(float(np.max(np.abs(ev)))),
        rms_position_error_m=float(np.sqrt(np.mean(ex ** 2))),
        max_position_error_m=float(np.max(np.abs(ex))),
        stop_errors_m=stop_errors, **energy)


def read_stop_errors(times_s, positions, stops: list[StopSample]) -> dict[str, float]:
    """The stopping error at each stop (module docstring) of ``positions`` sampled at
    ``times_s``: the truth's, or the position the train's own odometer measured (what the
    controller stops on)."""
    t = np.asarray(times_s, dtype=float)
    stop_errors = {}
    for stop in stops:
        if stop.time_s > t[-1] + 1e-9:
            continue  # the run ended before this stop: no stopping error to read
        i = min(int(np.searchsorted(t, stop.time_s, side='right')) - 1, t.size - 1)
        stop_errors[stop.station] = float(positions[max(i, 0)] - stop.station_position_m)
    return stop_errors


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
        *(f'{ENERGY_LABELS[key]:<22}{getattr(metrics, key):.2f} kWh' for key in ENERGY_LABELS),
        f'simulated time        {metrics.simulated_time_s:.1f} s ({metrics.samples} steps)',
    ]
    if wall_time_s is not None and wall_time_s > 0.0:
        lines += [f'wall time             {wall_time_s:.2f} s',
                  f'real-time factor      {metrics.simulated_time_s / wall_time_s:.0f}x']
    return '\n'.join(lines)
