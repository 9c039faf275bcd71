"""campaign: every law of a campaign file on many draws of the uncertain train, on Dask.

    python -m ato_campaigns.campaign [FILE] [--scheduler tcp://HOST:8786] [--workers N]
                                          [--serial] [--out runs/campaigns]
                                          [--results-page PAGE]
    python -m ato_campaigns.campaign FILE --through ros [--workers N] [--out runs/campaigns]
    python -m ato_campaigns.campaign --campaign FILE --draw N --law LABEL
                                          [--configuration published|tuned] [--scenario S]
                                          [--through offline|ros] [--save RUN.npz]
                                          [--out runs/campaigns]

FILE defaults to the default campaign of ``make campaign`` (ato_campaigns/campaigns/default.yaml;
``--campaign FILE`` is the same as FILE). The campaign file, the engine and the rows:
ato_campaigns.engine; the report (markdown, plots and its statistics as CSV and JSON in
``<out>/<name>/``): ato_campaigns.report; how to run one on a cluster: docs/guide/campaigns.md.

With ``--draw`` and ``--law`` the command makes one row of the campaign again, offline, in this
process, as the campaign made it (ato_campaigns.engine.rerun), prints it (and whether it equals
the row stored in ``<out>``), and with ``--save`` writes the run's arrays (numpy .npz). The row
is named by its label (``--law pid/tuned``) or by its entry and configuration (``--law pid
--configuration tuned``). ``--through ros`` makes it again through the ROS graph too (the
plant, profile and controller nodes in lockstep, the plant given the draw's truth and the
controller its knowledge part) and prints each metric of the two beside the stored one, with
whether they agree: ``ato_bringup.graph_row``, which this command runs in a process of its own
with the same arguments (this module is pure: it imports no rclpy).

Without ``--draw``, ``--through ros`` makes every row of the campaign through the ROS graph and
offline, writes the graph's rows and their report to ``<out>/<name>-ros/`` and prints per row
whether the two agree: ``python -m ato_bringup.graph_campaign FILE [--workers N] [--out DIR]``,
run in a process of its own (``--workers``: rows at once, default 1 there).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ato_campaigns.engine import (
    DEFAULT_OUT,
    METRICS,
    load_campaign,
    read_rows,
    rerun,
    rows_folder,
    run_campaign,
)
from ato_campaigns.margins import campaign_margins
from ato_campaigns.provenance import results_page_provenance
from ato_campaigns.report import write_report
from ato_common.validation import ConfigError
from ato_controller_node.gains import GAINS

#: the default campaign of `make campaign`, shipped beside this module
DEFAULT_CAMPAIGN = Path(__file__).resolve().with_name('campaigns') / 'default.yaml'
DEFAULT_RESULTS_PAGE = Path('docs/results/campaign.md')


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('file', nargs='?', type=Path, default=None,
                        help=f'the campaign file (default: {DEFAULT_CAMPAIGN.name}, the '
                        'default campaign of make campaign)')
    parser.add_argument('--campaign', type=Path, default=None, help='the campaign file (as FILE)')
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT)
    parser.add_argument('--scheduler', default=None,
                        help='address of a running Dask scheduler (tcp://HOST:8786); default: '
                        "Dask's scheduler-address configuration, else a LocalCluster")
    parser.add_argument('--workers', type=int, default=None,
                        help='workers of the LocalCluster (default: one per core); with '
                        '--through ros, rows run at once through the graph (default 1)')
    parser.add_argument('--serial', action='store_true', help='run in this process, in order')
    parser.add_argument('--results-page', type=Path, default=None,
                        help='also write the report, with date, machine and commit, to this '
                        'results page of the docs (make campaign: docs/results/campaign.md)')
    parser.add_argument('--readme', type=Path, default=None,
                        help='also write the summary between the campaign markers of this '
                        'README (make campaign: README.md)')
    rerunning = parser.add_argument_group('one row again')
    rerunning.add_argument('--draw', type=int, default=None, help='the draw index of the row')
    rerunning.add_argument('--law', default=None,
                           help="the row's label (pid/tuned), or its entry's (pid) with "
                           '--configuration')
    rerunning.add_argument('--configuration', default=None, choices=GAINS,
                           help="the row's configuration of the gains (with --law ENTRY)")
    rerunning.add_argument('--scenario', default=None,
                           help='the scenario of the row (a campaign of several scenarios)')
    rerunning.add_argument('--through', default='offline', choices=('offline', 'ros'),
                           help='offline (default): the offline loop, in this process; ros: '
                           'also through the ROS graph in lockstep, each metric beside the '
                           'offline one (ato_bringup.graph_row); without --draw, every row of '
                           'the campaign (ato_bringup.graph_campaign)')
    rerunning.add_argument('--save', type=Path, default=None, metavar='RUN.npz',
                           help="also write the run's arrays to this file (numpy .npz)")
    args = parser.parse_args(argv)
    if args.file is not None and args.campaign is not None:
        parser.error('give the campaign file once: FILE or --campaign FILE')
    args.campaign = args.campaign or args.file or DEFAULT_CAMPAIGN
    if (args.draw is None) != (args.law is None):
        parser.error('--draw and --law go together: the row to make again')
    if args.draw is None and (args.save is not None or args.scenario is not None
                              or args.configuration is not None):
        parser.error('--save, --scenario and --configuration are for one row again: give '
                     '--draw and --law')
    if args.draw is None and args.through == 'ros' and (
            args.serial or args.scheduler is not None or args.results_page is not None
            or args.readme is not None):
        parser.error('--serial, --scheduler, --results-page and --readme are for the offline '
                     'campaign; --through ros runs --workers rows at once on this machine')
    if args.through == 'ros' and args.save is not None:
        parser.error('--save writes the offline run\'s arrays; --through ros records the '
                     'graph run (its folder is printed): give one of them')
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    path = args.campaign
    if path.resolve().is_relative_to(Path.cwd()):
        path = path.resolve().relative_to(Path.cwd())  # as the report names it
    try:
        campaign = load_campaign(path)
        if args.through == 'ros':
            return through_graph(argv, args)
        if args.draw is not None:
            return rerun_row(campaign, args)
        return run_all(campaign, args, argv)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2


def run_all(campaign, args: argparse.Namespace, argv: list[str]) -> int:
    """The campaign, what is missing of it, and its report."""
    measured = (results_page_provenance(args.results_page)
                if args.results_page is not None else None)
    started = time.monotonic()
    print(f'{campaign.name}: {len(campaign.tasks())} runs ({len(campaign.scenarios)} '
          f'scenarios x {len(campaign.laws) // len(campaign.configurations)} laws x '
          f'{len(campaign.configurations)} configurations x {campaign.draws} draws), rows in '
          f'{rows_folder(args.out, campaign.name)}', file=sys.stderr)
    try:
        rows = run_campaign(campaign, args.out, serial=args.serial, scheduler=args.scheduler,
                            workers=args.workers)
    except KeyboardInterrupt:
        print('interrupted: the finished rows are kept; run the same command again to run '
              'only the missing ones', file=sys.stderr)
        return 130
    elapsed = time.monotonic() - started
    command = ('make campaign' if argv in ([], ['--results-page', str(DEFAULT_RESULTS_PAGE),
                                                '--readme', 'README.md'])
               else ' '.join(['python -m ato_campaigns.campaign', *argv]))
    report = write_report(campaign, rows, args.out / campaign.name, command, elapsed,
                          args.results_page, measured, args.readme,
                          law_columns=campaign_margins(campaign))
    print(f'wrote {report}')
    return 0


def rerun_row(campaign, args: argparse.Namespace) -> int:
    """One row again: print it, say whether it equals the stored one, save the arrays."""
    row, run = rerun(campaign, args.law, args.draw, args.scenario, args.configuration)
    shown = {k: row[k] for k in ('scenario', 'law', 'configuration', 'envelope', 'draw',
                                 'status', 'reason', 'events')}
    shown.update({k: row[k] for k in METRICS if k in row})
    shown['drawn'] = {k[2:]: v for k, v in row.items() if k.startswith('p_')}
    print(json.dumps({k: None if isinstance(v, float) and math.isnan(v) else v
                      for k, v in shown.items()}, indent=1, default=str))
    stored = stored_row(campaign, args.out, row)
    if stored is not None:
        print(same_as_stored(row, stored), file=sys.stderr)
    if args.save is not None:
        save_run(run, args.save)
        print(f"wrote the run's arrays to {args.save}", file=sys.stderr)
    return 0


def through_graph(argv: list[str], args: argparse.Namespace) -> int:
    """``--through ros``: the row (``--draw``) or the whole campaign through the ROS graph, in
    a process of its own (``python -m ato_bringup.graph_row`` with the same arguments, or
    ``python -m ato_bringup.graph_campaign``): its exit code."""
    if args.draw is not None:
        return subprocess.call([sys.executable, '-m', 'ato_bringup.graph_row', *argv])
    command = [sys.executable, '-m', 'ato_bringup.graph_campaign', str(args.campaign),
               '--out', str(args.out)]
    if args.workers is not None:
        command += ['--workers', str(args.workers)]
    return subprocess.call(command)


def stored_row(campaign, out: Path, row: dict) -> dict | None:
    """The row of ``<out>`` with the scenario, law and draw of ``row`` (the same campaign's
    fingerprint), or None."""
    stored = read_rows(rows_folder(out, campaign.name), campaign.fingerprint)
    if stored.empty:
        return None
    mine = stored[(stored['scenario'] == row['scenario']) & (stored['law'] == row['law'])
                  & (stored['draw'] == row['draw'])]
    return None if mine.empty else mine.iloc[0].to_dict()


def same_as_stored(row: dict, stored: dict) -> str:
    """Whether a row made again equals the stored one in its status and metrics."""
    differ = [k for k in ('status', *METRICS) if k in row and k in stored and not (
        row[k] == stored[k] or (isinstance(row[k], float) and isinstance(stored[k], float)
                                and math.isnan(row[k]) and math.isnan(stored[k])))]
    if not differ:
        return 'the same status and metrics as the stored row'
    return 'differs from the stored row in ' + ', '.join(
        f'{k} ({stored[k]} stored, {row[k]} now)' for k in differ)


def save_run(run, path: Path) -> Path:
    """An OfflineRun's arrays as a numpy .npz file: the lead car's and every car's truth, the
    applied forces, the references, the saturated steps, the ATP's interventions and each
    estimate a law reported (``estimate_<name>``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = sorted({k for e in run.estimates for k in e})
    np.savez_compressed(
        path, times_s=run.times_s, positions_m=run.positions, speeds_mps=run.speeds,
        forces_n=run.forces, ref_positions_m=run.ref_positions, ref_speeds_mps=run.ref_speeds,
        ref_accelerations_mps2=run.ref_accelerations, car_positions_m=run.car_positions,
        car_speeds_mps=run.car_speeds, actuator_forces_n=run.actuator_forces,
        saturated=run.saturated, atp_times_s=np.array(run.atp_times_s),
        laws=np.array(run.laws), **{f'estimate_{k}': run.estimate(k) for k in keys})
    return path


if __name__ == '__main__':
    raise SystemExit(main())
