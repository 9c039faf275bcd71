"""graph_row: one row of a campaign made again through the ROS graph, beside the row made offline.

    python -m ato_campaigns.campaign --campaign FILE --draw N --law LABEL --through ros
                                     [--configuration C] [--scenario S] [--out runs/campaigns]

(the campaign command hands ``--through ros`` to ``python -m ato_bringup.graph_row`` with the
same arguments: the campaign's modules are pure and import no rclpy). The row's task is the
campaign's own (``ato_campaigns.engine.task_of``: draw, law, settings, rate, model, envelope,
window); it runs twice:

- offline, in this process, as the campaign made it (``ato_campaigns.engine.rerun``);
- through the graph, in lockstep, with the suite's three nodes as processes
  (``ato_bringup.runner.run_lockstep``) in a DDS domain of its own: the plant takes the draw's
  truth (``draw_values``: its plant parameters, ``train_plant_node.draw_values``) and publishes
  the nominal scenario's identity; the controller is told only the knowledge part of the draw
  (``gradient_known``) and runs the row's law with its settings (``gains`` published with the
  row's settings as the ``<law>.<gain>`` parameters, as the offline loop takes them) and the
  campaign's envelope, at the row's rate; the run ends where the offline run ended (the
  campaign's stated end, else the end the journey rule gave offline, see below) and is
  recorded (``<out>/<name>/graph/<row>/bag``).

The graph's row is computed by the campaign's own ``run_metrics`` and status rules
(``ato_campaigns.engine``) on what was on the wire: the truth the run monitor received
(``train/state``: every car's position, speed and applied force), the reference the profile
streamed, the measured position from the recording (``train/state/measured``: the odometer
stop error), and from ``/diagnostics``, which the plant and the controller publish at every
control step in this run: the ATP's interventions and the watchdog (the plant's) and the law's
saturation, law and faults (the controller's). Then each metric is printed beside the offline
row (and the stored one, if ``<out>`` has it) with whether the two agree within
``TOLERANCE``.

What is not compared: the step times (wall time, of two different processes); the
saturation of a law that runs faster than the nodes publish diagnostics (100 Hz). The force of
a step is the force that acts once the step's command is given, as offline (``graph_run``
says where the wire has it). The run's end: without a stated
``end_time_s`` the offline run's end follows the journey (``ato_simulation.plans.JourneyEnd``:
a late train runs on); through the graph the plant ends at a time given at its start, so the
graph run is given the offline run's end and judged with the same journey rule. A scenario
whose profile replans (timetable strategy) is decided differently by the campaign's offline
loop (from every step's state) and the profile node (at its check instants): such a row is
flagged, its figures are not expected to agree.

Exit code: 0 when every compared metric and the status agree, 1 when one differs or the graph
run failed, 2 for bad input.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
from pathlib import Path

import numpy as np

from ato_bringup.runner import RunFailed, RunOutcome, run_lockstep
from ato_bringup.stack import StackConfig
from ato_common.conventions import TOPICS
from ato_common.run_events import WATCHDOG, RunEvents, safety_events
from ato_common.uncertainty import knowledge_options
from ato_simulation.loop import OfflineRun
from ato_simulation.plans import cached_plan, late_readings, stop_samples

#: relative and absolute tolerance of a metric's agreement (math.isclose). The graph's lockstep
#: loop is the offline loop step for step (the same cores, the same order of operations, the
#: same draw and noise streams: tests/test_lockstep_replan.py finds the states bit-identical),
#: so the metrics read from the wire agree to the last bits of a double; what may differ there
#: is only the order of a few floating-point sums (the forces of several actuators, read from
#: the published truth). A difference beyond this is a defect of one of the two paths.
TOLERANCE = {'rel_tol': 1e-9, 'abs_tol': 1e-9}

#: the plant's and the controller's statuses on /diagnostics (ato_ros.messages.status_name)
PLANT_STATUS = 'train_plant_node: simulation'
LAW_STATUS = 'ato_controller_node: law'
#: the plant's watchdog state when no brake is applied (train_plant_node.simulation.NORMAL)
WATCHDOG_NORMAL = 'normal'
#: the shortest diagnostics period the nodes take, s (their diagnostics_period_s minimum)
SHORTEST_DIAGNOSTICS_S = 0.01


def graph_config(task: dict, end_time_s: float, log_dir: Path, domain_id: int,
                 controller_command: str = '') -> StackConfig:
    """The stack that runs ``task`` (a campaign's task, ``engine.task_of``) through the graph:
    the plant with the draw's truth, the controller with its knowledge part, the row's law,
    settings, rate, envelope and model; recorded; diagnostics at every step.
    ``controller_command``: an ATO node of the user's in place of the suite's controller (told
    the knowledge part as the contract's ``gradient_known`` parameter)."""
    from train_plant_node.draw_values import draw_values_text
    law, rate = task['law_name'], task['rate_hz']
    gains = {f'{law}.{k}': v if isinstance(v, bool) else float(v)
             for k, v in task['settings'].items()}
    known = not knowledge_options(task['values'])['hide_gradient']
    return StackConfig(
        scenario=task['scenario'], controller=law, end_time_s=end_time_s, domain_id=domain_id,
        log_dir=log_dir, record_to=log_dir / 'bag', monitor='lean', model=task['model'],
        controller_command=controller_command,
        diagnostics_period_s=max(1.0 / rate, SHORTEST_DIAGNOSTICS_S),
        plant_params={'control_rate_hz': rate,
                      'draw_values': draw_values_text(task['values'])},
        controller_params={'rate_hz': rate, 'gains': 'published', 'envelope': task['envelope'],
                           'gradient_known': known, **gains})


def measured_positions(bag: Path, stamps: list[int]) -> np.ndarray:
    """The lead car's measured position at each stamp, from the recording's measured state
    (logged at its stamp in lockstep); NaN where it holds none."""
    from ato_ros import wire
    from recorder.bag import read_messages
    name = '/' + TOPICS['state_measured'].name.lstrip('/')
    found = {}
    for message in read_messages(bag, [name]):
        found[message.log_time_ns] = wire.decode_state(message.data).positions[0]
    return np.array([found.get(k, math.nan) for k in stamps])


def _latest(diagnostics: list, name: str, stamps: list[int]) -> list[dict[str, str]]:
    """For each stamp, the values of the newest status ``name`` stamped at or before it."""
    statuses = sorted(((k, values) for k, n, values, _ in diagnostics if n == name),
                      key=lambda item: item[0])
    out, i, current = [], 0, {}
    for stamp in stamps:
        while i < len(statuses) and statuses[i][0] <= stamp:
            current = statuses[i][1]
            i += 1
        out.append(current)
    return out


def graph_run(outcome: RunOutcome, measured: np.ndarray, journey, every_step: bool,
              instant: bool) -> OfflineRun:
    """The graph run as an OfflineRun (what ``engine.run_metrics`` reads) from what was on the
    wire. ``every_step``: the controller's diagnostics came at every step (its saturation flag
    and faults per step), else the saturation is left empty (``saturated_fraction`` is then not
    compared). ``instant``: the truth's actuators act at once (no lag, rate limit or dead
    time).

    The offline force of step k is what acts once the step's command is given. A lagging
    actuator has not moved yet then: the truth published at step k holds it. An instant one
    delivers the command at once, held through the period: the truth published at step k+1
    holds it (the last step's is the last published)."""
    scenario = outcome.scenario
    stamps = [k for k, _ in outcome.samples]
    samples = [s for _, s in outcome.samples]
    cars_x = np.array([s.positions for s in samples])
    cars_v = np.array([s.speeds for s in samples])
    applied = [s.forces for s in samples]
    if instant:
        applied = applied[1:] + applied[-1:]
    forces = np.array([math.fsum(f) for f in applied])
    plant = _latest(outcome.diagnostics, PLANT_STATUS, stamps)
    law = _latest(outcome.diagnostics, LAW_STATUS, stamps)
    counts = [int(v.get('atp_interventions', 0)) for v in plant]
    atp_times = tuple(k / 1e9 for k, c, before in zip(stamps, counts, [0] + counts[:-1])
                      if c > before)
    faults = [int(v.get('faults', 0)) for v in law]
    fault_text = ['' if c <= before else message_of(outcome.diagnostics, k)
                  for k, c, before in zip(stamps, faults, [0] + faults[:-1])]
    saturated = (np.array([v.get('saturated') == 'True' for v in law]) if every_step
                 else np.zeros(0, dtype=bool))
    # not read by the metrics, and not taken from the wire here: the reference's acceleration,
    # the forces per actuator, the step times, the law's estimates
    nan = np.full(len(samples), math.nan)
    run = OfflineRun(
        scenario, cached_plan(scenario), np.array(stamps) / 1e9, cars_x[:, 0].copy(),
        cars_v[:, 0].copy(), forces, np.array([s.ref_position for s in samples]),
        np.array([s.ref_speed for s in samples]), nan, cars_x, cars_v,
        np.empty((len(samples), 0)), nan.copy(), [v.get('law', '') for v in law],
        [], fault_text, counts[-1] if counts else 0,
        sum(v.get('watchdog', WATCHDOG_NORMAL) != WATCHDOG_NORMAL for v in plant),
        saturated, atp_times, (), journey, measured_positions=measured)
    if run.extended:
        run.late_readings = late_readings(stop_samples(run.plan), run.times_s, run.positions,
                                          run.speeds, scenario.train.length_m)
    return run


def message_of(diagnostics: list, stamp: int) -> str:
    """The controller's status message at ``stamp`` (a fault's text)."""
    return next((m for k, n, _, m in diagnostics if k == stamp and n == LAW_STATUS), 'fault')


def instant_actuators(scenario, values) -> bool:
    """The truth's actuators of the draw ``values`` act at once (no lag, rate limit or dead
    time): the analysis side's question, for the force's alignment; nothing of it reaches a
    node."""
    from ato_common.plant_setup import ActuatorSettings
    from ato_common.uncertainty import perturbed
    return perturbed(scenario, values).plant.actuators == ActuatorSettings()


def rerun_through_graph(campaign, law: str, draw: int, scenario: str | None = None,
                        configuration: str | None = None, out: Path | None = None,
                        domain_id: int | None = None, progress: bool = True):
    """One row of ``campaign`` made again offline and through the graph: (the offline row, the
    graph's row, notes on what is not expected to agree, the graph run's folder)."""
    from ato_campaigns.engine import DEFAULT_OUT, rerun, task_of
    offline, run = rerun(campaign, law, draw, scenario, configuration)
    entry = next(e for e in campaign.laws if e.label == offline['law'])
    task = task_of(campaign, offline['scenario'], entry, draw)
    row, notes, log_dir = graph_row_of(task, run, (out or DEFAULT_OUT) / campaign.name / 'graph',
                                       domain_id=domain_id, progress=progress)
    return offline, row, notes, log_dir


def graph_row_of(task: dict, run: OfflineRun, runs: Path, domain_id: int | None = None,
                 progress: bool = False, timeout_s: float | None = None
                 ) -> tuple[dict, list[str], Path]:
    """The row of ``task`` (a campaign's task, ``engine.task_of``) made through the graph, given
    its offline run ``run`` (the run's end and journey rule come from it): (the graph's row,
    notes on what is not expected to agree, the graph run's folder, made in ``runs``). The run
    takes a free DDS domain unless ``domain_id`` is given, and ends with RunFailed past
    ``timeout_s`` s of wall time (default: 900 s, or the simulated time if longer), or when a
    node ends before the plant does (``ato_bringup.runner.run_lockstep``)."""
    end = task['end_time_s'] or float(run.times_s[-1])
    outcome, log_dir = run_through_graph(task, end, runs, domain_id=domain_id,
                                         progress=progress, timeout_s=timeout_s)
    every_step = 1.0 / task['rate_hz'] >= SHORTEST_DIAGNOSTICS_S
    row = row_from_wire(task, outcome, log_dir / 'bag', run.journey, every_step)
    notes = []
    if not every_step:
        notes.append(f"the law runs at {task['rate_hz']:g} Hz, faster than the nodes publish "
                     'diagnostics (100 Hz at most): its saturation per step is not on the wire '
                     '(saturated_fraction not compared), and the steps its faults held are '
                     'counted at the diagnostics\' instants')
    if run.replans:
        notes.append('the offline run was replanned (timetable strategy): the campaign decides '
                     'from every step\'s state, the profile node at its check instants, so the '
                     'two runs are not expected to agree')
    return row, notes, log_dir


def run_through_graph(task: dict, end_time_s: float, runs: Path, domain_id: int | None = None,
                      progress: bool = False, timeout_s: float | None = None,
                      controller_command: str = '') -> tuple[RunOutcome, Path]:
    """``task`` run through the graph to ``end_time_s`` (``graph_config``), recorded in a new
    folder in ``runs``: (the outcome, the folder). A free DDS domain unless ``domain_id`` is
    given; RunFailed past ``timeout_s`` s of wall time (default: 900 s, or the simulated time if
    longer) or when a node ends before the plant does."""
    from ato_bringup.run_scenario import unique_run_dir
    from ato_common.domains import free_domain
    log_dir = unique_run_dir(runs, f"{task['law'].replace('/', '-')}-draw{task['draw']}")
    with contextlib.ExitStack() as held:
        if domain_id is None:
            domain_id = held.enter_context(free_domain())
        config = graph_config(task, end_time_s, log_dir, domain_id, controller_command)
        outcome = run_lockstep(config, timeout_s=timeout_s or max(900.0, end_time_s),
                               progress=progress)
    return outcome, log_dir


def row_from_wire(task: dict, outcome: RunOutcome, bag: Path, journey, every_step: bool
                  ) -> dict:
    """The campaign's row of ``task`` computed by its own ``run_metrics`` from the graph run
    ``outcome`` (recorded in ``bag``) judged with the end rule ``journey``; ``every_step``: the
    controller's diagnostics came at every step, else ``saturated_fraction`` is NaN (not on the
    wire)."""
    from ato_campaigns.engine import base_row, run_metrics
    graph = graph_run(outcome, measured_positions(bag, [k for k, _ in outcome.samples]),
                      journey, every_step, instant_actuators(outcome.scenario, task['values']))
    row = base_row(task)
    row.update(run_metrics(graph, 1.0 / task['rate_hz'],
                           watchdog_brakes(outcome.diagnostics, outcome.samples[-1][0])))
    if not every_step:
        row['saturated_fraction'] = math.nan
    return row


def watchdog_brakes(diagnostics: list, last_ns: int) -> RunEvents:
    """The plant's command-watchdog brakes up to ``last_ns`` from its diagnostics (the ATP's
    interventions are the run's own, ``graph_run``): the campaign's status names them."""
    safety = safety_events([d for d in diagnostics if d[0] <= last_ns])
    return RunEvents(tuple(e for e in safety.events if e.kind == WATCHDOG),
                     {WATCHDOG: safety.count(WATCHDOG)}, safety.tolerance_m)


#: what is compared besides the metrics (engine.METRICS)
COMPARED = ('status', 'reason')


def agree(a, b) -> bool:
    """Whether two values of a row agree: equal text, both NaN, or numbers within TOLERANCE."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    a, b = float(a), float(b)
    return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, **TOLERANCE)


def comparison(offline: dict, graph: dict, stored: dict | None = None
               ) -> list[tuple[str, object, object, object, str]]:
    """(what, stored, offline, graph, verdict) for the status, the reason and every metric;
    verdict 'agree', 'DIFFERS', or why it is not compared."""
    from ato_campaigns.engine import METRICS
    rows = []
    for key in (*COMPARED, *METRICS):
        a, b = offline.get(key), graph.get(key)
        if key == 'saturated_fraction' and isinstance(b, float) and math.isnan(b) and not (
                isinstance(a, float) and math.isnan(a)):
            verdict = 'not compared (not on the wire)'
        else:
            verdict = 'agree' if agree(a, b) else 'DIFFERS'
        rows.append((key, None if stored is None else stored.get(key), a, b, verdict))
    return rows


def differing(rows) -> list[str]:
    """What differs in a ``comparison``: the keys whose verdict is DIFFERS."""
    return [key for key, *_, verdict in rows if verdict == 'DIFFERS']


def _shown(value) -> str:
    if value is None:
        return '-'
    if isinstance(value, float):
        return 'nan' if math.isnan(value) else f'{value:.10g}'
    text = str(value)
    return text if len(text) <= 60 else text[:57] + '...'


def format_comparison(rows) -> str:
    widths = [max(len(r[0]) for r in rows), 16, 16, 16]
    head = (f"{'':<{widths[0]}}  {'stored':>16}  {'offline':>16}  {'graph':>16}  verdict")
    lines = [head]
    for key, stored, a, b, verdict in rows:
        if key == 'reason':
            lines.append(f'{key:<{widths[0]}}  offline: {_shown(a)}')
            lines.append(f"{'':<{widths[0]}}  graph:   {_shown(b)}  {verdict}")
            continue
        lines.append(f'{key:<{widths[0]}}  {_shown(stored):>16}  {_shown(a):>16}  '
                     f'{_shown(b):>16}  {verdict}')
    return '\n'.join(lines)


def main(argv=None) -> int:
    from ato_campaigns.campaign import parse_args, stored_row
    from ato_campaigns.engine import load_campaign
    from ato_common.validation import ConfigError
    from recorder.bag import BagError
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    if args.draw is None:
        print('error: give the row to make again through the graph: --draw N --law L',
              file=sys.stderr)
        return 2
    try:
        campaign = load_campaign(args.campaign)
        offline, graph, notes, folder = rerun_through_graph(
            campaign, args.law, args.draw, args.scenario, args.configuration, args.out)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except (RunFailed, BagError) as error:
        print(f'error: the run through the graph failed: {error}', file=sys.stderr)
        return 1
    rows = comparison(offline, graph, stored_row(campaign, args.out, offline))
    print(json.dumps({k: offline[k] for k in ('scenario', 'law', 'configuration', 'envelope',
                                              'draw')}))
    print(format_comparison(rows))
    for note in notes:
        print(f'note: {note}')
    print(f"tolerance: math.isclose(rel_tol={TOLERANCE['rel_tol']:g}, "
          f"abs_tol={TOLERANCE['abs_tol']:g}); the graph run and its recording: {folder}")
    differ = differing(rows)
    print('the graph gives the offline row' if not differ else
          'the graph differs from the offline row in ' + ', '.join(differ), file=sys.stderr)
    return 1 if differ else 0


if __name__ == '__main__':
    raise SystemExit(main())
