"""``replan.LockstepPlans``, the lockstep profile's decisions (no ROS): checks only at the check
instants, a decision from the state of check instant t_c in force from t_c + 2 periods, the new
plan continuous in acceleration with bounded jerk, a standing train far behind resumed, and the
same decisions from the same states."""

from __future__ import annotations

import pytest

from ato_common.scenario import parse_scenario
from profile_node.planner import plan_reference
from profile_node.replan import LAG_PERIODS, LockstepPlans

PERIOD_NS = 100_000_000
LATE_S = 15.0


def scenario(strategy: str = 'timetable'):
    return parse_scenario({
        'name': 'lockstep_plans', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'lockstep_plans', 'length_m': 15000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 15000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 300}]},
        'planning': {'max_acceleration_mps2': 0.4, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.3, 'speed_margin_kmh': 5},
        'timetable': {'strategy': strategy, 'supplement_percent': 10.0}})


def late_train(plan, t_s: float):
    """A train on the plan until 100 s, then LATE_S behind it (position and speed)."""
    lag = 0.0 if t_s < 100.0 else LATE_S
    point = plan.trajectory.at(max(t_s - lag, 0.0))
    return point.position, point.speed


def drive(plans: LockstepPlans, state, steps: int):
    checked = []
    for k in range(steps):
        stamp = k * PERIOD_NS
        if plans.schedule(stamp):
            checked.append(stamp)
            plans.check(stamp, *state(stamp / 1e9))
        assert not plans.schedule(stamp)   # once per check instant (a re-sent tick)
    return checked


def test_a_late_train_is_replanned_from_a_check_instant_two_periods_later():
    s = scenario()
    plan = plan_reference(s)
    plans = LockstepPlans(s, plan, PERIOD_NS, check_period_s=1.0)
    checked = drive(plans, lambda t: late_train(plan, t), 1500)
    assert checked == [k * 1_000_000_000 for k in range(150)]
    assert len(plans.decisions) == 1
    decision = plans.decisions[0]
    assert decision.kind == 'replanned'
    assert decision.checked_ns % 1_000_000_000 == 0 and decision.checked_ns >= 100 * 10**9
    assert decision.start_ns == decision.checked_ns + LAG_PERIODS * PERIOD_NS
    new = decision.plan
    assert plans.plan_at(decision.start_ns - PERIOD_NS) is plan
    assert plans.plan_at(decision.start_ns) is new is plans.latest
    # from the measured state carried on at its speed, in acceleration continuous
    start_s = decision.start_ns / 1e9
    first = new.trajectory.at(start_s)
    lag_s = LAG_PERIODS * PERIOD_NS / 1e9
    assert first.position == pytest.approx(decision.position_m + decision.speed_mps * lag_s,
                                           abs=1e-6)
    assert first.speed == pytest.approx(decision.speed_mps, abs=1e-9)
    assert first.acceleration == pytest.approx(plan.trajectory.at(start_s).acceleration,
                                               abs=1e-9)
    assert max(abs(seg.jerk) for seg in new.trajectory.segments) <= \
        s.planning.max_jerk_mps3 + 1e-9
    # the same states give the same decisions, whatever else happened between the checks
    again = LockstepPlans(s, plan, PERIOD_NS, check_period_s=1.0)
    drive(again, lambda t: late_train(plan, t), 1500)
    assert [(d.checked_ns, d.start_ns, d.position_m) for d in again.decisions] == \
        [(d.checked_ns, d.start_ns, d.position_m) for d in plans.decisions]
    assert again.latest.trajectory.segments == new.trajectory.segments


def test_the_check_instants_follow_the_check_period_not_every_tick():
    s = scenario()
    plans = LockstepPlans(s, plan_reference(s), PERIOD_NS, check_period_s=2.5)
    stamps = [k * 300_000_000 for k in range(40)]   # ticks every 0.3 s
    due = [t for t in stamps if plans.schedule(t)]
    # the first tick at or after each multiple of 2.5 s
    assert due == [0, 2_700_000_000, 5_100_000_000, 7_500_000_000, 10_200_000_000]


def test_a_train_standing_far_behind_the_reference_is_resumed():
    s = scenario('fastest')
    plan = plan_reference(s)
    plans = LockstepPlans(s, plan, PERIOD_NS)

    def braked(t: float):
        """On the plan up to 1200 m, where an emergency brake has stopped it."""
        point = plan.trajectory.at(t)
        return (point.position, point.speed) if point.position < 1200.0 else (1200.0, 0.0)
    drive(plans, braked, 1200)
    decision = plans.decisions[0]
    assert decision.kind == 'resumed'
    # at the first check instant with the reference more than 50 m ahead of the standing train
    behind = [k for k in range(120) if plan.trajectory.at(k).position - 1200.0 > 50.0]
    assert decision.checked_ns == behind[0] * 1_000_000_000
    first = plans.plan_at(decision.start_ns).trajectory.at(decision.start_ns / 1e9)
    assert (first.position, first.speed) == (1200.0, 0.0)
    assert plans.plan_at(decision.start_ns - 1) is plan


@pytest.mark.parametrize('period', [0.0, -1.0, float('nan'), float('inf')])
def test_a_bad_check_period_is_refused_naming_it(period):
    s = scenario()
    with pytest.raises(ValueError, match='replan check period'):
        LockstepPlans(s, plan_reference(s), PERIOD_NS, check_period_s=period)
