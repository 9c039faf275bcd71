"""scorecard: an ATO node of your own through a campaign's draws, through the ROS graph, beside
the suite's laws on the same draws.

    ato scorecard --controller-command CMD --campaign FILE [--workers N] [--label NAME]
                  [--out runs/campaigns]
    ros2 run ato_bringup scorecard --controller-command "ros2 run my_pkg my_ato" --campaign FILE

Every scenario x draw of the campaign (``ato_campaigns.engine``) runs once with your node
(``CMD``, started as the ATO node contract says: ``ato_common.contract``) in place of the
suite's controller, in lockstep, the three nodes as processes in a DDS domain of its own,
recorded (``<out>/<name>-scorecard-<label>/graph/``):

- the plant takes the draw's truth (its ``draw_values`` parameter), the same plant the
  campaign's baseline law gets on that draw (common random numbers);
- your node is told what the contract lets it know: the scenario, and the draw's knowledge part
  as the ``gradient_known`` parameter (the baseline entry's, as the suite's law is told it);
- the run goes on to the latest end the journey rule allows (``ato_simulation.plans``:
  ``JourneyEnd.limit_s``) and is judged, as the offline loop judges a run, up to where that
  rule ends it (a late train runs on, a train standing at its stop ends the run);
- its row is computed by the campaign's own metrics and status rules
  (``ato_campaigns.engine.run_metrics``) from what was on the wire (``graph_row.row_from_wire``;
  the share of steps your law saturated is not on the wire: NaN).

The suite's laws' rows are the campaign's own (offline, ``ato_campaigns.engine.run_campaign``:
the rows stored in ``<out>/<name>/rows/`` are used, the missing ones are run). Your node's rows
are written in the campaign's row format to ``<out>/<name>-scorecard-<label>/rows/`` (law
``<label>/own``, ``through``: how they were made), and the campaign's report
(``ato_campaigns.report``: the overview, each metric, the failure rates, the paired comparison
with the baseline on the same draws, plots) is written on both to
``<out>/<name>-scorecard-<label>/``. Every invocation runs the node's rows again.
A run that fails (your node exits or crashes, a run past the campaign's ``timeout_s``) is a row
with status ``error`` and the failure as its reason; the scorecard goes on. Then the scorecard
is printed: per law its runs and statuses and the ATO's KPIs (punctuality, stopping accuracy,
comfort, energy, ATP interventions), and your node's paired differences with the baseline.

``--workers N`` runs N of your node's runs at once on a Dask LocalCluster (and the missing
offline rows on it too); the default, 1, one after the other in this process.

Exit code: 0 when every run of your node finished with metrics (whatever its status), 1 when
one failed (status error or timeout), 2 for bad input.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

#: the folder of a node's scorecard on a campaign: ``<out>/<name><SUFFIX><label>/``
SUFFIX = '-scorecard-'
#: the configuration of the external node's rows (its own gains, whatever they are)
OWN = 'own'
#: the KPIs the scorecard prints: (metric, heading, format)
KPIS = (('arrival_delay_s', 'delay s', '.1f'), ('stop_error_m', 'stop err m', '.2f'),
        ('max_jerk_mps3', 'jerk m/s3', '.2f'), ('traction_energy_kwh', 'energy kWh', '.1f'),
        ('atp_interventions', 'ATP', '.2f'), ('rms_speed_error_kmh', 'RMS dv km/h', '.2f'))


def through(command: str) -> str:
    """How the external node's rows were made (their ``through`` column)."""
    return (f'the external ATO node `{command}` through the ROS graph (ato_bringup.scorecard: '
            'the plant and profile nodes in lockstep, each row computed from what was on the '
            'wire)')


def external_tasks(campaign, label: str) -> list[dict]:
    """One task per draw and scenario (draw-major): the campaign's task of its baseline entry
    (the draw's truth and knowledge, model, window, time limit) with the node's label, no
    settings, and the scenario's control rate (the node takes its period from the stamps)."""
    from ato_campaigns.engine import task_of, task_scenario
    entry = next((e for e in campaign.laws if e.label == campaign.baseline), campaign.laws[0])
    tasks = []
    for draw in range(campaign.draws):
        for scenario in campaign.scenarios:
            task = task_of(campaign, scenario, entry, draw)
            task.update(law=f'{label}/{OWN}', law_name=label, configuration=OWN, settings={},
                        rate_hz=task_scenario(scenario).run.controller_rate_hz)
            tasks.append(task)
    return tasks


def journey_count(journey, period_ns: int, times_s, positions, speeds) -> int:
    """How many samples (from the first) the offline loop would have run for a train that moved
    as ``positions`` and ``speeds`` at ``times_s`` (every sample to the latest end, one control
    period ``period_ns`` apart): the planned end's samples, then on as long as the journey rule
    (``JourneyEnd.remaining_s``) says, as ``ato_simulation.loop`` grows a run."""
    limit = min(int(journey.limit_s * 1e9 // period_ns) + 1, len(times_s))
    count = min(int(journey.planned_s * 1e9 // period_ns) + 1, limit)
    while count < limit:
        left = journey.remaining_s(times_s[:count], positions[:count], speeds[:count])
        if left <= 0.0:
            break
        count = min(count + math.ceil(left * 1e9 / period_ns - 1e-6), limit)
    return count


def external_row(item: tuple) -> dict:
    """One run of the external node as the campaign's row; never raises. ``item``: (its task,
    the node's command line, the folder of the graph runs). A failed run is a row with status
    ``error`` and its reason."""
    from ato_bringup.graph_campaign import error_row, failure_text
    from ato_bringup.graph_row import row_from_wire, run_through_graph
    from ato_campaigns.engine import task_scenario
    from ato_simulation.plans import JourneyEnd, cached_plan, run_end_time_s
    task, command, runs = item
    started = time.perf_counter()
    try:
        scenario = task_scenario(task['scenario'])
        plan = cached_plan(scenario)
        journey = None if task['end_time_s'] else JourneyEnd.of(scenario, plan)
        end = task['end_time_s'] or (journey.limit_s if journey is not None
                                     else run_end_time_s(scenario, plan))
        outcome, log_dir = run_through_graph(task, end, runs, timeout_s=task['timeout_s'],
                                             controller_command=command)
        if journey is not None:
            truth = [s for _, s in outcome.samples]
            count = journey_count(journey, round(1e9 / task['rate_hz']),
                                  [k / 1e9 for k, _ in outcome.samples],
                                  [s.positions[0] for s in truth], [s.speeds[0] for s in truth])
            outcome = dataclasses.replace(outcome, samples=outcome.samples[:count])
        row = row_from_wire(task, outcome, log_dir / 'bag', journey, every_step=False)
    except Exception as error:  # noqa: BLE001 -- a failed run is a row to show
        row = error_row(task, failure_text(error))
    row.update(wall_s=time.perf_counter() - started, through=through(command))
    return row


def lost_row(item: tuple, reason: str) -> dict:
    """A run the Dask cluster lost (its worker died): an error row."""
    from ato_bringup.graph_campaign import error_row
    return dict(error_row(item[0], reason), through=through(item[1]))


def run_external(campaign, command: str, label: str, out: Path, workers: int = 1):
    """Every run of the external node (``external_row``), ``workers`` at once; its rows written
    to ``<out>/<name>-scorecard-<label>/rows/`` as they finish (that folder's earlier rows are
    replaced). Returns them (a DataFrame)."""
    from ato_bringup.graph_campaign import first_line
    from ato_campaigns.dataset import check_folder, compact, read_rows, rows_folder, write_row
    from ato_campaigns.engine import data_description, execute
    name = f'{campaign.name}{SUFFIX}{label}'
    folder = rows_folder(out, name)
    check_folder(folder, campaign.fingerprint, campaign.identity())
    for old in folder.glob('*.parquet'):
        old.unlink()
    description = dict(data_description(campaign), through=through(command))
    items = [(task, command, out / name / 'graph') for task in external_tasks(campaign, label)]
    done: list[dict] = []

    def finished(row: dict) -> None:
        write_row(folder, row, description)
        done.append(row)
        print(f"{len(done)}/{len(items)} {row['law']} draw {row['draw']}: {row['status']}"
              + (f" ({first_line(row['reason'])})" if row['reason'] else ''), file=sys.stderr)

    execute(items, external_row, finished, lost_row, serial=workers == 1, workers=workers)
    compact(folder, description)
    return read_rows(folder, campaign.fingerprint)


def scorecard_table(campaign, rows, tables: dict, label: str) -> str:
    """Per scenario: each law's runs, statuses and mean KPIs (of the runs with metrics), then
    the external node's paired differences with the baseline (mean, 95 % interval)."""
    from ato_campaigns.report import scenario_name
    lines = []
    overview, summaries = tables['overview'], tables['metrics']
    paired = tables['paired_differences']
    for scenario in campaign.scenarios:
        head = ('law', 'runs', *(h for _, h, _ in KPIS), 'statuses')
        cells = []
        for _, law in overview[overview['scenario'] == scenario].iterrows():
            means = []
            for metric, _, fmt in KPIS:
                found = summaries[(summaries['scenario'] == scenario) & (
                    summaries['law'] == law['law']) & (summaries['metric'] == metric)]
                value = float(found['mean'].iloc[0]) if len(found) else math.nan
                means.append('-' if math.isnan(value) else format(value, fmt))
            cells.append((law['law'], str(law['runs']), *means, law['statuses']))
        widths = [max(len(c[i]) for c in [head, *cells]) for i in range(len(head) - 1)]
        lines += [f'{scenario_name(scenario)}: mean of the runs with metrics']
        lines += ['  '.join(f'{c:<{w}}' for c, w in zip(row, widths)) + '  ' + row[-1]
                  for row in [head, *cells]]
        mine = paired[(paired['scenario'] == scenario) & (paired['law'] == f'{label}/{OWN}')]
        for _, p in mine.iterrows():
            lines.append(f"  {p['law']} - {p['baseline']}, {p['metric']}: mean "
                         f"{p['mean_diff']:+.3g} [{p['low']:+.3g}, {p['high']:+.3g}] on "
                         f"{p['pairs']} paired draws")
    return '\n'.join(lines)


def parse_args(argv: list[str]) -> argparse.Namespace:
    from ato_campaigns.engine import DEFAULT_OUT
    parser = argparse.ArgumentParser(
        prog='scorecard', description='An ATO node of your own through a campaign\'s draws '
        '(through the ROS graph), beside the campaign\'s laws on the same draws.')
    parser.add_argument('--controller-command', required=True, metavar='CMD',
                        help='your ATO node\'s command line (the contract\'s parameters are '
                        'appended)')
    parser.add_argument('--campaign', required=True, type=Path, help='the campaign file')
    parser.add_argument('--label', default='external',
                        help='your node\'s label in the rows and the report (default external)')
    parser.add_argument('--workers', type=int, default=1,
                        help='runs at once, on a Dask LocalCluster when above 1 (default 1)')
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT,
                        help=f'where the rows and the report go (default {DEFAULT_OUT})')
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error(f'--workers: at least 1, got {args.workers}')
    if not args.controller_command.split() or '/' in args.label or not args.label:
        parser.error('--controller-command must not be empty; --label must be a name '
                     'without "/"')
    return args


def main(argv: list[str] | None = None) -> int:
    import pandas as pd

    from ato_bringup.graph_campaign import first_line
    from ato_campaigns.dataset import FolderConflict
    from ato_campaigns.engine import load_campaign, run_campaign
    from ato_campaigns.report import statistics, write_report
    from ato_common.validation import ConfigError
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    started = time.monotonic()
    try:
        campaign = load_campaign(args.campaign)
        builtin = run_campaign(campaign, args.out, serial=args.workers == 1,
                               workers=args.workers, progress=False)
        mine = run_external(campaign, args.controller_command, args.label, args.out,
                            args.workers)
    except (ConfigError, FolderConflict) as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('interrupted: the finished rows are kept', file=sys.stderr)
        return 130
    rows = pd.concat([builtin, mine], ignore_index=True)
    folder = args.out / f'{campaign.name}{SUFFIX}{args.label}'
    command = ' '.join(['scorecard', *argv])
    report = write_report(campaign, rows, folder, command, time.monotonic() - started)
    print(scorecard_table(campaign, rows, statistics(campaign, rows), args.label))
    failed = mine[mine['status'].isin(('error', 'timeout'))]
    for _, row in failed.iterrows():
        print(f"failed: {row['law']} draw {row['draw']}: {first_line(row['reason'])}")
    print(f'{len(mine) - len(failed)} of {len(mine)} runs of {args.controller_command} '
          f'finished with metrics; the report: {report}', file=sys.stderr)
    return 1 if len(failed) else 0


if __name__ == '__main__':
    raise SystemExit(main())
