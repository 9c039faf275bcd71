"""train_plant_node: the rclpy adapter of :class:`TrainSimulation`.

Lockstep (default): the plant owns simulated time. It publishes /clock and the measured state at
t_k (and, while they have a subscriber, the true state and the commanded and applied actuator
forces: ``ato_common.conventions.OBSERVED_STEP``), waits for the command stamped t_k, holds it
while integrating to t_k+1, and publishes again. Until the first command arrives (and while
waiting for one) it re-publishes the current step every ``resend_period_s`` of wall time, so
start-up order and DDS discovery do not matter. A step whose command has not come after
``command_wait_limit_s`` of wall time (the controller or the profile gone) is reported as a WARN
in the diagnostics and in the log, again each such period. A command stamped for another step
is dropped and counted, and the plant waits on at its step: the command stamped for it moves
the loop on (a controller that fell behind or ahead is in step again at once). Real time: the
same simulation advanced by a wall-clock timer, commands held as they come.

A run whose emergency brake has held for longer than ``emergency_brake_limit_s`` of simulated
time ends with exit code ``EMERGENCY_BRAKE_HELD`` (3) and the reason, in the log and the
diagnostics.

``draw_values`` (a JSON object of uncertain parameters, ``train_plant_node.draw_values``): the
plant runs the truth of one draw of a campaign, ``perturbed(scenario, values)`` as the offline
loop does; only the plant reads it (the controller is told only the knowledge part, its own
``gradient_known``). The plant publishes the identity of the nominal scenario, latched
(``train/identity``: the scenario's name and a hash of the resolved scenario; a draw is the
truth of that scenario, not another one); the controller and the profile refuse to run on
another scenario. A failed publish (the middleware refusing a sample) is counted and
reported, never fatal. Before it exits at ``end_time_s`` the plant waits until every matched
subscriber has acknowledged the last step.
"""

from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String
from trajectory_msgs.msg import JointTrajectory

from ato_common import units
from ato_common.identity import scenario_identity
from ato_common.plant_setup import parse_failure_injection
from ato_common.scenario import DEFAULT_SCENARIO, load_scenario
from ato_common.types import TrainState, nanoseconds, seconds
from ato_common.uncertainty import perturbed
from ato_common.validation import ConfigError
from ato_ros import wire
from ato_ros.lifecycle import RunNodeHooks, freeze_startup_objects, node_usage, run_node
from ato_ros.messages import (
    MessageError,
    command_from_msg,
    decoded,
    diagnostic_status,
    qos_profile,
    status_name,
    to_time,
    topic,
)
from ato_ros.params import WAIT_FOR_DIAGNOSTICS_READERS, Param, ParameterTable
from ato_ros.publishing import (
    Observation,
    Publishing,
    RecorderLead,
    first_unmatched,
    step_recorder,
    wait_until_delivered,
)
from ato_ros.step_records import LEAD_S, least_lead_s
from train_plant_node.draw_values import parse_draw_values
from train_plant_node.models import MODELS
from train_plant_node.simulation import (
    NORMAL,
    CommandRejected,
    FailureRejected,
    SafetySettings,
    SensorSettings,
    TrainSimulation,
    check_failure,
    control_period_ns,
)

#: the exit code of a run ended because its emergency brake held beyond emergency_brake_limit_s
EMERGENCY_BRAKE_HELD = 3

PARAMS = (
    Param('scenario', DEFAULT_SCENARIO, 'built-in scenario name or path to a scenario YAML file'),
    Param('model', 'point_mass', 'plant model', choices=tuple(sorted(MODELS))),
    Param('draw_values', '', 'the truth of one draw of a campaign\'s uncertainty: a JSON object '
          'of uncertain parameters (ato_common.uncertainty), e.g. {"mass_factor": 1.08, '
          '"wind_mps": -2.5}, each a finite number in its range; one left out is nominal '
          "('': the nominal plant). The plant runs perturbed(scenario, values); gradient_known "
          "is the controller's"),
    Param('lockstep', True, 'advance simulated time one control period per command and '
          'publish /clock (false: real time on a wall-clock timer)'),
    Param('control_rate_hz', 0.0, 'control rate the plant steps at in lockstep, Hz; must equal '
          "the controller's rate_hz (0: the scenario's controller_rate_hz)",
          minimum=0.0, maximum=1000.0),
    Param('real_time_rate_hz', 100.0, 'integration and publication rate in real-time mode, Hz',
          minimum=1.0, maximum=1000.0),
    Param('end_time_s', 0.0, 'simulated time at which the run ends and the node exits '
          '(0: run until shut down)', minimum=0.0, maximum=1e7),
    Param('wait_for_subscribers', 0, 'number of subscribers of train/state to wait for before '
          'the first step (so a monitor or recorder misses nothing)', minimum=0, maximum=100),
    Param('wait_for_recorders', 0, 'recorders of the run (the suite\'s recorder, which takes '
          'the per-step topics from ato/step_records): the first step waits until '
          'ato/step_records and /diagnostics each have this many subscribers (DDS matches each '
          'topic separately)', minimum=0, maximum=100),
    WAIT_FOR_DIAGNOSTICS_READERS,
    Param('start_delay_s', 0.0, 'wall time to wait after wait_for_subscribers and '
          'wait_for_recorders are met before the first step', minimum=0.0, maximum=60.0),
    Param('recorder_lead_s', LEAD_S, 'lockstep: how far the plant may run ahead of what every '
          "recorder that acknowledges (the suite's recorder) has written to its file, s of "
          'simulated time: the most a SIGKILLed recorder loses; at least the step records\' '
          'bundle and acknowledgement periods plus two control periods '
          '(ato_ros.step_records.least_lead_s); 0: do not wait for recorders',
          minimum=0.0, maximum=3600.0),
    Param('resend_period_s', 0.2, 'lockstep: re-publish the current step after this much wall '
          'time without its command', minimum=0.01, maximum=10.0),
    Param('max_substep_s', 0.1, 'longest internal integration step, s', minimum=1e-4,
          maximum=1.0),
    Param('sensor_position_noise_m', 0.0, 'standard deviation of position measurement noise, m '
          "(> 0: replaces the scenario's plant.sensors.position.noise_std)",
          minimum=0.0, maximum=100.0),
    Param('sensor_speed_noise_mps', 0.0, 'standard deviation of speed measurement noise, m/s '
          "(> 0: replaces the scenario's plant.sensors.speed.noise_std)",
          minimum=0.0, maximum=10.0),
    Param('seed', 0, "seed of the sensor noise (used when the scenario's plant.sensors.seed "
          'is 0)', minimum=0, maximum=2**31 - 1),
    Param('inject_failure', '', 'run time: actuator failure(s) as YAML, the schema of the '
          "scenario's plant.failures, e.g. \"{actuator: motor_2, kind: stuck, force_n: 2.0e+5}\"; "
          'start_s defaults to now; kind healthy repairs', read_only=False),
    Param('watchdog_periods', 3, 'control periods without a valid command before service '
          'braking', minimum=1, maximum=1000),
    Param('emergency_periods', 10, 'control periods without a valid command before emergency '
          'braking', minimum=1, maximum=10000),
    Param('command_stamp_tolerance_s', 1.0, 'real time: a command stamped more than this before '
          'or after now is dropped (counted, and the watchdog sees no valid command), s',
          minimum=0.001, maximum=60.0, read_only=False),
    Param('command_wait_limit_s', 5.0, 'lockstep: wall time to wait for the command of a step '
          'before reporting the wait (WARN diagnostics and log, again each such period), s',
          minimum=0.1, maximum=3600.0, read_only=False),
    Param('diagnostics_period_s', 1.0, 'period of the diagnostics, s of (simulated) time; a '
          'safety reaction, a rejected command and an injected failure are reported at once',
          minimum=0.01, maximum=3600.0, read_only=False),
    Param('final_delivery_timeout_s', 5.0, 'at end_time_s: wall time to wait for every matched '
          'subscriber to acknowledge the last step before exiting, s', minimum=0.0,
          maximum=60.0),
    Param('emergency_brake_limit_s', 300.0, "a run whose emergency brake (the ATP's or the "
          "watchdog's) has held for longer than this, in s of simulated time, ends with exit "
          f'code {EMERGENCY_BRAKE_HELD} and the reason (0: no limit)', minimum=0.0, maximum=1e6),
)


class TrainPlantNode(RunNodeHooks, Node):
    def __init__(self):
        super().__init__('train_plant_node')
        self.params = ParameterTable(self, PARAMS)
        p = self.params
        self.scenario = load_scenario(p['scenario'])  # nominal: its identity is published
        drawn = parse_draw_values(p['draw_values'])
        # the truth: only the simulation (and the failures checked against it) reads it
        self.truth = self.scenario if drawn is None else perturbed(self.scenario, drawn)
        rate = p['control_rate_hz'] or self.scenario.run.controller_rate_hz
        self.lockstep = p['lockstep']
        self.period_ns = (control_period_ns(rate) if self.lockstep
                          else control_period_ns(p['real_time_rate_hz']))
        self.end_ns = nanoseconds(p['end_time_s'])
        self.control_period_ns = control_period_ns(rate)
        self.sim = self._simulation()
        self._start_state()
        self._create_outputs()
        self.recorder_lead = self._recorder_lead()
        self.identity = scenario_identity(self.scenario)
        self.publishing(self.identity_pub, String(data=self.identity))
        self.add_on_set_parameters_callback(self.check_use_sim_time)
        # Validate in the set callback, apply once the change is accepted (validate-then-apply).
        self.params.extra_checks.append(self.check_inject_failure)
        self.add_post_set_parameters_callback(self.apply_parameters)
        if p['inject_failure']:  # given at start-up: like scenario failures
            reason = self.check_inject_failure({'inject_failure': p['inject_failure']})
            if reason:
                raise ConfigError(reason)
            self.inject_failure(p['inject_failure'])
        self.create_subscription(JointState, topic('command').name, self.on_command,
                                 qos_profile(topic('command').qos), raw=True)
        # Wall-clock timer: start-up, re-sends in lockstep, integration in real time.
        self.timer = self.create_timer(
            0.02 if self.lockstep else 1.0 / p['real_time_rate_hz'], self.on_timer)
        if not (self.sim.sensors.exact_odometer or self.scenario.line.balise_groups_m):
            self.get_logger().warning(
                'the odometer errs (plant.sensors) and the line has no balise groups '
                "(balise_groups: []): the ATP's odometry cannot relocate, so an odometer error "
                'beyond its declared interval goes unseen by the supervision')
        groups = self.scenario.line.balise_groups_m
        self.get_logger().info(
            f"scenario {self.scenario.name} ({self.scenario.origin}), model {p['model']}, "
            f"{'lockstep at ' + format(rate, 'g') + ' Hz' if self.lockstep else 'real time'}, "
            f'actuators {list(self.sim.actuator_names)}, {len(groups)} balise groups'
            + (f' ({groups[0]:.0f} to {groups[-1]:.0f} m)' if groups else '')
            + (f", the truth of the draw {p['draw_values']}" if drawn is not None else ''))
        freeze_startup_objects()

    def _simulation(self) -> TrainSimulation:
        """The simulation the parameters ask for; a parameter or scenario it refuses is a
        ConfigError naming it."""
        p = self.params
        if p['emergency_periods'] < p['watchdog_periods']:
            raise ConfigError(f"emergency_periods ({p['emergency_periods']}) must not be below "
                              f"watchdog_periods ({p['watchdog_periods']})")
        if not self.lockstep and self.get_parameter('use_sim_time').value:
            raise ConfigError('use_sim_time is true on a real-time plant (lockstep false): '
                              'nobody publishes /clock then, so its clock would never advance '
                              'and it would publish nothing; set use_sim_time false (only the '
                              'other nodes of a lockstep run use simulated time)')
        try:
            return TrainSimulation(
                self.truth, p['model'],
                SensorSettings(p['sensor_position_noise_m'], p['sensor_speed_noise_mps'],
                               p['seed']),
                SafetySettings(p['watchdog_periods'], p['emergency_periods']),
                max_substep_s=p['max_substep_s'])
        except ConfigError:
            raise  # names the scenario's field already (plant.sensors...)
        except FailureRejected as error:
            raise ConfigError(f'plant.failures: {error}') from None
        except ValueError as error:  # e.g. multi_car with a train that has no car description
            raise ConfigError(f"model {p['model']}: {error}") from None

    def _start_state(self) -> None:
        """The node's own state before the first step."""
        self.last_valid_command_wall = time.monotonic()
        self.safety_state = (NORMAL, False)
        self.finished = False
        self.started = False
        self.last_rejection = ''
        self.last_publish_wall = 0.0
        self.next_diagnostic_ns = 0
        self.wall_start_ns = 0
        self.step_messages: list | None = None
        self.steps_published = 0  # re-sent steps included: what a recording must hold
        self.ready_since: float | None = None
        self.start_wait_since: float | None = None  # when the first step began to wait
        self.wrong_stamp_commands = 0   # dropped for their stamp (lockstep and real time)
        self.last_wrong_stamp = ''      # why the last one was dropped
        self.failures_reported = 0
        self.step_since_wall = 0.0      # when the current step was first published
        self.waiting_reported_wall = 0.0
        self.waiting = ''               # lockstep: the wait for a command beyond the limit
        self.held_reported_wall = 0.0   # lockstep: a step held for a recorder, last reported
        self.held = ''                  # lockstep: the wait for a recorder beyond the limit
        self.ended = ''                 # why the run ended before end_time_s ('' if it did not)

    def _create_outputs(self) -> None:
        """The plant's outputs: the state (true and measured), /clock in lockstep, the
        actuator forces, diagnostics, the step records and the identity."""
        self.publishing = Publishing(self)
        self.status_name = status_name(self, 'simulation')
        # The per-step messages for the recorders, bundled (ato_ros.step_records); created before
        # the per-step publishers (``ato_ros.publishing.step_recorder``).
        self.records = step_recorder(self, self.publishing)
        self.truth_pub = self.create_publisher(JointTrajectory, topic('state').name,
                                               qos_profile(topic('state').qos))
        self.measured_pub = self.create_publisher(JointTrajectory, topic('state_measured').name,
                                                  qos_profile(topic('state_measured').qos))
        self.diag_pub = self.create_publisher(DiagnosticArray, topic('diagnostics').name,
                                              qos_profile(topic('diagnostics').qos))
        self.clock_pub = (self.create_publisher(Clock, topic('clock').name,
                                                qos_profile(topic('clock').qos))
                          if self.lockstep else None)
        self.commanded_pub = self.create_publisher(
            JointState, topic('actuators_commanded').name,
            qos_profile(topic('actuators_commanded').qos))
        self.applied_pub = self.create_publisher(
            JointState, topic('actuators_applied').name,
            qos_profile(topic('actuators_applied').qos))
        self.observations = tuple(Observation(self, p) for p in (
            self.truth_pub, self.commanded_pub, self.applied_pub))
        # the actuator forces' messages (commanded and applied): one force per actuator
        self.encode_forces = wire.joint_forces_encoder(self.sim.actuator_names)
        self.identity_pub = self.create_publisher(String, topic('identity').name,
                                                  qos_profile(topic('identity').qos))

    def _recorder_lead(self) -> RecorderLead | None:
        """Lockstep: a step waits while a recorder has not written the steps more than the lead
        before it (back-pressure: what a SIGKILLed recorder loses is bounded)."""
        lead_s = self.params['recorder_lead_s']
        if not (self.lockstep and lead_s > 0):
            return None
        least = least_lead_s(seconds(self.period_ns))
        if lead_s < least:
            raise ConfigError(
                f'recorder_lead_s {lead_s:g} s is under the least lead of this loop, {least:g} s '
                "(the step records' bundle and acknowledgement periods and two control periods: "
                'a smaller lead would wait for records no node sends before the next step); '
                'give at least that, or 0 not to wait for recorders')
        return RecorderLead(self, lead_s, self.publish_step)

    # --- time ----------------------------------------------------------------------------------
    def stamp_ns(self) -> int:
        """Header stamp: simulated time in lockstep, the wall clock in real time."""
        if self.lockstep:
            return self.sim.stamp_ns
        return self.wall_start_ns + self.sim.stamp_ns

    # --- publishing ---------------------------------------------------------------------------
    def publish_step(self) -> None:
        stamp = self.stamp_ns()
        new_step = self.step_messages is None or self.step_messages[0] != stamp
        if new_step and self.recorder_lead is not None and self.recorder_lead.holds(
                stamp, last=bool(self.end_ns and stamp >= self.end_ns)):
            return  # published once a recorder acknowledges (RecorderLead.on_release)
        if new_step:
            # Once per step: a re-sent step must repeat the same measurement (sensor noise is
            # drawn here), or lockstep runs would depend on how often a step was re-sent.
            truth = self.sim.truth()
            # The per-step messages go out as CDR bytes packed from templates (ato_ros.wire):
            # standard messages on the wire, without rclpy's message objects.
            self.step_messages = [stamp, wire.encode_clock(stamp), truth,
                                  self._msg(self.sim.measured(truth), stamp), None, None, None]
            self.step_since_wall = time.monotonic()
            if self.waiting:
                self.get_logger().info(f'commands again after {self.waiting}')
                self.waiting = ''
            if self.held:
                self.get_logger().info(f'the recorders caught up after {self.held}')
                self.held = ''
        messages = self.step_messages
        assert messages is not None  # built above for this step
        publish, records = self.publishing, self.records
        recording = records.begin_step()  # a recorder takes every message of the step from it
        if self.clock_pub is not None:
            publish(self.clock_pub, messages[1])
            records.add(self.clock_pub, stamp, messages[1])
        publish(self.measured_pub, messages[3])
        records.add(self.measured_pub, stamp, messages[3])
        # The observation topics (conventions.OBSERVED_STEP): built and published while
        # someone subscribes; while only a recorder records, built when it takes the step
        # records (``StepRecorder.add_later``); the loop itself needs only the measured state
        # and /clock.
        truth, commanded, applied = self.observations
        forces = self.encode_forces
        for index, observation, encode, args in (
                (4, truth, self._msg, (messages[2], stamp)),
                (5, commanded, forces, (stamp, self.sim.commanded)),
                (6, applied, forces, (stamp, self.sim.applied))):
            if observation.due():
                if messages[index] is None:
                    messages[index] = encode(*args)
                publish(observation.publisher, messages[index])
                records.add(observation.publisher, stamp, messages[index])
            elif recording:
                records.add_later(observation.publisher, stamp, encode, *args)
        records.end_step(stamp)
        self.steps_published += 1
        self.last_publish_wall = time.monotonic()
        safety_state = (self.sim.watchdog, self.sim.atp_intervention)
        if safety_state != self.safety_state:  # report a safety reaction at once
            self.safety_state = safety_state
            self.log_safety()
            self.next_diagnostic_ns = 0
        if self.sim.stamp_ns >= self.next_diagnostic_ns:
            self.publish_diagnostics()
            period_ns = nanoseconds(self.params['diagnostics_period_s'])
            self.next_diagnostic_ns = self.sim.stamp_ns + period_ns

    def _msg(self, state: TrainState, stamp_ns: int) -> bytes:
        # Run time since the start, so real-time subscribers can relate stamps to the curve.
        return wire.encode_state(state, stamp_ns, seconds(state.stamp_ns))

    def safety_message(self) -> str:
        sim = self.sim
        atp, odometry = sim.atp, sim.odometry
        if atp.emergency_brake:
            if sim.actuators.failures and sim.actuators.drive_fault(sim.time_s):
                until = ('a traction drive delivers force it is not asked for: brake and '
                         'traction cut-off held until the failure is isolated')
            elif atp.odometry_lost:
                until = 'the odometry is lost (its position and speed sensors failed)'
            elif not atp.hold_to_standstill:
                until = (f'until at or under the permitted '
                         f'{units.mps_to_kmh(atp.permitted_speed(odometry)):.1f} km/h')
            elif odometry.max_safe_front_m < sim.supervision.legs[atp.leg].end_of_authority_m:
                until = 'until standstill (target-speed monitoring)'
            else:
                until = 'past the end of authority (trip): until the authority moves on'
            return ('ATP emergency brake intervention: '
                    f'{units.mps_to_kmh(odometry.speed_mps):.1f} km/h, intervention speed '
                    f'{units.mps_to_kmh(atp.intervention_speed(odometry)):.1f} km/h, {until}')
        if sim.watchdog != NORMAL:
            cause = self.last_rejection or self.last_wrong_stamp
            return (f'command watchdog: {sim.watchdog} after {sim.missed_periods} control '
                    'periods without a valid command' + (f' (last: {cause})' if cause else ''))
        return ''

    def log_safety(self) -> None:
        message = self.safety_message()
        if message:
            self.get_logger().error(message)
        else:
            self.get_logger().info('safety functions released: the ATO is in control again')

    def unmatched_output(self) -> str:
        """The first of the plant's outputs that has fewer subscribers than the start waits
        for (``wait_for_recorders`` on the step records and, with
        ``wait_for_diagnostics_readers``, on /diagnostics), '' if none."""
        recorders = self.params['wait_for_recorders']
        return first_unmatched((
            (self.records.publisher, recorders),
            (self.diag_pub, recorders + self.params['wait_for_diagnostics_readers'])))

    def observers_lost(self) -> str:
        """'' while train/state and the step records have the subscribers the start waited for,
        else what is missing (an observer, e.g. a monitor or the recorder, went away: the loop
        goes on without it)."""
        if not self.started:
            return ''
        for publisher, wanted, what in (
                (self.truth_pub, self.params['wait_for_subscribers'], 'subscribers'),
                (self.records.publisher, self.params['wait_for_recorders'], 'recorders')):
            have = publisher.get_subscription_count()
            if have < wanted:
                return (f'{publisher.topic_name.lstrip("/")} has {have} of the {wanted} {what} '
                        'the run started with (an observer went away)')
        return ''

    def publish_diagnostics(self) -> None:
        safety = self.safety_message()
        lost = self.observers_lost()
        failed = self.publishing.failures - self.failures_reported
        self.failures_reported = self.publishing.failures
        warning = (self.waiting and f'{self.waiting} (is the controller, or the profile, '
                   'running?)') or self.held or self.last_rejection or lost or (
            failed and f'{failed} publishes failed (last: {self.publishing.last_failure})')
        level = (DiagnosticStatus.ERROR if safety else
                 DiagnosticStatus.WARN if warning else DiagnosticStatus.OK)
        sim = self.sim
        status = diagnostic_status(
            self.status_name, self.scenario.train.name, level,
            self.ended or safety or warning or 'running',
            {'time_s': sim.time_s, 'commanded_n': list(sim.commanded),
             'applied_n': list(sim.applied),
             'rejected_commands': sim.rejected_commands,
             'wrong_stamp_commands': self.wrong_stamp_commands,
             'last_wrong_stamp': self.last_wrong_stamp or 'none',
             'emergency_brake': sim.emergency_brake,
             'emergency_brake_held_s': self.emergency_brake_held_s(),
             'steps_published': self.steps_published,
             'watchdog': sim.watchdog, 'missed_periods': sim.missed_periods,
             **self.supervision_values(),
             'mode_index': sim.setup.mode_index(sim.time_s, sim.lead_position()),
             'active_failures': '; '.join(f.describe() for f in
                                          sim.actuators.active(sim.time_s).values()) or 'none',
             'scheduled_failures': len(sim.actuators.failures),
             'waiting_for_command_s': (time.monotonic() - self.step_since_wall
                                       if self.waiting else 0.0),
             'held_for_recorder_s': (time.monotonic() - self.recorder_lead.held_since
                                     if self.held else 0.0),
             'steps_held_for_recorders': (self.recorder_lead.steps_held
                                          if self.recorder_lead else 0),
             'state_subscribers': self.truth_pub.get_subscription_count(),
             'identity': self.identity,
             **self.publishing.values()})
        self.publishing(self.diag_pub, DiagnosticArray(header=self._header(), status=[status]))

    def supervision_values(self) -> dict:
        """The ATP's and its odometry's state, for the diagnostics."""
        atp, odometry = self.sim.atp, self.sim.odometry
        return {'supervised_leg': atp.leg, 'supervision_status': atp.status(odometry),
                'atp_intervention': atp.emergency_brake,
                'atp_interventions': atp.interventions,
                'holding_brake': atp.holding_brake,
                'permitted_speed_mps': atp.permitted_speed(odometry),
                'odometry_position_m': odometry.position_m,
                'odometry_interval_m': odometry.max_safe_front_m - odometry.min_safe_front_m,
                'odometry_speed_mps': odometry.speed_mps,
                'odometry_relocations': odometry.relocations,
                'odometry_last_discrepancy_m': odometry.last_discrepancy_m,
                'odometry_outside_interval': odometry.outside_interval}

    def emergency_brake_held_s(self) -> float:
        """How long the emergency brake has been held without a break, s of simulated time."""
        since = self.sim.actuators.brake_since_s
        return 0.0 if since is None else self.sim.time_s - since

    def _header(self) -> Header:
        return Header(stamp=to_time(self.stamp_ns()))

    # --- events -------------------------------------------------------------------------------
    def check_use_sim_time(self, parameters):
        from rcl_interfaces.msg import SetParametersResult
        for parameter in parameters:
            if parameter.name == 'use_sim_time' and parameter.value and not self.lockstep:
                return SetParametersResult(
                    successful=False, reason='use_sim_time true on a real-time plant: nobody '
                    'publishes /clock, its clock would stop and it would publish nothing')
        return SetParametersResult(successful=True)

    def check_inject_failure(self, changes) -> str | None:
        """``ros2 param set /train_plant_node inject_failure '...'``: a text that does not parse
        is rejected with the reason and changes nothing."""
        if 'inject_failure' not in changes:
            return None
        try:
            failures, _ = parse_failure_injection(changes['inject_failure'],
                                                  self.sim.actuator_names, self.sim.time_s)
            for failure in failures:
                check_failure(failure, self.truth.train)
        except (ConfigError, FailureRejected) as error:
            return f'inject_failure: {error}' if isinstance(error, FailureRejected) \
                else str(error)
        return None

    def apply_parameters(self, parameters) -> None:
        for parameter in parameters:
            if parameter.name == 'inject_failure':
                self.inject_failure(parameter.value)

    def report_start_wait(self, topic: str, now: float) -> None:
        """A first step that waited beyond command_wait_limit_s for the subscribers it waits for
        is reported (WARN log), again each such period: a run never waits silently."""
        if self.start_wait_since is None:
            self.start_wait_since = now
        waited, limit = now - self.start_wait_since, self.params['command_wait_limit_s']
        if waited < limit or now - self.waiting_reported_wall < limit:
            return
        self.waiting_reported_wall = now
        self.get_logger().warning(
            f'not started after {waited:.1f} s of wall time: {topic} has fewer subscribers than '
            f'the first step waits for (wait_for_subscribers {self.params["wait_for_subscribers"]} '
            f'on train/state; wait_for_recorders {self.params["wait_for_recorders"]} on '
            f'ato/step_records and, with wait_for_diagnostics_readers '
            f'{self.params["wait_for_diagnostics_readers"]}, on /diagnostics: a recorder of a '
            'list of topics without /diagnostics never subscribes to it)')

    def inject_failure(self, text: str) -> None:
        """Apply an accepted ``inject_failure`` text at once."""
        failures, repaired = parse_failure_injection(text, self.sim.actuator_names,
                                                     self.sim.time_s)
        self.sim.inject_failures(failures, repaired)
        for failure in failures:
            self.get_logger().warning(f'failure injected: {failure.describe()}')
        for name in repaired:
            self.get_logger().info(f'actuator {name} repaired')
        self.next_diagnostic_ns = 0

    def on_timer(self) -> None:
        if self.finished:
            return
        if not self.started:
            now = time.monotonic()
            unmatched = self.truth_pub.topic_name if (
                self.truth_pub.get_subscription_count() < self.params['wait_for_subscribers']
            ) else self.unmatched_output()
            if unmatched:
                self.report_start_wait(unmatched, now)
                return
            if self.ready_since is None:
                self.ready_since = now
            if now - self.ready_since < self.params['start_delay_s']:
                return
            self.started = True
            self.wall_start_ns = self.get_clock().now().nanoseconds
            self.publish_step()
            return
        if self.lockstep:
            now = time.monotonic()
            lead = self.recorder_lead
            if lead is not None and lead.held is not None:
                lead.check()  # a recorder that left lets go
                self.report_held(now)
                return
            if now - self.last_publish_wall >= self.params['resend_period_s']:
                self.publish_step()  # the command for this step has not come: say it again
            waited = now - self.step_since_wall
            limit = self.params['command_wait_limit_s']
            if waited >= limit and now - self.waiting_reported_wall >= limit:
                self.waiting_reported_wall = now
                self.waiting = (f'waiting {waited:.1f} s of wall time for the command of the '
                                f'step at {self.sim.time_s:.3f} s (limit {limit:g} s)')
                self.get_logger().warning(f'{self.waiting}: simulated time stands still until '
                                          'a command comes')
                self.publish_diagnostics()
        else:
            missed = int((time.monotonic() - self.last_valid_command_wall) * 1e9
                         // self.control_period_ns)
            if missed > 0:
                self.sim.command_missed(missed)
            # Keep simulated time on the wall clock: a late timer tick is caught up with
            # several fixed steps (at most a second's worth), each published, so the state
            # stream has no holes.
            behind_ns = self.get_clock().now().nanoseconds - self.wall_start_ns - self.sim.stamp_ns
            steps = min(max(behind_ns // self.period_ns, 1), nanoseconds(1.0) // self.period_ns)
            for _ in range(steps):
                self.advance()
                if self.finished:
                    break

    def report_held(self, now: float) -> None:
        """A step held for a recorder beyond command_wait_limit_s is reported (WARN log and
        diagnostics), again each such period."""
        lead, limit = self.recorder_lead, self.params['command_wait_limit_s']
        if lead.held is None or now - lead.held_since < limit or \
                now - self.held_reported_wall < limit:
            return
        self.held_reported_wall = now
        self.held = lead.waiting()
        if self.held:
            self.get_logger().warning(f'{self.held}: simulated time stands still until it '
                                      'catches up or leaves')
            self.publish_diagnostics()

    def on_command(self, data: bytes) -> None:
        if not self.started or self.finished:
            return
        try:
            command = decoded(data, wire.decode_command, JointState, command_from_msg,
                              self.sim.actuator_names)
            if self.lockstep and command.stamp_ns == self.stamp_ns() - self.period_ns:
                return  # the previous step's command again (it answered a re-sent step)
            wrong = self.wrong_stamp(command.stamp_ns)
            if wrong:
                # Dropped and counted. In lockstep it is no command for this step: the plant
                # waits on for the one stamped for it (re-sending the step), so a controller
                # that fell behind or ahead answers the step it is sent and the loop is in
                # step again; advancing here would leave the gap open for good.
                self.wrong_stamp_commands += 1
                self.last_wrong_stamp = wrong
                self.get_logger().warning(wrong, throttle_duration_sec=1.0)
                if self.lockstep:
                    self.publish_diagnostics()
                return
            self.sim.apply_command(command.forces)
            self.last_valid_command_wall = time.monotonic()
            if self.last_rejection:
                self.get_logger().info('valid commands again')
                self.last_rejection = ''
            self.last_wrong_stamp = ''  # the count stays; the cause is no longer current
        except (MessageError, CommandRejected) as error:
            if isinstance(error, MessageError):  # CommandRejected is counted by the simulation
                self.sim.rejected_commands += 1
            self.last_rejection = f'rejected command: {error}; holding the previous one'
            self.get_logger().warning(self.last_rejection, throttle_duration_sec=1.0)
            self.publish_diagnostics()
            if self.lockstep and wire.stamp_of(data) != self.stamp_ns():
                return
            if self.lockstep:
                self.sim.command_missed()  # this step's command was not valid
        if self.lockstep:
            self.advance()

    def wrong_stamp(self, stamp_ns: int) -> str:
        """Why a command's stamp rules it out ('' if it does not): in lockstep a stamp other
        than the current step's (the previous step's, a reply to a re-sent step, is ignored
        before); in real time one further than ``command_stamp_tolerance_s`` from now."""
        now_ns = self.stamp_ns() if self.lockstep else self.get_clock().now().nanoseconds
        offset = seconds(stamp_ns - now_ns)
        if self.lockstep:
            if stamp_ns == now_ns:
                return ''
        elif abs(offset) <= self.params['command_stamp_tolerance_s']:
            return ''
        where = 'ahead of' if offset > 0 else 'behind'
        return (f'command stamped {abs(offset):.3f} s {where} '
                f"{'the step' if self.lockstep else 'now'} ({seconds(now_ns):.3f} s): dropped")

    def advance(self) -> None:
        self.sim.advance(self.period_ns)
        self.publish_step()
        limit = self.params['emergency_brake_limit_s']
        if limit and self.emergency_brake_held_s() > limit:
            self.end_on_held_brake(limit)
            return
        if self.end_ns and self.sim.stamp_ns >= self.end_ns:
            self.publish_diagnostics()
            held = self.recorder_lead
            self.get_logger().info(f'end of run at t = {self.sim.time_s:.3f} s' + (
                f'; {held.steps_held} steps waited {held.held_s:.2f} s of wall time in all for '
                'the recorders' if held and held.steps_held else ''))
            self.finished = True

    def end_on_held_brake(self, limit_s: float) -> None:
        """The emergency brake has held longer than ``emergency_brake_limit_s``: the run
        cannot go on as a run of the ATO, so it ends now with ``EMERGENCY_BRAKE_HELD``, the
        reason in the log and the diagnostics."""
        sim = self.sim
        cause = self.safety_message() or 'emergency brake'
        self.ended = (f'run ended at t = {sim.time_s:.3f} s: the emergency brake held for '
                      f'{self.emergency_brake_held_s():.1f} s of simulated time, over the limit '
                      f'emergency_brake_limit_s {limit_s:g} s ({cause})')
        self.get_logger().error(self.ended)
        self.publish_diagnostics()
        self.exit_code = EMERGENCY_BRAKE_HELD
        self.finished = True

    def close_outputs(self) -> None:
        """The last step (and diagnostics) reach every matched subscriber before the exit."""
        if not self.started:
            return
        self.records.flush()  # the last steps' records
        publishers = [self.truth_pub, self.measured_pub, self.commanded_pub, self.applied_pub,
                      self.diag_pub, self.records.publisher] + (
                          [self.clock_pub] if self.clock_pub else [])
        if not wait_until_delivered(publishers, self.params['final_delivery_timeout_s']):
            self.get_logger().warning(
                'some subscribers did not acknowledge the last messages within '
                f"{self.params['final_delivery_timeout_s']:g} s (gone?); exiting anyway")


def main(args=None) -> int:
    return run_node(TrainPlantNode, args,
                    usage=lambda: node_usage('train_plant_node', 'train_plant_node', __doc__,
                                             PARAMS))


if __name__ == '__main__':
    raise SystemExit(main())
