"""campaign: every law of a campaign file on many draws of the uncertain train, on Dask.

    python -m ato_campaigns.campaign [FILE] [--scheduler tcp://HOST:8786] [--workers N]
                                          [--serial] [--out runs/campaigns]
                                          [--results-page PAGE]

FILE defaults to the default campaign of ``make campaign`` (ato_bringup/campaigns/default.yaml).
The campaign file, the engine and the rows: ato_campaigns.engine; the report (markdown
and plots in ``<out>/<name>/``): ato_campaigns.report; how to run one on a cluster:
docs/guide/campaigns.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ato_campaigns.engine import DEFAULT_OUT, load_campaign, rows_folder, run_campaign
from ato_campaigns.provenance import results_page_provenance
from ato_campaigns.report import write_report
from ato_common.validation import ConfigError

#: the default campaign of `make campaign`, shipped beside this module
DEFAULT_CAMPAIGN = Path(__file__).resolve().with_name('campaigns') / 'default.yaml'
DEFAULT_RESULTS_PAGE = Path('docs/results/campaign.md')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('campaign', nargs='?', type=Path, default=DEFAULT_CAMPAIGN,
                        help=f'the campaign file (default: {DEFAULT_CAMPAIGN.name}, the '
                        'default campaign of make campaign)')
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT)
    parser.add_argument('--scheduler', default=None,
                        help='address of a running Dask scheduler (tcp://HOST:8786); default: '
                        "Dask's scheduler-address configuration, else a LocalCluster")
    parser.add_argument('--workers', type=int, default=None,
                        help='workers of the LocalCluster (default: one per core)')
    parser.add_argument('--serial', action='store_true', help='run in this process, in order')
    parser.add_argument('--results-page', type=Path, default=None,
                        help='also write the report, with date, machine and commit, to this '
                        'results page of the docs (make campaign: docs/results/campaign.md)')
    parser.add_argument('--readme', type=Path, default=None,
                        help='also write the summary between the campaign markers of this '
                        'README (make campaign: README.md)')
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    path = args.campaign
    if path.resolve().is_relative_to(Path.cwd()):
        path = path.resolve().relative_to(Path.cwd())  # as the report names it
    try:
        campaign = load_campaign(path)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    measured = (results_page_provenance(args.results_page)
                if args.results_page is not None else None)
    started = time.monotonic()
    print(f'{campaign.name}: {len(campaign.tasks())} runs ({len(campaign.scenarios)} '
          f'scenarios x {len(campaign.laws)} laws x {campaign.draws} draws), rows in '
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
                          args.results_page, measured, args.readme)
    print(f'wrote {report}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
