"""run_scenario: the full stack as separate processes on one scenario, to its end, in lockstep
simulated time (or in real time); then every process is stopped and the run's summary printed.

    ros2 run ato_bringup run_scenario --scenario short_line --controller luo_xu
    ros2 run ato_bringup run_scenario --composed      # the three loop nodes in one process
    ros2 run ato_bringup run_scenario --scenario mao_4car --controller mao_multibody_rigid
    ros2 run ato_bringup run_scenario --controller-command "python3 my_ato_node.py"
    ros2 run ato_bringup run_scenario --real-time --end-time 120

(``ato run ato_bringup run_scenario ...`` where there is no ``ros2``.) The plant's model, the
control rate and the run's end are decided as the launch file decides them
(``ato_bringup.launch_arguments``): the plant of a scenario that describes its train car by car
is the multi-car one (``--model`` names another), a law runs at the scenario's rate or the first
faster one its design accepts, and a law that cannot drive the plant it would be given is
refused with the reason (exit code 2) before anything starts.

``--composed`` runs the plant, the profile and the controller in one process on one executor
(``ato_stack``, ato_bringup.composed) instead of three: the same nodes, topics and results (bit
for bit in lockstep), faster. The run's monitor takes the true state and the reference the
profile streamed in batches, not per message, and the diagnostics (ato_bringup.stack.LEAN), so
the summary measures the tracking against the curve the train was given, replanned or not.

A campaign's draw through the graph: ``--draw-values JSON`` gives the plant the truth of one draw
(a JSON object of uncertain parameters, ``train_plant_node.draw_values``; only the plant reads
it), ``--gradient hidden`` tells the controller a flat line (the knowledge part of a draw),
``--gains`` and ``--no-envelope`` set the controller's configuration and envelope (what
``python -m ato_campaigns.campaign --campaign FILE --draw N --law L --through ros`` gives them
for one row)::

    ros2 run ato_bringup run_scenario --draw-values '{"mass_factor": 1.1, "wind_mps": 4}'

``--controller-command CMD`` runs an ATO node of your own instead of the suite's controller (the
contract it must honour: docs/guide/external-ato.md), started as ``CMD --ros-args -p
scenario:=<scenario>``. ``--real-time`` runs the stack on the wall clock (the run lasts as long
as the scenario); its summary measures the tracking against the planned curve at each state's
run time.

Without --controller the law is the PID baseline (``DEFAULT_CONTROLLER``): a run does not depend
on what an earlier comparison left on this machine.

The summary ends with what went wrong (ato_common.run_events): ATP interventions, watchdog
brakes, missed journey windows and stopping errors beyond the platform tolerance, each with its
count and first occurrence. Exit code: 0 for a clean run (or any completed run with
--no-fail-on-events), 3 for a completed run with such events, 1 for a failed run, 2 for bad
input, 130 for a run stopped by Ctrl-C (143: SIGTERM), which ends every process and prints no
summary.

Runs side by side: by default each run takes a DDS domain that no other run or test session on
this machine holds (a lock file per domain, ato_common.domains) and a run folder of its own, so
two runs started in the same second neither hear each other nor share a recording. Any process
of the run that exits before the plant's end (a node that fails, a recorder that stops, the
plant killed) ends the run at once, naming it with its exit code (and the signal that killed
it), the simulated time reached and the end of its log; in both modes.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from datetime import datetime
from pathlib import Path

from ato_ros.interrupts import quiet_until_running


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
#: wall time a real-time run may take beyond its simulated length, s
REAL_TIME_MARGIN_S = 300.0


def parse_args(argv=None) -> argparse.Namespace:
    from ato_bringup.launch_arguments import AUTO_MODEL, SCENARIO_END
    from ato_bringup.stack import RUN_DIAGNOSTICS_PERIOD_S, STEP_WAITED
    from ato_common.run_events import PLATFORM_TOLERANCE_M
    from ato_common.scenario import DEFAULT_SCENARIO, builtin_scenarios
    from ato_controller_node.gains import GAINS
    from ato_controller_node.laws import LAWS
    from train_plant_node.models import MODELS
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenario', default=DEFAULT_SCENARIO,
                        help=f"built-in ({', '.join(builtin_scenarios())}) or a YAML file")
    parser.add_argument('--controller', default=DEFAULT_CONTROLLER, choices=sorted(LAWS),
                        help='the law (default: %(default)s, the baseline)')
    parser.add_argument('--controller-command', default='', metavar='CMD',
                        help='run this ATO node of yours instead of the suite\'s controller '
                             '(a command line; the contract\'s parameters are appended: '
                             '--ros-args -p scenario:=<scenario> -p gradient_known:=true)')
    parser.add_argument('--model', default=AUTO_MODEL, choices=(AUTO_MODEL, *sorted(MODELS)),
                        help="the plant model (default %(default)s: the scenario's, multi_car "
                             'for a train described car by car)')
    parser.add_argument('--draw-values', default='', metavar='JSON',
                        help="the plant's truth of one draw of a campaign's uncertainty: a JSON "
                             'object of uncertain parameters, e.g. \'{"mass_factor": 1.1}\' '
                             '(ato_common.uncertainty; one left out is nominal; default: the '
                             'nominal plant)')
    parser.add_argument('--gradient', default='known', choices=('known', 'hidden'),
                        help="what the controller is told of the line's grades (hidden: a flat "
                             'line; the plant keeps the grades); default %(default)s')
    parser.add_argument('--gains', default=GAINS[0], choices=GAINS,
                        help="the laws' configuration (default %(default)s)")
    parser.add_argument('--no-envelope', action='store_true',
                        help="the controller host's ATO envelope off (for every law)")
    parser.add_argument('--real-time', action='store_true',
                        help='run on the wall clock instead of in lockstep simulated time')
    parser.add_argument('--end-time', default=SCENARIO_END, metavar='S',
                        help="simulated time at which the run ends, s (default: the scenario's "
                             'end, the end of its target curve plus its settle time)')
    parser.add_argument('--domain-id', type=int, default=None,
                        help='ROS_DOMAIN_ID of the run (default: a free one, that no other run '
                             'or test session on this machine holds; printed at the start)')
    parser.add_argument('--timeout', type=float, default=None,
                        help='wall-time limit, s (default 900 in lockstep; in real time the '
                             f'run\'s length plus {REAL_TIME_MARGIN_S:g})')
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
    parser.add_argument('--watched-by', type=watched_keys, default=(), metavar='KEYS',
                        help='the topics another process (a live view) already reads before the '
                             f'run starts, comma-separated, of {",".join(STEP_WAITED)}: each '
                             'node waits for those readers as well, or the run monitor could '
                             'miss the first steps (docs/guide/recording.md)')
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
    if args.composed and args.controller_command:
        parser.error('--composed runs the suite\'s controller in the one process: it does not '
                     'take --controller-command')
    return args


def watched_keys(text: str) -> tuple[str, ...]:
    """``--watched-by``: comma-separated keys of the topics whose readers the loop waits for
    (``ato_bringup.stack.STEP_WAITED``), each at most once."""
    from ato_bringup.stack import STEP_WAITED
    keys = tuple(key.strip() for key in text.split(',') if key.strip())
    unknown = [key for key in keys if key not in STEP_WAITED]
    if unknown:
        raise argparse.ArgumentTypeError(f'{", ".join(unknown)}: not a topic the loop waits '
                                         f'for readers of (one of {", ".join(STEP_WAITED)})')
    if len(set(keys)) != len(keys):
        raise argparse.ArgumentTypeError(f'{text}: a topic named twice')
    return keys


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


class Stopped(Exception):
    """The run was told to stop (Ctrl-C: SIGINT, or SIGTERM)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.code = 128 + signum


def _raise_stopped(signum, frame) -> None:
    # once: the stack's own teardown must not be interrupted by a second Ctrl-C
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Stopped(signum)


def main(argv=None) -> int:
    quiet_until_running(say=False)  # a Ctrl-C while importing: exit at once, no traceback
    args = parse_args(argv)
    from ato_common.domains import NoFreeDomain, free_domain
    signal.signal(signal.SIGINT, _raise_stopped)
    signal.signal(signal.SIGTERM, _raise_stopped)
    try:
        with contextlib.ExitStack() as held:
            if args.domain_id is None:
                try:
                    args.domain_id = held.enter_context(free_domain())
                except NoFreeDomain as error:
                    print(f'error: {error}', file=sys.stderr)
                    return 1
            return run(args)
    except Stopped as stopped:
        print(f'stopped ({stopped}): every process of the run has ended; no summary',
              file=sys.stderr)
        return stopped.code


def configure(args: argparse.Namespace):
    """The run's StackConfig, with the launch file's decisions (model, rate, end); LaunchRefused
    for arguments that cannot make a run."""
    from ato_bringup.launch_arguments import resolve
    from ato_bringup.stack import StackConfig
    launch = resolve({'scenario': args.scenario, 'controller': args.controller,
                      'model': args.model, 'end_time_s': str(args.end_time),
                      'lockstep': 'false' if args.real_time else 'true',
                      'draw_values': args.draw_values, 'gains': args.gains,
                      'gradient_known': 'true' if args.gradient == 'known' else 'false',
                      'envelope': 'false' if args.no_envelope else 'true'},
                     external=bool(args.controller_command))
    stamp = datetime.now().strftime('%Y%m%d-%H%M%S')
    law = 'external' if args.controller_command else args.controller
    log_dir = args.log_dir or unique_run_dir(Path('runs'),
                                             f'{stamp}-{Path(args.scenario).stem}-{law}')
    config = StackConfig(scenario=args.scenario, controller=args.controller,
                         lockstep=launch.lockstep, end_time_s=launch.end_time_s,
                         model=launch.model, domain_id=args.domain_id, log_dir=log_dir,
                         record_to=None if args.no_record else log_dir / 'bag',
                         composed=args.composed, monitor='lean',
                         diagnostics_period_s=args.diagnostics_period,
                         watched_by=args.watched_by,
                         plant_params={'control_rate_hz': launch.rate_hz,
                                       'draw_values': launch.draw_values},
                         controller_params={'rate_hz': launch.rate_hz, 'gains': launch.gains,
                                            'envelope': launch.envelope,
                                            'gradient_known': launch.gradient_known},
                         controller_command=args.controller_command)
    return config, launch


def run(args: argparse.Namespace) -> int:
    from ato_bringup.launch_arguments import LaunchRefused
    from ato_bringup.runner import RunFailed, run_lockstep
    from ato_common.commands import ros_command
    from ato_common.metrics import format_summary
    from ato_common.run_events import final_exit_code
    from ato_common.validation import ConfigError
    from recorder.bag import BagError
    from recorder.report import build_report, write_report
    try:
        config, launch = configure(args)
    except LaunchRefused as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    law = f'your ATO node ({args.controller_command})' if args.controller_command \
        else args.controller
    print(f'running {args.scenario} with {law} '
          f"{'in lockstep' if launch.lockstep else 'in real time'}, plant {launch.model}"
          f"{', composed in one process' if args.composed else ''} "
          f'(ROS_DOMAIN_ID={args.domain_id}, node logs in {config.log_dir})', file=sys.stderr)
    for note in launch.notes:
        print(f'  {note}', file=sys.stderr)
    timeout = args.timeout or (900.0 if launch.lockstep
                               else launch.end_time_s + REAL_TIME_MARGIN_S)
    try:
        outcome = run_lockstep(config, timeout_s=timeout, progress=True,
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
    if config.record_to is not None:
        record_to = config.record_to
        try:
            page = write_report(build_report(record_to, scenario=args.scenario),
                                record_to / 'report')
        except BagError as error:
            print(f'error: the recording cannot be read: {error}', file=sys.stderr)
            return 1
        print(f'recording             {record_to} '
              f'({ros_command(f"run recorder info {record_to}")})')
        print(f'report                {page}')
    return final_exit_code(outcome.events, not args.no_fail_on_events)


if __name__ == '__main__':
    raise SystemExit(main())
