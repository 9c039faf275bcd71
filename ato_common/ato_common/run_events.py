"""What went wrong in a run, from what the run published: ATP emergency brake interventions and
command-watchdog brakes (the plant's diagnostics, or the plant's ATP rule replayed on the truth
of an offline run), journey timing points outside their time windows and stopping errors beyond
the platform tolerance (the measured positions). Each kind with its count and first occurrence;
a run without any is clean. No ROS here: the lockstep runner and the offline command share it.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Iterable, Sequence

from ato_common.metrics import RunMetrics
from ato_common.scenario import Scenario

#: the platform-stop tolerance, m: the usual ATO accuracy requirement (the comparison's ranking
#: constraint, ``ato_campaigns.compare.STOP_ERROR_LIMIT_M``, is the same figure)
PLATFORM_TOLERANCE_M = 0.5
#: the plant's diagnostic status (train_plant_node.node)
PLANT_STATUS = 'train_plant_node: simulation'
NORMAL_WATCHDOG = 'normal'

ATP, WATCHDOG, JOURNEY, STOP = ('ATP interventions', 'watchdog brakes', 'missed journey windows',
                                'stop errors')
KINDS = (ATP, WATCHDOG, JOURNEY, STOP)
LABELS = {ATP: ATP, WATCHDOG: WATCHDOG, JOURNEY: 'missed time windows', STOP: STOP}


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
        parts = []
        for kind in KINDS:
            if self.count(kind):
                first = self.first(kind)
                when = '' if first is None or math.isnan(first.time_s) else \
                    f' (first at {first.time_s:.1f} s)'
                parts.append(f'{self.count(kind)} {LABELS[kind]}{when}')
        return '; '.join(parts)

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


def timing_points_passed(scenario: Scenario, times_s: Sequence[float],
                         positions: Sequence[float],
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


def journey_events(scenario: Scenario, times_s: Sequence[float], positions: Sequence[float],
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
