"""The conformance harness's cases, judged from what it observed (no ROS here): each case of the
ATO node contract (``ato_common.contract``) passed or failed with its evidence.

The harness (``ato_bringup.conformance``) runs the user's ATO node twice. The main run drives a
variant of the scenario made for the test (:func:`variant_document`: a total traction loss at
the start, so that the train stands while its reference leaves and the profile replans the leg
from where it stands, then a failed speed sensor), then a new plant (a restart), then stops the
plant and tells the node to stop. The other run gives the node a plant of another scenario.
What it saw is an :class:`Observation`; :func:`judge` turns it into one :class:`CaseResult` per
case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ato_common.contract import CASES
from ato_common.types import NS_PER_S

#: the parts of the main run, as fractions of its horizon (``Schedule``)
LOSS = (0.0, 0.1)          # every actuator's traction lost: the train stands, the plan leaves
TRACKING = (0.3, 0.5)      # after the profile resumed: the node must track the new reference
SENSOR = (0.75, 0.8)       # the speed sensor failed (NaN)
#: the longest horizon of the main run, s of simulated time (a long scenario is cut there)
HORIZON_S = 200.0
#: the restarted plant's run, s of simulated time
RESTART_S = 20.0
#: a node told to stop must end within this, s of wall time (launch's SIGINT-to-SIGTERM), not
#: counting the time the machine kept it waiting for a CPU: on a loaded machine (the harness's
#: own processes, two cores) a node can be runnable for seconds without a CPU, and a limit in
#: wall time would judge the machine. The time counted is ``ato_ros.stall``'s: wall time in
#: which the node made no progress although it could have.
STOP_LIMIT_S = 5.0
#: ... and within this many times the limit of wall time in any case
STOP_WALL_FACTOR = 4.0
#: the node following the replanned reference: its RMS position error to the streamed
#: reference at most this fraction of its error to the first plan's curve
FOLLOWS_RATIO = 0.5


@dataclass(frozen=True)
class Schedule:
    """When the main run does what, s of simulated time."""

    horizon_s: float

    def at(self, span: tuple[float, float]) -> tuple[float, float]:
        return span[0] * self.horizon_s, span[1] * self.horizon_s


def variant_document(document: dict, actuators: tuple[str, ...], schedule: Schedule) -> dict:
    """The scenario ``document`` (a scenario YAML's content) with the test's conditions:
    every actuator's traction lost during ``LOSS`` (from the start: the train stands while its
    reference leaves, and the profile plans the leg again from where it stands, a replanned
    reference), the speed sensor failed during ``SENSOR``. Its name stays: a node compares the
    plant's identity with the scenario it was given, which is this file."""
    variant = dict(document)
    plant = dict(variant.get('plant') or {})
    start, end = schedule.at(LOSS)
    plant['failures'] = [*(plant.get('failures') or []),
                         *({'actuator': name, 'kind': 'loss', 'start_s': start, 'end_s': end}
                           for name in actuators)]
    sensors = dict(plant.get('sensors') or {})
    speed = dict(sensors.get('speed') or {})
    speed['failed_from_s'], speed['failed_until_s'] = schedule.at(SENSOR)
    sensors['speed'] = speed
    plant['sensors'] = sensors
    variant['plant'] = plant
    return variant


@dataclass(frozen=True)
class Sent:
    """A command the node published."""

    stamp_ns: int
    frame_id: str
    names: tuple[str, ...]
    effort: tuple[float, ...]
    arrived_s: float  # monotonic wall time it was received


@dataclass
class Epoch:
    """One plant's run, as observed: each measured state's stamp (and how often it was sent),
    the truth and the streamed reference per stamp, the commands, the plant's last counters and
    the profile's plan statuses."""

    states: dict[int, int] = field(default_factory=dict)
    truth: dict[int, tuple[float, float]] = field(default_factory=dict)  # position, speed
    reference: dict[int, tuple[float, float]] = field(default_factory=dict)
    commands: list[Sent] = field(default_factory=list)
    plant: dict[str, str] = field(default_factory=dict)
    plans: list[tuple[int, str]] = field(default_factory=list)
    end_s: float = 0.0  # the simulated time the plant was to end at
    stalled: str = ''  # why the run did not reach its end ('' if it did)


@dataclass
class Observation:
    """What the harness saw of the node."""

    actuators: tuple[str, ...]
    period_ns: int
    schedule: Schedule
    main: Epoch
    restarted: Epoch
    original_positions: dict[int, float] = field(default_factory=dict)  # the first plan's
    stop_sent_s: float = math.nan  # wall time of the stop signal
    stop_exit: int | None = None  # the node's exit code after it (None: it did not end)
    stop_took_s: float = math.nan  # wall time from the signal to the exit (or the harness's
    # giving up)
    stop_stalled_s: float = math.nan  # of which without progress it could have made
    after_stop: list[Sent] = field(default_factory=list)
    other_scenario: str = ''
    other_commands: int = 0
    other_exit: int | None = None
    other_stalled: str = ''


@dataclass(frozen=True)
class CaseResult:
    """One case: passed (True), failed (False) or not run (None), with the evidence."""

    name: str
    passed: bool | None
    evidence: str

    @property
    def title(self) -> str:
        return CASES[self.name].title

    @property
    def verdict(self) -> str:
        return {True: 'PASS', False: 'FAIL', None: 'NOT RUN'}[self.passed]


def _s(stamp_ns: int) -> str:
    return f'{stamp_ns / NS_PER_S:.1f} s'


def _steps(e: Epoch) -> list[int]:
    """The stamps of the epoch's plant (a message of the plant before it, still in flight
    when the new one started, is not one)."""
    return sorted(k for k in e.states if k <= e.end_s * NS_PER_S)


def answers_every_step(o: Observation) -> CaseResult:
    e = o.main
    answered = {c.stamp_ns for c in e.commands}
    steps = _steps(e)
    missing = [k for k in steps[:-1] if k not in answered]  # the last may end the run first
    evidence = f'{len([k for k in steps if k in answered])} of {len(steps)} steps answered'
    if e.stalled:
        return CaseResult('answers_every_step', False, f'{evidence}; {e.stalled}')
    if not steps:
        return CaseResult('answers_every_step', None, 'the plant published no step')
    if missing:
        return CaseResult('answers_every_step', False, f'{evidence}; the first unanswered at '
                                                       f'{_s(missing[0])}')
    return CaseResult('answers_every_step', True, evidence + ' (the last may end the run first)')


def stamps(o: Observation) -> CaseResult:
    problems = []
    for epoch in (o.main, o.restarted):
        for c in epoch.commands:
            if c.stamp_ns not in epoch.states:
                problems.append(f'stamped {_s(c.stamp_ns)}, which no state had')
            elif tuple(c.names) != o.actuators:
                problems.append(f'names {list(c.names)} for actuators {list(o.actuators)}')
            elif len(c.effort) != len(o.actuators):
                problems.append(f'{len(c.effort)} forces at {_s(c.stamp_ns)}')
            elif not c.frame_id:
                problems.append(f'no law name in header.frame_id at {_s(c.stamp_ns)}')
    wrong = o.main.plant.get('wrong_stamp_commands', '?')
    commands = len(o.main.commands) + len(o.restarted.commands)
    if not commands:
        return CaseResult('stamps', None, 'the node published no command')
    if problems or wrong not in ('0', '?'):
        return CaseResult('stamps', False, f'{len(problems)} of {commands} commands wrong, '
                          f"first: {problems[0] if problems else 'none'}; the plant dropped "
                          f'{wrong} for their stamp')
    return CaseResult('stamps', True, f'{commands} commands, each stamped with a step of its '
                                      'plant, named after the actuators with a force each and '
                                      f'a law name; the plant dropped {wrong} for their stamp')


def rate(o: Observation) -> CaseResult:
    e = o.main
    per_stamp: dict[int, list[Sent]] = {}
    for c in e.commands:
        per_stamp.setdefault(c.stamp_ns, []).append(c)
    if not per_stamp:
        return CaseResult('rate', None, 'the node published no command')
    extra = [k for k, sent in per_stamp.items() if len(sent) > e.states.get(k, 0)]
    changed = [k for k, sent in per_stamp.items() if len({repr(c.effort) for c in sent}) > 1]
    stamps_ns = sorted(per_stamp)
    gaps = {b - a for a, b in zip(stamps_ns, stamps_ns[1:])}
    evidence = (f'{len(e.commands)} commands for {len(per_stamp)} steps, {len(e.states)} '
                f'steps sent; periods between stamps: '
                + ', '.join(f'{g / NS_PER_S:g} s' for g in sorted(gaps)[:3]))
    if extra:
        return CaseResult('rate', False, f'{evidence}; more commands than states at '
                                         f'{_s(extra[0])} (commanding on its own timer?)')
    if changed:
        return CaseResult('rate', False, f'{evidence}; a re-sent step at {_s(changed[0])} got '
                                         'another command (the law stepped twice)')
    if gaps - {o.period_ns}:
        return CaseResult('rate', False, f'{evidence}; the control period is '
                                         f'{o.period_ns / NS_PER_S:g} s')
    return CaseResult('rate', True, evidence)


def refuses_other_scenario(o: Observation) -> CaseResult:
    if o.other_stalled:
        return CaseResult('refuses_other_scenario', None, o.other_stalled)
    evidence = (f'given a plant of {o.other_scenario}: {o.other_commands} commands, exit '
                f"{'none (still running)' if o.other_exit is None else o.other_exit}")
    refused = o.other_commands == 0 and o.other_exit not in (None, 0)
    return CaseResult('refuses_other_scenario', refused, evidence)


def survives_restart(o: Observation) -> CaseResult:
    e = o.restarted
    answered = {c.stamp_ns for c in e.commands}
    steps = _steps(e)
    missing = [k for k in steps[:-1] if k not in answered]
    evidence = (f'the new plant (from 0 s, {e.end_s:g} s): '
                f'{len([k for k in steps if k in answered])} of {len(steps)} steps answered')
    if not steps:
        return CaseResult('survives_restart', None, 'the new plant published no step')
    if e.stalled or missing:
        return CaseResult('survives_restart', False, f'{evidence}; {e.stalled or "first "}'
                          f"{'' if e.stalled else 'unanswered at ' + _s(missing[0])}")
    return CaseResult('survives_restart', True, evidence)


def stops_when_told(o: Observation) -> CaseResult:
    if math.isnan(o.stop_sent_s):
        return CaseResult('stops_when_told', None, 'the node was not running to be stopped')
    starved = (f'{o.stop_took_s:.2f} s of wall time, {o.stop_stalled_s:.2f} s of it without '
               'progress it could have made')
    if o.stop_exit is None:
        return CaseResult('stops_when_told', False, f'still running {starved} after SIGINT '
                                                    f'(limit {STOP_LIMIT_S:g} s)')
    ok = o.stop_exit == 0 and o.stop_stalled_s <= STOP_LIMIT_S and \
        o.stop_took_s <= STOP_WALL_FACTOR * STOP_LIMIT_S
    return CaseResult('stops_when_told', ok, f'SIGINT: exit code {o.stop_exit} after {starved} '
                                             f'(limit {STOP_LIMIT_S:g} s, code 0)')


def no_command_after_shutdown(o: Observation) -> CaseResult:
    if math.isnan(o.stop_sent_s):
        return CaseResult('no_command_after_shutdown', None, 'the node was not stopped')
    late = [c for c in o.after_stop if c.arrived_s > o.stop_sent_s]
    if late:
        first = late[0]
        return CaseResult('no_command_after_shutdown', False,
                          f'{len(late)} commands after the stop signal (the plant had ended), '
                          f'first {first.arrived_s - o.stop_sent_s:.2f} s after it: effort '
                          f'{list(first.effort)} stamped {_s(first.stamp_ns)}')
    return CaseResult('no_command_after_shutdown', True, 'no command after the stop signal '
                                                         '(the plant had ended before it)')


def _rms(values: list[float]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else math.nan


def follows_replanned_reference(o: Observation) -> CaseResult:
    e = o.main
    start_s, end_s = o.schedule.at(TRACKING)
    replans = [(k, why) for k, why in e.plans
               if why.startswith(('replanned', 'resumed')) and k / NS_PER_S < start_s]
    window = [k for k in sorted(e.truth) if start_s <= k / NS_PER_S < end_s
              and k in e.reference and k in o.original_positions]
    if not replans or not window:
        return CaseResult('follows_replanned_reference', None,
                          f'the profile did not replan before {start_s:g} s ({len(replans)} '
                          'replans): no replanned reference to follow')
    to_stream = _rms([e.truth[k][0] - e.reference[k][0] for k in window])
    to_first = _rms([e.truth[k][0] - o.original_positions[k] for k in window])
    evidence = (f'{replans[-1][1].split(":")[0]} at {_s(replans[-1][0])}; from {start_s:g} to '
                f'{end_s:g} s the train '
                f'is {to_stream:.1f} m (RMS) from the streamed reference and {to_first:.1f} m '
                'from the first plan')
    return CaseResult('follows_replanned_reference', to_stream <= FOLLOWS_RATIO * to_first,
                      evidence)


def failed_sensor(o: Observation) -> CaseResult:
    e = o.main
    start_s, end_s = o.schedule.at(SENSOR)
    steps = [k for k in sorted(e.states) if start_s <= k / NS_PER_S < end_s]
    inside = [c for c in e.commands if start_s <= c.stamp_ns / NS_PER_S < end_s]
    bad = [c for c in inside if not all(map(math.isfinite, c.effort))]
    answered = {c.stamp_ns for c in inside}
    rejected = e.plant.get('rejected_commands', '?')
    if not steps:
        return CaseResult('failed_sensor', None, f'the run did not reach {start_s:g} s')
    evidence = (f'speed sensor failed from {start_s:g} to {end_s:g} s: {len(answered)} of '
                f'{len(steps)} steps answered, {len(bad)} non-finite commands, the plant '
                f'rejected {rejected}')
    ok = not bad and len(answered) == len(steps) and rejected in ('0', '?')
    return CaseResult('failed_sensor', ok, evidence)


JUDGES = (answers_every_step, stamps, rate, refuses_other_scenario, survives_restart,
          stops_when_told, no_command_after_shutdown, follows_replanned_reference,
          failed_sensor)


def judge(observation: Observation) -> list[CaseResult]:
    """Every case of the contract, in the order of ``ato_common.contract.CASES``."""
    results = {r.name: r for r in (j(observation) for j in JUDGES)}
    return [results[name] for name in CASES]


def report(results: list[CaseResult], header: str) -> str:
    """The results as lines: a verdict per case with its evidence, then the tally."""
    lines = [header, '']
    width = max(len(r.title) for r in results)
    for r in results:
        lines.append(f'{r.verdict:<8}{r.title:<{width}}  {r.evidence}')
    failed = [r.name for r in results if r.passed is not True]
    passed = len(results) - len(failed)
    lines += ['', f'{passed} of {len(results)} cases passed'
              + (f'; not passed: {", ".join(failed)}' if failed else '')]
    return '\n'.join(lines)
