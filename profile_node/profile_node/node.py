"""profile_node: streams the target curve planned by :mod:`profile_node.planner`.

Per control instant: the reference x*, v*, a* (and the jerk, in the effort field) with a
preview; the distance from the reference position to the next target of the curve (a lower
speed limit's start, or the stop approached or dwelt at); the supervision's permitted speed at
the reference position (the lowest of the static limits and the braking curves,
:mod:`ato_common.braking_curves`).

Lockstep: the reference (with a preview) is published for each control instant, stamped with it;
the distance to go and the permitted speed too, while they have a subscriber (the loop does not
read them: ``ato_common.conventions.OBSERVED_STEP``). The reference is a function of time only,
so once the clock period is known (two ticks) the profile publishes the next instant's reference
one period ahead: the controller then finds it waiting when the plant's state arrives, which
takes the profile off the loop's critical path. A tick whose reference was not sent ahead (the
first ones, a changed period, a re-sent tick) gets it at once. Real time: the same on a wall-
clock timer, with the curve's time origin taken from the plant's first state message (its stamp
minus its run time). The whole curve is latched once at start-up. No reference goes out before
the plant's latched identity has been read and is this scenario's (``watch_plant_identity``: a
plant of another scenario is refused, exit 2); in lockstep the latest tick that came before it
is answered when it comes (the plant re-sends a tick only while it waits for a command).

Resume: a plant that starts again (its run time goes back; in lockstep its /clock) gives the
curve its time origin again, so the reference starts from the start of the run, not the dead
plant's origin. A measured train standing still more than ``RESUME_GAP_M`` behind the reference
(after an emergency or watchdog brake) gets the rest of its leg planned again from where it
stands (``planner.resume_plan``), so the law does not chase a reference far ahead. The latched
curve stays the original plan.

Checks in lockstep: the measured state is read only at check instants, the first tick at or
after each multiple of ``replan_check_period_s`` of simulated time, taken from a subscription
no executor spins (keep last ``MEASURED_DEPTH``: the states between checks are overwritten in
the middleware, never taken). A decision from the state of check instant t_c (a replan, a
resume) applies to the references from t_c + 2 control periods on
(``profile_node.replan.LockstepPlans``); a reference such a check decides is not sent ahead
before the check's state has come (if it has not, the tick is answered when the plant re-sends
it). The run stays bit-reproducible, and decides as the offline loop given the same period. With
no publisher of the measured state (a profile driven by /clock alone) no check is made.

Graph: ``wait_for_subscribers`` holds back only the first reference (an observer that goes away
later does not stop the loop); the plant's latched identity must be the profile's own scenario,
else the profile refuses to run (exit code 2, naming both); a failed publish is counted and
logged, never fatal. A preview of more than ``MAX_PREVIEW_POINTS`` points is refused.

The plan (strategy, forecast energy, expected delay, each stop's target and planned arrival and
reserve, each journey timing point's planned time) is published on ``/diagnostics`` as the
status ``<node>: plan``, only when the plan changes: at the first tick, then at each
replan or resume (no per-step message; the status message says ``replanned`` or ``resumed``).
``timetable`` strategy: a moving train late by more than ``timetable.replan_delay_s`` gets the
rest of its run planned again from its measured state (``profile_node.replan``): in real time
at each measurement, in lockstep at the check instants.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.clock import Clock as WallClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64, Header
from trajectory_msgs.msg import JointTrajectory

from ato_common.identity import scenario_identity
from ato_common.scenario import DEFAULT_SCENARIO, load_scenario
from ato_common.types import Reference, ReferencePoint, nanoseconds, seconds
from ato_common.validation import ConfigError
from ato_ros import wire
from ato_ros.lifecycle import RunNodeHooks, freeze_startup_objects, node_usage, run_node
from ato_ros.messages import (
    MessageError,
    decoded,
    diagnostic_status,
    from_duration,
    from_time,
    qos_profile,
    reference_to_msg,
    state_from_msg,
    status_name,
    to_time,
    topic,
)
from ato_ros.params import WAIT_FOR_DIAGNOSTICS_READERS, Param, ParameterTable
from ato_ros.publishing import (
    Observation,
    Publishing,
    first_unmatched,
    step_recorder,
    watch_plant_identity,
)
from profile_node.planner import RESUME_GAP_M, Plan, plan_reference
from profile_node.replan import CHECK_PERIOD_S, LockstepPlans, Replanner
from profile_node.timetable import plan_summary

# The plan's diagnostics warn from this expected delay on, s (below: the solver's accuracy).
DELAY_WARNING_S = 1.0

# Each preview point costs the profile a curve evaluation and every reader of ato/reference its
# bytes, on every step: 60,001 of them (a 600 s horizon every 0.01 s) slowed a lockstep run from
# 15.6x to 0.03x real time. A hundred cover a 100 s horizon at the default 1 s spacing.
MAX_PREVIEW_POINTS = 100

# Lockstep: the measured states the profile's unspun subscription keeps (taken oldest first).
# When a check instant's state is read, the plant has published at most the states up to two
# periods after it (it waits for the reference the check decides), so a few suffice; the
# states between checks are overwritten in the middleware, never taken.
MEASURED_DEPTH = 8


#: how often a tick held for the first output's subscribers is tried again, s of wall time
TICK_RETRY_PERIOD_S = 0.1


def encode_distance_to_go(plan: Plan, now: ReferencePoint) -> bytes:
    """/ato/distance_to_go of a reference point of ``plan``: to the next target, m."""
    return wire.encode_float64(plan.next_target(now.position, now.time_s).location_m
                               - now.position)


def encode_permitted_speed(plan: Plan, now: ReferencePoint) -> bytes:
    """/ato/permitted_speed of a reference point of ``plan``: the supervision's, m/s."""
    return wire.encode_float64(plan.permitted_speed(now.position, now.time_s))


def preview_problem(horizon_s: float, step_s: float) -> str | None:
    """None if the preview of ``horizon_s`` every ``step_s`` is acceptable, else the reason."""
    points = int(horizon_s / step_s + 1e-9) + 1
    if points > MAX_PREVIEW_POINTS:
        return (f'preview_horizon_s {horizon_s:g} every preview_step_s {step_s:g} is {points} '
                f'preview points per step, more than {MAX_PREVIEW_POINTS}: each costs CPU on '
                'every step in the profile and in every reader; lengthen the step or shorten '
                'the horizon')
    return None


PARAMS = (
    Param('scenario', DEFAULT_SCENARIO, 'built-in scenario name or path to a scenario YAML file'),
    Param('lockstep', True, 'publish on every /clock tick (false: on a wall-clock timer)'),
    Param('rate_hz', 10.0, 'publication rate in real-time mode, Hz', minimum=0.1, maximum=1000.0),
    Param('preview_horizon_s', 2.0, 'length of the preview published with each reference, s',
          minimum=0.0, maximum=600.0, read_only=False),
    Param('preview_step_s', 1.0, 'spacing of the preview points, s', minimum=0.01,
          maximum=60.0, read_only=False),
    Param('wait_for_subscribers', 0, 'lockstep: publish no reference before ato/reference has '
          'this many subscribers (so a monitor or recorder misses nothing)', minimum=0,
          maximum=100),
    Param('wait_for_recorders', 0, 'lockstep: recorders of the run (the suite\'s recorder, '
          'which takes the per-step topics from ato/step_records): nothing is published before '
          'ato/step_records and /diagnostics each have this many subscribers too', minimum=0,
          maximum=100),
    WAIT_FOR_DIAGNOSTICS_READERS,
    Param('curve_sample_period_s', 1.0, 'spacing of the latched whole-curve samples, s',
          minimum=0.01, maximum=60.0),
    Param('replan_check_period_s', CHECK_PERIOD_S, 'lockstep: simulated time between two '
          'checks of the measured state (replan a late train, resume a standing one), s',
          minimum=0.01, maximum=3600.0),
)


class ProfileNode(RunNodeHooks, Node):
    def __init__(self):
        super().__init__('profile_node')
        self.params = ParameterTable(self, PARAMS)
        problem = preview_problem(self.params['preview_horizon_s'], self.params['preview_step_s'])
        if problem:
            raise ConfigError(problem)
        self.params.extra_checks.append(self.check_preview)
        self.scenario = load_scenario(self.params['scenario'])
        self.plan = plan_reference(self.scenario)
        self.trajectory = self.plan.trajectory
        self.lockstep = self.params['lockstep']
        self.time_origin_ns: int | None = 0 if self.lockstep else None
        self.last_tick_ns: int | None = None
        self.sent_ahead_ns: int | None = None
        # (plan, stamp, point): the first point of the last reference sent (reference_at)
        self.reference_now: tuple | None = None
        self.last_run_time_ns = -1
        self.resumes = 0
        self.subscribers_met = False
        self.publishing = Publishing(self)
        self.identity = scenario_identity(self.scenario)
        self.replanner = Replanner(self.scenario, self.plan)
        self.plan_reported = False
        self.checks: list[int] = []  # lockstep: check instants whose state is still to read
        self.plans: LockstepPlans | None = None
        self.sampler: Node | None = None
        self.unchecked_reported = False
        self.diag_pub = self.create_publisher(DiagnosticArray, topic('diagnostics').name,
                                              qos_profile(topic('diagnostics').qos))
        # The per-step messages for the recorders, bundled (ato_ros.step_records); created before
        # the per-step publishers (``ato_ros.publishing.step_recorder``).
        self.records = step_recorder(self, self.publishing)
        self.reference_pub = self.create_publisher(JointTrajectory, topic('reference').name,
                                                   qos_profile(topic('reference').qos))
        self.dtg_pub = self.create_publisher(Float64, topic('distance_to_go').name,
                                             qos_profile(topic('distance_to_go').qos))
        self.permitted_pub = self.create_publisher(Float64, topic('permitted_speed').name,
                                                   qos_profile(topic('permitted_speed').qos))
        self.dtg_observation = Observation(self, self.dtg_pub)
        self.permitted_observation = Observation(self, self.permitted_pub)
        curve_pub = self.create_publisher(JointTrajectory, topic('curve').name,
                                          qos_profile(topic('curve').qos))
        self.publishing(curve_pub, self.curve_msg())
        self._curve_pub = curve_pub  # keep the latched publisher alive
        # the plant's identity read, and ours (watch_plant_identity): no reference before it
        self.identified = False
        # the latest tick that came before it, or while the first output's subscribers were
        # not all matched (answered by ``retry_timer`` once they are)
        self.unanswered_tick: bytes | None = None
        self.retry_timer = None
        watch_plant_identity(self, self.identity, 'refusing to stream the target curve',
                             self.on_identified)
        if self.lockstep:
            self.start_lockstep_plans()
            # Not spun (a node of its own, on no executor): the measured state is taken from
            # it only at check instants (module docstring), not paid for at every step.
            # Not renamed by the process's remappings (``-r __node:=...`` renames every node
            # of a process): a node of its own name, in this node's namespace.
            self.sampler = Node(f'{self.get_name()}_measured_sampler', context=self.context,
                                namespace=self.get_namespace(), use_global_arguments=False,
                                start_parameter_services=False)
            self.measured_sub = self.sampler.create_subscription(
                JointTrajectory, self.resolve_topic_name(topic('state_measured').name),
                lambda msg: None, QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                                             history=HistoryPolicy.KEEP_LAST,
                                             depth=MEASURED_DEPTH), raw=True)
            self.create_subscription(Clock, topic('clock').name, self.on_clock,
                                     qos_profile(topic('clock').qos), raw=True)
        else:
            self.create_subscription(JointTrajectory, topic('state').name, self.on_state,
                                     qos_profile(topic('state').qos))
            self.create_subscription(JointTrajectory, topic('state_measured').name,
                                     self.on_measured, qos_profile(topic('state_measured').qos))
            self.create_timer(1.0 / self.params['rate_hz'], self.on_timer)
        self.get_logger().info(
            f'scenario {self.scenario.name}: {len(self.plan.stops)} stops, '
            f'{len(self.plan.targets)} targets, reference ends at '
            f'{self.trajectory.end_time:.1f} s, {len(self.trajectory.segments)} segments')
        for check in self.plan.timing:
            if not check.within_window:
                point = check.point
                self.get_logger().warning(
                    f'journey timing point at {point.position_m:.0f} m: the curve is there at '
                    f'{check.planned_s:.1f} s, outside [{point.earliest_s}, {point.latest_s}] s')
        freeze_startup_objects()

    def start_lockstep_plans(self) -> None:
        period_ns = nanoseconds(1.0 / self.scenario.run.controller_rate_hz)
        self.plans = LockstepPlans(self.scenario, self.plan, period_ns,
                                   self.params['replan_check_period_s'])
        self.replanner = self.plans.replanner
        self.checks = []

    def close_outputs(self) -> None:
        if not self.records.close():  # the last steps' records
            self.get_logger().warning('a recorder did not acknowledge the last step records '
                                      'in time (gone?)')
        if self.sampler is not None:
            self.sampler.destroy_node()
            self.sampler = None

    @property
    def lockstep_plans(self) -> LockstepPlans:
        """The plans of a lockstep run (read only in lockstep)."""
        # set on construction in lockstep (start_lockstep_plans), before the /clock
        # subscription, and never unset
        assert self.plans is not None
        return self.plans

    def run_time_s(self, stamp_ns: int) -> float:
        """The curve's time at a stamp."""
        # 0 from construction in lockstep; in real time, taken from the plant's first state,
        # before which on_timer publishes nothing
        assert self.time_origin_ns is not None
        return seconds(stamp_ns - self.time_origin_ns)

    def plan_for(self, stamp_ns: int) -> Plan:
        """The plan whose reference is streamed for ``stamp_ns``."""
        return self.plan if self.plans is None else self.plans.plan_at(stamp_ns)

    def check_preview(self, changes) -> str | None:
        return preview_problem(changes.get('preview_horizon_s', self.params['preview_horizon_s']),
                               changes.get('preview_step_s', self.params['preview_step_s']))

    def curve_msg(self) -> JointTrajectory:
        step = self.params['curve_sample_period_s']
        count = int(self.trajectory.end_time // step) + 1
        # The exact arrival and departure of every stop are samples too, so a reader of the
        # curve (a report from a recording) finds the stops where the plan has them.
        times = sorted({i * step for i in range(count)} | {self.trajectory.end_time}
                       | {t for stop in self.plan.stops for t in (stop.arrival_s,
                                                                   stop.departure_s)})
        points = tuple(self.trajectory.at(t) for t in times)
        return reference_to_msg(Reference(0, points))

    def reference_at(self, stamp_ns: int) -> Reference:
        t = self.run_time_s(stamp_ns)
        horizon, step = self.params['preview_horizon_s'], self.params['preview_step_s']
        count = int(horizon / step + 1e-9)
        plan = self.plan_for(stamp_ns)
        at = plan.trajectory.at
        reference = Reference(stamp_ns, tuple(at(t + i * step) for i in range(count + 1)))
        # the reference now of this plan: what publish_supervision reads at this stamp
        self.reference_now = (plan, stamp_ns, reference.points[0])
        return reference

    def point_now(self, plan: Plan, stamp_ns: int):
        """The reference point of ``plan`` at ``stamp_ns``: the first of the reference sent for
        that stamp (in lockstep sent a tick ahead) if it was of this plan, else computed."""
        known = self.reference_now
        if known is not None and known[0] is plan and known[1] == stamp_ns:
            return known[2]
        return plan.trajectory.at(self.run_time_s(stamp_ns))

    def publish(self, stamp_ns: int) -> None:
        # as CDR bytes packed from a template (ato_ros.wire): a standard JointTrajectory
        data = wire.encode_reference(self.reference_at(stamp_ns))
        self.publishing(self.reference_pub, data)
        self.records.add(self.reference_pub, stamp_ns, data)

    def publish_supervision(self, stamp_ns: int) -> None:
        """Distance to go and permitted speed now (unstamped: only ever for the current tick),
        each computed and published while it has a subscriber (``ros.Observation``), and
        otherwise, while a recorder records (``records``), computed only when the recorder
        takes the step records (``StepRecorder.add_later``)."""
        dtg, permitted = self.dtg_observation.due(), self.permitted_observation.due()
        recording = self.records.active
        if not (dtg or permitted or recording):
            return
        plan = self.plan_for(stamp_ns)
        now = self.point_now(plan, stamp_ns)
        for publisher, due, encode in ((self.dtg_pub, dtg, encode_distance_to_go),
                                       (self.permitted_pub, permitted, encode_permitted_speed)):
            if due:
                data = encode(plan, now)
                self.publishing(publisher, data)
                self.records.add(publisher, stamp_ns, data)
            else:
                self.records.add_later(publisher, stamp_ns, encode, plan, now)

    def publish_plan(self, stamp_ns: int, why: str, plan: Plan | None = None) -> None:
        """The plan on diagnostics: only when it changes (start, replan, resume)."""
        self.plan_reported = True
        plan = plan or self.plan
        late = plan.expected_delay_s > DELAY_WARNING_S
        status = diagnostic_status(status_name(self, 'plan'), self.scenario.name,
                                   DiagnosticStatus.WARN if late else DiagnosticStatus.OK, why,
                                   plan_summary(plan))
        self.publishing(self.diag_pub, DiagnosticArray(header=Header(stamp=to_time(stamp_ns)),
                                                       status=[status]))

    def on_identified(self) -> None:
        """The plant's identity is this scenario's: the latest tick that came before it is
        answered now, and its step records sent at once. The plant re-sends a tick only while
        it waits for a command; an ATO node of one's own that does not wait for the reference
        lets it run on without one, up to a recorder's lead, and a recorder vouches for nothing
        before it has the profile's records (``ato_ros.step_records.Written``): a tick left
        unanswered here would hold the loop for good."""
        if self.lockstep:
            self.answer_held_tick()
        else:
            self.unanswered_tick = None

    def hold_tick(self, data: bytes) -> None:
        """A tick that came before the first output's subscribers were all matched: answered
        once they are. The plant re-sends a tick while it waits for a command, but an ATO node
        of one's own that does not wait for the reference lets it run on without one, so a
        tick dropped here (the last before such a node's run, or the one ``on_identified``
        answers) could hold the loop for good; checked every ``TICK_RETRY_PERIOD_S`` of wall
        time until answered."""
        self.unanswered_tick = data
        if self.retry_timer is None:
            self.retry_timer = self.create_timer(
                TICK_RETRY_PERIOD_S, self.retry_tick,
                clock=WallClock(clock_type=ClockType.STEADY_TIME))

    def retry_tick(self) -> None:
        if not self.answer_held_tick() and self.retry_timer is not None:
            self.destroy_timer(self.retry_timer)
            self.retry_timer = None

    def answer_held_tick(self) -> bool:
        """Answer the tick held (``unanswered_tick``), its step records sent at once; whether
        a tick is still held (a subscriber still missing)."""
        data, self.unanswered_tick = self.unanswered_tick, None
        if data is not None:
            self.on_clock(data)  # held again if a subscriber is still missing
            if self.unanswered_tick is None:
                self.records.flush()
        return self.unanswered_tick is not None

    def on_clock(self, data: bytes) -> None:
        if not self.identified:
            # nothing to a plant it may refuse: answered once its identity comes (on_identified)
            self.unanswered_tick = data
            return
        if not self.subscribers_met:
            recorders = self.params['wait_for_recorders']
            if first_unmatched(((self.reference_pub, self.params['wait_for_subscribers']),
                                (self.records.publisher, recorders),
                                (self.diag_pub,
                                 recorders + self.params['wait_for_diagnostics_readers']))):
                self.hold_tick(data)
                return
            self.subscribers_met = True
        self.unanswered_tick = None  # this tick is as late as any held
        try:
            tick = decoded(data, wire.decode_clock, Clock, lambda msg: from_time(msg.clock))
        except MessageError as error:
            self.get_logger().warning(f'bad /clock message: {error}', throttle_duration_sec=1.0)
            return
        if self.last_tick_ns is not None and tick < self.last_tick_ns:
            self.restart_lockstep()
        if self.lockstep_plans.schedule(tick):
            self.checks.append(tick)
        if not self.plan_reported:
            self.publish_plan(tick, f'{self.plan.strategy} plan')
        self.records.begin_step()
        if tick != self.sent_ahead_ns or tick == self.last_tick_ns:
            # not sent ahead, or the plant re-sent the tick
            if not self.decided_until(tick):
                return  # the state of a check instant has not come: the plant re-sends the tick
            self.publish(tick)
        self.publish_supervision(tick)
        if self.last_tick_ns is not None and tick > self.last_tick_ns:
            ahead = 2 * tick - self.last_tick_ns
            if self.decided_until(ahead):  # else it is sent at its own tick
                self.sent_ahead_ns = ahead
                self.publish(ahead)
        self.last_tick_ns = tick
        self.records.end_step(tick)

    def restart_lockstep(self) -> None:
        """A new plant (its simulated time went back): the run and the curve start again."""
        self.plan = plan_reference(self.scenario)
        self.trajectory = self.plan.trajectory
        self.start_lockstep_plans()
        self.last_tick_ns = self.sent_ahead_ns = None
        self.plan_reported = False
        self.get_logger().warning('lockstep: the plant started again; the curve restarts from '
                                  'its origin')

    def decided_until(self, stamp_ns: int) -> bool:
        """Whether every check instant whose decision applies to the reference of
        ``stamp_ns`` has been decided (its measured state read now if it has come)."""
        start_of = self.lockstep_plans.start_of
        if not self.checks or start_of(self.checks[0]) > stamp_ns:
            return True
        self.read_checks()
        if self.checks and self.measured_sub.get_publisher_count() == 0:
            # Nobody publishes the measured state (a profile driven by /clock alone, or before
            # the plant's publisher is matched): no state can come, so no check can be made.
            if not self.unchecked_reported:
                self.unchecked_reported = True
                self.get_logger().info('lockstep: no publisher of the measured state: the '
                                       'reference goes on without checks of the train')
            self.checks.clear()
        return not self.checks or start_of(self.checks[0]) > stamp_ns

    def read_checks(self) -> None:
        """Take the measured states that have come, up to the oldest pending check instant's,
        and decide from it (``LockstepPlans.check``); the older ones are dropped."""
        sub = self.measured_sub
        while self.checks:
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                return
            stamp = wire.stamp_of(taken[0])  # as bytes: only a check's state is read
            if stamp is None:
                continue
            while self.checks and self.checks[0] < stamp:
                self.get_logger().error(
                    f'lockstep: the measured state of {seconds(self.checks.pop(0)):.3f} s was '
                    f'overwritten before it was read (more than {MEASURED_DEPTH} states came '
                    'after it): no check at that instant')
            if self.checks and self.checks[0] == stamp:
                self.checks.pop(0)
                self.check_measured(stamp, taken[0])

    def check_measured(self, stamp_ns: int, data: bytes) -> None:
        try:
            state = decoded(data, wire.decode_state, JointTrajectory, state_from_msg)
        except MessageError as error:
            self.get_logger().warning(f'lockstep: the measured state of '
                                      f'{seconds(stamp_ns):.3f} s is not usable ({error})')
            return
        decision = self.lockstep_plans.check(stamp_ns, state.positions[0], state.speeds[0])
        if decision is None:
            return
        self.plan = decision.plan
        self.trajectory = decision.plan.trajectory
        self.report_decision(decision.kind, decision.checked_ns, decision.position_m,
                             decision.plan, seconds(decision.start_ns))

    def report_decision(self, kind: str, stamp_ns: int, position: float, plan: Plan,
                        start_s: float) -> None:
        if self.replanner.note:  # an odometer's error placed the train outside the line
            self.get_logger().warning(self.replanner.note)
        if kind == 'replanned':
            late = self.replanner.replans[-1][1]
            self.get_logger().warning(
                f'the train is late by {late:.1f} s at {position:.1f} m: the rest of the run is '
                f'planned again from {start_s:.2f} s, expected delay '
                f'{plan.expected_delay_s:.1f} s')
            self.publish_plan(stamp_ns, 'replanned: the train was late', plan)
        else:
            self.resumes += 1
            self.get_logger().warning(
                f'the train stands at {position:.1f} m, behind the reference by more than '
                f'{RESUME_GAP_M:g} m: the leg is planned again from there from {start_s:.2f} s '
                f'({self.resumes} resumes)')
            self.publish_plan(stamp_ns, 'resumed: the train stood behind the reference', plan)

    def on_state(self, msg: JointTrajectory) -> None:
        if not msg.points:
            return
        run_time_ns = nanoseconds(from_duration(msg.points[0].time_from_start))
        restarted = run_time_ns < self.last_run_time_ns
        self.last_run_time_ns = run_time_ns
        if self.time_origin_ns is None or restarted:
            self.time_origin_ns = from_time(msg.header.stamp) - run_time_ns
            if restarted:  # a new plant: its run starts again, and so does the curve
                self.plan = plan_reference(self.scenario)
                self.trajectory = self.plan.trajectory
                self.replanner = Replanner(self.scenario, self.plan)
                self.plan_reported = False
                self.get_logger().warning('real time: the plant started again; the curve '
                                          'restarts from its origin')
            else:
                self.get_logger().info('real time: curve origin taken from the plant')

    def on_measured(self, msg: JointTrajectory) -> None:
        """Real time: resume the curve from a train that stands far behind it."""
        if self.time_origin_ns is None:
            return
        try:
            state = state_from_msg(msg)
        except MessageError:
            return  # the controller reports a bad measurement
        position, speed = state.positions[0], state.speeds[0]
        now_ns = self.get_clock().now().nanoseconds
        time_s = seconds(now_ns - self.time_origin_ns)
        decided = self.replanner.decide(time_s, position, speed)
        if decided is None:
            return
        kind, self.plan = decided
        self.trajectory = self.plan.trajectory
        self.report_decision(kind, now_ns, position, self.plan, time_s)

    def on_timer(self) -> None:
        if self.time_origin_ns is not None and self.identified:
            now = self.get_clock().now().nanoseconds
            if not self.plan_reported:
                self.publish_plan(now, f'{self.plan.strategy} plan')
            self.records.begin_step()
            self.publish(now)
            self.publish_supervision(now)
            self.records.end_step(now)


def main(args=None) -> int:
    return run_node(ProfileNode, args,
                    usage=lambda: node_usage('profile_node', 'profile_node', __doc__, PARAMS))


if __name__ == '__main__':
    raise SystemExit(main())
