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
from ato_common.metrics import RunMetrics, compute_metrics
from ato_common.scenario import Scenario
from ato_common.types import nanoseconds, seconds
from ato_common.uncertainty import knowledge_options, perturbed
from ato_controller_node.gains import configured
from ato_controller_node.host import ControllerHost
from ato_simulation.plans import (
    cached_plan,
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

    @property
    def final_plan(self) -> Plan:
        return self.replans[-1] if self.replans else self.plan

    def metrics(self) -> RunMetrics:
        return compute_metrics(self.times_s, self.positions, self.speeds, self.forces,
                               self.ref_positions, self.ref_speeds,
                               stop_samples(self.plan, self.replans))

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
    run then follows the new plan (to its end, if that is later). ``replan_check_period_s``:
    decide as the profile node does in lockstep (``profile_node.replan.LockstepPlans``: the
    measured state read at check instants this far apart, a replan or a resume from a standing
    train applied two periods later) instead of replanning from every step's state at once.
    ``gains``: the laws' configuration (``ato_controller_node.gains``: 'published' or 'tuned',
    for the scenario's train), with ``settings`` on top; ``envelope``: the host's ATO envelope
    (``ato_controller_node.envelope``) on or off, for every law."""
    key = scenario_key(scenario)
    plan = cached_plan(scenario, key)
    period_ns = nanoseconds(1.0 / (controller_rate_hz or scenario.run.controller_rate_hz))
    lockstep = (None if replan_check_period_s is None else
                LockstepPlans(scenario, plan, period_ns, replan_check_period_s))
    replanner = Replanner(scenario, plan) if lockstep is None else lockstep.replanner
    replanning = replanner.active or lockstep is not None
    in_force = plan
    truth_scenario = perturbed(scenario, uncertainty) if uncertainty is not None else scenario
    sim = TrainSimulation(truth_scenario, model, sensors=sensors, **model_options)
    laws = {controller, *(switches or {}).values()}
    host = ControllerHost(knowledge_of(scenario, **knowledge_options(uncertainty)),
                          seconds(period_ns), controller,
                          configured(gains, scenario.train.name, laws, settings),
                          envelope=envelope)
    end = end_time_s if end_time_s is not None else run_end_time_s(scenario, plan)
    steps = int(end * 1e9 // period_ns)
    references = sampled_references(plan, key, period_ns, steps)
    sampled = references is not None
    if not sampled:
        references = []  # sampled as the run goes
    at, add_reference = plan.trajectory.at, references.append
    pending = sorted((switches or {}).items())
    count = steps + 1
    times = np.empty(count)
    forces = np.empty(count)
    step_times = np.empty(count)
    saturated = np.empty(count, dtype=bool)
    car_positions, car_speeds, actuator_forces = [], [], []
    laws, estimates, faults = [], [], []
    watchdog_events = 0
    atp_times = []
    # Hoisted out of the loop: bound methods and the appends (one attribute look-up each).
    truth_of, measured_of, measurement_of = sim.truth, sim.measured, host.measurement
    step, command, advance = host.step, sim.apply_command, sim.advance
    clock, fsum = time.perf_counter, math.fsum
    add_positions, add_speeds, add_forces = (car_positions.append, car_speeds.append,
                                             actuator_forces.append)
    add_law, add_estimates, add_fault = laws.append, estimates.append, faults.append
    k = 0
    while k < count:
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
            changed = replanning and replanner.update(t, measured.positions[0],
                                                      measured.speeds[0])
        if changed:
            # From now on the new plan's reference, sampled as the run goes.
            in_force = replanner.plan if lockstep is None else lockstep.plan_at(sim.stamp_ns)
            at = in_force.trajectory.at
            if sampled:
                references, sampled = references[:k], False
                add_reference = references.append
            if end_time_s is None:  # a later arrival: the run goes on to the new plan's end
                later = int(run_end_time_s(scenario, replanner.plan) * 1e9 // period_ns) + 1
                if later > count:
                    times, forces, step_times, saturated = (
                        np.resize(a, later) for a in (times, forces, step_times, saturated))
                    count = later
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
            atp_times.append(sim.time_s)
        k += 1
    positions, speeds = np.array(car_positions), np.array(car_speeds)
    ref = np.array([(r.position, r.speed, r.acceleration) for r in references])
    return OfflineRun(scenario, plan, times, positions[:, 0].copy(), speeds[:, 0].copy(),
                      forces, ref[:, 0].copy(), ref[:, 1].copy(), ref[:, 2].copy(), positions,
                      speeds, np.array(actuator_forces), step_times, laws, estimates, faults,
                      sim.atp_interventions, watchdog_events, saturated, tuple(atp_times),
                      tuple(p for _, p in replanner.history))
