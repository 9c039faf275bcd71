"""The closed loop on the same cores as the nodes, without ROS: fast, for unit tests, law
reproduction and benchmarks. Same order of operations as the lockstep graph: at each control
instant the plant's measurement and the reference at that time go to the controller, whose
command is held while the plant advances one period.

The plant simulates the whole scenario (the truth); the controller knows only
``knowledge_of(scenario)`` (ato_common.knowledge): the nominal train and the known modes. With
``uncertainty`` (the values of one draw, ato_common.uncertainty) the plant runs the perturbed
truth ``perturbed(scenario, uncertainty)`` while the controller keeps the knowledge of the
nominal ``scenario``: no drawn value of the truth reaches it (a draw's ``gradient_known`` 0
hides the gradient profile from its knowledge)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ato_common.knowledge import knowledge_of
from ato_common.metrics import RunMetrics, compute_metrics, read_stop_errors
from ato_common.scenario import Scenario
from ato_common.types import nanoseconds, seconds
from ato_common.uncertainty import knowledge_options, perturbed
from ato_controller_node.gains import configured
from ato_controller_node.host import ControllerHost
from ato_simulation.plans import (
    JourneyEnd,
    cached_plan,
    late_readings,
    run_end_time_s,
    sampled_references,
    scenario_key,
    stop_samples,
)
from profile_node.planner import Plan
from profile_node.replan import LockstepPlans, Replanner
from train_plant_node.simulation import NORMAL, SensorSettings, TrainSimulation


@dataclass
class OfflineRun:
    """One closed-loop run, sampled at every control instant. Lead-car arrays are 1-D; the
    ``car_*`` arrays have one column per car and ``actuator_forces`` one per actuator."""

    scenario: Scenario
    plan: Plan
    times_s: np.ndarray
    positions: np.ndarray
    speeds: np.ndarray
    forces: np.ndarray
    ref_positions: np.ndarray
    ref_speeds: np.ndarray
    ref_accelerations: np.ndarray
    car_positions: np.ndarray
    car_speeds: np.ndarray
    actuator_forces: np.ndarray
    step_times_s: np.ndarray
    laws: list[str] = field(default_factory=list)
    estimates: list[dict] = field(default_factory=list)
    faults: list[str] = field(default_factory=list)
    #: what the plant's safety functions counted: ATP emergency brake interventions, and
    #: control periods in which the command watchdog braked the train
    atp_interventions: int = 0
    watchdog_events: int = 0
    #: per control instant: the host limited the law's wanted force (StepResult.saturated)
    saturated: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: the end of each control period in which the plant's ATP began an intervention, s
    atp_times_s: tuple[float, ...] = ()
    #: the plans that replaced ``plan`` when the train was late (timetable strategy), in order
    replans: tuple[Plan, ...] = ()
    #: the rule that ended the run (None: a stated end, ``end_time_s`` or the scenario's)
    journey: JourneyEnd | None = None
    #: (stop, time) of each stop whose error is read where the train stood, not at its planned
    #: time (a late train's run: ``ato_simulation.plans.late_readings``)
    late_readings: tuple[tuple[str, float], ...] = ()
    #: the lead car's position as the train's own odometer measured it at each control instant
    #: (what the controller knows; ``positions`` is the truth)
    measured_positions: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def final_plan(self) -> Plan:
        return self.replans[-1] if self.replans else self.plan

    def metrics(self) -> RunMetrics:
        return compute_metrics(self.times_s, self.positions, self.speeds, self.forces,
                               self.ref_positions, self.ref_speeds,
                               stop_samples(self.plan, self.replans, self.late_readings),
                               self.scenario.train.regenerative_efficiency,
                               self.scenario.train.regenerative_power_w)

    def odometer_stop_errors_m(self) -> dict[str, float]:
        """The stopping error at each stop as the train's own odometer measured it, read as
        ``metrics().stop_errors_m`` is: the part of the stop error the controller can act on
        (the rest is the odometer's error there, which no law can see); none for a run built
        without the odometer's readings."""
        if self.measured_positions.size != self.times_s.size:
            return {}
        return read_stop_errors(self.times_s, self.measured_positions,
                                stop_samples(self.plan, self.replans, self.late_readings))

    @property
    def extended(self) -> bool:
        """The run went on past its planned end: its train was not standing at its last stop
        then (``ato_simulation.plans.JourneyEnd``)."""
        return self.journey is not None and self.times_s[-1] > self.journey.planned_s + 1e-9

    def estimate(self, key: str) -> np.ndarray:
        """One reported estimate over the run (NaN where the law did not report it)."""
        return np.array([e.get(key, np.nan) for e in self.estimates])


def run_offline(scenario: Scenario, controller: str = 'pid', settings=None,
                switches: dict[float, str] | None = None,
                sensors: SensorSettings = SensorSettings(), model: str = 'point_mass',
                end_time_s: float | None = None, controller_rate_hz: float | None = None,
                uncertainty=None, replan_check_period_s: float | None = None,
                gains: str = 'published', envelope: bool = True,
                **model_options) -> OfflineRun:
    """Run ``controller`` on ``scenario`` with the plant ``model``; ``switches`` maps times to
    law names selected then; ``end_time_s`` and ``controller_rate_hz`` override the scenario's
    (a law that must run faster than a node can, e.g. Mao et al.'s feedback linearisation);
    ``uncertainty``: the drawn values the plant's truth is perturbed by (None: nominal), and
    what the controller is told (``gradient_known``: ``knowledge_options``). The
    plan comes from this process's cache of plans (``cached_plan``); with the ``timetable``
    strategy it is replanned when the train falls behind it (``profile_node.replan``), and the
    run then follows the new plan (to its end, if that is later, up to the limit below).
    ``replan_check_period_s``:
    decide as the profile node does in lockstep (``profile_node.replan.LockstepPlans``: the
    measured state read at check instants this far apart, a replan or a resume from a standing
    train applied two periods later) instead of replanning from every step's state at once.

    Without ``end_time_s`` (and without a stated end in the scenario) the run's end follows
    the journey (``ato_simulation.plans.JourneyEnd``): the planned end if the train then
    stands at its last stop, else once it has stood there for the settle time (a late train),
    at the latest a stated limit past the timetable.

    ``gains``: the laws' configuration (``ato_controller_node.gains``: 'published' or 'tuned',
    for the scenario's train), with ``settings`` on top; ``envelope``: the host's ATO envelope
    (``ato_controller_node.envelope``) on or off, for every law."""
    laws = {controller, *(switches or {}).values()}
    settings = configured(gains, scenario.train.name, laws, settings)
    loop = _ClosedLoop(scenario, controller, settings, sensors, model, end_time_s,
                       controller_rate_hz, uncertainty, replan_check_period_s, model_options,
                       envelope)
    loop.run(sorted((switches or {}).items()))
    return loop.result()


class _Lead:
    """The lead car's column of a list of per-car tuples, read in place."""

    __slots__ = ('rows',)

    def __init__(self, rows: list):
        self.rows = rows

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, k: int) -> float:
        return self.rows[k][0]


class _ClosedLoop:
    """One run of :func:`run_offline`: the set-up, the loop over the control instants
    (:meth:`run`, its per-step path kept to local names), what it does when the plan changes
    or the planned end comes (rare, in methods) and the :class:`OfflineRun` it gives."""

    def __init__(self, scenario: Scenario, controller: str, settings, sensors: SensorSettings,
                 model: str, end_time_s: float | None, controller_rate_hz: float | None,
                 uncertainty, replan_check_period_s: float | None, model_options: dict,
                 envelope: bool = True):
        self.scenario, self.end_time_s = scenario, end_time_s
        self.key = key = scenario_key(scenario)
        self.plan = plan = cached_plan(scenario, key)
        self.period_ns = period_ns = nanoseconds(
            1.0 / (controller_rate_hz or scenario.run.controller_rate_hz))
        self.lockstep = (None if replan_check_period_s is None else
                         LockstepPlans(scenario, plan, period_ns, replan_check_period_s))
        self.replanner = (Replanner(scenario, plan) if self.lockstep is None
                          else self.lockstep.replanner)
        self.replanning = self.replanner.active or self.lockstep is not None
        self.in_force = plan
        truth = perturbed(scenario, uncertainty) if uncertainty is not None else scenario
        self.sim = TrainSimulation(truth, model, sensors=sensors, **model_options)
        self.host = ControllerHost(knowledge_of(scenario, **knowledge_options(uncertainty)),
                                   seconds(period_ns), controller, settings,
                                   envelope=envelope)
        self.journey = JourneyEnd.of(scenario, plan) if end_time_s is None else None
        end = end_time_s if end_time_s is not None else run_end_time_s(scenario, plan)
        steps = int(end * 1e9 // period_ns)
        sampled = sampled_references(plan, key, period_ns, steps)
        self.sampled = sampled is not None
        # without a sampled table, sampled as the run goes
        self.references: list = sampled if sampled is not None else []
        self.at = plan.trajectory.at
        self.count = count = steps + 1
        self.times, self.forces, self.step_times, self.measured_positions = (
            np.empty(count) for _ in range(4))
        self.saturated = np.empty(count, dtype=bool)
        self.car_positions: list[tuple[float, ...]] = []
        self.car_speeds: list[tuple[float, ...]] = []
        self.actuator_forces: list[tuple[float, ...]] = []
        self.laws: list[str] = []
        self.estimates: list[dict] = []
        self.faults: list[str] = []
        self.watchdog_events = 0
        self.atp_times: list[float] = []

    def _grow(self, count: int) -> None:
        if count > self.count:
            self.times, self.forces, self.step_times, self.saturated, \
                self.measured_positions = (
                    np.resize(a, count) for a in (self.times, self.forces, self.step_times,
                                                  self.saturated, self.measured_positions))
            self.count = count

    def _plan_changed(self, k: int) -> None:
        """From now on the new plan's reference, sampled as the run goes; a later arrival: the
        run goes on to the new plan's end."""
        lockstep, sim = self.lockstep, self.sim
        self.in_force = (self.replanner.plan if lockstep is None
                         else lockstep.plan_at(sim.stamp_ns))
        self.at = self.in_force.trajectory.at
        if self.sampled:
            self.references, self.sampled = self.references[:k], False
        if self.end_time_s is None:
            self.journey = JourneyEnd.of(self.scenario, self.plan, self.replanner.plan)
            end = (run_end_time_s(self.scenario, self.replanner.plan) if self.journey is None
                   else self.journey.planned_s)
            self._grow(int(end * 1e9 // self.period_ns) + 1)

    def _go_on(self) -> bool:
        """At the last planned step: whether the run goes on (its end follows the journey and
        the train has not yet stood at its last stop for long enough)."""
        if self.journey is None:
            return False
        left = self.journey.remaining_s(self.times, _Lead(self.car_positions),
                                        _Lead(self.car_speeds))
        if left <= 0.0:
            return False
        limit = int(self.journey.limit_s * 1e9 // self.period_ns) + 1
        before = self.count
        self._grow(min(before + math.ceil(left * 1e9 / self.period_ns - 1e-6), limit))
        if self.sampled:  # the references beyond the planned end, sampled as the run goes
            self.references, self.sampled = self.references[:before], False
        return self.count > before

    def run(self, pending: list[tuple[float, str]]) -> None:
        sim, host, lockstep = self.sim, self.host, self.lockstep
        replanner, replanning = self.replanner, self.replanning
        # Hoisted out of the loop: bound methods and the appends (one attribute look-up each).
        truth_of, measured_of, measurement_of = sim.truth, sim.measured, host.measurement
        step, command, advance = host.step, sim.apply_command, sim.advance
        clock, fsum = time.perf_counter, math.fsum
        add_positions, add_speeds, add_forces = (self.car_positions.append,
                                                 self.car_speeds.append,
                                                 self.actuator_forces.append)
        add_law, add_estimates = self.laws.append, self.estimates.append
        add_fault, add_atp = self.faults.append, self.atp_times.append
        references, sampled, at = self.references, self.sampled, self.at
        add_reference = references.append
        times, forces, step_times, saturated = (self.times, self.forces, self.step_times,
                                                self.saturated)
        measured_positions = self.measured_positions
        count, period_ns, watchdog_events = self.count, self.period_ns, 0
        in_force = self.in_force
        k = 0
        while k < count or (k == count and self._go_on()):
            if k == count:  # the run goes on: its arrays grew
                count, references, sampled = self.count, self.references, self.sampled
                add_reference = references.append
                times, forces, step_times, saturated = (self.times, self.forces,
                                                        self.step_times, self.saturated)
                measured_positions = self.measured_positions
            t = sim.time_s
            while pending and pending[0][0] <= t:
                host.select(pending.pop(0)[1])
            truth = truth_of()
            measured = measured_of(truth)
            if lockstep is not None:
                if lockstep.schedule(sim.stamp_ns):
                    lockstep.check(sim.stamp_ns, measured.positions[0], measured.speeds[0])
                changed = lockstep.plan_at(sim.stamp_ns) is not in_force
            else:
                changed = replanning and replanner.update(
                    t, measured.positions[0], measured.speeds[0]) is not None
            if changed:
                self._plan_changed(k)
                references, sampled, at = self.references, self.sampled, self.at
                add_reference, in_force = references.append, self.in_force
                count = self.count
                times, forces, step_times, saturated = (self.times, self.forces,
                                                        self.step_times, self.saturated)
                measured_positions = self.measured_positions
            if sampled:
                reference = references[k]
            else:
                reference = at(t)
                add_reference(reference)
            measurement = measurement_of(t, measured)
            started = clock()
            result = step(measurement, reference)
            step_times[k] = clock() - started
            command(result.forces_n)
            applied = sim.applied
            times[k] = t
            forces[k] = fsum(applied)
            measured_positions[k] = measured.positions[0]
            add_positions(truth.positions)
            add_speeds(truth.speeds)
            add_forces(applied)
            add_law(result.law)
            add_estimates(dict(result.estimates))
            add_fault(result.fault)
            saturated[k] = result.saturated
            watchdog_events += sim.watchdog != NORMAL
            interventions = sim.atp_interventions
            advance(period_ns)
            if sim.atp_interventions > interventions:
                add_atp(sim.time_s)
            k += 1
        self.references, self.watchdog_events = references, watchdog_events

    def result(self) -> OfflineRun:
        positions, speeds = np.array(self.car_positions), np.array(self.car_speeds)
        ref = np.array([(r.position, r.speed, r.acceleration) for r in self.references])
        run = OfflineRun(self.scenario, self.plan, self.times, positions[:, 0].copy(),
                         speeds[:, 0].copy(), self.forces, ref[:, 0].copy(), ref[:, 1].copy(),
                         ref[:, 2].copy(), positions, speeds, np.array(self.actuator_forces),
                         self.step_times, self.laws, self.estimates, self.faults,
                         self.sim.atp_interventions, self.watchdog_events, self.saturated,
                         tuple(self.atp_times), tuple(p for _, p in self.replanner.history),
                         self.journey, measured_positions=self.measured_positions)
        if run.extended:
            run.late_readings = late_readings(stop_samples(run.plan, run.replans), run.times_s,
                                              run.positions, run.speeds,
                                              self.scenario.train.length_m)
        return run
