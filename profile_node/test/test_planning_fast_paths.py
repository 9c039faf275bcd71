"""The planner's fast paths give the plans of the straightforward computations they replaced, bit
for bit: the grade under the train summed over the grades it overlaps only
(``timetable.train_grade_sine``), the traction phases from one speed replayed from their shared
steps (``trajectory.AccelerationSteps``) and the other trial phases on a builder that keeps no
segments (``trajectory.StateBuilder``). The slow paths are written out here, from the public
builder's methods, and planned with in place of the fast ones."""

from __future__ import annotations

import math
import random
from dataclasses import replace

import pytest

from ato_common.scenario import builtin_scenarios, load_scenario
from profile_node import planner
from profile_node.planner import MIN_PLANNED_ACCELERATION_MPS2, plan_reference, traction_capability
from profile_node.timetable import train_grade_sine
from profile_node.trajectory import AccelerationSteps, StateBuilder, TrajectoryBuilder


def slow_train_grade_sine(line, front_m: float, length_m: float) -> float:
    """Every grade of the line, overlapping the train or not."""
    if length_m <= 0.0:
        return line.grade_sine(front_m)
    rear = front_m - length_m
    starts, values = line.grade_sine.starts, line.grade_sine.values
    total = 0.0
    for i, value in enumerate(values):
        a = starts[i] if i > 0 else -math.inf
        b = starts[i + 1] if i + 1 < len(starts) else math.inf
        overlap = min(b, front_m) - max(a, rear)
        if overlap > 0.0:
            total += value * overlap
    return total / length_m


def slow_traction_distance(traction, davis, mass_kg, planning, climb_sine, v_from, v_to):
    """The traction phase built segment by segment with the public builder, every time."""
    from types import SimpleNamespace
    train = SimpleNamespace(traction=traction, davis_nominal=davis, mass_kg=mass_kg)
    capability = traction_capability(SimpleNamespace(train=train, planning=planning),
                                     climb_sine)
    builder = TrajectoryBuilder()
    builder.v = v_from
    builder.accelerate_to(v_to, capability, planning.max_jerk_mps3,
                          MIN_PLANNED_ACCELERATION_MPS2)
    return builder.x


def plan_slowly(monkeypatch, scenario):
    with monkeypatch.context() as patch:
        patch.setattr(planner, 'train_grade_sine', slow_train_grade_sine)
        patch.setattr(planner, '_traction_distance', slow_traction_distance)
        patch.setattr(planner, 'StateBuilder', TrajectoryBuilder)
        return plan_reference(scenario)


@pytest.mark.parametrize('name', builtin_scenarios())
def test_the_grade_under_the_train_is_the_sum_over_every_grade(name):
    line = load_scenario(name).line
    rng = random.Random(7)
    starts = line.grade_sine.starts
    points = [rng.uniform(-500.0, line.length_m + 500.0) for _ in range(300)]
    points += [x + d for x in starts for d in (-1e-9, 0.0, 1e-9)]   # at the grade changes
    for length in (0.0, 1.0, 200.0, 400.0, 5000.0):
        for x in points:
            assert train_grade_sine(line, x, length) == slow_train_grade_sine(line, x, length)


def test_traction_phases_replayed_from_shared_steps_are_the_builders():
    scenario = load_scenario('short_line')
    planning = scenario.planning
    rng = random.Random(3)
    for climb in (0.0, 0.004, -0.003):
        capability = traction_capability(scenario, climb)
        for v_from in (0.0, 12.5, 40.0):
            steps = AccelerationSteps(v_from, capability, planning.max_jerk_mps3,
                                      MIN_PLANNED_ACCELERATION_MPS2)
            targets = [rng.uniform(0.0, 80.0) for _ in range(60)] + [v_from, v_from + 1e-13]
            for v_to in targets:  # in no particular order: the steps are extended as needed
                builder = TrajectoryBuilder()
                builder.v = v_from
                builder.accelerate_to(v_to, capability, planning.max_jerk_mps3,
                                      MIN_PLANNED_ACCELERATION_MPS2)
                assert steps.distance_to(v_to) == builder.x, (climb, v_from, v_to)


def test_a_state_builder_ends_where_the_trajectory_builder_does():
    full, state = TrajectoryBuilder(x0=10.0, t0=3.0), StateBuilder(x0=10.0, t0=3.0)
    for builder in (full, state):
        builder.v = 30.0
        builder.add(1.3, 0.2)
        builder.add(0.7, -0.25)
        builder.follow(lambda v, x: -0.01 - 1e-4 * v * v, 0.3, speed=20.0, step_s=3.0)
    assert (state.t, state.x, state.v, state.a) == (full.t, full.x, full.v, full.a)
    assert state.segments == [] and full.segments


@pytest.mark.parametrize('name, strategy', [('short_line', 'timetable'),
                                            ('short_line', 'fastest'),
                                            ('jinan_xuzhou', 'timetable')])
def test_the_plans_are_those_of_the_slow_paths_bit_for_bit(monkeypatch, name, strategy):
    base = load_scenario(name)
    scenario = replace(base, timetable=replace(base.timetable, strategy=strategy,
                                               supplement_percent=7.0))
    planner._traction_distance.cache_clear()
    fast = plan_reference(scenario)
    slow = plan_slowly(monkeypatch, scenario)
    assert fast.trajectory.segments == slow.trajectory.segments   # every float of the curve
    assert fast.stops == slow.stops
    assert fast.legs == slow.legs
    assert (fast.expected_delay_s, fast.forecast) == (slow.expected_delay_s, slow.forecast)
