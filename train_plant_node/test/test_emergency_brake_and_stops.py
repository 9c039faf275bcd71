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
        rows.append((x, v, sim.atp.leg, sim.supervision.curve('ebd', x, sim.atp.leg)))
    return rows


def in_stop_zone(scenario, x, zone):
    """The true front ``x`` is in the stop zone as an exact odometer's odometry sees it: its
    declared confidence interval (since the last balise group behind ``x``) reaches into it."""
    low, high = zone
    groups = [g for g in scenario.line.balise_groups_m if g <= x]
    o = scenario.supervision
    half = o.location_accuracy_m + o.odometry_accuracy * (x - (groups[-1] if groups else 0.0))
    return low - half <= x <= high + half


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
    first_at_stop = next(k for k, (x, v, *_) in enumerate(on_leg)
                         if v <= run.STANDSTILL_MPS and in_stop_zone(s, x, run.stop_zone(0)))
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
    assert sim.actuators.failures == []  # nothing injected
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
    assert len(sim.actuators.failures) == 3


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


def test_the_rogue_ato_never_passes_an_end_of_authority_and_dwells_standing():
    """Issue 29 item 1: with full traction every period the train ended 8 mm past Terminus'
    EOA after dozens of brake-to-stop hops, and the authority at Midway moved on 30 s after the
    train first stood in the stop zone, without a continuous standstill. The ATP now checks
    the cycle ahead at the train's highest acceleration, and a train standing at a stop is held
    there until its dwell is over."""
    sim = TrainSimulation(load_scenario('short_line'))
    run = sim.supervision
    rows = run_full_traction(sim, 1300)
    for leg in (0, 1):
        stopped_before_end_of_authority(rows, run, leg)
    assert sim.atp.leg == 1 and rows[-1][1] == 0.0  # stands before Terminus' EOA
    moved_on = next(k for k, row in enumerate(rows) if row[2] == 1)
    dwell = rows[moved_on - int(run.dwell_s(0) * 10):moved_on]
    assert all(v <= run.STANDSTILL_MPS and in_stop_zone(sim.scenario, x, run.stop_zone(0))
               for x, v, *_ in dwell)


@pytest.mark.parametrize('force_n, start_s', [(300e3, 0.0), (300e3, 200.0), (100e3, 0.0)])
def test_a_drive_that_keeps_pushing_keeps_the_emergency_brake_applied(force_n, start_s):
    """Issue 29 item 1: released at standstill, the brake let a stuck drive push the train on in
    hops until it ended past the EOA. The brake and the traction cut-off now hold while a drive
    delivers traction it is not asked for, and let go once the failure is isolated."""
    s = load_scenario('short_line')
    sim = TrainSimulation(s)
    sim.inject_failures([ActuatorFailure('traction', 'stuck', start_s, force_n=force_n)])
    rows = run_full_traction(sim, 900, command=(0.0,))  # the ATO asks for nothing
    moving = next(k for k, (x, v, *_) in enumerate(rows) if v > 1.0)
    stood = next(k for k, (x, v, *_) in enumerate(rows) if k > moving and v == 0.0)
    assert sim.atp_intervention and sim.atp_interventions == 1
    assert {round(x, 9) for x, *_ in rows[stood:]} == {round(rows[stood][0], 9)}
    assert 'traction' in sim.actuators.active(sim.time_s)  # still failed: held
    sim.inject_failures([], repaired=['traction'])        # isolated: the cause is gone
    sim.apply_command((0.0,))
    sim.advance(PERIOD_NS)
    assert not sim.atp_intervention
    run_full_traction(sim, 20, command=(100e3,))
    assert sim.lead_speed() > 0.0   # the ATO drives again


def test_a_train_at_a_stop_is_held_until_its_dwell_is_over():
    """A train that stands at Midway and is asked for traction before its dwell is over (it
    arrived later than its reference) stays until the dwell is over, then departs."""
    sim = TrainSimulation(load_scenario('short_line'))
    run = sim.supervision
    sim.state = sim.model.initial_state(run.stations_m[1], 0.0)
    # standing from the first period (braked: Midway lies on a descent), then full traction
    rows = run_full_traction(sim, 10, command=(-50e3,)) + run_full_traction(sim, 40)
    moving = [k for k, (x, v, *_) in enumerate(rows) if v > 0.0]
    # stood from the end of the first period; the dwell is over 30 s later; then it moves
    assert moving and moving[0] == int(run.dwell_s(0) * 10) + 1
    assert rows[moving[0]][2] == 1 and not sim.atp_interventions
