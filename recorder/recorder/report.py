"""report: a run's metrics and plots from its recording alone.

    ros2 run recorder report runs/my_run            # writes runs/my_run/report/*.png
    ros2 run recorder report runs/fleet --namespace /train1

The topics are the suite's (:data:`ato_common.conventions.TOPICS`). Their relative names are
found in the namespace the stack ran in (``-r __ns:=/train1``): by default the one namespace in
which the recording holds them, under their names and types; ``--namespace`` chooses when it
holds several (``/`` is the root namespace). ``/diagnostics`` is global: in a recording of
several stacks it mixes their laws' estimates.

The report tells the journey: the scenario and the train (from the plant's recorded identity,
or ``--scenario``), the metrics ``make demo`` prints (:mod:`ato_common.metrics`: the lead car's
true state against the reference at each stamp, stopping errors read where the latched target
curve leaves each stop, the energy from the applied force), each station by name with its
planned and actual arrival, departure and dwell and its stopping error, each timing point of the
journey with its window met or missed, what went wrong (ATP and watchdog events), and where the
run comes from (when it was recorded, from which commit of the suite, when reported).

The plots (``<bag>/report/*.png``, :mod:`recorder.report_plots`, and all of them with the
tables in the single page ``report.html``): target, actual and permitted speed (the profile's
permitted speed: static limits and braking curves) with the ATP's interventions and the command
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
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from mcap_ros2.decoder import DecoderFactory

from ato_common.conventions import TOPICS, status_in_namespace
from ato_common.identity import identity_mismatch, parse_identity, scenario_identity
from ato_common.metrics import RunMetrics, StopSample, compute_metrics, format_summary
from ato_common.run_events import PLATFORM_TOLERANCE_M, journey_events, timing_points_passed
from ato_common.scenario import Scenario, builtin_scenarios, load_scenario
from ato_common.validation import ConfigError
from recorder.bag import BagError, bag_info, read_messages
from recorder.report_plots import plot

REPORTED = ('state', 'reference', 'command', 'curve', 'diagnostics')
"""The keys of the conventions' topics the report needs."""
OPTIONAL = ('state_measured', 'permitted_speed', 'distance_to_go', 'actuators_commanded',
            'actuators_applied', 'identity')
"""The keys of the topics it plots when the recording holds them."""

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


@dataclass(frozen=True)
class PlannedStop:
    """A standstill of the target curve: where, from when (the planned arrival) and until when
    (``read_s``: the planned departure, or the end of the curve at the last stop, where
    ``departure_s`` is None); ``name`` the station's where the scenario is known."""

    name: str
    position_m: float
    arrival_s: float
    read_s: float
    departure_s: float | None

    def sample(self) -> StopSample:
        """Where the metrics read the stopping error: at the end of the dwell."""
        return StopSample(self.name, self.position_m, self.read_s)


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
    planned_stops: list[PlannedStop]
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
    custom_data: dict[str, str] = field(default_factory=dict)  # the bag's (provenance)

    @property
    def stops(self) -> list[StopSample]:
        return [stop.sample() for stop in self.planned_stops]


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
                     ) -> list[PlannedStop]:
    """Each standstill of the target curve after the train first moved: from its first to
    its last instant (the stop error is read at the last, the end of the dwell)."""
    stops: list[PlannedStop] = []
    moving = np.nonzero(speeds > 0.0)[0]
    if moving.size == 0:
        return stops
    i = moving[0]
    while i < times.size:
        if speeds[i] == 0.0:
            j = i
            while j + 1 < times.size and speeds[j + 1] == 0.0:
                j += 1
            stops.append(PlannedStop(f'stop at {positions[i]:.0f} m', float(positions[i]),
                                     float(times[i]), float(times[j]),
                                     float(times[j]) if j + 1 < times.size else None))
            i = j + 1
        else:
            i += 1
    return stops


class _Reader:
    """What ``load_run`` gathers from a recording, topic by topic (``take``)."""

    def __init__(self, topics: dict[str, str]):
        self.topics = topics
        # the stack's namespace, from where its state is ('/train1/train/state' -> '/train1')
        self.namespace = topics['state'][:-len(TOPICS['state'].name) - 1] or '/'
        self.states: dict[int, tuple] = {}
        self.cars_of: dict[int, tuple] = {}
        self.references: dict[int, tuple] = {}
        self.commands: list[tuple] = []
        self.estimates: dict[str, list] = {}
        self.stops: list[PlannedStop] = []
        self.watch = {'watchdog': 'normal', 'atp_intervention': 'False'}
        empty = np.array([])  # the arrays are load_run's
        self.extra = RunData(empty, empty, empty, empty, empty, empty, empty, empty, [], [])
        keys = {name: key for key, name in topics.items()}
        self.handlers = {name: getattr(self, f'on_{key}') for name, key in keys.items()}

    def take(self, message, msg) -> None:
        self.handlers[message.topic](msg, message.log_time_ns / 1e9)

    def on_state(self, msg, t_log: float) -> None:
        p = msg.points[0]
        self.states[_stamp(msg.header)] = (p.positions[0], p.velocities[0], sum(p.effort))
        self.cars_of[_stamp(msg.header)] = (tuple(msg.joint_names), tuple(p.positions),
                                            tuple(p.velocities), tuple(p.effort))

    def on_state_measured(self, msg, t_log: float) -> None:
        p = msg.points[0]
        self.extra.measured[_stamp(msg.header)] = (p.positions[0], p.velocities[0])

    def on_permitted_speed(self, msg, t_log: float) -> None:
        self.extra.permitted.append((t_log, msg.data))

    def on_distance_to_go(self, msg, t_log: float) -> None:
        self.extra.distance_to_go.append((t_log, msg.data))

    def _forces(self, msg, into: dict) -> None:
        for name, force in zip(msg.name, msg.effort):
            into.setdefault(name, []).append((_stamp(msg.header) / 1e9, force))

    def on_actuators_commanded(self, msg, t_log: float) -> None:
        self._forces(msg, self.extra.actuators_commanded)

    def on_actuators_applied(self, msg, t_log: float) -> None:
        self._forces(msg, self.extra.actuators_applied)

    def on_identity(self, msg, t_log: float) -> None:
        self.extra.identity = msg.data

    def on_reference(self, msg, t_log: float) -> None:
        p = msg.points[0]
        self.references[_stamp(msg.header)] = (p.positions[0], p.velocities[0])

    def on_command(self, msg, t_log: float) -> None:
        self.commands.append((_stamp(msg.header), sum(msg.effort), msg.header.frame_id))

    def on_curve(self, msg, t_log: float) -> None:
        times = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
                          for p in msg.points])
        self.stops = stops_from_curve(times, np.array([p.positions[0] for p in msg.points]),
                                      np.array([p.velocities[0] for p in msg.points]))

    def on_diagnostics(self, msg, t_log: float) -> None:
        for status in msg.status:
            own = status_in_namespace(status.name, self.namespace)
            if own is None:
                continue  # a status of another stack recorded alongside
            _events(own, status, _stamp(msg.header) / 1e9, self.watch, self.extra.events)
            for kv in status.values:
                if kv.key.startswith('estimate.'):
                    try:
                        self.estimates.setdefault(kv.key[9:], []).append(
                            (_stamp(msg.header) / 1e9, float(kv.value)))
                    except ValueError:
                        pass

    def run(self, bag: Path) -> RunData:
        """The run, once every message is taken: the states and references of the same
        stamps; BagError if there are none."""
        if not self.states:
            raise BagError(f'{bag} has no {self.topics["state"]} messages: nothing to report on')
        stamps = np.array(sorted(k for k in self.states if k in self.references))
        if stamps.size == 0:
            raise BagError(f'{bag}: no {self.topics["reference"]} message matches a state stamp')
        s = np.array([self.states[k] for k in stamps])
        r = np.array([self.references[k] for k in stamps])
        commands = sorted(self.commands)
        data = RunData(stamps, s[:, 0], s[:, 1], s[:, 2], r[:, 0], r[:, 1],
                       np.array([c[0] for c in commands]) / 1e9,
                       np.array([c[1] for c in commands]), sorted({c[2] for c in commands}),
                       self.stops, self.estimates)
        layouts = {self.cars_of[k][0] for k in stamps}
        if len(layouts) == 1:
            (data.cars,) = [list(c) for c in layouts]
            data.car_positions = np.array([self.cars_of[k][1] for k in stamps])
            data.car_speeds = np.array([self.cars_of[k][2] for k in stamps])
            data.car_forces = np.array([self.cars_of[k][3] for k in stamps])
        for name in ('measured', 'permitted', 'distance_to_go', 'actuators_commanded',
                     'actuators_applied', 'events', 'identity'):
            setattr(data, name, getattr(self.extra, name))
        data.events.sort()
        return data


def load_run(bag: Path, namespace: str | None = None) -> RunData:
    """The run recorded in ``bag``; ``namespace``: see :func:`resolve_topics`."""
    topics = resolve_topics(bag, namespace)
    reader = _Reader(topics)
    decode = _decoder()
    for message in read_messages(bag, list(topics.values())):
        reader.take(message, decode(message))
    data = reader.run(bag)
    data.custom_data = bag_info(bag).custom_data
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


def scenario_of_run(data: RunData, given: str | None, bag: Path) -> Scenario | None:
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


#: the energies of the metrics, in the report's order: (attribute, label); a run's metrics show
#: those they have (braking, regenerated and net energy where ato_common.metrics gives them)
ENERGIES = (('traction_energy_kwh', 'traction energy, gross (kWh)'),
            ('braking_energy_kwh', 'braking energy (kWh)'),
            ('regenerated_energy_kwh', 'regenerated energy (kWh)'),
            ('net_energy_kwh', 'net energy (kWh)'))


def energy_rows(metrics: RunMetrics) -> list[tuple[str, str]]:
    return [(text, f'{getattr(metrics, name):.2f}') for name, text in ENERGIES
            if getattr(metrics, name, None) is not None]


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
    rows += energy_rows(metrics)
    rows += [('simulated time (s)', f'{metrics.simulated_time_s:.1f}'),
             ('samples', str(metrics.samples))]
    return rows + event_rows(metrics, events, journey)


def name_stops(data: RunData, scenario) -> None:
    """The planned stops named after the scenario's stations where they stand (within a
    metre); the others keep their position as name."""
    if scenario is None:
        return
    named = []
    for stop in data.planned_stops:
        station = min(scenario.line.stations, key=lambda s: abs(s.position_m - stop.position_m))
        if abs(station.position_m - stop.position_m) <= 1.0:
            stop = replace(stop, name=station.name)
        named.append(stop)
    data.planned_stops = named


def _time(value: float | None) -> str:
    return '-' if value is None else f'{value:.1f}'


STOP_COLUMNS = ('station', 'position (m)', 'arrival, planned (s)', 'arrival (s)',
                'departure, planned (s)', 'departure (s)', 'dwell, planned (s)', 'dwell (s)',
                'stopping error (m)')
#: a train stands at a stop while it is this slow, m/s, and this near it, m (a stopping error
#: beyond is a failed stop, whose times the table does not give)
STANDSTILL_MPS = 0.01
STANDSTILL_RANGE_M = 5.0


def standstill(times, positions, speeds, position_m: float
               ) -> tuple[float | None, float | None]:
    """(arrival, departure) of the train at a stop: the first and last instant of its first
    standstill near it (None: never, or the run started or ended standing there)."""
    standing = (np.abs(np.asarray(speeds)) <= STANDSTILL_MPS) & \
        (np.abs(np.asarray(positions) - position_m) <= STANDSTILL_RANGE_M)
    found = np.flatnonzero(standing)
    if found.size == 0:
        return None, None
    first = found[0]
    last = first
    while last + 1 < standing.size and standing[last + 1]:
        last += 1
    return (None if first == 0 else float(times[first]),
            None if last == standing.size - 1 else float(times[last]))


def _dwell(arrival: float | None, departure: float | None) -> float | None:
    return departure - arrival if arrival is not None and departure is not None else None


def stop_rows(data: RunData, metrics: RunMetrics) -> list[tuple[str, ...]]:
    """Each stop of the target curve: the station, its planned (the curve's standstill) and
    actual (the train's standstill) arrival, departure and dwell ('-' where the run starts or
    ends standing) and its stopping error."""
    times = data.stamps_ns / 1e9
    rows: list[tuple[str, ...]] = []
    for stop in data.planned_stops:
        arrival, departure = standstill(times, data.positions, data.speeds, stop.position_m)
        error = metrics.stop_errors_m.get(stop.name)
        rows.append((stop.name, f'{stop.position_m:.1f}', _time(stop.arrival_s), _time(arrival),
                     _time(stop.departure_s), _time(departure),
                     _time(_dwell(stop.arrival_s, stop.departure_s)),
                     _time(_dwell(arrival, departure)),
                     '-' if error is None else f'{error:+.3f}'))
    return rows


WINDOW_COLUMNS = ('timing point', 'position (m)', 'timed', 'window (s)', 'time (s)', 'window')


def window_rows(data: RunData, scenario) -> list[tuple[str, ...]]:
    """Each timing point of the scenario's journey, its window and whether the run met it."""
    if scenario is None:
        return []
    return [(str(p.index), f'{p.position_m:.1f}', p.what,
             f'[{_time(p.earliest_s)}, {_time(p.latest_s)}]', _time(p.time_s),
             'met' if p.met else 'missed' if p.time_s is not None else 'missed (never reached)')
            for p in timing_points_passed(scenario, data.stamps_ns / 1e9, data.positions)]


def journey_facts(data: RunData, scenario, bag: Path) -> list[tuple[str, str]]:
    """What the run is and where it comes from: the scenario and the train, the recording,
    when it was recorded and from which commit of the suite, and when this report was made."""
    if scenario is not None:
        names = [('scenario', scenario.name), ('train', scenario.train.name)]
    elif data.identity:
        names = [('scenario', f'{parse_identity(data.identity)["scenario"]} (a file: give it '
                              'with --scenario for its stations and windows)'),
                 ('train', 'unknown')]
    else:
        names = [('scenario', 'unknown (no train/identity recorded: --scenario)'),
                 ('train', 'unknown')]
    custom = data.custom_data
    return names + [
        ('controller', ', '.join(data.laws) or 'none recorded'),
        ('recording', str(bag)),
        ('recorded at', custom.get('recorded_utc', 'not recorded')),
        ('suite commit of the run', custom.get('suite_commit', 'not recorded')),
        ('report made at', datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'))]


def _table(element_id: str, header: tuple[str, ...], rows) -> str:
    from html import escape
    head = ''.join(f'<th scope="col">{escape(h)}</th>' for h in header)
    body = ''.join('<tr>' + ''.join(f'<td>{escape(c)}</td>' for c in row) + '</tr>'
                   for row in rows)
    return f'<table id="{element_id}"><tr>{head}</tr>{body}</table>'


def _pairs(element_id: str, rows) -> str:
    from html import escape
    body = ''.join(f'<tr><th scope="row">{escape(k)}</th><td>{escape(v)}</td></tr>'
                   for k, v in rows)
    return f'<table id="{element_id}">{body}</table>'


@dataclass
class Report:
    """Everything the report says of a run (the text on stdout, ``report.html``)."""

    bag: Path
    data: RunData
    scenario: Scenario | None
    metrics: RunMetrics

    def sections(self) -> list[tuple[str, str]]:
        """(heading, HTML) of each part of the page but the plots."""
        data, scenario = self.data, self.scenario
        events = ''.join(f'<tr><td>{f"{t:.2f}" if math.isfinite(t) else "never"}</td>'
                         f'<td>{_escape(kind)}</td><td>{_escape(message)}</td></tr>'
                         for t, kind, message in data.events)
        windows = window_rows(data, scenario)
        return [
            ('The run', _pairs('journey', journey_facts(data, scenario, self.bag))),
            ('Summary', _pairs('summary', summary_rows(self.metrics, data.laws, data.events,
                                                       scenario))),
            ('Stations', _table('stations', STOP_COLUMNS, stop_rows(data, self.metrics))
             if data.planned_stops else '<p id="stations">no stop in the target curve</p>'),
            ('Timetable windows', _table('windows', WINDOW_COLUMNS, windows) if windows else
             '<p id="windows">' + ('the scenario is unknown: not checked (--scenario)'
                                   if scenario is None else 'the scenario has no timing '
                                   'points with windows') + '</p>'),
            ('ATP interventions, watchdog events and missed time windows',
             f'<table id="events"><tr><th>time (s)</th><th>event</th><th>message</th></tr>'
             f'{events}</table>' if data.events else '<p id="events">none</p>')]


def _escape(text: str) -> str:
    from html import escape
    return escape(text)


def write_html(path: Path, title: str, report: Report, plots: list[Path]) -> Path:
    """One self-contained page: the run, the summary, the stations, the windows, the events
    and every plot embedded (no file beside it needed, no script)."""
    import base64
    figures = ''.join(
        f'<figure id="{_escape(p.stem)}"><img alt="{_escape(p.stem)}" '
        f'src="data:image/png;base64,{base64.b64encode(p.read_bytes()).decode()}">'
        f'<figcaption>{_escape(p.stem)}</figcaption></figure>' for p in plots)
    sections = ''.join(f'<h2>{_escape(heading)}</h2>{body}'
                       for heading, body in report.sections())
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<title>{_escape(title)}</title><style>body{{font-family:sans-serif;margin:2em}}'
        'table{border-collapse:collapse;margin-bottom:1em}th,td{border:1px solid #ccc;'
        'padding:0.2em 0.6em;text-align:left}img{max-width:100%}</style></head><body>'
        f'<h1>{_escape(title)}</h1>{sections}<h2>Plots</h2>{figures}</body></html>\n')
    path.write_text(page, encoding='utf-8')
    return path


def build_report(bag: Path, namespace: str | None = None, scenario: str | None = None
                 ) -> Report:
    """The run recorded in ``bag`` with its scenario (``scenario``, or the plant's recorded
    identity's), its stops named and its missed windows among the events; BagError says what
    is wrong."""
    data = load_run(bag, namespace)
    journey = scenario_of_run(data, scenario, bag)
    name_stops(data, journey)
    data.events = sorted(data.events + journey_rows(data, journey),
                         key=lambda e: (not math.isfinite(e[0]), e[0]))
    return Report(Path(bag), data, journey, run_metrics(data))


def write_report(report: Report, folder: Path) -> Path:
    """The plots and ``report.html`` in ``folder``; the page's path."""
    plots = plot(report.data, folder, report.metrics.stop_errors_m)
    title = f'Run report: {report.bag.name}' if report.scenario is None else \
        f'Run report: {report.scenario.name} ({report.bag.name})'
    return write_html(folder / 'report.html', title, report, plots)


def print_report(report: Report) -> None:
    data, metrics = report.data, report.metrics
    facts = journey_facts(data, report.scenario, report.bag)
    print(format_summary(metrics, facts[0][1], ', '.join(data.laws)))
    for key, value in facts[1:]:
        if key != 'controller':
            print(f'{key + " ":22s}{value}')
    for key, value in energy_rows(metrics)[1:]:
        print(f'{key + " ":22s}{value}')
    for row in stop_rows(data, metrics):
        print(f'station {row[0]} at {row[1]} m: arrival {row[3]} s (planned {row[2]}), '
              f'departure {row[5]} s (planned {row[4]}), dwell {row[7]} s (planned {row[6]}), '
              f'stopping error {row[8]} m')
    for row in window_rows(data, report.scenario):
        print(f'timing point {row[0]} at {row[1]} m: {row[2]} at {row[4]} s, window {row[3]} '
              f's: {row[5]}')
    for key, value in event_rows(metrics, data.events, report.scenario):
        print(f'{key + " ":22s}{value}')
    for t, kind, message in data.events:
        print(f'event at {t:9.2f} s: {kind}: {message}' if math.isfinite(t)
              else f'event (never):    {kind}: {message}')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='report', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path)
    parser.add_argument('--output', type=Path, default=None,
                        help='folder for the plots and report.html (default: <bag>/report)')
    parser.add_argument('--namespace', default=None,
                        help="namespace the stack ran in (-r __ns:=...), '/' for the root "
                             "(default: the one namespace holding the suite's topics)")
    parser.add_argument('--scenario', default=None,
                        help='the scenario the run simulated (a name or a file), for its '
                             "stations' names and its journey's time windows (default: the "
                             "built-in scenario the plant's recorded identity names; checked "
                             'against it)')
    options = parser.parse_args(argv)
    try:
        report = build_report(options.bag, options.namespace, options.scenario)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    print_report(report)
    folder = options.output or Path(options.bag) / 'report'
    page = write_report(report, folder)
    for path in sorted(folder.glob('*.png')):
        print(f'plot: {path}')
    print(f'html: {page}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
