"""The run's end follows the journey (ato_simulation.plans.JourneyEnd): an on-time run ends at
its planned end, a late train's run goes on until it has stood at its last stop for the settle
time, and a train that does not arrive is stopped at a stated limit past the timetable."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ato_common import uncertainty
from ato_common.scenario import load_scenario
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import LawOutput
from ato_controller_node.laws.pid import PidLaw
from ato_simulation.loop import run_offline
from ato_simulation.plans import (
    LATE_LIMIT_MIN_S,
    LATE_LIMIT_SHARE,
    STANDSTILL_MPS,
    run_end_time_s,
    run_limit_time_s,
)


def traction_loss(share: float) -> dict[str, float]:
    """A draw that is nominal but for the traction effectiveness (a converter or more lost)."""
    values = {name: p.nominal for name, p in uncertainty.PARAMETERS.items()}
    values['traction_effectiveness'] = share
    return values


class StandingLaw(PidLaw):
    """Full brake whatever the reference: the train never leaves."""

    name = 'standing'

    def step(self, measurement, reference):
        return LawOutput(-1e9, {})


def test_an_on_time_run_ends_at_its_planned_end():
    scenario = load_scenario('short_line')
    run = run_offline(scenario, 'pid')
    planned = run_end_time_s(scenario, run.plan)
    assert planned == run.plan.trajectory.end_time + scenario.run.settle_time_s
    assert run.times_s.size == int(planned * 1e9 // 100_000_000) + 1
    assert not run.extended and run.late_readings == ()


def test_a_late_train_s_run_goes_on_until_it_has_stood_at_its_last_stop():
    # With 70 % of its traction the PID's train reaches the terminus long after the timetable;
    # the run used to end at the timetable's end plus the settle time, the train still running.
    scenario = load_scenario('short_line')
    run = run_offline(scenario, 'pid', uncertainty=traction_loss(0.7))
    planned = run_end_time_s(scenario, run.plan)
    assert run.extended and run.times_s[-1] > planned + 30.0
    assert run.times_s[-1] < run_limit_time_s(scenario, run.plan)
    terminus = run.plan.stops[-1].station.position_m
    standing = (np.abs(run.speeds) <= STANDSTILL_MPS) & (np.abs(run.positions - terminus) <= 200)
    # it ends the settle time after the train came to stand there (one period of rounding)
    since = run.times_s[np.flatnonzero(~standing)[-1] + 1]
    assert run.times_s[-1] - since == pytest.approx(scenario.run.settle_time_s, abs=0.1)
    # the terminal stop error is read where the train stands, not where it ran at the
    # timetable's arrival
    assert abs(run.metrics().stop_errors_m['Terminus']) < 1.0
    assert dict(run.late_readings)['Terminus'] == run.times_s[-1]


def test_a_train_that_does_not_arrive_is_stopped_at_the_limit_past_the_timetable(monkeypatch):
    monkeypatch.setitem(LAWS, StandingLaw.name, StandingLaw)
    scenario = load_scenario('short_line')
    run = run_offline(scenario, 'standing')
    plan = run.plan
    journey = plan.trajectory.end_time - plan.trajectory.start_time
    limit = run_end_time_s(scenario, plan) + max(LATE_LIMIT_MIN_S, LATE_LIMIT_SHARE * journey)
    assert run_limit_time_s(scenario, plan) == limit
    assert run.times_s[-1] == pytest.approx(limit, abs=0.1)
    assert run.positions[-1] < 1.0   # it never left


def test_a_stated_end_is_kept():
    scenario = load_scenario('short_line')
    fixed = dataclasses.replace(scenario, run=dataclasses.replace(scenario.run,
                                                                  end_time_s=300.0))
    run = run_offline(fixed, 'pid', uncertainty=traction_loss(0.7))
    assert run.times_s[-1] == pytest.approx(300.0) and run.journey is None
    assert run_limit_time_s(fixed, run.plan) == run_end_time_s(fixed, run.plan) == 300.0
    windowed = run_offline(scenario, 'pid', end_time_s=120.0, uncertainty=traction_loss(0.7))
    assert windowed.times_s[-1] == pytest.approx(120.0) and not windowed.extended
