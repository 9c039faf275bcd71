"""Drive one run of the stack to the end of its scenario and compute its metrics."""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ato_bringup.processes import describe_exit
from ato_bringup.stack import Monitor, Sample, Stack, StackConfig
from ato_common.metrics import RunMetrics, compute_metrics
from ato_common.run_events import PLATFORM_TOLERANCE_M, RunEvents, run_events, stations_of
from ato_common.scenario import Scenario, load_scenario
from ato_common.types import NS_PER_S, nanoseconds
from ato_simulation.plans import cached_plan, run_end_time_s, stop_samples


class RunFailed(RuntimeError):
    pass


class RunIncomplete(RunFailed):
    """A run whose record misses steps: its figures would be those of part of the run."""


@dataclass
class RunOutcome:
    scenario: Scenario
    config: StackConfig
    samples: list[tuple[int, Sample]]
    diagnostics: list
    wall_time_s: float
    exit_codes: dict[str, int]
    metrics: RunMetrics
    laws: list[str] = field(default_factory=list)
    parameter_results: list = field(default_factory=list)
    arrivals: list[tuple[float, int]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)  # messages the monitor received
    events: RunEvents = field(default_factory=RunEvents)  # what went wrong (run_events)
    startup_s: float = float('nan')  # wall time from starting the processes to the first state
    teardown_s: float = float('nan')  # wall time from the last state to the plant's exit
    # CPU seconds of each process (and 'monitor', this one) spent in the steady window
    # (STEADY_WINDOW of the run's simulated time), and the control steps in it
    window_cpu_s: dict[str, float] = field(default_factory=dict)
    window_steps: int = 0

    def steady_real_time_factor(self, start: float = 0.1, end: float = 0.9) -> float:
        """Simulated over wall time between two fractions of the run (start-up excluded)."""
        last = self.arrivals[-1][1]
        inside = [(w, s) for w, s in self.arrivals if start * last <= s <= end * last]
        (w0, s0), (w1, s1) = inside[0], inside[-1]
        return (s1 - s0) / NS_PER_S / (w1 - w0)

    def array(self, attribute: str, index: int = 0) -> np.ndarray:
        return np.array([getattr(s, attribute)[index] if isinstance(getattr(s, attribute), tuple)
                         else getattr(s, attribute) for _, s in self.samples])

    @property
    def times_s(self) -> np.ndarray:
        return np.array([k / NS_PER_S for k, _ in self.samples])


STEADY_WINDOW = (0.1, 0.9)
"""The fractions of a run's simulated time between which its steady speed and CPU are measured
(start-up and the end excluded)."""


def process_cpu_s(pid: int | None = None) -> float:
    """CPU time (user + system) a process has used so far, s, from /proc/<pid>/stat (None: this
    process); nan if it is gone."""
    if pid is None:
        return time.process_time()
    try:
        with open(f'/proc/{pid}/stat') as handle:
            fields = handle.read().rsplit(')', 1)[1].split()
    except OSError:
        return float('nan')
    # after the command name: state is field 3 of the line, utime 14 and stime 15
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def cpu_snapshot(stack: Stack) -> dict[str, float]:
    snapshot = {name: process_cpu_s(p.pid) for name, p in stack.processes.items()}
    snapshot['monitor'] = process_cpu_s()
    return snapshot


def progress_bar(end_time_s: float):
    """The run's progress on stderr: simulated seconds, with the rate (simulated s per wall s,
    the real-time factor) and the time left."""
    from tqdm import tqdm
    return tqdm(total=end_time_s, unit='sim s', file=sys.stderr, dynamic_ncols=True,
                bar_format='{l_bar}{bar}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}, '
                           '{rate_fmt}]')


def last_reports(stack: Stack) -> str:
    """Each node's newest diagnostics message and the tail of its log (a stalled run)."""
    newest = {}
    monitor = stack.monitor
    for _, name, _, message in (monitor.diagnostics if monitor is not None else ()):
        newest[name] = message
    lines = [f'  {name}: {message}' for name, message in sorted(newest.items())]
    alive = [n for n in stack.processes if not stack.exited(n)]
    lines.append(f'  running: {", ".join(alive) or "none"}')
    return '\n'.join(lines) + '\n' + stack.log_tail(stack.plant_process, 10)


def prepare(config: StackConfig) -> tuple[Scenario, float]:
    scenario = load_scenario(config.scenario)
    plan = cached_plan(scenario)
    if not config.end_time_s:
        config.end_time_s = run_end_time_s(scenario, plan)
    return scenario, config.end_time_s


@dataclass
class RunClock:
    """The run's simulated time as the monitor sees it: the newest state's stamp in lockstep;
    in real time (stamps on the wall clock) the time since the first state's stamp."""

    monitor: Monitor
    lockstep: bool
    origin_ns: int | None = None

    def stamp_ns(self) -> int:
        return self.monitor.last_stamp_ns

    def now_s(self) -> float:
        last = self.monitor.last_stamp_ns
        if last < 0:
            return 0.0
        if self.lockstep:
            return last / NS_PER_S
        if self.origin_ns is None:
            self.origin_ns = self.monitor.arrivals[0][1] if self.monitor.arrivals else last
        return (last - self.origin_ns) / NS_PER_S


def _watch(stack: Stack, clock: RunClock, end_time_s: float, timeout_s: float,
           pending: list, bar) -> tuple[list, list, float]:
    """Spin the monitor until the plant ends with 0: (the actions' results, the CPU snapshots
    at the steady window's ends, the wall time); RunFailed naming the first process that ends
    otherwise (the plant killed included) with the simulated time reached."""
    started = last_report = time.monotonic()
    window = [w * end_time_s for w in STEADY_WINDOW]
    results: list = []
    cpu: list[tuple[int, dict[str, float]]] = []  # (stamp ns, snapshot) at the window's ends
    while True:
        ended = stack.ended()  # every process the run started is watched
        if ended is not None:
            name, code = ended
            raise RunFailed(f'{name} exited with {describe_exit(code)} at simulated '
                            f'{clock.now_s():.1f} s of {end_time_s:.1f} s: the run is stopped. '
                            f'Its log ({stack.logs[name]}) ends:\n{stack.log_tail(name)}')
        if stack.exited(stack.plant_process):
            return results, cpu, time.monotonic() - started
        if time.monotonic() - started > timeout_s:
            raise RunFailed(f'the run did not end within {timeout_s:.0f} s of wall time '
                            f'(simulated {clock.now_s():.1f} s of {end_time_s:.1f} s); last '
                            'reports:\n' + last_reports(stack))
        stack.executor.spin_once(timeout_sec=0.05)
        t = clock.now_s()
        if len(cpu) < 2 and t >= window[len(cpu)]:
            cpu.append((clock.stamp_ns(), cpu_snapshot(stack)))
        while pending and t >= pending[0][0]:
            results.append(pending.pop(0)[1](stack))
        if bar is not None and time.monotonic() - last_report > 0.5:
            last_report = time.monotonic()
            bar.update(min(t, end_time_s) - bar.n)


def run_lockstep(config: StackConfig, actions: dict[float, Callable[[Stack], object]] | None = None,
                 timeout_s: float = 600.0, progress: bool = False,
                 stop_tolerance_m: float = PLATFORM_TOLERANCE_M) -> RunOutcome:
    """Run to the scenario's end, in lockstep or (``config.lockstep`` false) in real time.
    ``actions`` maps a simulated time to a callable run on the stack once the run has passed it
    (e.g. a parameter change); its result is kept. The outcome's ``events`` are the ATP
    interventions and watchdog brakes the plant reported, and the missed journey windows and
    stopping errors beyond ``stop_tolerance_m`` measured. Any process that ends before the
    plant's end (the plant killed included) ends the run with RunFailed naming it, its exit and
    the simulated time reached."""
    scenario, end_time_s = prepare(config)
    pending = sorted((actions or {}).items())
    with Stack(config) as stack:
        stack.start()
        started = time.monotonic()
        monitor = stack.monitor
        clock = RunClock(monitor, config.lockstep)
        bar = progress_bar(end_time_s) if progress else None
        try:
            results, cpu, wall = _watch(stack, clock, end_time_s, timeout_s, pending, bar)
            if bar is not None:  # the plant reached its end
                bar.update(end_time_s - bar.n)
        finally:
            if bar is not None:
                bar.close()
        stack.spin_for(0.3)  # the last messages in flight
        codes = stack.stop()
        codes[stack.plant_process] = stack.processes[stack.plant_process].returncode
        bad = {k: describe_exit(v) for k, v in codes.items() if v != 0}
        if bad:
            raise RunFailed(f'processes exited with errors {bad}:\n' +
                            '\n'.join(stack.log_tail(k) for k in bad))
        # in real time the stamps are the wall clock's: no step's stamp is known beforehand
        expected = expected_steps(config, scenario) if config.lockstep else []
        samples = complete_record(monitor, expected, config.record_to)
        diagnostics = list(monitor.diagnostics)
        arrivals = list(monitor.arrivals)
        counts = dict(monitor.counts)
        startup = monitor.arrivals[0][0] - started if monitor.arrivals else float('nan')
        teardown = started + wall - monitor.arrivals[-1][0] if monitor.arrivals else float('nan')
    if not samples:
        raise RunFailed('the monitor received no state')
    window_cpu, window_steps = {}, 0
    if len(cpu) == 2:
        (s0, c0), (s1, c1) = cpu
        window_cpu = {name: c1[name] - c0[name] for name in c1 if name in c0}
        window_steps = round((s1 - s0) / (NS_PER_S / scenario.run.controller_rate_hz))
    metrics, laws, events = judged(scenario, config, samples, diagnostics, stop_tolerance_m)
    return RunOutcome(scenario, config, samples, diagnostics, wall, codes, metrics, laws, results,
                      arrivals, counts, events, startup, teardown, window_cpu, window_steps)


def judged(scenario: Scenario, config: StackConfig, samples: list[tuple[int, Sample]],
           diagnostics: list, stop_tolerance_m: float) -> tuple[RunMetrics, list[str], RunEvents]:
    """The run's metrics, laws and events from what the monitor saw. In lockstep each state is
    paired with the reference the profile streamed for its stamp; in real time (stamps on the
    wall clock, the reference's not the state's) the state is judged at its run time (from the
    first state) against the planned curve."""
    plan = cached_plan(scenario)
    times = [k / NS_PER_S for k, _ in samples]
    if config.lockstep:
        references = [(s.ref_position, s.ref_speed) for _, s in samples]
    else:
        origin_ns = samples[0][0]
        times = [(k - origin_ns) / NS_PER_S for k, _ in samples]
        points = [plan.trajectory.at(t) for t in times]
        references = [(point.position, point.speed) for point in points]
        diagnostics = [(k - origin_ns, *rest) for k, *rest in diagnostics]
    # A state carries the force applied up to it; the force held after sample k is in k+1.
    applied = [sum(s.forces) for _, s in samples]
    metrics = compute_metrics(times, [s.positions[0] for _, s in samples],
                              [s.speeds[0] for _, s in samples], applied[1:] + applied[-1:],
                              [r[0] for r in references], [r[1] for r in references],
                              stop_samples(plan), scenario.train.regenerative_efficiency,
                              scenario.train.regenerative_power_w)
    laws = sorted({s.law for _, s in samples if s.law} or laws_in(diagnostics))
    if not laws and config.controller_command:
        laws = [f'external ({config.controller_command})']
    events = run_events(scenario, metrics, stations_of(plan), times,
                        [s.positions[0] for _, s in samples], diagnostics=diagnostics,
                        tolerance_m=stop_tolerance_m)
    return metrics, laws, events


def expected_steps(config: StackConfig, scenario: Scenario) -> list[int]:
    """The stamps of every step a lockstep run to ``config.end_time_s`` publishes: from 0, one
    control period apart, to the first at or past the end time (where the plant stops)."""
    rate = config.plant_params.get('control_rate_hz') or scenario.run.controller_rate_hz
    period = nanoseconds(1.0 / rate)
    last = -(-nanoseconds(config.end_time_s) // period)
    return list(range(0, last * period + 1, period))


def complete_record(monitor: Monitor, expected: list[int], recording: Path | None
                    ) -> list[tuple[int, Sample]]:
    """The run's samples, every expected step: those the monitor missed (it lagged behind the
    loop, which does not wait for it, further than the middleware keeps for it) are read from
    the run's recording, which the loop does wait for. RunIncomplete names the steps neither
    holds."""
    samples = monitor.complete_samples()
    missing = set(expected) - {k for k, _ in samples}
    if missing and recording is not None:
        monitor.fill_from_recording(recording, missing)
        samples = monitor.complete_samples()
        missing = set(expected) - {k for k, _ in samples}
    if missing:
        raise RunIncomplete(
            f'the run monitor missed {len(missing)} of the run\'s {len(expected)} steps '
            f'({step_ranges(sorted(missing), expected)})'
            + (' and the recording does not hold them either' if recording else
               ' and the run was not recorded') + ': no summary of part of a run')
    return samples


def step_ranges(missing: list[int], expected: list[int]) -> str:
    """The missing steps as ranges of simulated time: '966.8 s to 1101.9 s (1352 steps), ...'."""
    index = {stamp: i for i, stamp in enumerate(expected)}
    ranges: list[list[int]] = []
    for stamp in missing:
        if ranges and index[stamp] == index[ranges[-1][-1]] + 1:
            ranges[-1].append(stamp)
        else:
            ranges.append([stamp])
    parts = [f'{r[0] / NS_PER_S:.1f} s' if len(r) == 1 else
             f'{r[0] / NS_PER_S:.1f} s to {r[-1] / NS_PER_S:.1f} s ({len(r)} steps)'
             for r in ranges[:5]]
    return ', '.join(parts) + (f' and {len(ranges) - 5} more gaps' if len(ranges) > 5 else '')


def laws_in(diagnostics) -> set[str]:
    """The laws the controller's diagnostics name (a monitor that does not watch the command)."""
    return {values['law'] for _, name, values, _ in diagnostics
            if name == 'ato_controller_node: law' and 'law' in values}
