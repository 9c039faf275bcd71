"""The optimised offline loop (the plan cache, the references sampled once per plan, the slim
per-step path of the plant and the host) gives the same runs, to the last bit, as the loop it
replaced: ``reference_run`` below is ``run_offline`` as it was before (planning on every run,
the reference looked up per step, every snapshot taken through the public methods), kept here as
the reference. Compared: every array and list of ``OfflineRun`` except the step timings, byte
for byte (so -0.0 and 0.0, and NaN payloads, count as different), for every law that applies to
``short_line`` and for uncertain draws (actuator lag, sensor noise, ATP interventions)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ato_common.identity import content_key
from ato_common.knowledge import knowledge_of
from ato_common.scenario import load_scenario
from ato_common.types import nanoseconds, seconds
from ato_common.uncertainty import DEFAULTS, draw, perturbed
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws import LAWS
from ato_simulation import loop as offline
from ato_simulation.applies import applicable_rate, plant_model_for
from ato_simulation.loop import OfflineRun, run_offline
from ato_simulation.plans import JourneyEnd, late_readings, run_end_time_s, stop_samples
from profile_node.planner import plan_reference
from profile_node.replan import Replanner
from train_plant_node.simulation import NORMAL, SensorSettings, TrainSimulation

#: liu_li runs at 200 Hz (185 770 steps on short_line): compared over its first 120 s
WINDOW_S = {'liu_li': 120.0}


def reference_run(scenario, controller='pid', settings=None, switches=None,
                  sensors=SensorSettings(), model='point_mass', end_time_s=None,
                  controller_rate_hz=None, uncertainty=None, **model_options) -> OfflineRun:
    """``run_offline`` before the optimisation, verbatim but for the names (with the
    timetable's replanning, which came at the same time, and the journey's end, which came
    later)."""
    plan = plan_reference(scenario)
    replanner = Replanner(scenario, plan)
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

    def go_on() -> bool:
        """At the last step: the journey's end (ato_simulation.plans.JourneyEnd) says whether
        the run goes on, from the lead car's truth so far."""
        nonlocal steps
        journey = None if end_time_s is not None else JourneyEnd.of(scenario, plan,
                                                                      replanner.plan)
        if journey is None:
            return False
        left = journey.remaining_s(*([row[i] for row in rows] for i in range(3)))
        more = min(steps + math.ceil(left * 1e9 / period_ns - 1e-6),
                   int(journey.limit_s * 1e9 // period_ns))
        steps, longer = max(steps, more), more > steps
        return longer

    while step <= steps or go_on():
        step += 1
        t = sim.time_s
        while pending and pending[0][0] <= t:
            host.select(pending.pop(0)[1])
        truth = sim.truth()
        measured = sim.measured(truth)
        if replanner.active and replanner.update(t, measured.positions[0],
                                                 measured.speeds[0]) and end_time_s is None:
            steps = max(steps, int(JourneyEnd.of(scenario, plan, replanner.plan).planned_s
                                   * 1e9 // period_ns))
        reference = replanner.plan.trajectory.at(t)
        measurement = host.measurement(t, measured)
        result = host.step(measurement, reference)
        step_times.append(0.0)
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
    run = OfflineRun(scenario, plan, *data.T, np.array(car_positions), np.array(car_speeds),
                     np.array(actuator_forces), np.array(step_times), laws, estimates, faults,
                     sim.atp_interventions, watchdog_events, np.array(saturated, dtype=bool),
                     tuple(atp_times), tuple(p for _, p in replanner.history),
                     None if end_time_s is not None else JourneyEnd.of(scenario, plan,
                                                                        replanner.plan))
    if run.extended:
        run.late_readings = late_readings(stop_samples(run.plan, run.replans), run.times_s,
                                          run.positions, run.speeds, scenario.train.length_m)
    return run


ARRAYS = ('times_s', 'positions', 'speeds', 'forces', 'ref_positions', 'ref_speeds',
          'ref_accelerations', 'car_positions', 'car_speeds', 'actuator_forces', 'saturated')


def assert_identical(run: OfflineRun, expected: OfflineRun) -> None:
    for name in ARRAYS:
        got, want = getattr(run, name), getattr(expected, name)
        assert got.dtype == want.dtype and got.shape == want.shape, name
        assert np.ascontiguousarray(got).tobytes() == np.ascontiguousarray(want).tobytes(), \
            f'{name} differs first at row {int(np.argmax(got != want))}'
    assert run.step_times_s.shape == expected.step_times_s.shape
    assert run.laws == expected.laws
    assert run.faults == expected.faults
    # Estimates compared through repr: float bits, NaN included, and the keys in order.
    assert [repr(sorted(e.items())) for e in run.estimates] == \
        [repr(sorted(e.items())) for e in expected.estimates]
    assert (run.atp_interventions, run.watchdog_events, run.atp_times_s) == \
        (expected.atp_interventions, expected.watchdog_events, expected.atp_times_s)
    assert run.metrics() == expected.metrics()


def short_line_laws():
    """Every law that applies to short_line, with its plant model and control rate."""
    scenario = load_scenario('short_line')
    rates = {law: applicable_rate(law, scenario)[0] for law in sorted(LAWS)}
    return [(law, plant_model_for(scenario), rate) for law, rate in rates.items() if rate]


@pytest.mark.parametrize('law, model, rate_hz', short_line_laws(), ids=lambda v: str(v))
def test_every_law_on_short_line_is_bit_identical_to_the_reference_loop(law, model, rate_hz):
    options = dict(model=model, controller_rate_hz=rate_hz, end_time_s=WINDOW_S.get(law))
    expected = reference_run(load_scenario('short_line'), law, **options)
    # Twice: planning (or a plan cached by an earlier test), then certainly from the cache.
    for _ in range(2):
        assert_identical(run_offline(load_scenario('short_line'), law, **options), expected)


@pytest.mark.parametrize('law', ['pid', 'luo_xu', 'tan_second_level_adaptive'])
def test_uncertain_draws_are_bit_identical_to_the_reference_loop(law):
    """A campaign's draws share the nominal scenario's plan; each draw's truth stays its own
    (lag, noise, ATP interventions: the plant's general paths)."""
    runs = []
    for index in range(2):
        values = draw(DEFAULTS, 2026, index)
        expected = reference_run(load_scenario('short_line'), law, uncertainty=values)
        run = run_offline(load_scenario('short_line'), law, uncertainty=values)
        assert_identical(run, expected)
        runs.append(run)
    assert runs[0].plan is runs[1].plan  # one plan for both draws
    assert not np.array_equal(runs[0].speeds, runs[1].speeds)  # two truths


def test_switches_and_a_law_that_measures_nothing_new_are_bit_identical():
    switches = {150.0: 'luo_xu', 450.0: 'pid'}
    expected = reference_run(load_scenario('short_line'), 'pid', switches=switches)
    assert_identical(run_offline(load_scenario('short_line'), 'pid', switches=switches),
                     expected)


def test_sensor_noise_overrides_are_bit_identical():
    sensors = SensorSettings(position_noise_m=0.05, speed_noise_mps=0.02, seed=7)
    expected = reference_run(load_scenario('short_line'), 'pid', sensors=sensors,
                             end_time_s=200.0)
    assert_identical(run_offline(load_scenario('short_line'), 'pid', sensors=sensors,
                                 end_time_s=200.0), expected)


# --- the plan cache: keyed by content ----------------------------------------------------------

def test_the_plan_is_shared_by_content_not_by_object_or_name():
    first, second = load_scenario('short_line'), load_scenario('short_line')
    assert first is not second
    assert offline.cached_plan(first) is offline.cached_plan(second)
    # Same name, other content: another plan, from the planner itself.
    slower = dataclasses.replace(first, planning=dataclasses.replace(
        first.planning, max_acceleration_mps2=0.5 * first.planning.max_acceleration_mps2))
    assert slower.name == first.name
    plan = offline.cached_plan(slower)
    assert plan is not offline.cached_plan(first)
    assert plan.trajectory.end_time > offline.cached_plan(first).trajectory.end_time
    assert plan.trajectory.end_time == plan_reference(slower).trajectory.end_time
    # A change deep in the line (one station's dwell) is content too.
    line = first.line
    stations = (*line.stations[:-1], dataclasses.replace(line.stations[-1], dwell_s=17.0))
    other = dataclasses.replace(first, line=dataclasses.replace(line, stations=stations))
    assert offline.scenario_key(other) != offline.scenario_key(first)


def test_the_key_tells_apart_what_equality_would_merge():
    """0.0 and -0.0, 1 and 1.0 and True, and two closures of different values."""
    from ato_common.braking_curves import constant_deceleration
    key = content_key
    assert key(0.0) != key(-0.0)
    assert len({key(1), key(1.0), key(True)}) == 3
    assert key(constant_deceleration(0.5)) == key(constant_deceleration(0.5))
    assert key(constant_deceleration(0.5)) != key(constant_deceleration(0.6))
    assert key((1.0, 2.0)) != key([1.0, 2.0])
    assert key({'a': 1.0, 'b': 2.0}) == key({'b': 2.0, 'a': 1.0})
    assert key(np.arange(3.0)) != key(np.arange(3.0).astype(np.float32))


def test_a_scenario_the_key_cannot_describe_is_planned_every_time():
    class Opaque:
        __slots__ = ()

    scenario = load_scenario('short_line')
    odd = dataclasses.replace(scenario, description=Opaque())
    assert offline.scenario_key(odd) is None
    assert offline.cached_plan(odd) is not offline.cached_plan(odd)
