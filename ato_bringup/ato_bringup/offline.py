"""The closed loop on the same cores as the nodes, without ROS: fast, for unit tests, law
reproduction and benchmarks. Same order of operations as the lockstep graph: at each control
instant the plant's measurement and the reference at that time go to the controller, whose
command is held while the plant advances one period.

The plant simulates the whole scenario (the truth); the controller knows only
``knowledge_of(scenario)`` (ato_common.knowledge): the nominal train and the known modes. With
``uncertainty`` (the values of one draw, ato_common.uncertainty) the plant runs the perturbed
truth ``perturbed(scenario, uncertainty)`` while the controller keeps the knowledge of the
nominal ``scenario``: no drawn value reaches it."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ato_common.knowledge import knowledge_of
from ato_common.metrics import RunMetrics, StopSample, compute_metrics
from ato_common.scenario import Scenario
from ato_common.types import nanoseconds, seconds
from ato_common.uncertainty import perturbed
from ato_controller_node.host import ControllerHost
from profile_node.planner import Plan, plan_reference
from profile_node.replan import Replanner
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


def stop_samples(plan: Plan, replans: tuple[Plan, ...] = ()) -> list[StopSample]:
    """Each stop sampled at its departure in the last plan that has it (a replan's)."""
    stops = {s.station.name: s for s in plan.stops}
    for later in replans:
        stops.update((s.station.name, s) for s in later.stops)
    return [StopSample(s.station.name, s.station.position_m, s.departure_s)
            for s in sorted(stops.values(), key=lambda s: s.station.position_m)]


def run_end_time_s(scenario: Scenario, plan: Plan) -> float:
    if scenario.run.end_time_s > 0.0:
        return scenario.run.end_time_s
    return plan.trajectory.end_time + scenario.run.settle_time_s


def run_offline(scenario: Scenario, controller: str = 'pid', settings=None,
                switches: dict[float, str] | None = None,
                sensors: SensorSettings = SensorSettings(), model: str = 'point_mass',
                end_time_s: float | None = None, controller_rate_hz: float | None = None,
                uncertainty=None, **model_options) -> OfflineRun:
    """Run ``controller`` on ``scenario`` with the plant ``model``; ``switches`` maps times to
    law names selected then; ``end_time_s`` and ``controller_rate_hz`` override the scenario's
    (a law that must run faster than a node can, e.g. Mao et al.'s feedback linearisation);
    ``uncertainty``: the drawn values the plant's truth is perturbed by (None: nominal)."""
    plan = plan_reference(scenario)
    replanner = Replanner(scenario, plan)  # the timetable strategy's replans when late
    period_ns = nanoseconds(1.0 / (controller_rate_hz or scenario.run.controller_rate_hz))
    truth_scenario = perturbed(scenario, uncertainty) if uncertainty is not None else scenario
    sim = TrainSimulation(truth_scenario, model, sensors=sensors, **model_options)
    host = ControllerHost(knowledge_of(scenario), seconds(period_ns), controller, settings)
    end = end_time_s if end_time_s is not None else run_end_time_s(scenario, plan)
    steps = int(end * 1e9 // period_ns)
    pending = sorted((switches or {}).items())
    rows, car_positions, car_speeds, actuator_forces, step_times = [], [], [], [], []
    laws, estimates, faults = [], [], []
    watchdog_events = 0
    saturated = []
    atp_times = []
    step = 0
    while step <= steps:
        step += 1
        t = sim.time_s
        while pending and pending[0][0] <= t:
            host.select(pending.pop(0)[1])
        truth = sim.truth()
        measured = sim.measured(truth)
        if replanner.active and replanner.update(t, measured.positions[0],
                                                 measured.speeds[0]) and end_time_s is None:
            # A later arrival: the run goes on to the end of the new plan.
            steps = max(steps, int(run_end_time_s(scenario, replanner.plan) * 1e9 // period_ns))
        reference = replanner.plan.trajectory.at(t)
        measurement = host.measurement(t, measured)  # with the known mode, from the knowledge
        started = time.perf_counter()
        result = host.step(measurement, reference)
        step_times.append(time.perf_counter() - started)
        sim.apply_command(result.forces_n)
        rows.append((t, truth.positions[0], truth.speeds[0], math.fsum(sim.applied),
                     reference.position, reference.speed, reference.acceleration))
        car_positions.append(truth.positions)
        car_speeds.append(truth.speeds)
        actuator_forces.append(sim.applied)
        laws.append(result.law)
        estimates.append(dict(result.estimates))
        faults.append(result.fault)
        saturated.append(result.saturated)
        watchdog_events += sim.watchdog != NORMAL
        interventions = sim.atp_interventions
        sim.advance(period_ns)
        if sim.atp_interventions > interventions:
            atp_times.append(sim.time_s)
    data = np.array(rows)
    return OfflineRun(scenario, plan, *data.T, np.array(car_positions), np.array(car_speeds),
                      np.array(actuator_forces), np.array(step_times), laws, estimates, faults,
                      sim.atp_interventions, watchdog_events, np.array(saturated, dtype=bool),
                      tuple(atp_times), tuple(p for _, p in replanner.history))
