"""Issue 13, defect 6: after an emergency or watchdog brake the reference resumes from where the
train stands (``planner.resume_plan``), instead of running on kilometres ahead."""

import pytest

from ato_common.scenario import load_scenario
from profile_node.planner import plan_reference, resume_plan


def test_the_leg_restarts_from_the_standing_train():
    scenario = load_scenario('short_line')
    original = plan_reference(scenario).trajectory
    assert original.at(300.0).position - 5000.0 > 1000.0  # where the old reference would be
    plan = resume_plan(scenario, 5000.0, 300.0)
    start = plan.trajectory.at(300.0)
    assert (start.position, start.speed, start.acceleration) == (5000.0, 0.0, 0.0)
    assert plan.trajectory.at(301.0).position - 5000.0 < 1.0  # a jerk-limited start
    names = [stop.station.name for stop in plan.stops]
    assert names == ['Midway', 'Terminus']
    midway = plan.stops[0]
    assert plan.trajectory.at(midway.arrival_s).position == pytest.approx(14000.0, abs=0.01)
    assert midway.departure_s - midway.arrival_s == pytest.approx(30.0)
    # never above the supervision's permitted speed (the plan is checked as any plan is)
    for k in range(0, 2000):
        point = plan.trajectory.at(300.0 + k * 0.5)
        assert point.speed <= plan.permitted_speed(point.position, point.time_s) + 1e-6


def test_no_resume_past_the_last_station():
    assert resume_plan(load_scenario('short_line'), 36000.0, 900.0) is None
