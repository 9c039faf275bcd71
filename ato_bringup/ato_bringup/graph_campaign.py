"""graph_campaign: a whole campaign made through the ROS graph, each row beside the row made
offline.

    python -m ato_bringup.graph_campaign FILE [--workers N] [--out runs/campaigns]
    python -m ato_campaigns.campaign FILE --through ros [--workers N] [--out runs/campaigns]

(the campaign command hands ``--through ros`` without ``--draw`` to this module in a process of
its own: the campaign's modules are pure and import no rclpy). Every row of the campaign (every
scenario x law and configuration x draw, ``Campaign.tasks``) is made twice, as
``ato_bringup.graph_row`` makes one row:

- offline, in the process that runs the row (``ato_campaigns.engine.rerun``: the campaign's own
  task and loop); its run also gives the graph run its end and journey rule;
- through the graph, in lockstep, the three nodes as processes in a DDS domain that no other run
  holds (``ato_common.domains.free_domain``: one per concurrent run), recorded
  (``<out>/<name>-ros/graph/<row>/``), the row computed by the campaign's own ``run_metrics``
  from what was on the wire (``graph_row.graph_row_of``).

The graph's rows are written as the campaign writes its rows (``ato_campaigns.dataset``: one
Parquet file per finished row, the campaign's fingerprint and description in its metadata; the
row and the metadata say how it was made, ``through``: :data:`THROUGH`) to
``<out>/<name>-ros/rows/``, and the campaign's report (``ato_campaigns.report``: report.md,
stats/*.csv, report.json, plots; it names how the rows were made from their ``through``) is
written on them to ``<out>/<name>-ros/``. Every invocation makes every row again (the latest
written row of a key counts). A row whose graph run fails (a node killed or crashed, a run past
the campaign's ``timeout_s`` of wall time, 900 s when it has none, the recording unreadable) is
a row with status ``error`` and the failure as its reason; the campaign goes on.

Then a table: per row, the offline and the graph statuses and whether the status, the reason and
every metric agree (``graph_row.comparison``, within ``graph_row.TOLERANCE``; the saturation of
a law faster than the nodes' diagnostics is not compared), and the count of identical rows.

``--workers N`` runs N rows at once on a Dask LocalCluster of N single-threaded workers
(``ato_campaigns.engine.execute``); the default, 1, runs them one after the other in this
process: on 2 cores one lockstep run (three nodes, the recorder and the run monitor) already
uses both, and a second run beside it slows both.

Exit code: 0 when every row agrees, 1 when one differs or a graph run failed, 2 for bad input
(an unreadable campaign, a folder that holds another version's rows, ``--workers`` below 1).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ato_bringup.graph_row import TOLERANCE, comparison, differing, graph_row_of
from ato_bringup.runner import RunFailed

#: the folder of a campaign's rows through the graph: ``<out>/<name><SUFFIX>/``
SUFFIX = '-ros'
#: how the graph's rows were made: in each row (its ``through`` column, which the campaign's
#: report names: ``ato_campaigns.report.how_run``) and in the rows' files' metadata
THROUGH = ('through the ROS graph (ato_bringup.graph_campaign: the plant, profile and controller '
           'nodes in lockstep, each row computed from what was on the wire)')


def parse_args(argv: list[str]) -> argparse.Namespace:
    from ato_campaigns.engine import DEFAULT_OUT
    parser = argparse.ArgumentParser(
        prog='python -m ato_bringup.graph_campaign',
        description='Every row of a campaign made through the ROS graph (the nodes in '
        'lockstep) and offline; the graph\'s rows in the campaign\'s row format in '
        '<out>/<name>-ros/, and per row whether the two agree.')
    parser.add_argument('file', type=Path, help='the campaign file')
    parser.add_argument('--workers', type=int, default=1,
                        help='rows run at once, each in a DDS domain of its own, on a Dask '
                        'LocalCluster when above 1 (default 1, in this process: on 2 cores '
                        'one lockstep run already uses both)')
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT,
                        help=f'where the rows and the report go: <out>/<name>{SUFFIX}/ '
                        f'(default {DEFAULT_OUT})')
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error(f'--workers: at least 1, got {args.workers}')
    return args


def error_row(task: dict, reason: str) -> dict:
    """The campaign's row of ``task`` with status ``error`` and ``reason`` (no metrics)."""
    from ato_campaigns.engine import base_row
    return dict(base_row(task), status='error', reason=reason)


def failure_text(error: BaseException) -> str:
    """Why a graph run failed: the runner's own message, else the exception and its line."""
    from ato_campaigns.run_process import failure_reason
    text = str(error) if isinstance(error, RunFailed) else failure_reason(error)
    return f'the run through the graph failed: {text}'


def run_row(item: tuple) -> dict:
    """One row of a campaign offline and through the graph; never raises. ``item``: (the
    campaign, its task, the folder of the graph runs). Returns {'offline': row, 'graph': row,
    'notes': [...]}; a failed run is a row with status ``error`` and its reason."""
    from ato_campaigns.engine import rerun
    from ato_campaigns.run_process import failure_reason
    campaign, task, runs = item
    try:
        offline, run = rerun(campaign, task['law'], task['draw'], task['scenario'])
    except Exception as error:  # noqa: BLE001 -- a failed run is a row to show
        reason = failure_reason(error)
        return {'offline': error_row(task, reason), 'notes': [], 'graph': error_row(
            task, f'not run through the graph: its offline run (which gives its end) failed: '
                  f'{reason}')}
    started = time.perf_counter()
    try:
        graph, notes, _ = graph_row_of(task, run, runs, timeout_s=task['timeout_s'])
    except Exception as error:  # noqa: BLE001 -- a failed run is a row to show
        graph, notes = error_row(task, failure_text(error)), []
    graph['wall_s'] = time.perf_counter() - started
    return {'offline': offline, 'graph': graph, 'notes': notes}


def lost_row(item: tuple, reason: str) -> dict:
    """A row the Dask cluster lost (its worker died): an error row, no offline row."""
    return {'offline': None, 'graph': error_row(item[1], reason), 'notes': []}


def verdict(result: dict) -> tuple[bool, str]:
    """(the graph's row equals the offline row, in words): equal statuses and reasons and every
    metric within TOLERANCE (graph_row.comparison)."""
    offline, graph = result['offline'], result['graph']
    if offline is None:
        return False, f'no offline row; graph: {first_line(graph["reason"])}'
    differ = differing(comparison(offline, graph))
    if not differ:
        return True, 'identical'
    if graph['status'] == 'error' and offline['status'] != 'error':
        return False, first_line(graph['reason'])
    return False, 'differs in ' + ', '.join(differ)


def first_line(text: str, width: int = 100) -> str:
    line = text.splitlines()[0] if text else ''
    return line if len(line) <= width else line[:width - 3] + '...'


def comparison_table(results: list[dict]) -> tuple[str, int]:
    """The table of the rows (sorted by scenario, law, draw): each row's statuses offline and
    through the graph and its verdict; and the count of identical rows."""
    results = sorted(results, key=lambda r: (r['graph']['scenario'], r['graph']['law'],
                                             r['graph']['draw']))
    lines, same = [], 0
    cells = []
    for result in results:
        graph, offline = result['graph'], result['offline']
        ok, words = verdict(result)
        same += ok
        cells.append((Path(graph['scenario']).stem, graph['law'], str(graph['draw']),
                      '-' if offline is None else offline['status'], graph['status'], words))
    head = ('scenario', 'law', 'draw', 'offline', 'graph', 'verdict')
    widths = [max(len(c[i]) for c in [head, *cells]) for i in range(5)]
    for row in [head, *cells]:
        lines.append('  '.join(f'{c:<{w}}' for c, w in zip(row, widths)) + '  ' + row[5])
    lines.append(f'{same} of {len(results)} rows identical offline and through the graph '
                 f"(the status, the reason and every metric within math.isclose(rel_tol="
                 f"{TOLERANCE['rel_tol']:g}, abs_tol={TOLERANCE['abs_tol']:g}))")
    return '\n'.join(lines), same


def run_graph_campaign(campaign, out: Path, workers: int = 1, client=None) -> list[dict]:
    """Every row of ``campaign`` offline and through the graph (``run_row``), ``workers`` at
    once; the graph's rows written to ``<out>/<name>-ros/rows/`` as they finish. A folder that
    holds the rows of another version of the campaign is refused (FolderConflict) before
    anything runs."""
    from ato_campaigns.dataset import check_folder, compact, rows_folder, write_row
    from ato_campaigns.engine import data_description, execute
    base = out / f'{campaign.name}{SUFFIX}'
    folder = rows_folder(out, f'{campaign.name}{SUFFIX}')
    check_folder(folder, campaign.fingerprint, campaign.identity())
    description = dict(data_description(campaign), through=THROUGH)
    items = [(campaign, task, base / 'graph') for task in campaign.tasks()]
    results: list[dict] = []

    def finished(result: dict) -> None:
        result['graph']['through'] = THROUGH
        write_row(folder, result['graph'], description)
        results.append(result)
        ok, words = verdict(result)
        graph = result['graph']
        print(f"{len(results)}/{len(items)} {graph['law']} draw {graph['draw']}: "
              f"{graph['status'] or '-'} through the graph, {words}", file=sys.stderr)

    execute(items, run_row, finished, lost_row, serial=workers == 1 and client is None,
            workers=workers, client=client)
    if len(results) == len(items):
        compact(folder, description)
    return results


def main(argv: list[str] | None = None) -> int:
    from ato_campaigns.dataset import read_rows, rows_folder
    from ato_campaigns.engine import load_campaign
    from ato_campaigns.report import write_report
    from ato_common.validation import ConfigError
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    started = time.monotonic()
    try:
        campaign = load_campaign(args.file)
        print(f'{campaign.name}: {len(campaign.tasks())} rows through the graph, '
              f'{args.workers} at once; rows in '
              f'{rows_folder(args.out, campaign.name + SUFFIX)}', file=sys.stderr)
        results = run_graph_campaign(campaign, args.out, args.workers)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('interrupted: the finished rows are kept', file=sys.stderr)
        return 130
    rows = read_rows(rows_folder(args.out, campaign.name + SUFFIX), campaign.fingerprint)
    command = ' '.join(['python -m ato_bringup.graph_campaign', *argv])
    report = write_report(campaign, rows, args.out / f'{campaign.name}{SUFFIX}', command,
                          time.monotonic() - started)
    table, same = comparison_table(results)
    print(table)
    for result in results:
        for note in result['notes']:
            print(f"note ({result['graph']['law']} draw {result['graph']['draw']}): {note}")
    print(f'wrote {report}', file=sys.stderr)
    return 0 if same == len(results) else 1


if __name__ == '__main__':
    raise SystemExit(main())
