"""Issue 29 item 3: an odometer that places the train outside the line (a position bias of
-60 m or -200 m at the start) made the profile fail in ``resume_plan`` -> ``planner.ceiling``
(``min() arg is an empty sequence``). A measured position outside the line is taken as the
nearest end of the line, and the replanner names it."""

from dataclasses import replace

import pytest

from ato_common.scenario import load_scenario
from profile_node.planner import plan_reference
from profile_node.replan import LockstepPlans, Replanner, on_line

PERIOD_NS = 100_000_000


@pytest.fixture(scope='module')
def short_line():
    scenario = load_scenario('short_line')
    return scenario, plan_reference(scenario)


@pytest.mark.parametrize('bias_m', [-60.0, -200.0])
def test_a_standing_train_measured_before_the_line_does_not_break_the_plan(short_line, bias_m):
    scenario, plan = short_line
    plans = LockstepPlans(scenario, plan, PERIOD_NS, check_period_s=0.1)
    for k in range(0, 40):  # 4 s standing at the origin, measured bias_m before it
        stamp = k * PERIOD_NS
        if plans.schedule(stamp):
            plans.check(stamp, bias_m, 0.0)
    assert plans.decisions == []   # taken at the line's start: not behind the reference
    assert plans.replanner.note == (f'the measured position {bias_m:.1f} m is outside the line '
                                    '(0 to 36000 m): taken as 0 m')


def test_a_train_standing_behind_the_reference_and_before_the_line_resumes_from_its_start(
        short_line):
    scenario, plan = short_line
    replanner = Replanner(scenario, plan)
    later = next(t for t in range(1, 600) if plan.trajectory.at(t).position > 500.0)
    decided = replanner.decide(float(later), -200.0, 0.0)
    assert decided is not None and decided[0] == 'resumed'
    resumed = decided[1]
    assert resumed.trajectory.at(float(later)).position == pytest.approx(0.0, abs=1e-6)
    assert 'outside the line' in replanner.note


def test_a_late_moving_train_measured_before_the_line_is_replanned_from_its_start():
    scenario = load_scenario('short_line')
    scenario = replace(scenario, timetable=replace(scenario.timetable, strategy='timetable'))
    plan = plan_reference(scenario)
    replanner = Replanner(scenario, plan)
    later = next(t for t in range(1, 900) if plan.trajectory.at(t).position > 2000.0)
    replanned = replanner.update(float(later), -200.0, 20.0)  # late by far more than 10 s
    assert replanned is not None
    assert replanned.trajectory.at(float(later)).position == pytest.approx(0.0, abs=1e-6)
    assert 'outside the line' in replanner.note
    assert replanner.update(float(later), 36500.0, 20.0) is None  # past the last stop


def test_on_the_line_a_position_is_itself():
    scenario = load_scenario('short_line')
    assert on_line(scenario, 1234.5) == (1234.5, '')
    assert on_line(scenario, 36000.0) == (36000.0, '')
    assert on_line(scenario, 36000.5)[0] == 36000.0
    assert on_line(scenario, -1.0)[0] == 0.0
