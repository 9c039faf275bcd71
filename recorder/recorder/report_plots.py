"""The report's plots (``recorder.report``): one function per figure, each building a matplotlib
figure from a run's data (:class:`recorder.report.RunData`) or returning None when the recording
has nothing for it; :func:`plot` saves them as PNG files. Every axis is labelled with its
quantity and unit. Legends sit beside the axes, where they cover no curve.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from ato_common import units

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: how the report names a raw key's unit suffix (SI, ``ato_common.units``)
UNITS = (('_n_per_mps2', 'N/(m/s²)'), ('_n_per_mps', 'N/(m/s)'), ('_kg_per_m', 'kg/m'),
         ('_mps2', 'm/s²'), ('_mps3', 'm/s³'), ('_mps', 'm/s'), ('_kmh', 'km/h'),
         ('_kwh', 'kWh'), ('_kn', 'kN'), ('_kg', 'kg'), ('_hz', 'Hz'), ('_ms', 'ms'),
         ('_rad', 'rad'), ('_per_s', '1/s'), ('_n', 'N'), ('_m', 'm'), ('_s', 's'),
         ('_w', 'W'), ('_j', 'J'), ('_pct', '%'))


def label(key: str) -> str:
    """A raw key as a reader reads it: 'integral_action_mps2' -> 'integral action (m/s²)',
    'b.gain' -> 'b gain' (no unit when the key names none)."""
    name = key.replace('.', ' ').strip()
    for suffix, unit in UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return f'{name[:-len(suffix)].replace("_", " ")} ({unit})'
    return name.replace('_', ' ')


def _pyplot():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def legend_beside(axis, **options) -> None:
    """The axis's legend right of its plotting area (never over a curve)."""
    axis.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                **{'fontsize': 8, **options})


def mark_events(axis, events) -> None:
    """ATP interventions (red), watchdog or controller events (orange) and missed time windows
    (blue) on the time axis (a timing point never reached has no time to mark)."""
    shown = set()
    for t, kind, _ in events:
        if not math.isfinite(t):
            continue
        colour = 'red' if kind.startswith('ATP') else 'tab:blue' if kind.startswith('missed') \
            else 'orange'
        axis.axvline(t, color=colour, lw=1, ls='--', alpha=0.8,
                     label=kind if kind not in shown else None)
        shown.add(kind)


def energy_over_time(data) -> np.ndarray:
    """Traction energy up to each sample, kWh: the metrics' sum, accumulated."""
    held = np.append(data.applied[1:], data.applied[-1:])
    work = np.maximum(held[:-1] * np.diff(data.positions), 0.0)
    return units.joules_to_kwh(np.concatenate([[0.0], np.cumsum(work)]))


def tracking_figure(data):
    plt = _pyplot()
    t = data.stamps_ns / 1e9
    fig, (a, b) = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    if data.permitted:
        a.plot([p[0] for p in data.permitted], np.array([p[1] for p in data.permitted]) * 3.6,
               label='permitted (static limits\nand braking curves)', lw=1, color='black',
               alpha=0.7)
    a.plot(t, data.ref_speeds * 3.6, label='target', lw=2, alpha=0.6)
    a.plot(t, data.speeds * 3.6, label='train (true)', lw=1)
    mark_events(a, data.events)
    a.set_ylabel('speed (km/h)')
    legend_beside(a)
    b.plot(t, data.ref_positions / 1000, label='target', lw=2, alpha=0.6)
    b.plot(t, data.positions / 1000, label='train (true)', lw=1)
    mark_events(b, data.events)
    b.set_ylabel('position (km)')
    b.set_xlabel('time (s)')
    legend_beside(b)
    fig.suptitle('tracking: target, actual and permitted speed; ATP and watchdog events')
    return fig


def errors_figure(data):
    plt = _pyplot()
    t = data.stamps_ns / 1e9
    fig, (a, b) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    a.plot(t, (data.ref_speeds - data.speeds) * 3.6)
    a.set_ylabel('speed error (km/h)')
    b.plot(t, data.ref_positions - data.positions)
    b.set_ylabel('position error (m)')
    b.set_xlabel('time (s)')
    fig.suptitle('tracking errors (target minus train)')
    return fig


def distance_to_go_figure(data):
    if not data.distance_to_go:
        return None
    plt = _pyplot()
    fig, a = plt.subplots(figsize=(10, 3.5))
    a.plot([d[0] for d in data.distance_to_go],
           np.array([d[1] for d in data.distance_to_go]) / 1000)
    a.set_ylabel('distance to go (km)')
    a.set_xlabel('time (s)')
    fig.suptitle('distance to the next target (lower speed limit or stop)')
    return fig


def stops_figure(data, errors: dict[str, float]):
    if not errors:
        return None
    plt = _pyplot()
    fig, a = plt.subplots(figsize=(10, 3.5))
    names = list(errors)
    a.bar(range(len(names)), [errors[n] for n in names])
    a.set_xticks(range(len(names)), names, rotation=20, fontsize=8)
    a.axhline(0.0, color='black', lw=0.8)
    a.set_ylabel('stopping error (m, + beyond the stop)')
    fig.suptitle('station stops and their stopping errors')
    return fig


def commands_figure(data):
    plt = _pyplot()
    fig, a = plt.subplots(figsize=(11, 4))
    a.plot(data.command_times, data.commands / 1000, label='commanded (ATO, sum)', lw=2,
           alpha=0.6)
    a.plot(data.stamps_ns / 1e9, data.applied / 1000, label='applied (plant, sum)', lw=1)
    a.set_ylabel('force (kN)')
    a.set_xlabel('time (s)')
    legend_beside(a)
    fig.suptitle(f'traction and braking force ({", ".join(data.laws)})')
    return fig


def actuators_figure(data):
    names = sorted(set(data.actuators_commanded) | set(data.actuators_applied))
    if not names:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 2.4 * len(names)), sharex=True,
                             squeeze=False)
    for axis, name in zip(axes[:, 0], names):
        for series, what, style in ((data.actuators_commanded, 'commanded', '-'),
                                    (data.actuators_applied, 'applied', '--')):
            values = series.get(name, [])
            axis.plot([v[0] for v in values], np.array([v[1] for v in values]) / 1000,
                      style, label=what, lw=1.2)
        axis.set_ylabel(f'{name}\nforce (kN)', fontsize=8)
        legend_beside(axis, fontsize=7)
    axes[-1, 0].set_xlabel('time (s)')
    fig.suptitle('force per actuator: commanded vs applied')
    return fig


def cars_figure(data):
    if not data.cars or len(data.cars) < 2:
        return None
    plt = _pyplot()
    t = data.stamps_ns / 1e9
    fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
    lead = data.car_positions[:, :1]
    for i, car in enumerate(data.cars):
        axes[0].plot(t, data.car_positions[:, i] - lead[:, 0], label=car, lw=1)
        axes[1].plot(t, data.car_speeds[:, i] * 3.6, label=car, lw=1)
        axes[2].plot(t, data.car_forces[:, i] / 1000, label=car, lw=1)
    axes[0].set_ylabel('position behind the\nlead car (m)')
    axes[1].set_ylabel('speed (km/h)')
    axes[2].set_ylabel('applied force (kN)')
    axes[2].set_xlabel('time (s)')
    legend_beside(axes[0], fontsize=7)
    fig.suptitle('per car: position, speed and applied force')
    return fig


def energy_figure(data):
    plt = _pyplot()
    fig, a = plt.subplots(figsize=(10, 3.5))
    a.plot(data.stamps_ns / 1e9, energy_over_time(data))
    a.set_ylabel('traction energy (kWh)')
    a.set_xlabel('time (s)')
    fig.suptitle('traction energy over time (work of the applied traction force)')
    return fig


def measured_figure(data):
    common = [k for k in data.stamps_ns if int(k) in data.measured]
    if not common:
        return None
    plt = _pyplot()
    tm = np.array(common) / 1e9
    index = {int(k): i for i, k in enumerate(data.stamps_ns)}
    true = np.array([(data.positions[index[int(k)]], data.speeds[index[int(k)]])
                     for k in common])
    measured = np.array([data.measured[int(k)] for k in common])
    fig, (a, b) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    a.plot(tm, (measured[:, 1] - true[:, 1]) * 3.6)
    a.set_ylabel('speed: measured\nminus true (km/h)')
    b.plot(tm, measured[:, 0] - true[:, 0])
    b.set_ylabel('position: measured\nminus true (m)')
    b.set_xlabel('time (s)')
    fig.suptitle('the sensors against the true state (lead car)')
    return fig


def estimates_figure(data):
    if not data.estimates:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(len(data.estimates), 1, figsize=(10, 2.2 * len(data.estimates)),
                             sharex=True, squeeze=False)
    for axis, (name, values) in zip(axes[:, 0], sorted(data.estimates.items())):
        axis.plot([v[0] for v in values], [v[1] for v in values])
        axis.set_ylabel(label(name), fontsize=8)
    axes[-1, 0].set_xlabel('time (s)')
    fig.suptitle('estimates and internal signals of the law')
    return fig


def figures(data, stop_errors: dict[str, float]
            ) -> list[tuple[str, Callable[[], Figure | None]]]:
    """(file stem, figure maker) of every plot, in the report's order (a maker returns None
    when the recording has no data for its plot)."""
    return [('tracking', lambda: tracking_figure(data)),
            ('errors', lambda: errors_figure(data)),
            ('distance_to_go', lambda: distance_to_go_figure(data)),
            ('stops', lambda: stops_figure(data, stop_errors)),
            ('commands', lambda: commands_figure(data)),
            ('actuators', lambda: actuators_figure(data)),
            ('cars', lambda: cars_figure(data)),
            ('energy', lambda: energy_figure(data)),
            ('measured', lambda: measured_figure(data)),
            ('estimates', lambda: estimates_figure(data))]


def plot(data, folder: Path, stop_errors: dict[str, float]) -> list[Path]:
    """Every plot the recording has data for, as ``folder/<name>.png``."""
    plt = _pyplot()
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in figures(data, stop_errors):
        fig = make()
        if fig is None:
            continue
        path = folder / f'{name}.png'
        fig.savefig(path, dpi=110, bbox_inches='tight')  # the legends beside the axes kept
        plt.close(fig)
        written.append(path)
    return written
