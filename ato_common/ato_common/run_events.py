"""What went wrong in a run, from what the run published: ATP emergency brake interventions and
command-watchdog brakes (the plant's diagnostics, or the plant's ATP rule replayed on the truth
of an offline run), journey timing points outside their time windows and stopping errors beyond
the platform tolerance (the measured positions). Each kind with its count and first occurrence;
a run without any is clean. No ROS here: the lockstep runner and the offline command share it.

A run's status (:func:`run_status`, the campaigns' and the comparison's) is ``ok`` only for a
clean run whose train finished its journey on time; otherwise it names the most serious of what
went wrong (:data:`STATUSES`, most serious first) and its reason lists every one. Lateness is
measured against the timetable (:func:`late_arrivals`): a train that arrives at a stop
``LATE_AFTER_S`` or more after the timetable's arrival there is late, however well it stops.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from ato_common.braking_curves import RunSupervision
from ato_common.metrics import RunMetrics
from ato_common.scenario import Scenario

#: the platform-stop tolerance, m: the usual ATO accuracy requirement (the comparison's ranking
#: constraint, ``ato_campaigns.compare.STOP_ERROR_LIMIT_M``, is the same figure)
PLATFORM_TOLERANCE_M = 0.5
#: the plant's diagnostic status (train_plant_node.node)
PLANT_STATUS = 'train_plant_node: simulation'
NORMAL_WATCHDOG = 'normal'
#: a train at most this fast stands still, m/s (the supervision's standstill)
STANDSTILL_MPS = RunSupervision.STANDSTILL_MPS

ATP, WATCHDOG, JOURNEY, STOP = ('ATP interventions', 'watchdog brakes', 'missed journey windows',
                                'stop errors')
KINDS = (ATP, WATCHDOG, JOURNEY, STOP)
LABELS = {ATP: ATP, WATCHDOG: WATCHDOG, JOURNEY: 'missed time windows', STOP: STOP}

#: an arrival this much after the timetable's or later is late, s. A suite setting: well beyond
#: how far a tracking law's arrival scatters around its reference's, well within the railways'
#: punctuality threshold of a minute (Network Rail's "On Time": within 59 s of the timetable),
#: which a late train of a 15-minute journey can reach with no control error at all
LATE_AFTER_S = 10.0
#: a run's statuses, the most serious first: the run could not be made (``error``, ``timeout``),
#: its state turned non-finite (``diverged``), its train did not finish its journey, then each
#: kind of what went wrong; ``ok`` only for a clean run that finished on time
STATUSES = ('error', 'timeout', 'diverged', 'did not finish', 'ATP intervention',
            'watchdog brake', 'faults', 'stop error', 'late', 'missed time window', 'ok')
#: the status a kind of event gives a run
STATUS_OF_KIND = {ATP: 'ATP intervention', WATCHDOG: 'watchdog brake', STOP: 'stop error',
                  JOURNEY: 'missed time window'}
#: the statuses of runs that were made and measured (every status but error and timeout)
MEASURED = STATUSES[2:]


@dataclass(frozen=True)
class RunEvent:
    kind: str        # one of KINDS
    time_s: float    # simulated time of the occurrence (nan if unknown)
    detail: str


@dataclass(frozen=True)
class RunEvents:
    events: tuple[RunEvent, ...] = ()
    counts: dict = field(default_factory=dict)  # kind -> count (a counter may exceed events)
    tolerance_m: float = PLATFORM_TOLERANCE_M

    @property
    def clean(self) -> bool:
        return not any(self.counts.get(kind, 0) for kind in KINDS)

    def count(self, kind: str) -> int:
        return self.counts.get(kind, 0)

    def first(self, kind: str) -> RunEvent | None:
        return next((e for e in self.events if e.kind == kind), None)

    def brief(self) -> str:
        """One line for a table: 'clean', or each kind that occurred with its count and its
        first occurrence ('1 ATP interventions (first at 103.4 s)')."""
        if self.clean:
            return 'clean'
        return '; '.join(self.brief_of(kind) for kind in KINDS if self.count(kind))

    def brief_of(self, kind: str) -> str:
        """One kind's count and first occurrence ('2 stop errors (first at 412.6 s)')."""
        first = self.first(kind)
        when = '' if first is None or math.isnan(first.time_s) else \
            f' (first at {first.time_s:.1f} s)'
        return f'{self.count(kind)} {LABELS[kind]}{when}'

    def format(self) -> str:
        """Summary lines: one per kind, with its count and its first occurrence."""
        lines = []
        for kind in KINDS:
            count = self.count(kind)
            label = LABELS[kind].ljust(22)
            if not count:
                lines.append(f'{label}0')
                continue
            first = self.first(kind)
            when = '' if first is None or math.isnan(first.time_s) else \
                f' at {first.time_s:.1f} s'
            lines.append(f'{label}{count}, first{when}: {first.detail if first else "?"}')
        verdict = 'clean' if self.clean else 'NOT CLEAN: ' + ', '.join(
            f'{self.count(k)} {k}' for k in KINDS if self.count(k))
        lines.append(f'{"events".ljust(22)}{verdict} (platform tolerance {self.tolerance_m:g} m)')
        return '\n'.join(lines)


def merge(*parts: RunEvents, tolerance_m: float = PLATFORM_TOLERANCE_M) -> RunEvents:
    events = sorted((e for p in parts for e in p.events),
                    key=lambda e: (KINDS.index(e.kind), e.time_s if not math.isnan(e.time_s)
                                   else math.inf))
    counts = {kind: sum(p.count(kind) for p in parts) for kind in KINDS}
    return RunEvents(tuple(events), counts, tolerance_m)


def safety_events(diagnostics: Iterable[tuple[int, str, dict, str]]) -> RunEvents:
    """ATP interventions and watchdog brakes from the plant's diagnostics ((stamp ns, name,
    values, message), in any order). The plant publishes its status at once when a safety
    state changes, so each onset is one status; its ``atp_interventions`` counter covers an
    onset whose status was lost."""
    statuses = sorted((d for d in diagnostics if d[1] == PLANT_STATUS), key=lambda d: d[0])
    events, atp_onsets, watchdog_onsets, counter = [], 0, 0, 0
    atp_before, watchdog_before = False, NORMAL_WATCHDOG
    for stamp_ns, _, values, message in statuses:
        atp = values.get('atp_intervention') == 'True'
        watchdog = values.get('watchdog', NORMAL_WATCHDOG)
        try:
            counter = max(counter, int(values.get('atp_interventions', 0)))
        except ValueError:
            pass
        if atp and not atp_before:
            atp_onsets += 1
            events.append(RunEvent(ATP, stamp_ns / 1e9, message))
        if watchdog != NORMAL_WATCHDOG and watchdog != watchdog_before:
            if watchdog_before == NORMAL_WATCHDOG:
                watchdog_onsets += 1
            events.append(RunEvent(WATCHDOG, stamp_ns / 1e9,
                                   message or f'command watchdog: {watchdog}'))
        atp_before, watchdog_before = atp, watchdog
    return RunEvents(tuple(events), {ATP: max(atp_onsets, counter), WATCHDOG: watchdog_onsets})


def plant_atp_events(atp_times_s: Sequence[float]) -> RunEvents:
    """The ATP interventions an offline run's plant made (``OfflineRun.atp_times_s``: the end of
    each control period in which one began)."""
    events = tuple(RunEvent(ATP, float(t), 'ATP emergency brake intervention of the plant, in '
                                           f'the control period ending at {t:.1f} s')
                   for t in atp_times_s)
    return RunEvents(events, {ATP: len(events)})


def stop_events(metrics: RunMetrics, stations: Sequence[tuple[str, float, float]],
                tolerance_m: float = PLATFORM_TOLERANCE_M) -> RunEvents:
    """Stopping errors beyond the tolerance (``stations``: (name, position, planned departure
    time)); a stop the run ended before is one too."""
    events = []
    for name, position_m, departure_s in stations:
        error = metrics.stop_errors_m.get(name)
        if error is None:
            events.append(RunEvent(STOP, departure_s, f'{name}: the run ended before the stop '
                                                      f'at {position_m:.0f} m'))
        elif not abs(error) <= tolerance_m:  # a NaN error is one too
            events.append(RunEvent(STOP, departure_s, f'{name}: stopped {error:+.3f} m from the '
                                                      f'stopping point (tolerance '
                                                      f'{tolerance_m:g} m)'))
    return RunEvents(tuple(events), {STOP: len(events)}, tolerance_m)


def _first_at_or_beyond(times_s, positions, position_m) -> float | None:
    for t, x in zip(times_s, positions):
        if x >= position_m:
            return float(t)
    return None


def _departure(times_s, positions, position_m) -> float | None:
    """The last instant at or before ``position_m`` after which the train is beyond it."""
    last = None
    for t, x in zip(times_s, positions):
        if x <= position_m:
            last = float(t)
        elif last is not None:
            return last
    return None


@dataclass(frozen=True)
class TimingPointPassed:
    """A timing point of a journey against a run: what is timed there (``departure``,
    ``arrival`` or ``passing``), its window, and when the run did it (None: never)."""

    index: int
    position_m: float
    what: str
    earliest_s: float | None
    latest_s: float | None
    time_s: float | None

    @property
    def met(self) -> bool:
        return self.time_s is not None and not (
            (self.earliest_s is not None and self.time_s < self.earliest_s)
            or (self.latest_s is not None and self.time_s > self.latest_s))


def timing_points_passed(scenario: Scenario, times_s: Sequence[float] | np.ndarray,
                         positions: Sequence[float] | np.ndarray,
                         tolerance_m: float = PLATFORM_TOLERANCE_M) -> list[TimingPointPassed]:
    """Each timing point of the scenario's journey against the run: a passing point when the
    front first reaches it, a stopping point's arrival when the front is first within the
    tolerance of it, a departure (the first point, or the second of a station's pair) when
    the front last is within the tolerance before leaving. No journey: none."""
    if scenario.journey is None:
        return []
    passed = []
    points = scenario.journey.timing_points
    times_s, positions = list(times_s), list(positions)
    for i, point in enumerate(points):
        is_departure = i == 0 or (point.is_stopping_point and points[i - 1].is_stopping_point
                                  and points[i - 1].position_m == point.position_m)
        last = i == len(points) - 1
        if point.is_stopping_point and is_departure and not last:
            what, t = 'departure', _departure(times_s, positions, point.position_m + tolerance_m)
        elif point.is_stopping_point:
            what, t = 'arrival', _first_at_or_beyond(times_s, positions,
                                                     point.position_m - tolerance_m)
        else:
            what, t = 'passing', _first_at_or_beyond(times_s, positions, point.position_m)
        passed.append(TimingPointPassed(i, point.position_m, what, point.earliest_s,
                                        point.latest_s, t))
    return passed


def journey_events(scenario: Scenario, times_s: Sequence[float] | np.ndarray,
                   positions: Sequence[float] | np.ndarray,
                   tolerance_m: float = PLATFORM_TOLERANCE_M) -> RunEvents:
    """The timing points of the scenario's journey (:func:`timing_points_passed`) outside
    [earliest, latest] or never reached: missed windows."""
    if scenario.journey is None:
        return RunEvents((), {JOURNEY: 0})
    events = []
    for p in timing_points_passed(scenario, times_s, positions, tolerance_m):
        window = f'[{_bound(p.earliest_s)}, {_bound(p.latest_s)}] s'
        where = f'timing point {p.index} at {p.position_m:.0f} m'
        if p.time_s is None:
            events.append(RunEvent(JOURNEY, math.nan, f'{where}: no {p.what} in the run '
                                                      f'(window {window})'))
        elif not p.met:
            events.append(RunEvent(JOURNEY, p.time_s, f'{where}: {p.what} at {p.time_s:.1f} s, '
                                                      f'outside {window}'))
    return RunEvents(tuple(events), {JOURNEY: len(events)}, tolerance_m)


def _bound(value: float | None) -> str:
    return '-' if value is None else f'{value:g}'


def run_events(scenario: Scenario, metrics: RunMetrics, stations, times_s, positions,
               diagnostics=None, atp_times_s: Sequence[float] = (),
               tolerance_m: float = PLATFORM_TOLERANCE_M) -> RunEvents:
    """Every kind: the safety events from the plant's diagnostics when given (a run through the
    graph), else from the interventions the offline run's plant made (``atp_times_s``; an
    offline run has no watchdog: its controller answers every period)."""
    if diagnostics is not None:
        safety = safety_events(diagnostics)
    else:
        safety = merge(plant_atp_events(atp_times_s), RunEvents((), {WATCHDOG: 0}))
    return merge(safety, journey_events(scenario, times_s, positions, tolerance_m),
                 stop_events(metrics, stations, tolerance_m), tolerance_m=tolerance_m)


def arrival_times(stops: Sequence[tuple[str, float, float]], times_s, positions, speeds,
                  reach_m: float) -> dict[str, float | None]:
    """When the train arrived at each stop ((name, position, planned arrival)): the start of
    its last standstill (at most STANDSTILL_MPS) within ``reach_m`` of the stop; None for a
    stop it never stood at. The lead car's true positions and speeds."""
    t = np.asarray(times_s, dtype=float)
    x = np.asarray(positions, dtype=float)
    standing = np.abs(np.asarray(speeds, dtype=float)) <= STANDSTILL_MPS
    arrived: dict[str, float | None] = {}
    for name, position_m, _ in stops:
        there = np.flatnonzero(standing & (np.abs(x - position_m) <= reach_m))
        if not there.size:
            arrived[name] = None
            continue
        gaps = np.flatnonzero(np.diff(there) > 1)  # where one standstill ends, another begins
        arrived[name] = float(t[there[gaps[-1] + 1] if gaps.size else there[0]])
    return arrived


def late_arrivals(stops: Sequence[tuple[str, float, float]], times_s, positions, speeds,
                  reach_m: float, late_after_s: float = LATE_AFTER_S
                  ) -> list[tuple[str, float]]:
    """(stop, delay) of each stop of the timetable (``stops``: (name, position, arrival)) that
    the train arrived at ``late_after_s`` or more after its timetabled arrival
    (:func:`arrival_times`)."""
    arrived = arrival_times(stops, times_s, positions, speeds, reach_m)
    delays = ((name, at - planned) for name, _, planned in stops
              if (at := arrived[name]) is not None)
    return [(name, delay) for name, delay in delays if delay >= late_after_s]


def run_status(events: RunEvents, unfinished: str = '', late: Sequence[tuple[str, float]] = (),
               held: Sequence[str] = ()) -> tuple[str, str]:
    """(status, reason) of a run that was made, with finite states: ``ok`` and '' for a clean
    run that finished on time; else the most serious of what went wrong (STATUSES) and, in
    that order, each thing: ``unfinished`` (why the train did not finish its journey), the
    events, ``held`` (the reasons the host held the command, one per step) and ``late``
    (:func:`late_arrivals`)."""
    found = []
    if unfinished:
        found.append(('did not finish', f'did not finish: {unfinished}'))
    for kind in KINDS:
        if events.count(kind):
            found.append((STATUS_OF_KIND[kind], events.brief_of(kind)))
    if held:
        found.append(('faults', f'{len(held)} steps held: {held[0]}'))
    if late:
        found.append(('late', 'late: ' + ', '.join(f'{name} {delay:.1f} s' for name, delay
                                                   in late)
                      + f' after the timetable (late from {LATE_AFTER_S:g} s)'))
    if not found:
        return 'ok', ''
    found.sort(key=lambda item: STATUSES.index(item[0]))
    return found[0][0], '; '.join(text for _, text in found)


def exit_code(events: RunEvents, fail_on_events: bool = True) -> int:
    """0 for a clean run or when the user asked not to fail on events, else EVENTS_EXIT_CODE."""
    return EVENTS_EXIT_CODE if fail_on_events and not events.clean else 0


def final_exit_code(events: RunEvents, fail_on_events: bool = True) -> int:
    """:func:`exit_code`, saying on stderr why a run that was not clean fails."""
    code = exit_code(events, fail_on_events)
    if code:
        print(f'the run was not clean: exit code {code} (--no-fail-on-events: 0)',
              file=sys.stderr)
    return code


#: the exit code of a run that completed but was not clean (1: the run failed, 2: bad input)
EVENTS_EXIT_CODE = 3


def stations_of(plan) -> list[tuple[str, float, float]]:
    """(name, position, planned departure) of every stop of a plan (profile_node.planner)."""
    return [(s.station.name, s.station.position_m, s.departure_s) for s in plan.stops]
