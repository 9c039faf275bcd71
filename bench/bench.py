"""make bench: how fast the suite runs on this machine.

1. Lockstep real-time factor of a scenario through the ROS graph (the run monitor of
   ``run_scenario`` beside three node processes, or the three nodes composed in one), overall
   (start-up included) and steady (10 % to 90 % of the run), the start-up (starting the
   processes to the first step) and the CPU time per step of each process in the steady window
   (from /proc/<pid>/stat), with the EventsExecutor the nodes use and, for comparison, the
   SingleThreadedExecutor; then with the recorder recording every topic, the per-step ones from
   the loop nodes' step records (its throughput in
   messages per second and how much slower the run is), and beside a process that only burns
   as much CPU as the recorder did (what any second process of its size costs the loop).
2. Controller step time (p50, p99, max) of every law on the same scenario, offline.
3. Plant simulation speed standalone (simulated seconds per CPU second, one core), driven period
   by period and given all its commands at once (``TrainSimulation.run_commands``).
4. The offline closed loop (ato_simulation.loop, what campaigns run thousands of times): the
   real-time factor of every law that applies to short_line (the PID and the adaptive laws) on
   one core, with the plan cached and with the planning included, and the planning time of
   every built-in scenario.
5. Campaign throughput (ato_campaigns.campaign): runs per minute of a small campaign with 1 and 2
   Dask workers and their ratio, and the engine's overhead per run (Dask, the time limit, the
   Parquet row) against the bare offline loop of the same runs; and through the ROS graph
   (``--through ros``, ``ato_bringup.graph_campaign``): rows per minute of a small campaign
   offline and through the graph, with 1 and 2 workers (``--only graph-campaign``).
6. Planning: CPU time to plan each built-in scenario's target curve, ``fastest`` and
   ``timetable`` (profile_node.timetable), and the two strategies in closed loop offline (PID,
   nominal plant): arrival against the target time and traction energy.
7. Tuning: the budget and wall time of ``make tune``, which measures them itself (not rerun
   here: it holds both cores for the whole budget) and writes them in each tuned artefact with
   its date, machine and commit; this section shows them from the committed artefacts
   (``--only tuning --results-page PAGE`` rewrites only this section of a page).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import math
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats

from ato_bringup.runner import STEADY_WINDOW, prepare, process_cpu_s, run_lockstep
from ato_bringup.stack import RUN_DIAGNOSTICS_PERIOD_S, STEP_WAITED, StackConfig, executable_path
from ato_campaigns.compare import plan_jobs
from ato_campaigns.provenance import results_page_provenance, write_results_page
from ato_common.conventions import TOPICS
from ato_common.domains import free_domain
from ato_common.scenario import DEFAULT_SCENARIO, builtin_scenarios, load_scenario
from ato_common.trains import train_preset
from ato_common.types import NS_PER_S, nanoseconds
from ato_controller_node import gains as gains_module
from ato_controller_node.laws import LAWS
from ato_ros.middleware import with_middleware_defaults
from ato_simulation.loop import run_offline
from ato_simulation.plans import clear_plan_cache
from profile_node.oracle import LegOracle, Physics
from profile_node.planner import leg_limits
from recorder.bag import DEFAULT_COMPRESSION, bag_file, bag_info
from train_plant_node.accuracy import accuracy_scenario, worst_speed_error
from train_plant_node.simulation import TrainSimulation


@dataclasses.dataclass
class GraphRun:
    overall: float        # real-time factor, start-up included
    steady: float         # real-time factor between 10 % and 90 % of the run
    steps: int
    startup_s: float      # starting the processes to the first step
    teardown_s: float     # the last step to the plant's exit
    cpu_ms_per_step: dict[str, float]  # per process, in the steady window
    count: int            # messages recorded, or received by the live view's client
    steps_held: int = 0   # steps the plant held for the recorder (back-pressure)
    bag_bytes: int = 0    # the size of the bag's file


def graph_rtf(scenario: str, executor: str, domain_id: int, record: bool = False,
              live: bool = False, composed: bool = False, neighbour: float = 0.0) -> GraphRun:
    """One lockstep run through the graph as ``run_scenario`` runs it (the lean monitor); with
    ``live``, the live view's own CPU per step in the steady window is given as ``live view``;
    with ``neighbour``, beside a process that only burns that share of a core (``burner``)."""
    if neighbour:
        with burner(neighbour):
            return graph_rtf(scenario, executor, domain_id, record, live, composed)
    os.environ['ATO_EXECUTOR'] = executor
    live_cpu: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as logs:
        bag = Path(logs) / 'bag' if record else None
        config = StackConfig(scenario=scenario, domain_id=domain_id, log_dir=Path(logs),
                             record_to=bag, composed=composed, monitor='lean',
                             diagnostics_period_s=RUN_DIAGNOSTICS_PERIOD_S,
                             watched_by=live_view_keys() if live else ())
        size = 0
        if live:
            with watched_live_view(domain_id, Path(logs)) as (watch, received, pid):
                _, end_s = prepare(config)

                def snapshot(stack, edge):
                    live_cpu[edge] = (process_cpu_s(pid), stack.monitor.last_stamp_ns)
                outcome = run_lockstep(config, actions={
                    0.0: watch, STEADY_WINDOW[0] * end_s: lambda s: snapshot(s, 'start'),
                    STEADY_WINDOW[1] * end_s: lambda s: snapshot(s, 'end')})
                count = received()
        else:
            outcome = run_lockstep(config)
            count = bag_info(bag).message_count if record else 0
            size = bag_file(bag).stat().st_size if record else 0
    cpu = {name: 1e3 * used / max(outcome.window_steps, 1)
           for name, used in outcome.window_cpu_s.items()}
    held = [values.get('steps_held_for_recorders', 0) for _, name, values, _ in
            outcome.diagnostics if name == 'train_plant_node: simulation']
    if len(live_cpu) == 2:
        (cpu0, stamp0), (cpu1, stamp1) = live_cpu['start'], live_cpu['end']
        steps = max((stamp1 - stamp0) // 100_000_000, 1)
        cpu['live view'] = 1e3 * (cpu1 - cpu0) / steps
    return GraphRun(outcome.metrics.simulated_time_s / outcome.wall_time_s,
                    outcome.steady_real_time_factor(), outcome.metrics.samples,
                    outcome.startup_s, outcome.teardown_s, cpu, count,
                    int(held[-1]) if held else 0, size)


PROCESS_ORDER = ('plant', 'profile', 'controller', 'loop', 'recorder', 'live view', 'monitor')


def cpu_cell(run: GraphRun) -> str:
    """CPU ms per step of each process, and their total."""
    parts = [f'{name} {run.cpu_ms_per_step[name]:.2f}' for name in PROCESS_ORDER
             if name in run.cpu_ms_per_step]
    return ', '.join(parts) + f'; total {sum(run.cpu_ms_per_step.values()):.2f}'


def graph_row(label: str, run: GraphRun, extra: str = '-') -> str:
    return (f'| {label} | {run.steps} | {run.overall:.1f}x | {run.steady:.1f}x | '
            f'{1e3 / (10 * run.steady):.2f} ms | {run.startup_s:.2f} s | '
            f'{run.teardown_s:.2f} s | {cpu_cell(run)} | {extra} |')


LOCKSTEP_HEADING = '## Lockstep through the ROS graph'


def lockstep_section(scenario: str, domain_id: int) -> list[str]:
    lines = [LOCKSTEP_HEADING, '',
             'The run monitor of `run_scenario` (the truth and the reference per step, the '
             f'diagnostics every {RUN_DIAGNOSTICS_PERIOD_S:g} s of simulated time) beside '
             'the three node processes, or the three nodes composed in one (`--composed`, '
             '`ato_stack`); real-time factor = simulated time / wall time, overall (start-up '
             'and teardown included) and steady (10 % to 90 % of the run); start-up = starting '
             'the processes to the first step; teardown = the last step to the plant\'s exit; '
             'CPU per step of each process (user + system, /proc/<pid>/stat) in the steady '
             'window. The recorder records every topic (chunk compression: '
             f'{DEFAULT_COMPRESSION}, the default, as rosbag2 Jazzy\'s), the per-step ones '
             'from the loop nodes\' step records: beside separate processes in a process of '
             'its own, at the lowest CPU priority (the plant waits for it when it falls more than '
             'recorder_lead_s behind: the steps held say how often), in the composed stack in '
             'the loop\'s process (`ato_stack --record`: the messages kept by the loop nodes '
             'as they add them and written in one go once per flush period, on the loop\'s '
             'thread; docs/guide/recording.md). A process that only '
             'burns as much CPU as the separate recorder did, at its priority, shows what any '
             'second process of that size costs the loop on this machine before it records '
             f'anything. The recorder and the live view are measured in turns with the runs '
             f'without them ({PAIRS} of each, {COMPOSED_PAIRS} for the composed stack\'s '
             'recorder), their cost as the median of the pairs\' ratios (for the composed '
             f'recorder with its {100 * MEDIAN_CONFIDENCE:g} % confidence interval, by the '
             'bootstrap). '
             'Goals: separate at least 150x steady, composed at least 250x; composed with the '
             'recorder at most 10 % slower than without; the separate recorder\'s own CPU at '
             f'most {RECORDER_CPU_GOAL_MS:g} ms per step (half of what it was before issue 31).',
             '',
             '| run | steps | overall | steady | per 0.1 s step | start-up | teardown | '
             'CPU ms per step | recorded |', '|---|---|---|---|---|---|---|---|---|']
    print('\n'.join(lines), flush=True)
    rows = []

    def add(row: str) -> None:
        rows.append(row)
        print(row, flush=True)

    # The cost of an observer is a ratio of two noisy figures: runs without and with it, in
    # turns, and the median of the pairs' ratios.
    plain, live, recorded = [], [], []
    for _ in range(PAIRS):
        plain.append(graph_rtf(scenario, 'events', domain_id))
        live.append(graph_rtf(scenario, 'events', domain_id, live=True))
        recorded.append(graph_rtf(scenario, 'events', domain_id, True))
    composed, composed_recorded = [], []
    for _ in range(COMPOSED_PAIRS):
        composed.append(graph_rtf(scenario, 'events', domain_id, composed=True))
        composed_recorded.append(graph_rtf(scenario, 'events', domain_id, True, composed=True))
    add(graph_row('separate processes, EventsExecutor', median_run(plain),
                  f'- (median of {PAIRS} runs)'))
    add(graph_row('composed (one process, one EventsExecutor)', median_run(composed),
                  f'- (median of {COMPOSED_PAIRS} runs)'))
    add(recorder_row('separate, with the recorder', plain, recorded))
    add(recorder_row('composed, with the recorder in its process', composed, composed_recorded))
    # The floor of an observer's cost on this machine: a process that burns as much CPU as the
    # recorder did (its median share of a core in the steady window), and does nothing else.
    share = statistics.median(cpu_share(run, 'recorder') for run in recorded)
    bare, burnt = [], []
    for _ in range(PAIRS):
        bare.append(graph_rtf(scenario, 'events', domain_id))
        burnt.append(graph_rtf(scenario, 'events', domain_id, neighbour=share))
    add(graph_row(f'separate, beside a process that only burns the recorder\'s CPU '
                  f'({100 * share:.0f} % of a core, nice 19, in {1e3 * BURNER_PERIOD_S:g} ms '
                  'cycles)', median_run(burnt),
                  f'-; {slower(zip(bare, burnt)):+.0f} % slower steady (median of the pairs): '
                  'what any second process of the recorder\'s size costs the loop here'))
    single = graph_rtf(scenario, 'single', domain_id)
    add(graph_row('separate processes, SingleThreadedExecutor', single))
    watched = median_run(live)
    add(graph_row(f'separate, with the live view (`recorder live`) and one Foxglove client '
                  f'watching the layout\'s {len(layout_topics())} topics', watched,
                  f'{watched.count} messages to the client; {slower(zip(plain, live)):+.0f} % '
                  f'slower steady (median of the pairs; goal at most 10 %)'))
    verdicts = recording_verdicts(composed, composed_recorded, recorded)
    print('\n'.join(verdicts), flush=True)
    return lines + rows + verdicts


#: how much slower (steady) the composed stack may run with its recorder, % (issue 31)
COMPOSED_RECORDER_GOAL_PERCENT = 10.0


def recording_verdicts(composed: list[GraphRun], composed_recorded: list[GraphRun],
                       recorded: list[GraphRun]) -> list[str]:
    """The two figures recording is accepted by, each against its goal."""
    ratios = sorted(pair_costs(zip(composed, composed_recorded)))
    cost = statistics.median(ratios)
    low, high = median_interval(ratios)
    own = recorder_cpu_ms(recorded)
    goal = COMPOSED_RECORDER_GOAL_PERCENT

    def met(ok: bool) -> str:
        return 'met' if ok else 'NOT met'
    # the goal is the median's; the interval says whether the median is surely on its side
    sureness = (f' (the interval of the median reaches across {goal:g} %)'
                if low <= goal < high else '')
    return ['', 'What recording costs, against its goals:', '',
            f'- composed with the recorder in its process: {cost:+.1f} % slower steady than '
            f'without (median of {len(composed)} pairs, which range from {ratios[0]:+.1f} to '
            f'{ratios[-1]:+.1f} %; {100 * MEDIAN_CONFIDENCE:g} % confidence interval of the '
            f'median {low:+.1f} to {high:+.1f} %; goal at most {goal:g} %): '
            f'{met(cost <= goal)}{sureness}',
            f'- separate processes: the recorder\'s own CPU {own:.3f} ms per step (median of '
            f'{len(recorded)} runs; goal at most {RECORDER_CPU_GOAL_MS:g} ms): '
            f'{met(own <= RECORDER_CPU_GOAL_MS)}']


#: the confidence of the interval given for the median of the pairs' costs
MEDIAN_CONFIDENCE = 0.95


def median_interval(costs: list[float]) -> tuple[float, float]:
    """The ``MEDIAN_CONFIDENCE`` interval of the median of ``costs`` (one per pair of runs), by
    the bootstrap (``scipy.stats.bootstrap``, percentile method, a fixed seed: the same runs
    give the same interval); the median itself when the costs are all equal or too few."""
    values = np.asarray(costs, dtype=float)
    if len(values) < 3 or np.all(values == values[0]):
        middle = float(np.median(values))
        return middle, middle
    result = stats.bootstrap((values,), np.median, confidence_level=MEDIAN_CONFIDENCE,
                             n_resamples=10_000, method='percentile', random_state=31)
    interval = result.confidence_interval
    return float(interval.low), float(interval.high)


def pair_costs(pairs) -> list[float]:
    """For each pair of runs (without, with an observer), how much slower (steady) the second
    is, %."""
    return [100 * (1 - b.steady / a.steady) for a, b in pairs]


def slower(pairs) -> float:
    """The median of :func:`pair_costs`."""
    return statistics.median(pair_costs(pairs))


def recorder_row(label: str, base: list[GraphRun], runs: list[GraphRun]) -> str:
    """The row of the runs with the recorder (the median run), against those without it: what
    it recorded, the steps it held, its own CPU per step when in a process of its own, and how
    much slower the loop ran."""
    run = median_run(runs)
    separate = 'recorder' in run.cpu_ms_per_step
    own = (f'the recorder\'s own CPU {recorder_cpu_ms(runs):.3f} ms per step (median; '
           f'goal at most {RECORDER_CPU_GOAL_MS:g}); ' if separate else '')
    return graph_row(label, run, f'{run.count} messages, {run.bag_bytes / 1e6:.1f} MB, '
                     f'{run.count * run.steady / (run.steps / 10):.0f} per second, '
                     f'{run.steps_held} steps held for the recorder; {own}'
                     f'{slower(zip(base, runs)):+.0f} % slower steady (median of the pairs'
                     + ('' if separate else '; goal at most 10 %') + ')')


#: runs without and with each observer (the recorder, the live view), in turns
PAIRS = 5
#: the same for the composed stack's recorder, whose cost is a goal of its own near the noise
#: of one pair (a few %): more pairs for a steadier median and a narrower interval of it
COMPOSED_PAIRS = 21
#: the separate recorder's own CPU per step, ms: half the 0.23 ms it took before issue 31
#: (mcap's Python writer, an acknowledgement every 0.2 s, a take every 5 ms)
RECORDER_CPU_GOAL_MS = 0.115


def recorder_cpu_ms(runs: list[GraphRun]) -> float:
    """The separate recorder's own CPU per step in the steady window, ms: the median of runs."""
    return statistics.median(run.cpu_ms_per_step['recorder'] for run in runs)


#: the burner's cycle (``burner``), s: a few lockstep steps at 200x
BURNER_PERIOD_S = 1e-3


@contextlib.contextmanager
def burner(share: float):
    """A process at the recorder's priority (nice 19) that does nothing but keep a core busy
    for ``share`` of every ``BURNER_PERIOD_S`` and sleep the rest: what any second process of
    the recorder's size costs a lockstep loop on this machine, before it records anything."""
    busy, idle = share * BURNER_PERIOD_S, (1.0 - share) * BURNER_PERIOD_S
    code = ('import os, time\nos.nice(19)\nclock = time.perf_counter\nwhile True:\n'
            f'    start = clock()\n    while clock() - start < {busy!r}:\n        pass\n'
            f'    time.sleep({idle!r})\n')
    process = subprocess.Popen([sys.executable, '-c', code], stdin=subprocess.DEVNULL)
    try:
        yield process.pid
    finally:
        process.kill()
        process.wait()


def cpu_share(run: GraphRun, name: str) -> float:
    """The share of a core that process ``name`` used in the steady window of ``run``."""
    return run.cpu_ms_per_step[name] * 1e-3 * run.steady * 10.0


def median_run(runs: list[GraphRun]) -> GraphRun:
    """The run of median steady real-time factor (an odd number of runs)."""
    return sorted(runs, key=lambda r: r.steady)[len(runs) // 2]


def layout_topics() -> list[str]:
    """The topics the shipped Foxglove layout plots (what a client of the live view watches)."""
    from ament_index_python.packages import get_package_share_directory
    layout = Path(get_package_share_directory('recorder')) / 'config' / 'foxglove_layout.json'
    return sorted(set(re.findall(r'"(/[a-z_]+(?:/[a-z_]+)*)[.{]', layout.read_text())))


def live_view_keys() -> tuple[str, ...]:
    """The keys (ato_common.conventions) of the loop's topics the live view subscribes to."""
    names = set(layout_topics())
    return tuple(key for key in STEP_WAITED if '/' + TOPICS[key].name.lstrip('/') in names)


@contextlib.contextmanager
def watched_live_view(domain_id: int, logs: Path):
    """``recorder live`` beside the stack, with one Foxglove client; yields (an action that
    subscribes the client to every topic of the layout once they are advertised, a function
    counting the messages the client received)."""
    from recorder.foxglove_client import FoxgloveClient
    from recorder.live import served_url
    env = with_middleware_defaults(dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))
    log = logs / 'live.log'
    with open(log, 'wb') as out:
        live = subprocess.Popen([executable_path('recorder', 'live'), '--port', '0',
                                 *layout_topics()], stdout=out, stderr=subprocess.STDOUT,
                                env=env, stdin=subprocess.DEVNULL)
    client = None
    try:
        deadline = time.monotonic() + 30
        while served_url(log.read_text(errors='replace')) is None:
            if time.monotonic() > deadline or live.poll() is not None:
                raise RuntimeError(f'the live view did not start:\n{log.read_text()}')
            time.sleep(0.1)
        client = FoxgloveClient(served_url(log.read_text(errors='replace')))

        def watch(stack) -> None:
            for k, topic in enumerate(layout_topics()):
                channel = client.channel(topic, 30, lambda: stack.spin_for(0.02))
                client.subscribe(k, channel['id'])

        def received() -> int:
            time.sleep(0.5)
            return sum(isinstance(m, bytes) and m[0] == 1 for m in list(client.received.queue))

        yield watch, received, live.pid
    finally:
        if client is not None:
            client.close()
        live.send_signal(signal.SIGINT)
        live.wait(timeout=30)


#: steps timed for a law that runs faster than its scenario's control rate
LAW_BENCH_STEPS = 20_000


def law_step_times(preferred_scenario: str) -> list[str]:
    """Step time (law plus host) of every registered law, offline, on the preferred scenario
    if the law applies to it, else on the first built-in scenario it applies to
    (ato_campaigns.compare decides applicability and the plant model): markdown table rows."""
    jobs, _ = plan_jobs([preferred_scenario] + [s for s in builtin_scenarios()
                                                 if s != preferred_scenario])
    rows = ['| law | scenario, plant, rate | steps | p50 (us) | p99 (us) | max (us) |',
            '|---|---|---|---|---|---|']
    print('\n'.join(rows), flush=True)
    for law in sorted(LAWS):
        job = next((j for j in jobs if j.law == law), None)
        if job is None:
            rows.append(f'| `{law}` | no built-in scenario it applies to | - | - | - | - |')
            continue
        # A law sampled faster than its scenario (compare picks the rate) runs a window of
        # LAW_BENCH_STEPS steps: its step time, not the whole run, is measured here.
        scenario = load_scenario(job.scenario)
        window_s = None
        if job.rate_hz != scenario.run.controller_rate_hz:
            window_s = LAW_BENCH_STEPS / job.rate_hz
        durations = run_offline(scenario, law, model=job.model, controller_rate_hz=job.rate_hz,
                                end_time_s=window_s).step_times_s
        p50, p99 = np.percentile(durations, [50, 99]) * 1e6
        rows.append(f'| `{law}` | {job.scenario}, {job.model}, {job.rate_hz:g} Hz | '
                    f'{durations.size} | {p50:.0f} | {p99:.0f} | {durations.max() * 1e6:.0f} |')
        print(rows[-1], flush=True)
    return rows


def plant_speed(scenario_name: str, model: str = 'point_mass', train: str | None = None,
                simulated_s: float = 600.0, batched: bool = False, repeats: int = 5) -> float:
    """Simulated seconds per CPU second of this process (one core), the median of ``repeats``
    runs: the plant simulation with its actuators and safety functions over 10 Hz control
    periods, either driven period by period as the node and the offline runner drive it
    (``apply_command``, ``advance``, then the ``truth`` snapshot) or given all its commands at once
    (``run_commands``, the truth of every period in arrays). The objects alive before a run
    are frozen out of the cyclic garbage collector, as a long-running node can do after
    start-up: otherwise a full collection, which visits every object of the imported libraries
    (numba, scipy), costs tens of ms every few thousand periods, whatever the plant does."""
    scenario = load_scenario(scenario_name)
    if train is not None:
        scenario = dataclasses.replace(scenario, train=train_preset(train))
    period_ns = nanoseconds(1.0 / scenario.run.controller_rate_hz)
    periods = int(round(simulated_s * NS_PER_S / period_ns))
    speeds = []
    for _ in range(repeats):
        sim = TrainSimulation(scenario, model)
        command = (100e3 / len(sim.actuator_names),) * len(sim.actuator_names)
        commands = np.tile(command, (periods, 1))
        if batched:
            TrainSimulation(scenario, model).run_commands(commands[:2], period_ns)  # compile
        gc.collect()
        gc.freeze()
        started = time.process_time()
        if batched:
            sim.run_commands(commands, period_ns)
        else:
            for _ in range(periods):
                sim.apply_command(command)
                sim.advance(period_ns)
                sim.truth()
        elapsed = time.process_time() - started
        gc.unfreeze()
        speeds.append(periods * period_ns / NS_PER_S / elapsed)
    return float(np.median(speeds))


#: the scenario of the offline loop's figures (issue 20: pid at least 4000x on it)
OFFLINE_SCENARIO = 'short_line'


def _cpu_time_of(run, repeats: int) -> float:
    """Median CPU time of this process (one core) of ``repeats`` calls of ``run``, with the
    objects alive before each frozen out of the cyclic garbage collector (see ``plant_speed``)."""
    times = []
    for _ in range(repeats):
        gc.collect()
        gc.freeze()
        started = time.process_time()
        run()
        times.append(time.process_time() - started)
        gc.unfreeze()
    return float(np.median(times))


def offline_loop_speed(repeats: int = 3) -> list[str]:
    """Real-time factor (simulated time / CPU time of one core) of the offline closed loop of
    every law that applies to OFFLINE_SCENARIO, as ``make compare`` runs it (its plant model and
    rate): with the plan cached (as a campaign's runs after the first of each scenario take it),
    and with the planning included (the plan cache cleared before each run). Markdown rows."""
    jobs, _ = plan_jobs([OFFLINE_SCENARIO])
    rows = ['| law | plant, rate | steps | plan cached | planning included |',
            '|---|---|---|---|---|']
    print('\n'.join(rows), flush=True)
    for job in jobs:
        # parsed once, as a campaign's worker parses each scenario once (task_scenario)
        scenario = load_scenario(job.scenario)

        def run(job=job, scenario=scenario):
            return run_offline(scenario, job.law, model=job.model,
                               controller_rate_hz=job.rate_hz, end_time_s=job.end_time_s)

        done = run()  # compiles, and caches the plan
        simulated_s = float(done.times_s[-1])
        cached = _cpu_time_of(run, repeats)

        def cold(run=run):
            clear_plan_cache()
            run()
        planning = _cpu_time_of(cold, repeats)
        rows.append(f'| `{job.law}` | {job.model}, {job.rate_hz:g} Hz | {done.times_s.size} | '
                    f'{simulated_s / cached:.0f}x | {simulated_s / planning:.0f}x |')
        print(rows[-1], flush=True)
    return rows


def plant_accuracy(model: str, preset: str, total_n: float, seconds: float = 600.0) -> float:
    """Largest speed error against DOP853 (rtol 1e-12) over a run with varying commands (kept
    below the power limit, which the plant re-evaluates within a command period)."""
    def command(t, n):
        return tuple(total_n * (1.0 + 0.5 * math.sin(0.05 * t)) / n
                     * (1.0 + 0.2 * math.sin(0.3 * t + i)) for i in range(n))
    return worst_speed_error(accuracy_scenario(preset), model, seconds, 1.0, command)[0]


class Page:
    """What the bench prints, kept as markdown for the results page."""

    def __init__(self):
        self.lines: list[str] = []

    def add(self, *lines: str) -> None:
        for line in lines:
            print(line, flush=True)
            self.lines.append(line)


#: the campaign of the throughput measurement: whole runs of the scenario, default uncertainty
#: (as many draws as the default campaign: about half a second a run, so that the last runs
#: left to two workers are a small part of the whole)
BENCH_CAMPAIGN_DRAWS = 30
BENCH_CAMPAIGN_LAWS = ('pid', 'luo_xu')
#: rounds of the campaign throughput (bare, 1 worker, 2 workers each, in a rotating order)
CAMPAIGN_ROUNDS = 3


def _warm_up() -> None:
    """On each worker before the clock starts: imports and the plant kernels' compilation."""
    from ato_simulation.loop import run_offline
    run_offline(load_scenario(DEFAULT_SCENARIO), 'pid', end_time_s=5.0)


def _warm_up_run_process() -> None:
    """On a worker: its run process (ato_campaigns.run_process) started and warmed up."""
    from ato_campaigns.run_process import worker_run_process
    worker_run_process().call(_warm_up, None)


def _bare_loop(tasks) -> tuple[float, float]:
    """(wall s, CPU s) of the offline runs of ``tasks`` one after the other in this process,
    its heap frozen first (what the engine's workers do after their first run)."""
    from ato_campaigns.engine import offline_metrics
    gc.collect()
    gc.freeze()
    started, cpu = time.perf_counter(), _cpu_s()
    for task in tasks:
        offline_metrics(task)
    return time.perf_counter() - started, _cpu_s() - cpu


def _cpu_s() -> float:
    return time.process_time()


README_START = '<!-- timetable table: written by make bench, do not edit -->'
README_END = '<!-- end of the timetable table -->'


def update_readme(path: Path, rows: list[str], measured, command: str) -> Path:
    """The closed-loop table of the two strategies between README_START and README_END."""
    text = path.read_text()
    if README_START not in text or README_END not in text:
        raise SystemExit(f'{path}: no timetable table markers ({README_START!r} ... '
                         f'{README_END!r}) to write between')
    head, rest = text.split(README_START, 1)
    _, tail = rest.split(README_END, 1)
    body = '\n'.join([measured.markdown(command), '', *rows])
    path.write_text(f'{head}{README_START}\n{body}\n{README_END}{tail}')
    return path


def planning_times() -> list[str]:
    """Median CPU time of 3 plannings of every built-in scenario, each strategy."""
    from profile_node.planner import _traction_distance, plan_reference
    rows = ['| scenario | fastest | timetable (7 %) |', '|---|---|---|']
    for name in builtin_scenarios():
        scenario = load_scenario(name)
        cells = []
        for strategy in ('fastest', 'timetable'):
            variant = dataclasses.replace(scenario, timetable=dataclasses.replace(
                scenario.timetable, strategy=strategy, supplement_percent=7.0))
            times = []
            for _ in range(3):
                _traction_distance.cache_clear()  # each planning from scratch
                started = _cpu_s()
                plan_reference(variant)
                times.append(_cpu_s() - started)
            cells.append(f'{1e3 * float(np.median(times)):.0f} ms')
        rows.append(f'| {name} | {cells[0]} | {cells[1]} |')
        print(rows[-1], flush=True)
    return rows


# The oracle's grid in the bench's timetable table: stages of a leg's length / this many, within
# the bounds below (the built-in scenarios' legs are from a few to hundreds of km), and a step
# of e = v^2/2 of this share of the stage's length (the tests' grid: 100 m x 2 m^2/s^2;
# profile_node/test/test_oracle.py measures how the optimum moves with the grid).
BENCH_ORACLE_STAGES = 150
BENCH_ORACLE_DX_BOUNDS_M = (50.0, 200.0)
BENCH_ORACLE_DE_PER_M = 0.02


def oracle_kwh(scenario, plan, objective: str) -> float:
    """The oracle's least energy (``profile_node.oracle``; ``objective`` 'gross' or 'net')
    summed over the plan's legs, each at the running time the plan gives it; nan where the
    oracle finds no way through a leg."""
    total = 0.0
    for k, leg in enumerate(plan.legs):
        limits = leg_limits(scenario, k)
        low, high = BENCH_ORACLE_DX_BOUNDS_M
        dx = min(max((limits.end_m - limits.start_m) / BENCH_ORACLE_STAGES, low), high)
        oracle = LegOracle(Physics.of(scenario), limits, limits.start_m, limits.end_m,
                           objective, dx, BENCH_ORACLE_DE_PER_M * dx,
                           scenario.planning.max_jerk_mps3)
        try:
            optimum = oracle.at_time(leg.planned_arrival_s - leg.departure_s)
        except ValueError:
            return math.nan
        total += optimum.energy_j(objective)
    return total / 3.6e6


def _arrival_s(run, end_m: float) -> float:
    standing = (np.abs(run.positions - end_m) < 1.0) & (np.abs(run.speeds) < 0.01)
    return float(run.times_s[np.argmax(standing)]) if standing.any() else math.nan


def timetable_against_fastest() -> list[str]:
    """Both strategies in closed loop offline on every built-in scenario (PID, nominal
    plant): the last arrival against its target; the gross and the net energy at the wheel
    (``ato_common.metrics``) of the runs and of the timetable plan's forecast, and the
    oracle's least energy at the plan's running times (net where the train regenerates, else
    gross), beside it."""
    rows = ['| scenario | fastest: arrival | fastest: gross energy | timetable (7 %): '
            'target arrival | timetable: arrival | timetable: gross energy | '
            'timetable: net energy | plan: gross / net energy | oracle at the plan\'s times | '
            'plan over oracle | saving (gross) |',
            '|---|---|---|---|---|---|---|---|---|---|---|']
    for name in builtin_scenarios():
        scenario = load_scenario(name)
        runs = {}
        for strategy in ('fastest', 'timetable'):
            variant = dataclasses.replace(scenario, timetable=dataclasses.replace(
                scenario.timetable, strategy=strategy, supplement_percent=7.0))
            runs[strategy] = run_offline(variant, 'pid')
        end = scenario.line.stations[-1].position_m
        arrivals = {strategy: _arrival_s(run, end) for strategy, run in runs.items()}
        metrics = {k: r.metrics() for k, r in runs.items()}
        plan = runs['timetable'].plan
        objective = 'net' if scenario.train.regenerative_efficiency > 0.0 else 'gross'
        optimum = oracle_kwh(runs['timetable'].scenario, plan, objective)
        planned = plan.forecast.kwh()
        stated = planned['net_energy_kwh' if objective == 'net' else 'traction_energy_kwh']
        gross = {k: m.traction_energy_kwh for k, m in metrics.items()}
        rows.append(f'| {name} | {arrivals["fastest"]:.1f} s | {gross["fastest"]:.0f} kWh | '
                    f'{plan.legs[-1].target_arrival_s:.1f} s | {arrivals["timetable"]:.1f} s | '
                    f'{gross["timetable"]:.0f} kWh | '
                    f'{metrics["timetable"].net_energy_kwh:.0f} kWh | '
                    f'{planned["traction_energy_kwh"]:.0f} / {planned["net_energy_kwh"]:.0f} '
                    f'kWh | {optimum:.0f} kWh ({objective}) | '
                    f'{100 * (stated / optimum - 1):+.1f} % | '
                    f'{100 * (1 - gross["timetable"] / gross["fastest"]):.1f} % |')
        print(rows[-1], flush=True)
    return rows


def timetable_section_intro() -> list[str]:
    """The heading and the definitions of the timetable table (``timetable_against_fastest``)."""
    return [
        '## Timetable against fastest, closed loop', '',
        'Offline loop, PID law, nominal plant; arrival: the train standing within 1 m of the '
        'last stopping point; the energies at the wheel as `ato_common.metrics` defines them: '
        'gross = the work of the positive traction force, net = gross - regenerated (the '
        'braking work times the train\'s regenerative efficiency, within its power). Plan: '
        'the timetable plan\'s forecast. Oracle: `profile_node.oracle`\'s least energy for '
        'each leg at the plan\'s running time (the energy the plan optimises: net where the '
        'train regenerates, else gross), on stages of a leg\'s length / '
        f'{BENCH_ORACLE_STAGES} within {BENCH_ORACLE_DX_BOUNDS_M[0]:.0f}-'
        f'{BENCH_ORACLE_DX_BOUNDS_M[1]:.0f} m and a step of v^2/2 of '
        f'{BENCH_ORACLE_DE_PER_M:g} m/s^2 x the stage; plan over oracle: the plan\'s forecast '
        'of that energy against it. Plan and oracle are computed on the train and line the '
        'planner is given (nominal mass, resistance and traction; the line\'s grades, curves '
        'and tunnels), not on a scenario\'s `plant:` section, so plan over oracle compares like '
        'with like; the closed-loop runs do meet that section (on `mao_2017_modes` its tunnel, '
        'slope and failing motor, which is why that run spends far more than its plan).', '']


def campaign_throughput(scenario: str) -> list[str]:
    """Runs per minute with 1 and 2 workers, their ratio, and the engine's overhead per run
    against the bare offline loop of the same runs, in wall time and in CPU time (this process,
    with the scheduler, plus every worker's). On a shared machine the speed of a core moves
    from one minute to the next by more than the overhead sought (the same runs measured twice
    in a row): the three are measured in ``CAMPAIGN_ROUNDS`` rounds, one after the other in a
    rotating order, and each figure is the median over the rounds."""
    from ato_campaigns.engine import parse_campaign
    data = {'name': 'bench', 'seed': 1, 'draws': BENCH_CAMPAIGN_DRAWS, 'scenarios': [scenario],
            'laws': list(BENCH_CAMPAIGN_LAWS), 'uncertainty': 'default',
            'configurations': ['published']}  # the throughput of one configuration's runs
    campaign = parse_campaign(data, 'bench', Path.cwd())
    tasks = campaign.tasks()
    n = len(tasks)

    def bare() -> tuple[float, float]:
        # in a new process of its own, as a worker is (this one has run graphs and clusters,
        # and holds their threads and its larger heap), warmed up and its heap frozen after
        # the warm-up as a worker's run process's is after its first run (run_process.serve)
        import concurrent.futures
        import multiprocessing
        with concurrent.futures.ProcessPoolExecutor(
                1, mp_context=multiprocessing.get_context('spawn')) as pool:
            pool.submit(_warm_up).result()
            return pool.submit(_bare_loop, tasks).result()

    engines = {'bare': bare, 1: lambda: _campaign_on(campaign, 1),
               2: lambda: _campaign_on(campaign, 2)}
    order = list(engines)
    rounds: list[dict] = []
    for k in range(CAMPAIGN_ROUNDS):
        measured = {}
        for engine in order[k % len(order):] + order[:k % len(order)]:
            measured[engine] = engines[engine]()
            print(f'  round {k + 1}, {engine}: {measured[engine][0]:.1f} s wall, '
                  f'{measured[engine][1]:.1f} s CPU', flush=True)
        rounds.append(measured)

    def median(of) -> float:
        return statistics.median(of(r) for r in rounds)

    def overhead(r, engine, i):
        return 100 * (r[engine][i] - r['bare'][i]) / r['bare'][i]

    def row(label, engine, wall_overhead):
        wall, cpu = median(lambda r: r[engine][0]), median(lambda r: r[engine][1])
        cpu_overhead = ('-' if engine == 'bare' else
                        f'{median(lambda r: overhead(r, engine, 1)):+.1f} %')
        return (f'| {label} | {n} | {wall:.1f} s | {cpu:.1f} s | {60 * n / wall:.1f} | '
                f'{wall_overhead} | {cpu_overhead} |')

    spread = ', '.join(f'{overhead(r, 1, 0):+.1f} %' for r in rounds)
    ratios = [r[1][0] / r[2][0] for r in rounds]
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    return [
        row('bare offline loop, a process of its own', 'bare', '-'),
        row('Dask LocalCluster, 1 worker', 1, f'{median(lambda r: overhead(r, 1, 0)):+.1f} % '
                                              f'(rounds: {spread})'),
        row('Dask LocalCluster, 2 workers', 2, '-'),
        f'| ratio 2 workers / 1 worker | | | | {statistics.median(ratios):.2f} (rounds: '
        f'{", ".join(f"{x:.2f}" for x in ratios)}) | | |', '',
        f'Medians of {CAMPAIGN_ROUNDS} rounds. Load average at the end: {load} (on '
        f'{os.cpu_count()} cores).']


def _campaign_on(campaign, workers: int) -> tuple[float, float]:
    """(wall s, CPU s) of ``campaign`` on a new LocalCluster of the engine (``open_client``)
    with ``workers`` workers, started and their run processes warmed up (a task on each worker,
    so in the thread that runs its runs) before the clock starts; CPU: this process (the client
    and the scheduler) and every worker with its run process."""
    from ato_campaigns.engine import open_client, run_campaign
    client, cluster = open_client(workers=workers)
    with tempfile.TemporaryDirectory() as out, cluster, client:
        client.gather([client.submit(_warm_up_run_process, workers=[address], pure=False,
                                     allow_other_workers=False)
                       for address in client.scheduler_info()['workers']])
        before, cpu = client.run(_tree_cpu_s), _cpu_s()
        started = time.perf_counter()
        run_campaign(campaign, Path(out), client=client, progress=False)
        wall_s = time.perf_counter() - started
        after = client.run(_tree_cpu_s)
        return wall_s, _cpu_s() - cpu + sum(after[w] - before[w] for w in after)


#: the campaign of the throughput through the ROS graph: a few short runs of the scenario (each
#: run through the graph costs the start of five processes and a wall-clock lockstep)
GRAPH_BENCH_DRAWS = 2
GRAPH_BENCH_END_S = 60.0
GRAPH_CAMPAIGN_HEADING = '## Campaign throughput through the ROS graph'


def graph_campaign_throughput(scenario: str, measured=None) -> list[str]:
    """The section of the campaign's throughput offline and ``--through ros`` (rows per minute)
    on the same small campaign, with 1 and 2 workers: offline on the engine's LocalCluster
    (``_campaign_on``: warmed up before the clock starts), through the graph with
    ``ato_bringup.graph_campaign`` (1 worker: one row after the other in this process; 2: on a
    LocalCluster started before the clock starts). Each graph row is made offline too (its end
    and journey rule) and compared: the identical rows are counted. One round each."""
    from ato_bringup.graph_campaign import run_graph_campaign, verdict
    from ato_campaigns.engine import open_client, parse_campaign
    from ato_campaigns.provenance import provenance
    measured = measured or provenance()
    data = {'name': 'bench_ros', 'seed': 1, 'draws': GRAPH_BENCH_DRAWS, 'scenarios': [scenario],
            'laws': list(BENCH_CAMPAIGN_LAWS), 'uncertainty': 'default',
            'configurations': ['published'], 'end_time_s': GRAPH_BENCH_END_S}
    campaign = parse_campaign(data, 'bench_ros', Path.cwd())
    n = len(campaign.tasks())
    rows, offline = [], {}
    for workers in (1, 2):
        offline[workers] = _campaign_on(campaign, workers)[0]
        rows.append(f'| offline | {workers} | {n} | {offline[workers]:.1f} s | '
                    f'{60 * n / offline[workers]:.1f} | 1 | - |')
        print(rows[-1], flush=True)
    for workers in (1, 2):
        client, cluster = open_client(workers=workers) if workers > 1 else (None, None)
        with tempfile.TemporaryDirectory() as out, contextlib.ExitStack() as held:
            if client is not None:
                held.enter_context(cluster)
                held.enter_context(client)
            started = time.perf_counter()
            results = run_graph_campaign(campaign, Path(out), workers, client=client)
            wall = time.perf_counter() - started
        same = sum(verdict(result)[0] for result in results)
        rows.append(f'| through the ROS graph | {workers} | {n} | {wall:.1f} s | '
                    f'{60 * n / wall:.1f} | {offline[workers] / wall:.3f} | {same} of {n} |')
        print(rows[-1], flush=True)
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    return [
        GRAPH_CAMPAIGN_HEADING, '',
        f'Measured on {measured.date_utc}; machine: {measured.machine}; commit: '
        f'{measured.commit}.', '',
        f'The same campaign offline (`python -m ato_campaigns.campaign FILE`, the engine\'s '
        f'LocalCluster, warmed up before the clock starts) and `--through ros` '
        f'(`ato_bringup.graph_campaign`: each row through the three nodes in lockstep, recorded, '
        f'in a DDS domain of its own, and made offline again to compare): {GRAPH_BENCH_DRAWS} '
        f'draws x {len(BENCH_CAMPAIGN_LAWS)} laws ({", ".join(BENCH_CAMPAIGN_LAWS)}) of '
        f'`{scenario}` cut at {GRAPH_BENCH_END_S:g} s, the default uncertainty; one round each. '
        'Speed against offline: the offline wall time with as many workers over this one. '
        '`python bench/bench.py --only graph-campaign --results-page '
        'docs/results/benchmarks.md` measures only this section and rewrites it on the page.',
        '', '| path | workers | rows | wall time | rows per minute | speed against offline | '
        'rows identical to offline |', '|---|---|---|---|---|---|---|', *rows, '',
        f'Load average at the end: {load} (on {os.cpu_count()} cores).']


def _tree_cpu_s() -> float:
    """CPU time of this process and its living children (a worker and its run process)."""
    import psutil
    me = psutil.Process()
    return sum(sum(p.cpu_times()[:2]) for p in [me, *me.children(recursive=True)])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default=DEFAULT_SCENARIO)
    parser.add_argument('--domain-id', type=int, default=None,
                        help='ROS_DOMAIN_ID of the lockstep runs (default: a free one, that no '
                             'other run or test session on this machine holds)')
    parser.add_argument('--results-page', type=Path, default=None,
                        help='also write the figures, with date, machine and commit, to this '
                        'results page of the docs (make bench: docs/results/benchmarks.md)')
    parser.add_argument('--readme', type=Path, default=None,
                        help='also write the closed-loop table of the two strategies between '
                        'its markers in this file (make bench: README.md)')
    parser.add_argument('--only', choices=('campaign', 'offline', 'planning', 'lockstep',
                                            'tuning', 'graph-campaign'),
                        default=None,
                        help='measure only this section (printed, no results page; lockstep, '
                        'tuning and graph-campaign: with --results-page, that section of the '
                        'page rewritten)')
    args = parser.parse_args()
    with contextlib.ExitStack() as held:
        if args.domain_id is None:
            args.domain_id = held.enter_context(free_domain())
        return measure(args)


TUNING_HEADING = '## Tuning'


def tuning_section() -> list[str]:
    """The tuning section: ``make tune``'s budget and wall time, from the committed tuned
    artefacts (``ato_controller_node.gains``), one row per run of the command."""
    runs: dict[tuple, list[str]] = {}
    for train, law in gains_module.available():
        record = gains_module.tuned_artefact(law, train).record
        produced, budget = record['produced'], record['budget']
        key = (produced['date'], produced['commit'], produced['machine'], produced['wall_s'],
               budget['trials'], budget['draws_per_trial'], budget['runs'])
        runs.setdefault(key, []).append(f'`{law}` ({train})')
    lines = [TUNING_HEADING, '',
             '`make tune` (ato_campaigns/tuning.py, docs/guide/laws.md#tuning): one procedure '
             'and one budget for every law, the trials of all laws interleaved on a Dask '
             'LocalCluster of one worker per core. The command measures its own wall time and '
             'writes it, with its date, machine and commit, into every tuned artefact '
             '(ato_controller_node/tuned/); this table reads them (it is not rerun by `make '
             'bench`). Results: [Tuning](tuning.md).', '',
             '| laws | budget per law | runs in all | wall time | runs per minute | measured |',
             '|---|---|---|---|---|---|']
    for (date, commit, machine, wall_s, trials, draws, per_law), laws in sorted(runs.items()):
        total = per_law * len(laws)
        lines.append(f'| {", ".join(laws)} | {trials} trials x {draws} draws ({per_law} runs) | '
                     f'{total} | {wall_s:.0f} s | {60.0 * total / wall_s:.1f} | {date}, '
                     f'commit {commit}; {machine} |')
    if not runs:
        lines.append('| (no tuned artefact: run `make tune`) | | | | | |')
    return lines


def replace_section(page: Path, heading: str, lines: list[str]) -> Path:
    """Put ``lines`` (a section starting with ``heading``) in place of that section of
    ``page`` (up to the next heading of its level), or at its end."""
    text = page.read_text().rstrip('\n').split('\n')
    level = heading.split(' ', 1)[0] + ' '
    if heading in text:
        start = text.index(heading)
        end = next((i for i in range(start + 1, len(text)) if text[i].startswith(level)),
                   len(text))
        text[start:end] = lines + ([''] if end < len(text) else [])
    else:
        text += [''] + lines
    page.write_text('\n'.join(text) + '\n')
    return page


def campaign_intro() -> list[str]:
    """The campaign throughput section's heading, method and table head."""
    return [
        '## Campaign throughput', '',
        f'`make campaign`\'s engine on {BENCH_CAMPAIGN_DRAWS} draws x '
        f'{len(BENCH_CAMPAIGN_LAWS)} laws ({", ".join(BENCH_CAMPAIGN_LAWS)}) of the whole '
        f'scenario with the default uncertainty; the workers are started and warmed up before '
        'the clock starts. Overhead: the 1-worker campaign (Dask, the time limit, one Parquet '
        'row per run) against the same runs in a bare offline loop; goal under 5 %. Ratio goal '
        f'on 2 cores: at least 1.8. The three are measured in {CAMPAIGN_ROUNDS} rounds in a '
        'rotating order (the speed of a core of a shared machine moves from one minute to the '
        'next by more than the overhead sought; the rounds\' figures show by how much); each '
        'figure is the median over the rounds.', '',
        '| engine | runs | wall time | CPU time | runs per minute | overhead, wall | '
        'overhead, CPU |', '|---|---|---|---|---|---|---|']


def offline_intro() -> list[str]:
    """The offline closed loop section's heading and method."""
    return [
        '## Offline closed loop', '',
        f'`ato_simulation.loop.run_offline` (what `make compare` and the campaigns run) of every '
        f'law that applies to `{OFFLINE_SCENARIO}`, the whole run, at the rate `make compare` '
        'gives it, the scenario parsed once (as a campaign\'s worker parses it); real-time '
        'factor = simulated time / CPU time of one core, median of 3. Plan '
        'cached: the target curve planned once per scenario content and reused (a campaign\'s '
        'runs of one scenario share it); planning included: the plan cache cleared before each '
        'run. Goal for `pid`: at least 4000x with the plan cached.', '']


def law_and_plant_sections(page: Page, scenario: str) -> None:
    """The controller's step time and the plant's speed alone, on ``page``."""
    page.add('', '## Controller step time', '',
             'Offline, the law and its host (saturation, bumpless transfer); target p99 < 1 ms. '
             f'A law sampled faster than its scenario is timed over {LAW_BENCH_STEPS} steps at '
             'its rate.', '')
    page.lines += law_step_times(scenario)
    page.add('', '## Plant simulation alone', '',
             'CPU time of one core, 10 Hz control periods, 600 s from standstill, median of 5 '
             'runs; period by period (`apply_command`, `advance`, `truth`, as the node drives '
             'it) and all commands at once (`run_commands`).', '',
             '| model | period by period | all commands at once |', '|---|---|---|')
    for model, train, what in (('point_mass', None, 'RK4, CRH3'),
                               ('multi_car', 'crh2_4car_mao',
                                'CRH2 4-car unit, exact coupler dynamics, ETDRK4')):
        page.add(f'| `{model}` ({what}) | {plant_speed(scenario, model, train):.0f}x | '
                 f'{plant_speed(scenario, model, train, batched=True):.0f}x |')


def measure(args: argparse.Namespace) -> int:
    measured = (results_page_provenance(args.results_page)
                if args.results_page is not None else None)
    readme_measured = (results_page_provenance(args.readme) if args.readme is not None
                       else None)
    page = Page()
    campaign_section, offline_section = campaign_intro(), offline_intro()
    if args.only == 'offline':
        page.add(*offline_section)
        offline_loop_speed()
        return 0
    planning_section = [
        '## Planning', '',
        'CPU time to plan the whole target curve of each built-in scenario from scratch (median '
        'of 3; the '
        'timetable strategy with a 7 % running-time supplement), '
        'docs/guide/target-curve.md.', '']
    comparison_section = timetable_section_intro()
    if args.only == 'campaign':
        page.add(f'Scenario `{args.scenario}`.', '', *campaign_section)
        page.add(*campaign_throughput(args.scenario))
        return 0
    if args.only == 'planning':
        page.add(*planning_section)
        page.add(*planning_times())
        page.add('', *comparison_section)
        table = timetable_against_fastest()
        page.add(*table)
        if args.readme is not None:
            command = f'python bench/bench.py --only planning --readme {args.readme}'
            print(f'\nwrote {update_readme(args.readme, table, readme_measured, command)}')
        return 0
    if args.only == 'lockstep':
        from ato_campaigns.provenance import provenance
        now = provenance()  # the load average at the start
        lines = lockstep_section(args.scenario, args.domain_id)
        if args.results_page is not None:
            lines[1:1] = ['', f'Measured by `python bench/bench.py --only lockstep '
                              f'--results-page {args.results_page}` on {now.date_utc}; machine: '
                              f'{now.machine}; commit: {now.commit}; scenario `{args.scenario}`.']
            print(f'\nwrote {replace_section(args.results_page, LOCKSTEP_HEADING, lines)}')
        return 0
    if args.only == 'graph-campaign':
        page.add(*graph_campaign_throughput(args.scenario, measured))
        if args.results_page is not None:
            written = replace_section(args.results_page, GRAPH_CAMPAIGN_HEADING, page.lines)
            print(f'\nwrote {written}')
        return 0
    if args.only == 'tuning':
        page.add(*tuning_section())
        if args.results_page is not None:
            print(f'\nwrote {replace_section(args.results_page, TUNING_HEADING, page.lines)}')
        return 0
    page.add(f'Scenario `{args.scenario}`.', '')
    page.lines += lockstep_section(args.scenario, args.domain_id)
    law_and_plant_sections(page, args.scenario)
    page.add('', *offline_section)
    page.lines += offline_loop_speed()
    page.add('', '## Plant accuracy', '',
             'Largest speed error against DOP853 (rtol 1e-12), 600 s, commands changing every '
             'second, across grade, curve and tunnel boundaries.', '',
             '| model | largest speed error |', '|---|---|',
             f'| `point_mass` | {plant_accuracy("point_mass", "crh3_luo_xu", 60e3):.2e} m/s |',
             f'| `multi_car` | {plant_accuracy("multi_car", "crh2_4car_mao", 6e3):.2e} m/s |')
    page.add('', *campaign_section)
    page.add(*campaign_throughput(args.scenario))
    page.add('', *graph_campaign_throughput(args.scenario, measured))
    page.add('', *planning_section)
    page.add(*planning_times())
    page.add('', *comparison_section)
    table = timetable_against_fastest()
    page.add(*table)
    page.add('', *tuning_section())
    if args.readme is not None:
        print(f'\nwrote {update_readme(args.readme, table, readme_measured, "make bench")}')
    if args.results_page is not None:
        written = write_results_page(args.results_page, 'Benchmarks', 'make bench',
                                     '\n'.join(page.lines), measured)
        print(f'\nwrote {written}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
