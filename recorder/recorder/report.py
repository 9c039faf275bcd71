"""report: a run's metrics and plots from its recording alone.

    ros2 run recorder report runs/my_run            # writes runs/my_run/report/*.png
    ros2 run recorder report runs/fleet --namespace /train1

The topics are the suite's (:data:`ato_common.conventions.TOPICS`). Their relative names are
found in the namespace the stack ran in (``-r __ns:=/train1``): by default the one namespace in
which the recording holds them, under their names and types; ``--namespace`` chooses when it
holds several (``/`` is the root namespace). ``/diagnostics`` is global: in a recording of
several stacks it mixes their laws' estimates.

The metrics are those ``make demo`` prints (:mod:`ato_common.metrics`): the lead car's true
state against the reference at each stamp, stopping errors read where the latched target curve
leaves each stop, traction energy from the applied force.

The plots (``<bag>/report/*.png``, and all of them with the summary table in the single page
``report.html``): target, actual and permitted speed (the profile's permitted
speed: static limits and braking curves) with the ATP's interventions and the command
watchdog's events marked on the time axis (from the plant's and the controller's diagnostics);
tracking errors; distance to go; the stops with their stopping errors; per car, position, speed
and applied force (the effort of train/state) for multi-car runs; per actuator, the commanded
and the applied force (train/actuators/*); traction energy over time; the measured against the
true state; the law's estimates. Every axis is labelled with its quantity and unit.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap_ros2.decoder import DecoderFactory

from ato_common import units
from ato_common.conventions import TOPICS, status_in_namespace
from ato_common.identity import identity_mismatch, parse_identity, scenario_identity
from ato_common.metrics import RunMetrics, StopSample, compute_metrics, format_summary
from ato_common.run_events import PLATFORM_TOLERANCE_M, journey_events
from ato_common.scenario import builtin_scenarios, load_scenario
from ato_common.validation import ConfigError
from recorder.bag import BagError, bag_info, read_messages

REPORTED = ('state', 'reference', 'command', 'curve', 'diagnostics')
"""The keys of the conventions' topics the report needs."""
OPTIONAL = ('state_measured', 'permitted_speed', 'distance_to_go', 'actuators_commanded',
            'actuators_applied', 'identity')
"""The keys of the topics it plots when the recording holds them."""

# Unit suffixes of the suite's keys (SI, `ato_common.units`) -> how a reader writes them.
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


def normalise_namespace(namespace: str) -> str:
    """'/train1', 'train1' and 'train1/' are '/train1'; '' and '/' are the root namespace ('')."""
    return '/' + namespace.strip().strip('/') if namespace.strip().strip('/') else ''


def _shown(namespace: str) -> str:
    return namespace or '/'


def topic_in(namespace: str, name: str) -> str:
    """The absolute name of a conventions name in ``namespace`` (a global name stays global)."""
    return name if name.startswith('/') else f'{normalise_namespace(namespace)}/{name}'


def namespaces_of(recorded: dict[str, str]) -> set[str]:
    """The namespaces in which ``recorded`` (topic name -> type) holds a relative topic of the
    conventions under its name and type."""
    found = set()
    for name, type_name in recorded.items():
        for convention in TOPICS.values():
            relative = convention.name
            if (not relative.startswith('/') and type_name == convention.type_name
                    and name.endswith('/' + relative)):
                found.add(name[:-len(relative) - 1])
    return found


def resolve_topics(bag: Path, namespace: str | None = None) -> dict[str, str]:
    """The recorded names of the reported topics (key -> absolute name): in ``namespace``, or
    else in the one namespace where the recording holds the suite's topics. A BagError names the
    namespaces when there are none or several to choose from."""
    recorded = {name: t.type for name, t in bag_info(bag).topics.items()}
    found = namespaces_of(recorded)
    relative = ', '.join(TOPICS[k].name for k in REPORTED if not TOPICS[k].name.startswith('/'))
    if namespace is None:
        if not found:
            raise BagError(f'{bag} holds none of the suite\'s topics ({relative}) in any '
                           f'namespace; it has {", ".join(sorted(recorded)) or "no topics"}')
        if len(found) > 1:
            raise BagError(f'{bag} holds the suite\'s topics in several namespaces: '
                           f'{", ".join(_shown(n) for n in sorted(found))}; choose one with '
                           '--namespace')
        (namespace,) = found
    elif normalise_namespace(namespace) not in found:
        raise BagError(f'{bag} holds none of the suite\'s topics ({relative}) in namespace '
                       f'{_shown(normalise_namespace(namespace))}; it holds them in '
                       f'{", ".join(_shown(n) for n in sorted(found)) or "no namespace"}')
    return {key: topic_in(namespace, TOPICS[key].name) for key in REPORTED + OPTIONAL
            if key in REPORTED or topic_in(namespace, TOPICS[key].name) in recorded}


@dataclass
class RunData:
    stamps_ns: np.ndarray
    positions: np.ndarray
    speeds: np.ndarray
    applied: np.ndarray
    ref_positions: np.ndarray
    ref_speeds: np.ndarray
    command_times: np.ndarray
    commands: np.ndarray
    laws: list[str]
    stops: list[StopSample]
    estimates: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    cars: list[str] = field(default_factory=list)
    car_positions: np.ndarray | None = None  # (samples, cars)
    car_speeds: np.ndarray | None = None
    car_forces: np.ndarray | None = None     # effort per car: the force applied on it, N
    measured: dict[int, tuple[float, float]] = field(default_factory=dict)  # stamp -> (x, v)
    permitted: list[tuple[float, float]] = field(default_factory=list)  # (s, m/s)
    distance_to_go: list[tuple[float, float]] = field(default_factory=list)  # (s, m)
    # actuator -> [(s, N)]
    actuators_commanded: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    actuators_applied: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (s, kind, message)
    identity: str = ''  # the plant's identity of its scenario (ato_common.identity), if recorded


def _decoder():
    """CDR to Python objects from the schema in the file (no ROS installation needed)."""
    factory = DecoderFactory()
    cache = {}

    def decode(message):
        key = message.channel.schema_id
        if key not in cache:
            cache[key] = factory.decoder_for('cdr', message.schema)
        return cache[key](message.data)
    return decode


def _stamp(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def stops_from_curve(times: np.ndarray, positions: np.ndarray, speeds: np.ndarray
                     ) -> list[StopSample]:
    """Each standstill of the target curve after the train first moved: the stop error is read
    at its last instant (the end of the dwell)."""
    stops = []
    moving = np.nonzero(speeds > 0.0)[0]
    if moving.size == 0:
        return stops
    i = moving[0]
    while i < times.size:
        if speeds[i] == 0.0:
            j = i
            while j + 1 < times.size and speeds[j + 1] == 0.0:
                j += 1
            stops.append(StopSample(f'stop at {positions[i]:.0f} m', float(positions[i]),
                                    float(times[j])))
            i = j + 1
        else:
            i += 1
    return stops


def load_run(bag: Path, namespace: str | None = None) -> RunData:
    """The run recorded in ``bag``; ``namespace``: see :func:`resolve_topics`."""
    topics = resolve_topics(bag, namespace)
    # the stack's namespace, from where its state is ('/train1/train/state' -> '/train1')
    stack_namespace = topics['state'][:-len(TOPICS['state'].name) - 1] or '/'
    decode = _decoder()
    states, references, commands, estimates = {}, {}, [], {}
    cars_of: dict[int, tuple] = {}
    extra = RunData(np.array([]), *([np.array([])] * 7), [], [])
    watch = {'watchdog': 'normal', 'atp_intervention': 'False'}
    stops: list[StopSample] = []
    for message in read_messages(bag, list(topics.values())):
        msg = decode(message)
        t_log = message.log_time_ns / 1e9
        if message.topic == topics['state']:
            p = msg.points[0]
            states[_stamp(msg.header)] = (p.positions[0], p.velocities[0], sum(p.effort))
            cars_of[_stamp(msg.header)] = (tuple(msg.joint_names), tuple(p.positions),
                                           tuple(p.velocities), tuple(p.effort))
        elif message.topic == topics.get('state_measured'):
            p = msg.points[0]
            extra.measured[_stamp(msg.header)] = (p.positions[0], p.velocities[0])
        elif message.topic == topics.get('permitted_speed'):
            extra.permitted.append((t_log, msg.data))
        elif message.topic == topics.get('distance_to_go'):
            extra.distance_to_go.append((t_log, msg.data))
        elif message.topic in (topics.get('actuators_commanded'), topics.get('actuators_applied')):
            into = extra.actuators_commanded if message.topic == topics.get(
                'actuators_commanded') else extra.actuators_applied
            for name, force in zip(msg.name, msg.effort):
                into.setdefault(name, []).append((_stamp(msg.header) / 1e9, force))
        elif message.topic == topics.get('identity'):
            extra.identity = msg.data
        elif message.topic == topics['reference']:
            p = msg.points[0]
            references[_stamp(msg.header)] = (p.positions[0], p.velocities[0])
        elif message.topic == topics['command']:
            commands.append((_stamp(msg.header), sum(msg.effort), msg.header.frame_id))
        elif message.topic == topics['curve']:
            times = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                              for p in msg.points])
            stops = stops_from_curve(times, np.array([p.positions[0] for p in msg.points]),
                                     np.array([p.velocities[0] for p in msg.points]))
        elif message.topic == topics['diagnostics']:
            for status in msg.status:
                own = status_in_namespace(status.name, stack_namespace)
                if own is None:
                    continue  # a status of another stack recorded alongside
                _events(own, status, _stamp(msg.header) / 1e9, watch, extra.events)
                for kv in status.values:
                    if kv.key.startswith('estimate.'):
                        try:
                            estimates.setdefault(kv.key[9:], []).append(
                                (_stamp(msg.header) / 1e9, float(kv.value)))
                        except ValueError:
                            pass
    if not states:
        raise BagError(f'{bag} has no {topics["state"]} messages: nothing to report on')
    stamps = np.array(sorted(k for k in states if k in references))
    if stamps.size == 0:
        raise BagError(f'{bag}: no {topics["reference"]} message matches a state stamp')
    s = np.array([states[k] for k in stamps])
    r = np.array([references[k] for k in stamps])
    commands.sort()
    data = RunData(stamps, s[:, 0], s[:, 1], s[:, 2], r[:, 0], r[:, 1],
                   np.array([c[0] for c in commands]) / 1e9, np.array([c[1] for c in commands]),
                   sorted({c[2] for c in commands}), stops, estimates)
    layouts = {cars_of[k][0] for k in stamps}
    if len(layouts) == 1:
        (data.cars,) = [list(c) for c in layouts]
        data.car_positions = np.array([cars_of[k][1] for k in stamps])
        data.car_speeds = np.array([cars_of[k][2] for k in stamps])
        data.car_forces = np.array([cars_of[k][3] for k in stamps])
    for name in ('measured', 'permitted', 'distance_to_go', 'actuators_commanded',
                 'actuators_applied', 'events', 'identity'):
        setattr(data, name, getattr(extra, name))
    data.events.sort()
    return data


def _events(name: str, status, t: float, watch: dict, events: list) -> None:
    """ATP interventions and watchdog events: where the plant's diagnostics change state, and
    every error of the controller (e.g. its own watchdog on stale measurements). ``name``: the
    status's name within its stack's namespace (``train_plant_node: simulation``)."""
    values = {kv.key: kv.value for kv in status.values}
    if name.startswith('train_plant_node'):
        atp = values.get('atp_intervention')
        if atp is not None and atp != watch['atp_intervention']:
            watch['atp_intervention'] = atp
            events.append((t, 'ATP intervention' if atp == 'True' else 'ATP released',
                           status.message))
        dog = values.get('watchdog')
        if dog is not None and dog != watch['watchdog']:
            watch['watchdog'] = dog
            events.append((t, f'watchdog: {dog}', status.message))
    elif name.startswith('ato_controller_node') and status.level in (2, b'\x02'):
        events.append((t, 'controller error', status.message))


def run_metrics(data: RunData) -> RunMetrics:
    # A state carries the force applied up to it; the force held after sample k is in k+1.
    held = np.append(data.applied[1:], data.applied[-1:])
    return compute_metrics(data.stamps_ns / 1e9, data.positions, data.speeds, held,
                           data.ref_positions, data.ref_speeds, data.stops)


def _mark_events(axis, events) -> None:
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


def energy_over_time(data: RunData) -> np.ndarray:
    """Traction energy up to each sample, kWh: the metrics' sum, accumulated."""
    held = np.append(data.applied[1:], data.applied[-1:])
    work = np.maximum(held[:-1] * np.diff(data.positions), 0.0)
    return units.joules_to_kwh(np.concatenate([[0.0], np.cumsum(work)]))


def plot(data: RunData, folder: Path) -> list[Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    folder.mkdir(parents=True, exist_ok=True)
    t = data.stamps_ns / 1e9
    written = []

    def save(fig, name):
        path = folder / name
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)

    fig, (a, b) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    if data.permitted:
        a.plot([p[0] for p in data.permitted], np.array([p[1] for p in data.permitted]) * 3.6,
               label='permitted (static limits and braking curves)', lw=1, color='black',
               alpha=0.7)
    a.plot(t, data.ref_speeds * 3.6, label='target', lw=2, alpha=0.6)
    a.plot(t, data.speeds * 3.6, label='train (true)', lw=1)
    _mark_events(a, data.events)
    a.set_ylabel('speed (km/h)')
    a.legend(fontsize=8)
    b.plot(t, data.ref_positions / 1000, label='target', lw=2, alpha=0.6)
    b.plot(t, data.positions / 1000, label='train (true)', lw=1)
    _mark_events(b, data.events)
    b.set_ylabel('position (km)')
    b.set_xlabel('time (s)')
    b.legend(fontsize=8)
    fig.suptitle('tracking: target, actual and permitted speed; ATP and watchdog events')
    save(fig, 'tracking.png')

    fig, (a, b) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    a.plot(t, (data.ref_speeds - data.speeds) * 3.6)
    a.set_ylabel('speed error (km/h)')
    b.plot(t, data.ref_positions - data.positions)
    b.set_ylabel('position error (m)')
    b.set_xlabel('time (s)')
    fig.suptitle('tracking errors (target minus train)')
    save(fig, 'errors.png')

    if data.distance_to_go:
        fig, a = plt.subplots(figsize=(10, 3.5))
        a.plot([d[0] for d in data.distance_to_go],
               np.array([d[1] for d in data.distance_to_go]) / 1000)
        a.set_ylabel('distance to go (km)')
        a.set_xlabel('time (s)')
        fig.suptitle('distance to the next target (lower speed limit or stop)')
        save(fig, 'distance_to_go.png')

    errors = run_metrics(data).stop_errors_m
    if errors:
        fig, a = plt.subplots(figsize=(10, 3.5))
        names = list(errors)
        a.bar(range(len(names)), [errors[n] for n in names])
        a.set_xticks(range(len(names)), names, rotation=20, fontsize=8)
        a.axhline(0.0, color='black', lw=0.8)
        a.set_ylabel('stopping error (m, + beyond the stop)')
        fig.suptitle('station stops and their stopping errors')
        save(fig, 'stops.png')

    fig, a = plt.subplots(figsize=(10, 4))
    a.plot(data.command_times, data.commands / 1000, label='commanded (ATO, sum)', lw=2,
           alpha=0.6)
    a.plot(t, data.applied / 1000, label='applied (plant, sum)', lw=1)
    a.set_ylabel('force (kN)')
    a.set_xlabel('time (s)')
    a.legend(fontsize=8)
    fig.suptitle(f'traction and braking force ({", ".join(data.laws)})')
    save(fig, 'commands.png')

    names = sorted(set(data.actuators_commanded) | set(data.actuators_applied))
    if names:
        fig, axes = plt.subplots(len(names), 1, figsize=(10, 2.4 * len(names)), sharex=True,
                                 squeeze=False)
        for axis, name in zip(axes[:, 0], names):
            for series, what, style in ((data.actuators_commanded, 'commanded', '-'),
                                        (data.actuators_applied, 'applied', '--')):
                values = series.get(name, [])
                axis.plot([v[0] for v in values], np.array([v[1] for v in values]) / 1000,
                          style, label=what, lw=1.2)
            axis.set_ylabel(f'{name}\nforce (kN)', fontsize=8)
            axis.legend(fontsize=7)
        axes[-1, 0].set_xlabel('time (s)')
        fig.suptitle('force per actuator: commanded vs applied')
        save(fig, 'actuators.png')

    if data.cars and len(data.cars) > 1:
        fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
        lead = data.car_positions[:, :1]
        for i, car in enumerate(data.cars):
            axes[0].plot(t, data.car_positions[:, i] - lead[:, 0], label=car, lw=1)
            axes[1].plot(t, data.car_speeds[:, i] * 3.6, label=car, lw=1)
            axes[2].plot(t, data.car_forces[:, i] / 1000, label=car, lw=1)
        axes[0].set_ylabel('position behind the\nlead car (m)')
        axes[1].set_ylabel('speed (km/h)')
        axes[2].set_ylabel('applied force (kN)')
        axes[2].set_xlabel('time (s)')
        axes[0].legend(fontsize=7, ncol=min(len(data.cars), 6))
        fig.suptitle('per car: position, speed and applied force')
        save(fig, 'cars.png')

    fig, a = plt.subplots(figsize=(10, 3.5))
    a.plot(t, energy_over_time(data))
    a.set_ylabel('traction energy (kWh)')
    a.set_xlabel('time (s)')
    fig.suptitle('traction energy over time (work of the applied traction force)')
    save(fig, 'energy.png')

    common = [k for k in data.stamps_ns if int(k) in data.measured]
    if common:
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
        save(fig, 'measured.png')

    if data.estimates:
        fig, axes = plt.subplots(len(data.estimates), 1, figsize=(10, 2.2 * len(data.estimates)),
                                 sharex=True, squeeze=False)
        for axis, (name, values) in zip(axes[:, 0], sorted(data.estimates.items())):
            axis.plot([v[0] for v in values], [v[1] for v in values])
            axis.set_ylabel(label(name), fontsize=8)
        axes[-1, 0].set_xlabel('time (s)')
        fig.suptitle('estimates and internal signals of the law')
        save(fig, 'estimates.png')
    return written


def scenario_of_run(data: RunData, given: str | None, bag: Path):
    """The scenario the recorded plant simulated: ``given`` (a name or a file), checked against
    the identity the plant published, or else the built-in scenario the identity names. None
    when neither is known (a recording without the plant's identity, and no scenario given);
    BagError when the given scenario is not the one the plant simulated."""
    if given is None and not data.identity:
        return None
    try:
        name = given or parse_identity(data.identity)['scenario']
        if given is None and name not in builtin_scenarios():
            return None  # a scenario from a file: the report cannot know which file
        scenario = load_scenario(name)
    except (ValueError, ConfigError) as error:
        raise BagError(f'{bag}: {error}') from None
    if data.identity:
        mismatch = identity_mismatch(scenario_identity(scenario), data.identity, 'the report')
        if mismatch:
            raise BagError(f'{bag}: {mismatch}')
    return scenario


def journey_rows(data: RunData, scenario) -> list[tuple[float, str, str]]:
    """The journey's timing points the run missed (outside their windows, or never reached),
    as events."""
    if scenario is None or scenario.journey is None:
        return []
    missed = journey_events(scenario, data.stamps_ns / 1e9, data.positions)
    return [(e.time_s, 'missed time window', e.detail) for e in missed.events]


def event_rows(metrics: RunMetrics, events, journey=None) -> list[tuple[str, str]]:
    """What went wrong, each kind with its count and its first occurrence: ATP interventions
    and command-watchdog brakes (from the plant's diagnostics), stopping errors beyond the
    platform tolerance, and the journey's missed time windows when the scenario (``journey``,
    see :func:`scenario_of_run`) is known."""
    def row(label, times, detail=''):
        if not times:
            return (label, '0')
        return (label, f'{len(times)}, first at {min(times):.1f} s{detail}')
    atp = [t for t, kind, _ in events if kind == 'ATP intervention']
    dog = [t for t, kind, _ in events
           if kind.startswith('watchdog: ') and kind != 'watchdog: normal']
    beyond = {name: e for name, e in metrics.stop_errors_m.items()
              if abs(e) > PLATFORM_TOLERANCE_M}
    stops = [('stop errors beyond 0.5 m', '0')] if not beyond else [
        ('stop errors beyond 0.5 m', f'{len(beyond)}: '
         + ', '.join(f'{name} {e:+.2f} m' for name, e in beyond.items()))]
    missed = [t for t, kind, _ in events if kind == 'missed time window']
    windows = [('missed time windows', 'not checked (the scenario is unknown: --scenario)')] \
        if journey is None else [] if journey.journey is None else [
            row('missed time windows', [t for t in missed if math.isfinite(t)],
                '' if all(map(math.isfinite, missed)) else
                f' ({sum(not math.isfinite(t) for t in missed)} never reached)')
            if missed else ('missed time windows', '0')]
    return [row('ATP interventions', atp), row('watchdog brakes', dog), *stops, *windows]


def summary_rows(metrics: RunMetrics, laws: list[str], events=(), journey=None
                 ) -> list[tuple[str, str]]:
    """The summary table: quantity (with its unit) and value, then what went wrong."""
    rows = [('controller', ', '.join(laws)),
            ('speed error, RMS (km/h)', f'{metrics.rms_speed_error_kmh:.4f}'),
            ('speed error, max (km/h)', f'{metrics.max_speed_error_kmh:.4f}'),
            ('position error, RMS (m)', f'{metrics.rms_position_error_m:.4f}'),
            ('position error, max (m)', f'{metrics.max_position_error_m:.4f}')]
    rows += [(f'stopping error, {station} (m)', f'{error:+.4f}')
             for station, error in metrics.stop_errors_m.items()]
    rows += [('traction energy (kWh)', f'{metrics.traction_energy_kwh:.2f}'),
             ('simulated time (s)', f'{metrics.simulated_time_s:.1f}'),
             ('samples', str(metrics.samples))]
    return rows + event_rows(metrics, events, journey)


def write_html(path: Path, title: str, metrics: RunMetrics, data: RunData,
               plots: list[Path], journey=None) -> Path:
    """One self-contained page: the summary table, the events, and every plot embedded (no
    file beside it needed, no script)."""
    import base64
    from html import escape
    rows = ''.join(f'<tr><th scope="row">{escape(k)}</th><td>{escape(v)}</td></tr>'
                   for k, v in summary_rows(metrics, data.laws, data.events, journey))
    events = ''.join(f'<tr><td>{f"{t:.2f}" if math.isfinite(t) else "never"}</td>'
                     f'<td>{escape(kind)}</td><td>{escape(message)}</td></tr>'
                     for t, kind, message in data.events)
    figures = ''.join(
        f'<figure id="{escape(p.stem)}"><img alt="{escape(p.stem)}" src="data:image/png;base64,'
        f'{base64.b64encode(p.read_bytes()).decode()}"><figcaption>{escape(p.stem)}'
        '</figcaption></figure>' for p in plots)
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<title>{escape(title)}</title><style>body{{font-family:sans-serif;margin:2em}}'
        'table{border-collapse:collapse}th,td{border:1px solid #ccc;padding:0.2em 0.6em;'
        'text-align:left}img{max-width:100%}</style></head><body>'
        f'<h1>{escape(title)}</h1><h2>Summary</h2><table id="summary">{rows}</table>'
        '<h2>ATP interventions, watchdog events and missed time windows</h2>'
        + (f'<table id="events"><tr><th>time (s)</th><th>event</th><th>message</th></tr>'
           f'{events}</table>' if data.events else '<p id="events">none</p>')
        + f'<h2>Plots</h2>{figures}</body></html>\n')
    path.write_text(page, encoding='utf-8')
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='report', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path)
    parser.add_argument('--output', type=Path, default=None,
                        help='folder for the plots (default: <bag>/report)')
    parser.add_argument('--namespace', default=None,
                        help="namespace the stack ran in (-r __ns:=...), '/' for the root "
                             "(default: the one namespace holding the suite's topics)")
    parser.add_argument('--scenario', default=None,
                        help='the scenario the run simulated (a name or a file), to check its '
                             "journey's time windows (default: the built-in scenario the "
                             "plant's recorded identity names; checked against it)")
    options = parser.parse_args(argv)
    try:
        data = load_run(options.bag, options.namespace)
        journey = scenario_of_run(data, options.scenario, options.bag)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    data.events = sorted(data.events + journey_rows(data, journey),
                         key=lambda e: (not math.isfinite(e[0]), e[0]))
    metrics = run_metrics(data)
    print(format_summary(metrics, str(options.bag), ', '.join(data.laws)))
    for label, value in event_rows(metrics, data.events, journey):
        print(f'{label:22s}{value}')
    for t, kind, message in data.events:
        print(f'event at {t:9.2f} s: {kind}: {message}' if math.isfinite(t)
              else f'event (never):    {kind}: {message}')
    folder = options.output or Path(options.bag) / 'report'
    plots = plot(data, folder)
    for path in plots:
        print(f'plot: {path}')
    page = write_html(folder / 'report.html', f'Run report: {Path(options.bag).name}', metrics,
                      data, plots, journey)
    print(f'html: {page}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
