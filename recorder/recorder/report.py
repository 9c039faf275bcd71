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
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap_ros2.decoder import DecoderFactory

from ato_common.conventions import TOPICS
from ato_common.metrics import RunMetrics, StopSample, compute_metrics, format_summary
from recorder.bag import BagError, bag_info, read_messages

REPORTED = ('state', 'reference', 'command', 'curve', 'diagnostics')
"""The keys of the conventions' topics the report reads."""


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
    return {key: topic_in(namespace, TOPICS[key].name) for key in REPORTED}


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
    decode = _decoder()
    states, references, commands, estimates = {}, {}, [], {}
    stops: list[StopSample] = []
    for message in read_messages(bag, list(topics.values())):
        msg = decode(message)
        if message.topic == topics['state']:
            p = msg.points[0]
            states[_stamp(msg.header)] = (p.positions[0], p.velocities[0], sum(p.effort))
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
    return RunData(stamps, s[:, 0], s[:, 1], s[:, 2], r[:, 0], r[:, 1],
                   np.array([c[0] for c in commands]) / 1e9, np.array([c[1] for c in commands]),
                   sorted({c[2] for c in commands}), stops, estimates)


def run_metrics(data: RunData) -> RunMetrics:
    # A state carries the force applied up to it; the force held after sample k is in k+1.
    held = np.append(data.applied[1:], data.applied[-1:])
    return compute_metrics(data.stamps_ns / 1e9, data.positions, data.speeds, held,
                           data.ref_positions, data.ref_speeds, data.stops)


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
    a.plot(t, data.ref_speeds * 3.6, label='target', lw=2, alpha=0.6)
    a.plot(t, data.speeds * 3.6, label='train', lw=1)
    a.set_ylabel('speed (km/h)')
    a.legend()
    b.plot(t, data.ref_positions / 1000, label='target', lw=2, alpha=0.6)
    b.plot(t, data.positions / 1000, label='train', lw=1)
    b.set_ylabel('position (km)')
    b.set_xlabel('time (s)')
    fig.suptitle('tracking')
    save(fig, 'tracking.png')

    fig, (a, b) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    a.plot(t, (data.ref_speeds - data.speeds) * 3.6)
    a.set_ylabel('speed error (km/h)')
    b.plot(t, data.ref_positions - data.positions)
    b.set_ylabel('position error (m)')
    b.set_xlabel('time (s)')
    fig.suptitle('tracking errors (target minus train)')
    save(fig, 'errors.png')

    fig, a = plt.subplots(figsize=(10, 4))
    a.plot(data.command_times, data.commands / 1000, label='commanded', lw=2, alpha=0.6)
    a.plot(t, data.applied / 1000, label='applied', lw=1)
    a.set_ylabel('force (kN)')
    a.set_xlabel('time (s)')
    a.legend()
    fig.suptitle(f'traction and braking ({", ".join(data.laws)})')
    save(fig, 'commands.png')

    if data.estimates:
        fig, axes = plt.subplots(len(data.estimates), 1, figsize=(10, 2.2 * len(data.estimates)),
                                 sharex=True, squeeze=False)
        for axis, (name, values) in zip(axes[:, 0], sorted(data.estimates.items())):
            axis.plot([v[0] for v in values], [v[1] for v in values])
            axis.set_ylabel(name, fontsize=8)
        axes[-1, 0].set_xlabel('time (s)')
        fig.suptitle('estimates and internal signals of the law')
        save(fig, 'estimates.png')
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='report', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path)
    parser.add_argument('--output', type=Path, default=None,
                        help='folder for the plots (default: <bag>/report)')
    parser.add_argument('--namespace', default=None,
                        help="namespace the stack ran in (-r __ns:=...), '/' for the root "
                             "(default: the one namespace holding the suite's topics)")
    options = parser.parse_args(argv)
    try:
        data = load_run(options.bag, options.namespace)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    metrics = run_metrics(data)
    print(format_summary(metrics, str(options.bag), ', '.join(data.laws)))
    folder = options.output or Path(options.bag) / 'report'
    for path in plot(data, folder):
        print(f'plot: {path}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
