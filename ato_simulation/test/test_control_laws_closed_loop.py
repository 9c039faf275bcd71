"""The PID and Luo & Xu laws in the offline closed loop on short_line: tracking, bounded
estimates, switching mid-run. (The laws and the host alone: ato_controller_node/test.)"""

import pytest

from ato_common.scenario import load_scenario
from ato_simulation.loop import run_offline


@pytest.fixture(scope='module')
def scenario():
    return load_scenario('short_line')


@pytest.mark.parametrize('law, gains', [('pid', 'published'), ('pid', 'tuned')])
def test_closed_loop_tracks_the_reference_offline(scenario, law, gains):
    metrics = run_offline(scenario, law, gains=gains).metrics()
    assert metrics.rms_speed_error_kmh < 0.2
    assert metrics.max_speed_error_kmh < 1.0
    assert metrics.max_position_error_m < 1.0
    assert all(abs(e) < 0.1 for e in metrics.stop_errors_m.values())


#: short_line's reference stands at Midway from 382.6 s to 412.5 s
MIDWAY_DWELL_S = (382.6, 412.5)


def test_luo_xu_as_tuned_tracks_between_the_stops(scenario):
    """The tuned gains (chosen on the campaign's drawn plants, whose actuators lag) on the
    nominal plant: within a metre of the reference from the start to Midway's dwell and after
    it has caught up again, and every stop within the platform tolerance."""
    run = run_offline(scenario, 'luo_xu', gains='tuned')
    t = run.times_s
    error = abs(run.ref_positions - run.positions)
    assert error[t < MIDWAY_DWELL_S[0]].max() < 1.0
    assert error[t > MIDWAY_DWELL_S[1] + 60.0].max() < 1.0
    assert run.atp_interventions == 0
    assert all(abs(e) < 0.5 for e in run.metrics().stop_errors_m.values())


def test_luo_xu_as_tuned_departs_on_time_after_a_dwell(scenario):
    """Within a metre of the reference in the minute after Midway's dwell. The law's adaptation
    (c0_hat) integrates any stop error through a dwell while the brake holds the train, and the
    envelope does not freeze adaptation at a standstill: gains tuned when the odometer's error
    stayed uncorrected at the stops (no balise groups) stood 0.18 m past Midway and departed
    about 7 s late; this test keeps that from coming back unseen."""
    run = run_offline(scenario, 'luo_xu', gains='tuned')
    t = run.times_s
    after = (t > MIDWAY_DWELL_S[1]) & (t < MIDWAY_DWELL_S[1] + 60.0)
    assert abs(run.ref_positions - run.positions)[after].max() < 1.0


def test_luo_xu_as_published_is_slow_but_safe(scenario):
    """The paper's gains (c1 = c2 = 0.1: error dynamics of about 0.1 rad/s) lag the reference
    by tens of metres on the nominal plant; the train is never braked by the ATP and stands at
    the terminus. Its figures are the comparison's (make compare, make campaign)."""
    run = run_offline(scenario, 'luo_xu', gains='published')
    metrics = run.metrics()
    assert run.atp_interventions == 0 and not any(run.faults)
    assert 1.0 < metrics.max_position_error_m < 500.0
    assert abs(metrics.stop_errors_m['Terminus']) < 0.1


def test_luo_xu_estimates_stay_bounded_and_error_converges(scenario):
    run = run_offline(scenario, 'luo_xu')
    nominal = scenario.train.mass_kg
    masses = [e['mass_hat_kg'] for e in run.estimates]
    assert 0.7 * nominal <= min(masses) and max(masses) <= 1.5 * nominal
    assert abs(run.estimates[-1]['z1_m']) < 0.05


def test_switching_mid_run_keeps_tracking(scenario):
    # in and out of luo_xu while cruising (its departure after a dwell: the xfail above)
    run = run_offline(scenario, 'pid', switches={150.0: 'luo_xu', 330.0: 'pid'}, gains='tuned')
    assert set(run.laws) == {'pid', 'luo_xu'}
    metrics = run.metrics()
    assert metrics.max_position_error_m < 1.0
    assert metrics.max_speed_error_kmh < 1.0
