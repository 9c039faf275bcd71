"""Issue 13: the emergency brake no drive fault cancels, failure forces bounded by what a drive
can exert, every stop supervised until the train has stopped and dwelt, the train's maximum
speed (lockstep, no ROS)."""

import math

import pytest

from ato_common.braking_curves import RunSupervision
from ato_common.plant_setup import ActuatorFailure
from ato_common.scenario import load_scenario, parse_scenario
from train_plant_node.simulation import FailureRejected, TrainSimulation, failure_force_bound

PERIOD_NS = 100_000_000
FULL = 1e9  # far above any drive's rating: the plant clamps it to the characteristic


def run_full_traction(sim, seconds, command=None):
    """The faulty ATO: full traction every period. Returns (position, speed, leg, EBD) rows."""
    n = len(sim.actuator_names)
    rows = []
    for _ in range(int(seconds * 10)):
        sim.apply_command(command or (FULL,) * n)
        sim.advance(PERIOD_NS)
        x, v = sim.lead_position(), sim.lead_speed()
        rows.append((x, v, sim.leg, sim.supervision.curve('ebd', x, sim.leg)))
    return rows


def stopped_before_end_of_authority(rows, run, stop_leg):
    """The train never passed the stop's EOA before its leg moved on."""
    eoa = run.legs[stop_leg].end_of_authority_m
    on_leg = [r for r in rows if r[2] == stop_leg]
    assert max(x for x, *_ in on_leg) < eoa
    return on_leg


def intervention_margin(scenario):
    """One control period at the train's highest acceleration: how far above a curve the
    speed can be when the ATP sees it (it intervenes after the period)."""
    return scenario.train.traction.max_traction_force_n / scenario.train.mass_kg * \
        PERIOD_NS / 1e9


def test_full_traction_on_short_line_stops_at_midway_and_dwells():
    """Defect 1: with full traction every period the train used to pass Midway at 28 km/h and
    its SvL at 49 km/h. Now it never passes the stop's EOA, and the authority moves on only
    once the 30 s dwell has passed since the train first stood still at the stop. (After each
    emergency brake to standstill, the faulty ATO's traction moves the train on again, in ever
    shorter hops towards the EOA, each stopped by the brake.)"""
    s = load_scenario('short_line')
    sim = TrainSimulation(s)
    run = sim.supervision
    rows = run_full_traction(sim, 900)
    on_leg = stopped_before_end_of_authority(rows, run, 0)
    assert sim.atp_interventions >= 1
    moved_on = len(on_leg)  # the first period of leg 1
    assert moved_on < len(rows), 'the authority never moved on'
    low, high = run.stop_zone(0)
    first_at_stop = next(k for k, (x, v, *_) in enumerate(on_leg)
                         if v <= run.STANDSTILL_MPS and low <= x <= high)
    assert (moved_on - first_at_stop) / 10 >= run.dwell_s(0) - 0.1
    # and the speed never exceeded the emergency brake deceleration curve by more than the
    # intervention margin
    margin = intervention_margin(s)
    assert all(v <= ebd + margin for _x, v, _leg, ebd in rows)


def test_stuck_drive_cannot_cancel_the_emergency_brake():
    """Defect 2: a single drive stuck at its maximum (300 kN) from the start used to keep the
    train at 463 km/h through the ATP's intervention. The emergency brake cuts its traction."""
    s = load_scenario('short_line')
    sim = TrainSimulation(s)
    sim.inject_failures([ActuatorFailure('traction', 'stuck', 0.0,
                                         force_n=s.train.traction.max_traction_force_n)])
    rows = run_full_traction(sim, 600)
    on_leg = stopped_before_end_of_authority(rows, sim.supervision, 0)
    # the EBI ceiling plus the intervention margin
    margin = intervention_margin(s)
    assert max(v for _x, v, *_ in on_leg) <= (250.0 + 15.0) / 3.6 + margin
    assert all(v <= ebd + margin for _x, v, _leg, ebd in rows)
    # the published force shows the brake, not the stuck 300 kN, once the brake is applied
    assert sim.applied[0] <= 0.0 or not sim.emergency_brake


def test_emergency_brake_builds_up_linearly_over_t_be():
    s = load_scenario('short_line')
    sim = TrainSimulation(s)
    sim.inject_failures([ActuatorFailure('traction', 'stuck', 0.0, force_n=2e5)])
    for _ in range(6000):
        sim.apply_command((FULL,))
        sim.advance(PERIOD_NS)
        if sim.emergency_brake:
            break
    assert sim.emergency_brake and sim.applied == (0.0,)  # the stuck drive's traction is cut
    t_be = s.supervision.emergency_brake_build_up_s
    full = s.train.traction.max_emergency_brake_force_n
    sim.apply_command((FULL,))
    for _ in range(int(round(t_be * 5))):
        sim.advance(PERIOD_NS)
    assert sim.applied[0] == pytest.approx(-0.5 * full)
    for _ in range(int(round(t_be * 5))):
        sim.advance(PERIOD_NS)
    assert sim.applied[0] == pytest.approx(-full)


@pytest.mark.parametrize('force', [1e12, -1e12, math.inf])
def test_physically_impossible_failure_force_is_refused(force):
    """Defect 3: a stuck force of 1e12 N used to be accepted (1.24 million km/h)."""
    s = load_scenario('short_line')
    sim = TrainSimulation(s)
    with pytest.raises(FailureRejected, match='force_n'):
        sim.inject_failures([ActuatorFailure('traction', 'stuck', 0.0, force_n=force)])
    assert sim.failures == []  # nothing injected
    with pytest.raises(FailureRejected, match=r'force_n \+ amplitude_n'):
        sim.inject_failures([ActuatorFailure('traction', 'stuck_signal', 0.0, force_n=1e5,
                                             amplitude_n=failure_force_bound(s.train))])


def test_impossible_failure_in_a_file_is_refused_at_load():
    data = {'name': 's', 'train': {'preset': 'crh3_luo_xu'},
            'line': {'name': 'l', 'length_m': 20000,
                     'stations': [{'name': 'A', 'position_m': 0},
                                  {'name': 'B', 'position_m': 15000}],
                     'speed_limits': [{'start_m': 0, 'speed_kmh': 200}]},
            'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                         'max_jerk_mps3': 0.5},
            'plant': {'failures': [{'actuator': 'traction', 'kind': 'stuck', 'start_s': 0,
                                    'force_n': 1e12}]}}
    with pytest.raises(FailureRejected, match=r'force_n\| = 1e\+12 N exceeds'):
        TrainSimulation(parse_scenario(data))


def test_paper_failures_stay_accepted():
    sim = TrainSimulation(load_scenario('mao_2017_modes'))
    assert len(sim.failures) == 3


def test_train_maximum_speed_bounds_the_ceiling():
    """Defect 4: a 500 km/h line limit used to give a permitted speed of 489 km/h."""
    data = {'name': 's', 'train': {'preset': 'crh3_luo_xu'},
            'line': {'name': 'l', 'length_m': 100000,
                     'stations': [{'name': 'A', 'position_m': 0},
                                  {'name': 'B', 'position_m': 90000}],
                     'speed_limits': [{'start_m': 0, 'speed_kmh': 500}]},
            'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                         'max_jerk_mps3': 0.5}}
    s = parse_scenario(data)
    run = RunSupervision.for_scenario(s)
    assert s.train.max_speed_mps == pytest.approx(350.0 / 3.6)
    assert run.permitted_speed(40000.0) == pytest.approx(350.0 / 3.6)
    assert run.curve('ebi', 40000.0) == pytest.approx((350.0 + 15.0) / 3.6)
