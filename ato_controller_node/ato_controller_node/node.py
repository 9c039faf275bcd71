"""ato_controller_node: runs the selected law of :mod:`ato_controller_node.laws` at a fixed rate.

Lockstep: a step is taken when the measured state and the reference of the same stamp have both
arrived; the command carries that stamp. A state re-sent by the plant gets the same command
again (the law is stepped once per stamp). Real time: a wall-clock timer at ``rate_hz`` steps on
the latest state and reference; a measurement or a reference older than ``stale_after_s`` (a
dead plant or a dead profile) is stale: the controller commands nothing, says which in its
diagnostics, and the plant's watchdog brakes.

Parameters: ``controller`` selects the law and may change at run time (``ros2 param set
/ato_controller_node controller luo_xu``; bumpless); an unknown name or a law that does not fit
the train is rejected with the reason and the running law stays. Every law's gains are
parameters ``<law>.<gain>`` with ranges; their defaults are the configuration ``gains``
(``ato_controller_node.gains``): ``published`` (the papers' values) or ``tuned`` (the suite's
tuning artefacts for the scenario's train; a law without one cannot be selected then, and
says so). ``envelope`` turns the host's ATO envelope (anti-windup of the position error, the
same for every law) on or off, ``envelope.*`` are its settings. ``gradient_known`` false gives
the controller a flat line for knowledge (``knowledge_of(scenario, hide_gradient=True)``: a
campaign draw's ``gradient_known`` 0) while the plant keeps the grades: the only part of a
draw the controller is told; the plant's drawn truth (its ``draw_values``) never reaches it.

Graph: ``wait_for_subscribers`` holds back only the first command; an observer that goes away
later does not stop the loop. A state stamped before the last step (lockstep) is a restarted
plant: the controller starts its law again from that step. The plant's latched identity
(``train/identity``) must be the controller's own scenario: on another one the controller
refuses to drive (exit code 2, naming both); it commands nothing before it has read it (in
lockstep the plant sends the step again until the command comes). A failed publish is counted
and reported, never fatal.
"""

from __future__ import annotations

import dataclasses
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from ato_common.identity import scenario_identity
from ato_common.knowledge import knowledge_of
from ato_common.scenario import DEFAULT_SCENARIO, load_scenario
from ato_common.types import Command, Reference, ReferencePoint, seconds
from ato_common.uncertainty import knowledge_options
from ato_common.validation import ConfigError
from ato_controller_node.envelope import EnvelopeSettings
from ato_controller_node.gains import GAINS, GainsUnavailable, settings_for
from ato_controller_node.host import ControllerHost, LawRejected
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import setting_fields, validated_settings
from ato_ros import wire
from ato_ros.lifecycle import RunNodeHooks, freeze_startup_objects, node_usage, run_node
from ato_ros.messages import (
    MessageError,
    decoded,
    diagnostic_status,
    qos_profile,
    reference_from_msg,
    state_from_msg,
    status_name,
    to_time,
    topic,
)
from ato_ros.params import WAIT_FOR_DIAGNOSTICS_READERS, Param, ParameterTable
from ato_ros.publishing import Publishing, first_unmatched, step_recorder, watch_plant_identity

NODE_PARAMS = (
    Param('scenario', DEFAULT_SCENARIO, 'built-in scenario name or path to a scenario YAML file '
          '(the train the controller drives: nominal mass, resistance, traction limits)'),
    Param('controller', 'pid', 'control law', choices=tuple(sorted(LAWS)), read_only=False),
    Param('rate_hz', 0.0, "control rate, Hz (0: the scenario's controller_rate_hz)",
          minimum=0.0, maximum=1000.0),
    Param('lockstep', True, 'step on each (state, reference) pair of equal stamp '
          '(false: on a wall-clock timer)'),
    Param('wait_for_subscribers', 0, 'lockstep: command nothing before ato/command has this '
          'many subscribers (so a monitor or recorder misses nothing)', minimum=0, maximum=100),
    Param('wait_for_recorders', 0, 'lockstep: recorders of the run (the suite\'s recorder, '
          'which takes the commands from ato/step_records): nothing is commanded before '
          'ato/step_records and /diagnostics each have this many subscribers too', minimum=0,
          maximum=100),
    WAIT_FOR_DIAGNOSTICS_READERS,
    Param('stale_after_s', 0.5, 'real time: a measurement or a reference older than this is '
          'stale; the controller then commands nothing (and the plant watchdog brakes), s',
          minimum=0.01,
          maximum=60.0, read_only=False),
    Param('bumpless_time_constant_s', 3.0, 'decay time of the command step on a law switch, s',
          minimum=0.01, maximum=600.0, read_only=False),
    Param('gains', GAINS[0], "the laws' configuration: the defaults of every <law>.<gain> "
          '(published: the papers\' values; tuned: the suite\'s tuning artefacts for the '
          "scenario's train)", choices=GAINS),
    Param('gradient_known', True, "the controller knows the line's gradient profile (false: "
          'its knowledge is a flat line while the plant keeps the grades; a campaign draw\'s '
          'gradient_known 0)'),
    Param('envelope', True, 'the ATO envelope of the host: anti-windup of the position error '
          'under saturation, the same for every law (false: off for every law)'),
    Param('diagnostics_period_s', 1.0, 'period of the diagnostics, s of (simulated) time',
          minimum=0.01, maximum=3600.0, read_only=False),
)


def reference_now(reference: Reference, now_ns: int) -> ReferencePoint:
    """Real time: the latest reference brought forward to now along its preview (from the last
    preview point not after now, with its speed, acceleration and jerk)."""
    elapsed = seconds(now_ns - reference.stamp_ns)
    t0 = reference.points[0].time_s
    base = reference.points[0]
    for point in reference.points:
        if point.time_s - t0 <= elapsed:
            base = point
    dt = elapsed - (base.time_s - t0)
    a, j = base.acceleration, base.jerk
    return ReferencePoint(base.time_s + dt,
                          base.position + dt * (base.speed + dt * (a / 2.0 + dt * j / 6.0)),
                          base.speed + dt * (a + dt * j / 2.0), a + dt * j, j)


def _setting_params(prefix: str, settings_type, defaults, read_only: bool) -> list[Param]:
    params = []
    for f in setting_fields(settings_type):
        meta = f.metadata
        is_bool = isinstance(f.default, bool)
        default = defaults.get(f.name, f.default)
        params.append(Param(
            f'{prefix}.{f.name}', default if is_bool else float(default),
            f"{meta['description']} [{meta['units']}]",
            minimum=None if is_bool else meta['minimum'],
            maximum=None if is_bool else meta['maximum'], read_only=read_only))
    return params


def gain_params(defaults=None) -> list[Param]:
    """One parameter per setting of every law, its default from ``defaults`` (law -> {setting:
    value}, e.g. a configuration's), else the law's own; and the envelope's settings."""
    params = []
    for law_name, law in LAWS.items():
        params += _setting_params(law_name, law.Settings, (defaults or {}).get(law_name, {}),
                                  read_only=False)
    return params + _setting_params('envelope', EnvelopeSettings, {}, read_only=True)


def configuration(gains: str, train: str) -> tuple[dict[str, dict], dict[str, str]]:
    """(the settings of every law in configuration ``gains``, {law without them: why})."""
    values, missing = {}, {}
    for law in LAWS:
        try:
            values[law] = settings_for(law, gains, train)
        except GainsUnavailable as error:
            missing[law] = str(error)
    return values, missing


class AtoControllerNode(RunNodeHooks, Node):
    def __init__(self):
        super().__init__('ato_controller_node')
        self.params = ParameterTable(self, NODE_PARAMS)
        p = self.params
        scenario = load_scenario(p['scenario'])  # not kept: its plant section is the truth
        self.identity = scenario_identity(scenario)  # name and hash only: no truth in it
        self.rate_hz = p['rate_hz'] or scenario.run.controller_rate_hz
        self.dt = 1.0 / self.rate_hz
        self.lockstep = p['lockstep']
        # all the controller knows of the train: the knowledge part of a draw, nothing of its truth
        self.knowledge = knowledge_of(scenario, **knowledge_options(
            {'gradient_known': float(p['gradient_known'])}))
        # the laws' gains: parameters whose defaults are the configuration's
        configured, self.untuned = configuration(p['gains'], scenario.train.name)
        self.gain_table = ParameterTable(self, gain_params(configured))
        settings = {law: {f.name: p[f'{law}.{f.name}'] for f in setting_fields(cls.Settings)}
                    for law, cls in LAWS.items()}
        self.envelope_settings = {f.name: p[f'envelope.{f.name}']
                                  for f in setting_fields(EnvelopeSettings)}
        try:
            if p['controller'] in self.untuned:
                raise ConfigError(self.untuned[p['controller']])
            self.host = self.make_host(p['controller'], settings)
        except (LawRejected, ValueError) as error:
            raise ConfigError(str(error)) from None
        for table in (self.params, self.gain_table):
            table.extra_checks.append(self.check_changes)
        self.add_post_set_parameters_callback(self.apply_changes)

        self.states: dict[int, object] = {}
        self.references: dict[int, Reference] = {}
        self.last_stamp_ns = -1
        self.last_command_msg = None
        self.last_result = None
        self.next_diagnostic_ns = 0
        self.step_times_s: list[float] = []
        self.period_warning_given = False
        self.input_fault = ''
        self.last_fault_logged = ''
        self.state_received_wall = 0.0
        self.reference_received_wall = 0.0
        self.stale_steps = 0  # real-time periods without a command for a stale input
        self.stale_reported_wall = 0.0
        self.subscribers_met = False  # wait_for_subscribers holds back the first command only
        self.identified = False  # the plant's identity read, and ours (watch_plant_identity)
        self.restarts = 0
        self.publishing = Publishing(self)
        self.status_name = status_name(self, 'law')

        # The commands for the recorders, bundled (ato_ros.step_records); created before the
        # command's publisher (``ato_ros.publishing.step_recorder``).
        self.records = step_recorder(self, self.publishing)
        self.command_pub = self.create_publisher(JointState, topic('command').name,
                                                 qos_profile(topic('command').qos))
        self.diag_pub = self.create_publisher(DiagnosticArray, topic('diagnostics').name,
                                              qos_profile(topic('diagnostics').qos))
        # The per-step inputs are taken as bytes and read by ato_ros.wire (no rclpy message
        # objects); the command goes out the same way.
        self.create_subscription(JointTrajectory, topic('state_measured').name, self.on_state,
                                 qos_profile(topic('state_measured').qos), raw=True)
        self.create_subscription(JointTrajectory, topic('reference').name, self.on_reference,
                                 qos_profile(topic('reference').qos), raw=True)
        watch_plant_identity(self, self.identity, 'refusing to drive')
        if not self.lockstep:
            self.create_timer(self.dt, self.on_timer)
        self.get_logger().info(f"law {self.host.law.name} at {self.rate_hz:g} Hz "
                               f"({'lockstep' if self.lockstep else 'real time'}), actuators "
                               f'{list(self.knowledge.actuator_names)}')
        freeze_startup_objects()

    def make_host(self, law: str, settings=None) -> ControllerHost:
        if settings is None:  # the current gains of every law
            settings = {name: dataclasses.asdict(self.host.settings(name)) for name in LAWS}
        return ControllerHost(self.knowledge, self.dt, law, settings,
                              self.params['bumpless_time_constant_s'],
                              envelope=self.params['envelope'],
                              envelope_settings=self.envelope_settings)

    # --- parameters: validate, then apply ---------------------------------------------------
    def _gain_changes(self, changes: dict) -> dict[str, dict]:
        per_law: dict[str, dict] = {}
        for name, value in changes.items():
            if '.' in name:
                law, field = name.split('.', 1)
                per_law.setdefault(law, {})[field] = value
        return per_law

    def check_changes(self, changes: dict) -> str | None:
        if 'controller' in changes:
            if changes['controller'] in self.untuned:
                return self.untuned[changes['controller']]
            try:
                self.host.check(changes['controller'])
            except LawRejected as error:
                return str(error)
        for law, values in self._gain_changes(changes).items():
            if law not in LAWS:
                continue  # envelope.*: fixed at start-up (the table refuses a change)
            try:
                validated_settings(LAWS[law].Settings, values, self.host.settings(law))
            except ValueError as error:
                return f'{law}: {error}'
        return None

    def apply_changes(self, parameters) -> None:
        changes = {p.name: p.value for p in parameters}
        for law, values in self._gain_changes(changes).items():
            if law in LAWS:
                self.host.update_settings(law, values)
        if 'bumpless_time_constant_s' in changes:
            self.host.bumpless_time_constant_s = changes['bumpless_time_constant_s']
        if 'controller' in changes and changes['controller'] != self.host.law.name:
            previous = self.host.law.name
            self.host.select(changes['controller'])
            self.get_logger().info(f'law switched from {previous} to {self.host.law.name}')
            self.next_diagnostic_ns = 0  # announce the new law at the next step

    # --- inputs -------------------------------------------------------------------------------
    def on_state(self, data: bytes) -> None:
        try:
            state = decoded(data, wire.decode_state, JointTrajectory, state_from_msg)
        except MessageError as error:
            self.input_fault = f'bad state message: {error}'
            return
        if self.lockstep:
            self.states[state.stamp_ns] = state
            self.try_step(state.stamp_ns)
        else:
            self.states = {0: state}
            self.state_received_wall = time.monotonic()

    def on_reference(self, data: bytes) -> None:
        try:
            reference = decoded(data, wire.decode_reference, JointTrajectory, reference_from_msg)
        except MessageError as error:
            self.input_fault = f'bad reference message: {error}'
            return
        if self.lockstep:
            self.references[reference.stamp_ns] = reference
            self.try_step(reference.stamp_ns)
        else:
            self.references = {0: reference}
            self.reference_received_wall = time.monotonic()

    def try_step(self, stamp_ns: int) -> None:
        if stamp_ns == self.last_stamp_ns:
            if stamp_ns in self.states and self.last_command_msg is not None:
                self.states.pop(stamp_ns, None)
                self.references.pop(stamp_ns, None)
                self.send_command(self.last_command_msg, stamp_ns)  # asked again
            return
        if stamp_ns not in self.states or stamp_ns not in self.references:
            return
        if not self.identified:
            return  # nothing to a plant it may refuse; the plant re-sends the step
        if not self.subscribers_met:
            recorders = self.params['wait_for_recorders']
            if first_unmatched(((self.command_pub, self.params['wait_for_subscribers']),
                                (self.records.publisher, recorders),
                                (self.diag_pub, recorders
                                 + self.params['wait_for_diagnostics_readers']))):
                return  # the plant re-sends the step until the command comes
            self.subscribers_met = True
        if stamp_ns < self.last_stamp_ns:
            self.restart(stamp_ns)
        if (not self.period_warning_given and self.last_stamp_ns >= 0
                and abs(seconds(stamp_ns - self.last_stamp_ns) - self.dt) > 1e-6):
            self.period_warning_given = True
            self.get_logger().warning(
                f'state period {seconds(stamp_ns - self.last_stamp_ns):g} s differs from the '
                f'control period {self.dt:g} s: set the same rate on plant and controller')
        state = self.states.pop(stamp_ns)
        reference = self.references.pop(stamp_ns)
        # Drop anything older (a stamp that will never be completed).
        self.states = {k: v for k, v in self.states.items() if k > stamp_ns}
        self.references = {k: v for k, v in self.references.items() if k > stamp_ns}
        self.step(stamp_ns, state, reference, seconds(stamp_ns))

    def restart(self, stamp_ns: int) -> None:
        """A state and a reference stamped before the last step: a new plant (and so a new
        run). The law starts again from this step; what was kept of the old run goes."""
        self.restarts += 1
        self.get_logger().warning(
            f'state stamped {seconds(stamp_ns):.3f} s, before the last step '
            f'{seconds(self.last_stamp_ns):.3f} s: the plant started again; the law '
            f'{self.host.law.name} starts again from there ({self.restarts} restarts)')
        self.host = self.make_host(self.host.law.name)
        self.states = {k: v for k, v in self.states.items() if k <= stamp_ns}
        self.references = {k: v for k, v in self.references.items() if k <= stamp_ns}
        self.last_stamp_ns = -1
        self.last_command_msg = None
        self.next_diagnostic_ns = 0
        self.period_warning_given = False

    def on_timer(self) -> None:
        state, reference = self.states.get(0), self.references.get(0)
        if state is None or reference is None or not self.identified:
            return
        now = time.monotonic()
        for what, received in (('measurement', self.state_received_wall),
                               ('reference', self.reference_received_wall)):
            age = now - received
            if age > self.params['stale_after_s']:
                # No command on an old input: the plant's watchdog takes the train to a stop.
                self.stale_steps += 1
                if now - self.stale_reported_wall >= 1.0:
                    self.stale_reported_wall = now
                    self.report_stale(age, what)
                return
        now_ns = self.get_clock().now().nanoseconds
        target = reference_now(reference, now_ns)
        # The laws and the mode schedule work in run time (the curve's time), not clock time.
        self.step(now_ns, state, Reference(now_ns, (target,)), target.time_s)

    # --- the step -----------------------------------------------------------------------------
    def step(self, stamp_ns: int, state, reference, time_s: float) -> None:
        started = time.perf_counter()
        # The operating mode is known on board (line data), as the indicators chi_i of
        # Mao et al. 2017 assume: the knowledge's schedule at the lead car's measured position.
        result = self.host.step(self.host.measurement(time_s, state), reference.now)
        if result.fault and result.fault != self.last_fault_logged:
            self.get_logger().error(result.fault)
        self.last_fault_logged = result.fault
        self.step_times_s.append(time.perf_counter() - started)
        msg = wire.encode_command(Command(stamp_ns, self.knowledge.actuator_names,
                                          result.forces_n, result.law))
        self.send_command(msg, stamp_ns)
        self.last_command_msg = msg
        self.last_stamp_ns = stamp_ns
        self.last_result = result
        if stamp_ns >= self.next_diagnostic_ns:
            self.publish_diagnostics(stamp_ns)
            self.next_diagnostic_ns = stamp_ns + int(self.params['diagnostics_period_s'] * 1e9)

    def send_command(self, msg: bytes, stamp_ns: int) -> None:
        self.publishing(self.command_pub, msg)
        if self.records.begin_step():
            self.records.add(self.command_pub, stamp_ns, msg)
        self.records.end_step(stamp_ns)

    def close_outputs(self) -> None:
        if not self.records.close():  # the last commands' records
            self.get_logger().warning('a recorder did not acknowledge the last step records '
                                      'in time (gone?)')

    def report_stale(self, age_s: float, what: str = 'measurement') -> None:
        message = (f'{what} stale for {age_s:.1f} s (limit {self.params["stale_after_s"]:g} '
                   's): commanding nothing')
        self.get_logger().warning(message)
        status = diagnostic_status(self.status_name, self.host.law.name,
                                   DiagnosticStatus.ERROR, message,
                                   {'law': self.host.law.name, f'{what}_age_s': age_s,
                                    'stale_input': what, 'stale_periods': self.stale_steps})
        self.publishing(self.diag_pub, DiagnosticArray(
            header=Header(stamp=self.get_clock().now().to_msg()), status=[status]))

    def publish_diagnostics(self, stamp_ns: int) -> None:
        r = self.last_result
        fault = r.fault or self.input_fault
        values = {'law': r.law, 'rate_hz': self.rate_hz, 'gains': self.params['gains'],
                  'envelope': self.params['envelope'],
                  'gradient_known': self.params['gradient_known'],
                  'speed_error_mps': r.speed_error_mps,
                  'position_error_m': r.position_error_m, 'command_n': r.total_force_n,
                  'wanted_n': r.wanted_force_n, 'saturated': r.saturated,
                  'faults': self.host.faults, 'restarts': self.restarts,
                  **self.publishing.values()}
        values.update({f'estimate.{k}': v for k, v in r.estimates.items()})
        if self.step_times_s:
            values['step_time_max_ms'] = 1e3 * max(self.step_times_s)
            self.step_times_s.clear()
        status = diagnostic_status(
            self.status_name, r.law,
            DiagnosticStatus.WARN if fault else DiagnosticStatus.OK,
            fault or f'{r.law} running', values)
        self.publishing(self.diag_pub, DiagnosticArray(header=Header(stamp=to_time(stamp_ns)),
                                                       status=[status]))
        self.input_fault = ''


def main(args=None) -> int:
    return run_node(AtoControllerNode, args,
                    usage=lambda: node_usage('ato_controller_node', 'ato_controller_node',
                                             __doc__, NODE_PARAMS + tuple(gain_params())))


if __name__ == '__main__':
    raise SystemExit(main())
