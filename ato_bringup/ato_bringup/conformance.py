"""conformance: check an ATO node of your own against the suite's contract, case by case.

    ato conformance --controller-command "python3 examples/external_ato/p_ato_node.py"
    ros2 run ato_bringup conformance --controller-command "ros2 run my_pkg my_ato" --json r.json

Starts the plant and the profile (the plant holds the ATP supervision) in lockstep with your node
started as ``CMD --ros-args -p scenario:=<scenario> -p gradient_known:=true``
(``ato_common.contract``: the contract, docs/reference/ato-contract.md), and checks each case of
``ato_common.contract.CASES``: it answers every step, stamps and lays out its commands right, one
per step at the control rate, refuses a plant of another scenario, survives a restarted plant,
stops when told, publishes nothing after shutdown, follows a replanned reference and behaves under
a failed speed sensor. Each case is printed PASS, FAIL or NOT RUN (the harness could not bring the
situation about) with its evidence (``ato_bringup.conformance_cases``). Exit code: 0 if every case
passed, 1 otherwise, 2 for bad input; the nodes' logs are kept in ``--log-dir``.

The main run drives a variant of ``--scenario`` (default short_line) made for the test, written
beside the logs (``variant.yaml``; its name is the scenario's): a total traction loss at the
start (the train stands while its reference leaves, and the profile plans the leg again from
where it stands), then a failed speed sensor, over at most 200 s of simulated time; then a new
plant for 20 s. Your node must be able to drive the scenario's train. The plant starts once the
harness is matched to your node's ato/command publisher (what a node sends before that never
reaches the harness), or after ``MATCH_S`` of wall time without it, saying so.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from datetime import datetime
from importlib import resources
from pathlib import Path

import yaml
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from ato_bringup.conformance_cases import (
    HORIZON_S,
    RESTART_S,
    STOP_LIMIT_S,
    STOP_WALL_FACTOR,
    Epoch,
    Observation,
    Schedule,
    Sent,
    judge,
    report,
    variant_document,
)
from ato_bringup.stack import Stack, StackConfig
from ato_common.contract import CONTRACT_VERSION
from ato_common.domains import NoFreeDomain, free_domain
from ato_common.knowledge import knowledge_of
from ato_common.scenario import builtin_scenarios, load_scenario
from ato_common.types import NS_PER_S
from ato_common.validation import ConfigError
from ato_ros import wire
from ato_ros.messages import qos_profile, topic
from ato_ros.stall import StallWatch, wait_for_exit
from ato_simulation.plans import cached_plan, run_end_time_s

#: wall time a run may stand still (no new step) before the harness calls it stalled, s
STALL_S = 30.0
#: how long a node given another scenario's plant is watched, s of wall time
OTHER_WATCH_S = 10.0
#: how long the main run waits for the harness to hear the node's commands, s of wall time
MATCH_S = 60.0


class Observer:
    """The harness's subscriptions on the stack's node: every measured state (its stamp), the
    truth and the streamed reference per stamp, every command, the diagnostics; into the
    current :class:`Epoch`."""

    def __init__(self, node):
        self.epoch = Epoch()
        self.stopping = False
        self.after_stop: list[Sent] = []
        self.subscriptions = {
            key: node.create_subscription(msg_type, topic(key).name, callback,
                                          qos_profile(topic(key).qos), raw=raw)
            for key, msg_type, callback, raw in (
                ('state_measured', JointTrajectory, self.on_measured, True),
                ('state', JointTrajectory, self.on_truth, True),
                ('reference', JointTrajectory, self.on_reference, True),
                ('command', JointState, self.on_command, True),
                ('diagnostics', DiagnosticArray, self.on_diagnostics, False))}

    def hears_commands(self) -> bool:
        """Whether a publisher of ato/command (the node's) is matched to the harness: what a
        publisher sends before it is matched never reaches the harness (volatile), so the run
        must not start before (the plant matches it on its own, and would be answered)."""
        return self.subscriptions['command'].get_publisher_count() > 0

    def on_measured(self, data: bytes) -> None:
        stamp = wire.stamp_of(data)
        if stamp is not None and not self.stopping:  # the steps of the runs, not after
            self.epoch.states[stamp] = self.epoch.states.get(stamp, 0) + 1

    def on_truth(self, data: bytes) -> None:
        state = wire.decode_state(data)
        self.epoch.truth[state.stamp_ns] = (state.positions[0], state.speeds[0])

    def on_reference(self, data: bytes) -> None:
        reference = wire.decode_reference(data)
        self.epoch.reference[reference.stamp_ns] = (reference.now.position, reference.now.speed)

    def on_command(self, data: bytes) -> None:
        stamp, frame_id, names, _, _, effort = wire.decode_joint_state(data)
        sent = Sent(stamp, frame_id, tuple(names), tuple(effort), time.monotonic())
        (self.after_stop if self.stopping else self.epoch.commands).append(sent)

    def on_diagnostics(self, msg) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name.endswith('train_plant_node: simulation'):
                self.epoch.plant.update(values)
            elif status.name.endswith('profile_node: plan'):
                stamp = msg.header.stamp.sec * NS_PER_S + msg.header.stamp.nanosec
                self.epoch.plans.append((stamp, status.message))

    def newest_step_ns(self) -> int:
        return max(self.epoch.states, default=-1)


def run_epoch(stack, observer: Observer, end_s: float) -> None:
    """Spin until the plant has ended by itself at ``end_s``; what stopped it otherwise goes
    into the epoch's ``stalled``."""
    epoch = observer.epoch
    epoch.end_s = end_s
    newest, since = -1, time.monotonic()
    while stack.processes['plant'].poll() is None:
        stack.executor.spin_once(timeout_sec=0.05)
        step = observer.newest_step_ns()
        if step != newest:
            newest, since = step, time.monotonic()
        elif time.monotonic() - since > STALL_S:
            epoch.stalled = (f'the plant stood at the step of {max(newest, 0) / NS_PER_S:.1f} '
                             f's for {STALL_S:g} s of wall time without its command')
            return
        if stack.processes['controller'].poll() is not None:
            code = stack.processes['controller'].returncode
            epoch.stalled = (f'the node exited with code {code} at simulated '
                             f'{max(newest, 0) / NS_PER_S:.1f} s')
            return
    if stack.processes['plant'].returncode != 0:
        epoch.stalled = f'the plant exited with code {stack.processes["plant"].returncode}'
    stack.spin_for(0.5)  # the last commands in flight


def stop_node(stack, observer: Observer, observation: Observation) -> None:
    """The plant has ended: tell the node to stop, time its exit, keep what it sends after."""
    process = stack.processes['controller']
    if process.poll() is not None:
        return
    stack.spin_for(1.0)  # the answers to the last steps are in
    observer.stopping = True
    observation.stop_sent_s = time.monotonic()
    process.send_signal(signal.SIGINT)
    watch = StallWatch(process.pid)
    with contextlib.suppress(subprocess.TimeoutExpired):  # judged from the times below
        wait_for_exit(process, STOP_LIMIT_S + 1.0, STOP_WALL_FACTOR * STOP_LIMIT_S + 1.0,
                      idle=lambda: stack.spin_for(0.05), watch=watch)
    observation.stop_took_s = time.monotonic() - observation.stop_sent_s
    observation.stop_stalled_s = watch.update()
    observation.stop_exit = process.poll()
    stack.spin_for(0.5)
    observation.after_stop = list(observer.after_stop)


def main_run(args, variant: Path, schedule: Schedule, domain_id: int) -> Observation:
    scenario = load_scenario(str(variant))
    plan = cached_plan(scenario)
    period_ns = round(NS_PER_S / scenario.run.controller_rate_hz)
    config = StackConfig(scenario=str(variant), domain_id=domain_id, monitor='',
                         log_dir=args.log_dir / 'main', end_time_s=schedule.horizon_s,
                         controller_command=args.controller_command,
                         plant_params={'wait_for_subscribers': 1, 'diagnostics_period_s': 1.0,
                                       'wait_for_diagnostics_readers': 1},
                         profile_params={'wait_for_subscribers': 2,
                                         'wait_for_diagnostics_readers': 1})
    with Stack(config) as stack:
        observer = Observer(stack.node)
        stack.start(order=('controller', 'profile'))
        node = stack.processes['controller']
        if not stack.spin_until(lambda: observer.hears_commands() or node.poll() is not None,
                                MATCH_S):
            print(f'conformance: no publisher of {topic("command").name} matched within '
                  f'{MATCH_S:g} s of wall time; the run starts all the same (a node that creates '
                  'it late may lose its first commands to the harness)', file=sys.stderr)
        stack.start_process('plant', stack.node_params()['plant'])
        run_epoch(stack, observer, schedule.horizon_s)
        main = observer.epoch
        observer.epoch = Epoch()
        if not main.stalled:  # a new plant: the node must take it on from its first step
            params = stack.node_params()['plant']
            stack.start_process('plant', {**params, 'end_time_s': RESTART_S})
            run_epoch(stack, observer, RESTART_S)
        observation = Observation(knowledge_of(scenario).actuator_names, period_ns, schedule,
                                  main, observer.epoch)
        stop_node(stack, observer, observation)
    observation.original_positions = {k: plan.trajectory.at(k / NS_PER_S).position
                                      for k in main.truth}
    return observation


def other_run(args, variant: Path, observation: Observation, domain_id: int) -> None:
    """The plant and the profile of another scenario, the node told the variant."""
    own = load_scenario(str(variant)).name
    other = next(name for name in builtin_scenarios() if name != own)
    observation.other_scenario = other
    config = StackConfig(scenario=other, domain_id=domain_id, monitor='', end_time_s=60.0,
                         log_dir=args.log_dir / 'other_scenario',
                         controller_command=args.controller_command,
                         plant_params={'wait_for_subscribers': 1},
                         profile_params={'wait_for_subscribers': 1})
    with Stack(config) as stack:
        observer = Observer(stack.node)
        stack.start(order=('profile', 'plant'))
        if not stack.spin_until(lambda: observer.epoch.states, 120.0):
            observation.other_stalled = 'the plant of the other scenario published no step'
            return
        stack.start_external_controller(scenario=str(variant))
        node = stack.processes['controller']
        stack.spin_until(lambda: node.poll() is not None, OTHER_WATCH_S)
        stack.spin_for(0.5)
        observation.other_commands = len(observer.epoch.commands)
        observation.other_exit = node.poll()


def scenario_document(name_or_path: str) -> dict:
    """A scenario's YAML content (a built-in's or a file's)."""
    if name_or_path in builtin_scenarios():
        text = (resources.files('ato_common') / 'scenarios' / f'{name_or_path}.yaml').read_text()
    else:
        text = Path(name_or_path).read_text()
    return yaml.safe_load(text)


def write_variant(args) -> tuple[Path, Schedule]:
    """The main run's scenario (``variant_document``) beside the logs; ConfigError if it does
    not load."""
    scenario = load_scenario(args.scenario)
    schedule = Schedule(min(HORIZON_S, run_end_time_s(scenario, cached_plan(scenario))))
    variant = args.log_dir / 'variant.yaml'
    variant.write_text(yaml.safe_dump(variant_document(
        scenario_document(args.scenario), scenario.train.actuator_names, schedule),
        sort_keys=False))
    cached_plan(load_scenario(str(variant)))  # it plans (a journey's windows may not)
    return variant, schedule


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='conformance', description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--controller-command', required=True, metavar='CMD',
                        help='your ATO node\'s command line (the contract\'s parameters '
                             'are appended: --ros-args -p scenario:=<scenario> -p '
                             'gradient_known:=true)')
    parser.add_argument('--scenario', default='short_line',
                        help='the scenario whose variant the main run drives (default '
                             '%(default)s)')
    parser.add_argument('--log-dir', type=Path, default=None,
                        help='the nodes\' logs and the variant scenario (default: '
                             'runs/conformance-<time>)')
    parser.add_argument('--domain-id', type=int, default=None,
                        help='ROS_DOMAIN_ID (default: a free one, ato_common.domains)')
    parser.add_argument('--json', type=Path, default=None, metavar='FILE',
                        help='also write the results to FILE as JSON')
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    args.log_dir = args.log_dir or Path('runs') / \
        f'conformance-{datetime.now().strftime("%Y%m%d-%H%M%S")}'
    args.log_dir.mkdir(parents=True, exist_ok=True)
    try:
        variant, schedule = write_variant(args)
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    print(f'conformance to the ATO contract {CONTRACT_VERSION}: {args.controller_command} '
          f'(logs in {args.log_dir})', file=sys.stderr)
    with contextlib.ExitStack() as held:
        domain = args.domain_id
        if domain is None:
            try:
                domain = held.enter_context(free_domain())
            except NoFreeDomain as error:
                print(f'error: {error}', file=sys.stderr)
                return 1
        observation = main_run(args, variant, schedule, domain)
        other_run(args, variant, observation, domain)
    results = judge(observation)
    print(report(results, f'ATO contract {CONTRACT_VERSION}: {args.controller_command} on '
                          f'{args.scenario} (variant {variant}), lockstep'))
    if args.json is not None:
        args.json.write_text(json.dumps({
            'contract': CONTRACT_VERSION, 'command': args.controller_command,
            'scenario': args.scenario,
            'cases': [{**asdict(r), 'title': r.title, 'verdict': r.verdict} for r in results]},
            indent=1))
    return 0 if all(r.passed for r in results) else 1


if __name__ == '__main__':
    raise SystemExit(main())
