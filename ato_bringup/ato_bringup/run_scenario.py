"""run_scenario: the full stack as separate processes on one scenario, to its end, in lockstep
simulated time; then every process is stopped and the run's summary printed.

    ros2 run ato_bringup run_scenario --scenario short_line --controller luo_xu
    ros2 run ato_bringup run_scenario --composed      # the three loop nodes in one process

``--composed`` runs the plant, the profile and the controller in one process on one executor
(``ato_stack``, ato_bringup.composed) instead of three: the same nodes, topics and results (bit
for bit in lockstep), faster. The run's monitor takes the true state and the reference the
profile streamed in batches, not per message, and the diagnostics (ato_bringup.stack.LEAN), so
the summary measures the tracking against the curve the train was given, replanned or not.

Without --controller the law is the PID baseline (``DEFAULT_CONTROLLER``): a run does not depend
on what an earlier comparison left on this machine.

The summary ends with what went wrong (ato_common.run_events): ATP interventions, watchdog
brakes, missed journey windows and stopping errors beyond the platform tolerance, each with its
count and first occurrence. Exit code: 0 for a clean run (or any completed run with
--no-fail-on-events), 3 for a completed run with such events, 1 for a failed run, 2 for bad
input.

Runs side by side: by default each run takes a DDS domain that no other run or test session on
this machine holds (a lock file per domain, ato_common.domains) and a run folder of its own, so
two runs started in the same second neither hear each other nor share a recording. Any process
of the run that exits before the plant's end (a node that fails, a recorder that stops) ends the
run at once, naming it with its exit code and the end of its log.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from datetime import datetime
from pathlib import Path

from ato_bringup.runner import RunFailed, run_lockstep
from ato_bringup.stack import RUN_DIAGNOSTICS_PERIOD_S, StackConfig
from ato_common.domains import NoFreeDomain, free_domain
from ato_common.metrics import format_summary
from ato_common.run_events import PLATFORM_TOLERANCE_M, final_exit_code
from ato_common.scenario import DEFAULT_SCENARIO, builtin_scenarios
from ato_common.validation import ConfigError
from ato_controller_node.laws import LAWS
from recorder.bag import BagError
from recorder.report import build_report, write_report


def positive_seconds(text: str) -> float:
    """A period in seconds, finite and from 0.01 s to an hour (the nodes' own bounds)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number of seconds') from None
    if not 0.01 <= value <= 3600.0:
        raise argparse.ArgumentTypeError(f'{text!r}: must be from 0.01 to 3600 s')
    return value


#: the law of a run that names none: the PID baseline
DEFAULT_CONTROLLER = 'pid'


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenario', default=DEFAULT_SCENARIO,
                        help=f"built-in ({', '.join(builtin_scenarios())}) or a YAML file")
    parser.add_argument('--controller', default=DEFAULT_CONTROLLER, choices=sorted(LAWS),
                        help='the law (default: %(default)s, the baseline)')
    parser.add_argument('--domain-id', type=int, default=None,
                        help='ROS_DOMAIN_ID of the run (default: a free one, that no other run '
                             'or test session on this machine holds; printed at the start)')
    parser.add_argument('--timeout', type=float, default=900.0, help='wall-time limit, s')
    parser.add_argument('--log-dir', type=Path, default=None,
                        help='where each node writes its log and the recording goes '
                             '(default: runs/<time>-<scenario>-<controller>)')
    parser.add_argument('--diagnostics-period', type=positive_seconds,
                        default=RUN_DIAGNOSTICS_PERIOD_S, metavar='S',
                        help='period of the plant\'s and the controller\'s periodic diagnostics, '
                             's of simulated time (safety reactions and law switches are '
                             'reported at once); default %(default)g')
    parser.add_argument('--composed', action='store_true',
                        help='the plant, the profile and the controller in one process on one '
                             'executor (ato_stack) instead of three processes')
    parser.add_argument('--no-record', action='store_true',
                        help='do not record the run (by default: <log-dir>/bag, with a report)')
    parser.add_argument('--no-fail-on-events', action='store_true',
                        help='exit with 0 even if the run had ATP interventions, watchdog brakes, '
                             'missed journey windows or stopping errors beyond the tolerance '
                             '(by default such a run exits with 3)')
    parser.add_argument('--stop-tolerance', type=float, default=PLATFORM_TOLERANCE_M,
                        metavar='M', help='the platform tolerance of a stopping error, m '
                                          f'(default {PLATFORM_TOLERANCE_M:g})')
    args = parser.parse_args(argv)
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        parser.error(f'--domain-id: must be 0..232 (Fast DDS derives its ports from it), got '
                     f'{args.domain_id}')
    if not args.stop_tolerance >= 0.0 or args.stop_tolerance == float('inf'):
        parser.error(f'--stop-tolerance: must be a finite number >= 0 m, got '
                     f'{args.stop_tolerance}')
    return args


def unique_run_dir(parent: Path, name: str) -> Path:
    """``parent/name``, or ``parent/name-2``, ``-3``... : a folder this call created, so two runs
    started in the same second never share one (mkdir is atomic)."""
    parent.mkdir(parents=True, exist_ok=True)
    for index in range(1, 1000):
        candidate = parent / (name if index == 1 else f'{name}-{index}')
        try:
            candidate.mkdir()
            return candidate
        except FileExistsError:
            continue
    raise FileExistsError(f'{parent / name} and 998 numbered folders beside it exist')


def main(argv=None) -> int:
    args = parse_args(argv)
    with contextlib.ExitStack() as held:
        if args.domain_id is None:
            try:
                args.domain_id = held.enter_context(free_domain())
            except NoFreeDomain as error:
                print(f'error: {error}', file=sys.stderr)
                return 1
        return run(args)


def run(args: argparse.Namespace) -> int:
    stamp = datetime.now().strftime('%Y%m%d-%H%M%S')
    scenario_label = Path(args.scenario).stem
    log_dir = args.log_dir or unique_run_dir(Path('runs'),
                                             f'{stamp}-{scenario_label}-{args.controller}')
    record_to = None if args.no_record else log_dir / 'bag'
    config = StackConfig(scenario=args.scenario, controller=args.controller,
                         domain_id=args.domain_id, log_dir=log_dir, record_to=record_to,
                         composed=args.composed, monitor='lean',
                         diagnostics_period_s=args.diagnostics_period)
    print(f'running {args.scenario} with {args.controller} in lockstep'
          f"{', composed in one process' if args.composed else ''} "
          f'(ROS_DOMAIN_ID={args.domain_id}, node logs in {log_dir})', file=sys.stderr)
    try:
        outcome = run_lockstep(config, timeout_s=args.timeout, progress=True,
                               stop_tolerance_m=args.stop_tolerance)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except (RunFailed, FileNotFoundError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    print(format_summary(outcome.metrics, outcome.scenario.name, ', '.join(outcome.laws),
                         outcome.wall_time_s))
    print(outcome.events.format())
    if record_to is not None:
        try:
            page = write_report(build_report(record_to, scenario=args.scenario),
                                record_to / 'report')
        except BagError as error:
            print(f'error: the recording cannot be read: {error}', file=sys.stderr)
            return 1
        print(f'recording             {record_to} (ros2 run recorder info {record_to})')
        print(f'report                {page}')
    return final_exit_code(outcome.events, not args.no_fail_on_events)


if __name__ == '__main__':
    raise SystemExit(main())
