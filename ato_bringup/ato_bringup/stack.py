"""Start the suite's executables as separate processes, watch the run over rclpy, stop cleanly.

This is what ``make demo``, ``make bench`` and the integration tests use. The executables are
found the way ``ros2 run`` finds them (``<prefix>/lib/<package>/<executable>`` of the package's
ament prefix), so the tests exercise exactly what a user starts. The loop runs as three
processes (plant, profile, controller) or, composed (``StackConfig.composed``), as one
(``ato_stack``: the three nodes on one executor, ``ato_bringup.composed``).

The run monitor watches either everything the tests look at (``FULL``: the truth, the
reference, the command and the diagnostics, each per step) or only what a run's summary needs
(``LEAN``: the truth and the reference per step, taken in batches rather than per message, and
the diagnostics; the laws are read from the controller's diagnostics), so that watching costs
the loop little.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.clock import Clock as RclpyClock
from rclpy.clock import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from ato_bringup.processes import executable_path
from ato_common.contract import PARAMETERS
from ato_common.conventions import normalised_namespace, stack_remaps, status_in_namespace
from ato_common.scenario import load_scenario
from ato_common.validation import ConfigError
from ato_ros import wire
from ato_ros.lifecycle import make_executor
from ato_ros.messages import (
    MessageError,
    decoded,
    from_time,
    qos_profile,
    reference_from_msg,
    state_from_msg,
    topic,
)
from ato_ros.middleware import with_middleware_defaults
from ato_ros.stall import wait_for_exit
from ato_simulation.applies import plant_model_for

EXECUTABLES = {
    'plant': ('train_plant_node', 'train_plant_node'),
    'profile': ('profile_node', 'profile_node'),
    'controller': ('ato_controller_node', 'ato_controller_node'),
    'recorder': ('recorder', 'recorder'),
    'loop': ('ato_bringup', 'ato_stack'),  # the three loop nodes composed in one process
}
NODE_NAMES = {'plant': 'train_plant_node', 'profile': 'profile_node',
              'controller': 'ato_controller_node'}

FULL = ('state', 'reference', 'command', 'diagnostics')
"""What the monitor watches for the tests: every per-step topic of the loop it reports."""
LEAN = ('state', 'reference', 'diagnostics')
"""What a run's summary needs: the truth and the reference per step, and the diagnostics."""
MONITORS = {'full': (FULL, ()), 'lean': (LEAN, ('state', 'reference'))}
"""Each monitor: what it watches, and which of those it takes in batches (``Monitor.batch``)."""
RUN_DIAGNOSTICS_PERIOD_S = 10.0
"""The periodic diagnostics of the plant and the controller in a ``run_scenario`` run, s of
simulated time: a lockstep runs about a hundred times faster than real time, where 1 s would
be that many reports per node and wall second, each costing the monitor and the plant CPU per
step (``make bench`` measures the loop). What a run's summary and report need of them is
published at once (a safety reaction, a rejected command, a failure, a law switch) and at the
end; the counters are cumulative."""


def ros_args(params: dict[str, object], namespace: str = '') -> list[str]:
    """``--ros-args`` with the parameters and, for a stack in ``namespace``, its remappings
    (the namespace and a ``/clock`` of its own: ``conventions.stack_remaps``)."""
    args = ['--ros-args']
    for name, value in params.items():
        if isinstance(value, bool):
            value = 'true' if value else 'false'
        elif isinstance(value, str):
            value = yaml_text(value)
        args += ['-p', f'{name}:={value}']
    for source, target in stack_remaps(namespace):
        args += ['-r', f'{source}:={target}']
    return args


def yaml_text(text: str) -> str:
    """``text`` as ``-p name:=VALUE`` takes it: rcl reads VALUE as YAML, so text that YAML
    reads as something else (a JSON object such as a plant's ``draw_values``, a list, '') is
    given single-quoted; anything else as it is."""
    try:
        same = yaml.safe_load(text) == text
    except yaml.YAMLError:
        same = False
    return text if same else "'" + text.replace("'", "''") + "'"


@dataclass
class Sample:
    """What the monitor saw at one control instant."""

    positions: tuple[float, ...] = ()
    speeds: tuple[float, ...] = ()
    accelerations: tuple[float, ...] = ()
    forces: tuple[float, ...] = ()
    ref_position: float = float('nan')
    ref_speed: float = float('nan')
    command: tuple[float, ...] = ()
    law: str = ''


#: how many reasons for unread messages the monitor keeps
MAX_REJECTED = 10
#: how often the lean monitor takes what its batched subscriptions hold, s of wall time
BATCH_PERIOD_S = 0.05


@dataclass
class Monitor:
    """Subscriptions of the runner, keyed by stamp: those of ``watch`` (``FULL`` or ``LEAN``).

    ``batch``: the watched per-step topics taken in batches rather than per message: their
    subscriptions sit on a node no executor spins, and every ``BATCH_PERIOD_S`` of wall time
    (and before the samples are read, ``complete_samples``) the monitor takes what they hold, so
    that no message wakes the monitor; a state's arrival time is its reception time from the
    message info. ``last_stamp_ns`` then lags the loop by at most a batch period."""

    node: Node
    namespace: str = '/'  # of the stack: statuses of other stacks' nodes are left out
    watch: tuple[str, ...] = FULL
    batch: tuple[str, ...] = ()
    samples: dict[int, Sample] = field(default_factory=dict)
    diagnostics: list[tuple[int, str, dict[str, str], str]] = field(default_factory=list)
    last_stamp_ns: int = -1  # of the newest state
    arrivals: list[tuple[float, int]] = field(default_factory=list)  # (monotonic s, stamp ns)
    counts: dict[str, int] = field(default_factory=dict)  # messages received per watched topic
    rejected: list[str] = field(default_factory=list)  # why a message was not read (the first)

    def __post_init__(self):
        unknown = set(self.watch) - set(FULL)
        if unknown or 'state' not in self.watch or not set(self.batch) <= set(self.watch) - {
                'diagnostics'}:
            raise ValueError(f'monitor watch {self.watch}, batch {self.batch}: must hold state '
                             f'and only topics of {FULL}, the per-step ones of them in batches')
        self.counts = dict.fromkeys(self.watch, 0)
        n = self.node
        # The per-step topics are taken as bytes and read by ato_ros.wire (the monitor must
        # cost the loop little: no rclpy message objects); the diagnostics as messages.
        callbacks = {'state': (JointTrajectory, self.on_state, True),
                     'reference': (JointTrajectory, self.on_reference, True),
                     'command': (JointState, self.on_command, True),
                     'diagnostics': (DiagnosticArray, self.on_diagnostics, False)}
        self.batched: dict[str, tuple[Any, Callable]] = {}  # (rclpy Subscription, callback)
        self.batch_node = Node(f'{n.get_name()}_batched', namespace=n.get_namespace(),
                               context=n.context, start_parameter_services=False) \
            if self.batch else None
        for key in self.watch:
            msg_type, callback, raw = callbacks[key]
            if key in self.batch:
                sub = self.batch_node.create_subscription(
                    msg_type, topic(key).name, lambda data: None, qos_profile(topic(key).qos),
                    raw=True)
                self.batched[key] = (sub, callback)
            else:
                n.create_subscription(msg_type, topic(key).name, callback,
                                      qos_profile(topic(key).qos), raw=raw)
        if self.batch:
            n.create_timer(BATCH_PERIOD_S, self.take_batched,
                           clock=RclpyClock(clock_type=ClockType.STEADY_TIME))

    def take_batched(self) -> None:
        """Take what the batched subscriptions hold, in their order of reception per topic."""
        now_s, now_ns = time.monotonic(), time.time_ns()
        for sub, callback in self.batched.values():
            with sub.handle:
                while True:
                    taken = sub.handle.take_message(sub.msg_type, True)
                    if taken is None:
                        break
                    received = taken[1].get('received_timestamp')
                    callback(taken[0], now_s - (now_ns - received) * 1e-9 if received else now_s)

    def _sample(self, stamp_ns: int) -> Sample:
        sample = self.samples.get(stamp_ns)
        if sample is None:
            sample = self.samples[stamp_ns] = Sample()
        return sample

    def _read(self, key: str, data: bytes, *read):
        """A message of ``key`` read by ``read`` (``ros.decoded``'s arguments), or None for
        one that breaks the suite's layout (some other publisher on the topic): the monitor
        says so, keeps the reason and goes on."""
        self.counts[key] += 1
        try:
            return decoded(data, *read)
        except MessageError as error:
            if len(self.rejected) < MAX_REJECTED:
                self.rejected.append(f'{topic(key).name}: {error}')
            self.node.get_logger().warning(f'{topic(key).name}: not read: {error}',
                                           throttle_duration_sec=1.0)
            return None

    def on_state(self, data: bytes, arrived_s: float | None = None) -> None:
        state = self._read('state', data, wire.decode_state, JointTrajectory, state_from_msg)
        if state is None:
            return
        self._state(state)
        self.last_stamp_ns = max(self.last_stamp_ns, state.stamp_ns)
        self.arrivals.append((time.monotonic() if arrived_s is None else arrived_s,
                              self.last_stamp_ns))

    def _state(self, state) -> None:
        s = self._sample(state.stamp_ns)
        s.positions, s.speeds = state.positions, state.speeds
        s.accelerations, s.forces = state.accelerations, state.forces

    def on_reference(self, data: bytes, arrived_s: float | None = None) -> None:
        reference = self._read('reference', data, wire.decode_reference, JointTrajectory,
                               reference_from_msg)
        if reference is not None:
            self._reference(reference)

    def _reference(self, reference) -> None:
        s = self._sample(reference.stamp_ns)
        s.ref_position, s.ref_speed = reference.now.position, reference.now.speed

    def on_command(self, data: bytes, arrived_s: float | None = None) -> None:
        read = self._read('command', data, wire.decode_joint_state, JointState,
                          lambda m: (from_time(m.header.stamp), m.header.frame_id, m.name,
                                     m.position, m.velocity, m.effort))
        if read is not None:
            self._command(read)

    def _command(self, read) -> None:
        stamp_ns, law, _, _, _, effort = read
        s = self._sample(stamp_ns)
        s.command, s.law = tuple(effort), law

    def fill_from_recording(self, bag: Path, stamps: set[int]) -> None:
        """The samples at ``stamps`` (steps the monitor missed) from the recording ``bag``, the
        run's complete record (the loop waits for its recorder, not for the monitor): their
        state, reference and, if watched, command."""
        from recorder.bag import read_messages
        readers = {'state': (wire.decode_state, self._state),
                   'reference': (wire.decode_reference, self._reference),
                   'command': (wire.decode_joint_state, self._command)}
        names = {self.node.resolve_topic_name(topic(key).name): readers[key]
                 for key in self.watch if key in readers}
        for message in read_messages(bag, list(names)):
            decode, fill = names[message.topic]
            if message.log_time_ns in stamps:  # logged at its stamp by the run's recorder
                try:
                    fill(decode(message.data))
                except MessageError:
                    continue  # not the loop's: the monitor would not have read it either

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.counts['diagnostics'] += 1
        for status in msg.status:
            name = status_in_namespace(status.name, self.namespace)
            if name is None:
                continue  # another stack's node on the one /diagnostics
            self.diagnostics.append((from_time(msg.header.stamp), name,
                                     {kv.key: kv.value for kv in status.values}, status.message))

    def complete_samples(self) -> list[tuple[int, Sample]]:
        """Samples that have a state, sorted by stamp (what the batches hold taken first)."""
        self.take_batched()
        return sorted((k, s) for k, s in self.samples.items() if s.positions)


#: the topics whose readers the loop's nodes wait for (``StackConfig.watched_by``)
STEP_WAITED = ('state', 'reference', 'command', 'diagnostics')


@dataclass
class StackConfig:
    scenario: str
    controller: str = 'pid'
    lockstep: bool = True
    end_time_s: float = 0.0
    domain_id: int = 0
    log_dir: Path = Path('log/latest')
    plant_params: dict = field(default_factory=dict)
    profile_params: dict = field(default_factory=dict)
    controller_params: dict = field(default_factory=dict)
    record_to: Path | None = None  # bag folder: run the recorder too
    namespace: str = ''  # push the stack into it, with its own /clock ('' : the root)
    composed: bool = False  # the three loop nodes in one process (ato_stack) instead of three
    # what the run monitor watches: 'full' (FULL) or 'lean' (LEAN); '': no monitor (the caller
    # subscribes to what it needs on Stack.node)
    monitor: str = 'full'
    diagnostics_period_s: float = 1.0  # of the plant and the controller, s of simulated time
    # keys of the topics (ato_common.conventions) that another process subscribes to before the
    # run starts (a live view): the loop waits for those readers too. Each node waits for a
    # number of readers, not for names, so an unnamed reader matched first would let the loop
    # start before the monitor is, and the monitor would miss the first steps.
    watched_by: tuple[str, ...] = ()
    # an ATO node of the user's instead of the suite's controller: its command line (shell
    # words), started with the contract's parameters (``--ros-args -p scenario:=<scenario> -p
    # gradient_known:=...``) and the stack's remappings appended (and ATO_SCENARIO in its
    # environment); '' : the suite's controller
    controller_command: str = ''
    # the plant model; '' : the scenario's (``ato_simulation.applies.plant_model_for``: the
    # multi-car plant for a train described car by car); plant_params may name one too
    model: str = ''


def default_model(scenario: str) -> dict[str, str]:
    """``{'model': <the scenario's plant model>}``, or nothing for a scenario that does not
    load (the plant then exits naming what is wrong with it)."""
    try:
        return {'model': plant_model_for(load_scenario(scenario))}
    except ConfigError:
        return {}


class Stack:
    """The three nodes as processes (or composed, as one) plus an in-process monitor node, in
    one DDS domain."""

    def __init__(self, config: StackConfig):
        self.config = config
        self.processes: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}
        self.context = rclpy.Context()
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(config.domain_id), PYTHONUNBUFFERED='1')
        self.env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        # The stack runs on one host: shared memory only, short heartbeats (ato_ros.middleware)
        self.env = with_middleware_defaults(self.env)
        self.namespace = normalised_namespace(config.namespace)
        rclpy.init(context=self.context, domain_id=config.domain_id)
        self.node = Node('ato_run_monitor', namespace=self.namespace, context=self.context)
        if config.monitor and config.monitor not in MONITORS:
            raise ValueError(f'monitor {config.monitor!r}: one of {", ".join(MONITORS)}, or '
                             "'' for none")
        self.monitor = Monitor(self.node, self.namespace, *MONITORS[config.monitor]) \
            if config.monitor else None
        # The process that runs the plant (and so ends the run at end_time_s).
        self.plant_process = 'loop' if config.composed else 'plant'
        self.parameter_clients: dict[str, Any] = {}  # rclpy Clients
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)

    def node_params(self) -> dict[str, dict]:
        c = self.config
        common = {'scenario': c.scenario, 'lockstep': c.lockstep}
        # Nobody publishes into the loop before the observers (the monitor, the recorder) are
        # matched: they must see every step. The monitor subscribes to the topics it watches,
        # the recorder to the step records and /diagnostics (it takes the per-step topics from
        # the step records: ato_ros.step_records). The profile and the controller are driven
        # by the stamps of /clock and of the messages in lockstep: they need no use_sim_time
        # (which would cost each a /clock subscription taking every step).
        recorder = int(c.record_to is not None)
        watch = self.monitor.watch if self.monitor else ()
        # every monitor reads /diagnostics (FULL and LEAN): each node's first status too
        other = {key: int(key in c.watched_by) for key in STEP_WAITED}
        common['wait_for_diagnostics_readers'] = int('diagnostics' in watch) + other['diagnostics']
        common['wait_for_recorders'] = recorder
        model = {'model': c.model} if c.model else default_model(c.scenario)
        return {
            'plant': {**common, 'end_time_s': float(c.end_time_s), **model,
                      'wait_for_subscribers': 1 + other['state'],  # the monitor's truth
                      'diagnostics_period_s': float(c.diagnostics_period_s), **c.plant_params},
            # the controller's and the monitor's reference, watched or batched: none missed
            'profile': {**common, 'wait_for_subscribers': 2 + other['reference'],
                        **c.profile_params},
            'controller': {**common, 'controller': c.controller,
                           'wait_for_subscribers': 1 + ('command' in watch) + other['command'],
                           'diagnostics_period_s': float(c.diagnostics_period_s),
                           **c.controller_params},
            'recorder': {},
        }

    def start(self, order=('controller', 'profile', 'plant')) -> None:
        self.config.log_dir.mkdir(parents=True, exist_ok=True)
        params = self.node_params()
        if self.config.composed:
            self.start_composed(params)
            return
        if self.config.record_to is not None:
            # unstamped topics are logged at simulated time in lockstep: that of the /clock the
            # recorder records (--sim-time: no second subscription to /clock); it runs at the
            # lowest CPU priority (--background), on the CPU the loop leaves: the plant waits for
            # it when it falls behind (recorder_lead_s)
            self.start_process('recorder', params['recorder'],
                               ['-o', str(self.config.record_to), *self.provenance(),
                                *(['--sim-time', '--background'] if self.config.lockstep
                                  else [])])
        for name in order:
            if name == 'controller' and self.config.controller_command:
                self.start_external_controller()
            else:
                self.start_process(name, params[name])

    def start_external_controller(self, scenario: str | None = None) -> subprocess.Popen:
        """The user's ATO node (``StackConfig.controller_command``) as the process
        ``controller``: told the scenario (default the stack's) as the suite's nodes are (a
        ``scenario`` parameter, and ATO_SCENARIO in its environment) and the contract's other
        parameters (``ato_common.contract.PARAMETERS``: ``gradient_known``) from
        ``controller_params`` or their defaults, in the stack's namespace."""
        words = shlex.split(self.config.controller_command)
        if not words:
            raise ValueError('the controller command is empty')
        scenario = scenario or self.config.scenario
        told = {name: self.config.controller_params.get(name, default)
                for name, (_, default) in PARAMETERS.items() if name != 'scenario'}
        args = ros_args({'scenario': scenario, **told}, self.namespace)
        return self.start_process('controller', {}, command=[*words, *args],
                                  env={'ATO_SCENARIO': scenario})

    def start_composed(self, params: dict[str, dict]) -> subprocess.Popen:
        """The three loop nodes in one process (``ato_stack``), each with its own parameters
        from a parameters file with a section per node (the file is kept in the log folder);
        with ``record_to``, the recorder in that process too (``ato_stack --record``)."""
        sections = {f'/**/{NODE_NAMES[key]}': {'ros__parameters': params[key]}
                    for key in NODE_NAMES}
        path = self.config.log_dir / 'loop_parameters.yaml'
        path.write_text(yaml.safe_dump(sections, sort_keys=True))
        record = [] if self.config.record_to is None else [
            '--record', '-o', str(self.config.record_to), *self.provenance()]
        return self.start_process('loop', {}, record,
                                  extra_ros_args=['--params-file', str(path)])

    @staticmethod
    def provenance() -> list[str]:
        """The recorder's custom data of where the run comes from: the suite's commit (the
        report shows it)."""
        from ato_campaigns.provenance import commit_description
        return ['--custom-data', f'suite_commit={commit_description()}']

    def start_process(self, name: str, params: dict, args: Sequence[str] = (),
                      extra_ros_args: Sequence[str] = (), kind: str | None = None,
                      command: list[str] | None = None, env: dict[str, str] | None = None
                      ) -> subprocess.Popen:
        """Start the executable of ``kind`` (``EXECUTABLES``; default ``name``), or the
        ``command`` given, as the process ``name`` of the stack, its log in
        ``<log_dir>/<name>.log``; ``env``: variables added to the stack's environment."""
        if command is None:
            package, executable = EXECUTABLES[kind or name]
            command = [executable_path(package, executable), *args,
                       *ros_args(params, self.namespace), *extra_ros_args]
        self.config.log_dir.mkdir(parents=True, exist_ok=True)
        log = self.config.log_dir / f'{name}.log'
        self.logs[name] = log
        with open(log, 'ab') as out:
            process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT,
                                       env={**self.env, **(env or {})},
                                       stdin=subprocess.DEVNULL)
        self.processes[name] = process
        return process

    def spin_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def spin_for(self, duration_s: float) -> None:
        deadline = time.monotonic() + duration_s
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)

    def exited(self, name: str) -> bool:
        return self.processes[name].poll() is not None

    def ended(self, expected=None) -> tuple[str, int] | None:
        """The first process that has ended, other than the ``expected`` ones that end the run
        by themselves with code 0 (default: the plant's process, at its end time): (name, exit
        code), or None."""
        expected = (self.plant_process,) if expected is None else expected
        for name, process in self.processes.items():
            code = process.poll()
            if code is not None and (name not in expected or code != 0):
                return name, code
        return None

    def set_parameters(self, node_name: str, values: dict[str, object],
                       timeout_s: float = 10.0, attempt_s: float = 2.0):
        """ros2 param set, over the node's SetParameters service; returns the results.

        A service client is ready once its request reaches the server, which can be before the
        server's reply reaches the client (with Fast DDS, a reply sent before the client's reply
        reader is matched is lost for good). So the client is kept for the stack's life, and a
        request unanswered after ``attempt_s`` is sent again: setting the same values twice is
        the same as setting them once.
        """
        client = self.parameter_clients.get(node_name)
        if client is None:
            prefix = '' if self.namespace == '/' else self.namespace
            client = self.node.create_client(SetParameters,
                                             f'{prefix}/{node_name}/set_parameters')
            self.parameter_clients[node_name] = client
        deadline = time.monotonic() + timeout_s
        if not self.spin_until(lambda: client.service_is_ready(), timeout_s):
            raise TimeoutError(f'/{node_name}/set_parameters is not available')
        request = SetParameters.Request()
        request.parameters = [Parameter(name=k, value=parameter_value(v))
                              for k, v in values.items()]
        while True:
            future = client.call_async(request)
            left = deadline - time.monotonic()
            if self.spin_until(future.done, max(0.0, min(attempt_s, left))):
                return future.result().results
            client.remove_pending_request(future)
            if time.monotonic() >= deadline:
                raise TimeoutError(f'/{node_name}/set_parameters did not answer in {timeout_s} s')

    # Fast DDS 2.14 (Jazzy's rmw_fastrtps_cpp) can deadlock while deleting a participant if, at
    # that moment, discovery reports a remote endpoint going away: seen with gdb, the main thread
    # waits in rmw's destroy_participant (set_listener) for a discovery callback to end, and that
    # callback (onWriterDiscovery) waits on a mutex for good.
    # Peers that tear down together set this up, so the runner stops one process at a time and
    # lets discovery settle before each (a process that has just ended by itself, e.g. a replay,
    # is such a peer). Each stop costs this much more.
    SETTLE_S = 0.3
    # stop's bound in wall time on a process that keeps looking runnable, in stall limits
    STOP_WALL_FACTOR = 30.0

    def stop(self, names=None, timeout_s: float = 10.0) -> dict[str, int]:
        """Stop the processes one at a time: SIGINT, wait, abort what does not end; exit codes.
        The recorders go last, so that they record everything the others sent. A process is
        aborted once it has made no progress for ``timeout_s`` (stalled, not waiting for a CPU:
        ``ato_ros.stall``, so that a recorder at nice 19 on a loaded machine may finish), or
        after ``STOP_WALL_FACTOR`` times that in any case."""
        names = list(names or self.processes)
        order = [n for n in names if not n.startswith('recorder')] + \
            [n for n in names if n.startswith('recorder')]
        codes, error = {}, None
        for name in order:
            process = self.processes[name]
            if process.poll() is None:
                try:
                    self.spin_for(self.SETTLE_S)
                except Exception as raised:  # a monitor callback: stop the rest cleanly first
                    error = error or raised
                process.send_signal(signal.SIGINT)
                try:
                    wait_for_exit(process, timeout_s, self.STOP_WALL_FACTOR * timeout_s)
                except subprocess.TimeoutExpired:
                    self._abort(name)
            codes[name] = process.returncode
        if error is not None:
            raise error
        return codes

    def _abort(self, name: str) -> None:
        """End a process that ignored SIGINT: SIGABRT first, so that its faulthandler (run_node
        enables it) writes where every thread hung into its log, then SIGKILL."""
        process = self.processes[name]
        process.send_signal(signal.SIGABRT)
        try:
            process.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()

    def close(self) -> None:
        try:
            self.stop()
        finally:
            for process in self.processes.values():  # never leave a process behind
                if process.poll() is None:
                    process.kill()
                    process.wait()
        self.executor.shutdown()
        if self.monitor is not None and self.monitor.batch_node is not None:
            self.monitor.batch_node.destroy_node()
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def log_tail(self, name: str, lines: int = 30) -> str:
        try:
            return '\n'.join(self.logs[name].read_text(errors='replace').splitlines()[-lines:])
        except OSError:
            return ''


def parameter_value(value: object) -> ParameterValue:
    if isinstance(value, bool):
        return ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
    if isinstance(value, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    if isinstance(value, float):
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=str(value))
