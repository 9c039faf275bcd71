"""Issue 29 item 9: the ATP supervises what the train's own odometry reports, with its
confidence interval, never the plant's truth; the odometry relocates at the balise groups the
line declares and calibrates its scale between them (no ROS)."""

import math

import pytest

from ato_common.braking_curves import SupervisionSettings, constant_deceleration
from ato_common.scenario import parse_scenario
from train_plant_node.odometry import CALIBRATION_MIN_M, Odometry
from train_plant_node.simulation import TrainSimulation

PERIOD_NS = 100_000_000
FULL = 1e9


def scenario(sensors=None, balise_groups=(), supervision=None, stops=(15000.0,),
             limit_kmh=200.0):
    stations = [{'name': 'A', 'position_m': 0}] + [
        {'name': f'S{i}', 'position_m': x, 'dwell_s': 30} for i, x in enumerate(stops)]
    line = {'name': 'l', 'length_m': stops[-1] + 5000.0, 'stations': stations,
            'speed_limits': [{'start_m': 0, 'speed_kmh': limit_kmh}],
            'balise_groups': [{'position_m': x} for x in balise_groups]}
    return parse_scenario({
        'name': 's', 'train': {'preset': 'crh3_luo_xu'}, 'line': line,
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5},
        'supervision': supervision or {}, 'plant': {'sensors': sensors or {}}})


def rogue_until_standing(sim, seconds=1500):
    """Full traction every period until the train stands after having moved."""
    moved = False
    for _ in range(int(seconds * 10)):
        sim.apply_command((FULL,))
        sim.advance(PERIOD_NS)
        moved = moved or sim.lead_speed() > 1.0
        if moved and sim.lead_speed() == 0.0:
            return sim.lead_position()
    pytest.fail('the train never stopped')


def test_a_biased_odometer_moves_where_the_atp_brakes_the_train():
    """On the starting commit the ATP read the true position: an odometer reading 100 m ahead
    left its intervention where it was. It reads the odometer now: 100 m earlier."""
    exact = rogue_until_standing(TrainSimulation(scenario()))
    ahead = rogue_until_standing(TrainSimulation(scenario({'position': {'bias': 100.0}})))
    assert exact - ahead == pytest.approx(100.0, abs=5.0)
    behind = TrainSimulation(scenario({'position': {'bias': -30.0}}))
    # 30 m later, into the overlap (EOA + 50 m): the margin the supervision may use
    assert rogue_until_standing(behind) - exact == pytest.approx(30.0, abs=5.0)
    assert behind.odometry.position_m == pytest.approx(behind.lead_position() - 30.0)


def test_the_confidence_interval_grows_with_distance_and_resets_at_balise_groups():
    supervision = {'location_accuracy_m': 2.0, 'odometry_accuracy': 0.05}
    sim = TrainSimulation(scenario(balise_groups=[0, 1000, 3000], supervision=supervision))
    widths = {}
    for _ in range(2000):
        sim.apply_command((150e3,))
        sim.advance(PERIOD_NS)
        x, o = sim.lead_position(), sim.odometry
        widths[round(x)] = (o.max_safe_front_m - o.min_safe_front_m, o.lrbg_m)
        assert o.min_safe_front_m <= x <= o.max_safe_front_m  # an exact odometer: truth inside
        if x > 4000.0:
            break
    width, lrbg = widths[min(widths, key=lambda k: abs(k - 900))]
    assert lrbg == 0.0 and width == pytest.approx(2 * (2.0 + 0.05 * 900), abs=1.0)
    width, lrbg = widths[min(widths, key=lambda k: abs(k - 1100))]
    assert lrbg == 1000.0 and width == pytest.approx(2 * (2.0 + 0.05 * 100), abs=1.0)
    assert sim.odometry.relocations == 3


def test_relocation_and_calibration_undo_a_scale_error_and_a_start_bias():
    """A wheel 10 % too small and a start position 200 m off: from the first balise group on
    the estimate is relocated, from the second calibrated (its speed too)."""
    sensors = {'position': {'scale_error': -0.1, 'bias': -200.0},
               'speed': {'scale_error': -0.1}}
    sim = TrainSimulation(scenario(sensors, balise_groups=[1000, 2500]))
    errors = []
    for _ in range(3000):
        sim.apply_command((200e3,))
        sim.advance(PERIOD_NS)
        x, o = sim.lead_position(), sim.odometry
        errors.append((x, o.position_m - x, o.speed_mps - sim.lead_speed()))
        if x > 4000.0:
            break
    before = [e for x, e, _ in errors if x < 1000.0]
    assert before[-1] == pytest.approx(-200.0 - 0.1 * 1000.0, abs=3.0)   # not relocated yet
    between = [(x, e) for x, e, _ in errors if 1000.0 < x < 2500.0]
    assert abs(between[0][1]) < 5.0 and between[-1][1] == pytest.approx(-0.1 * 1500, abs=5.0)
    after = [(e, ev) for x, e, ev in errors if x > 2600.0]
    assert all(abs(e) < 0.5 and abs(ev) < 1e-3 for e, ev in after)   # calibrated
    assert sim.odometry.scale == pytest.approx(0.9, rel=1e-3)


def test_without_its_speed_sensor_the_odometry_differentiates_its_count():
    sim = TrainSimulation(scenario({'speed': {'failed_from_s': 20.0}}))
    for _ in range(600):
        sim.apply_command((200e3,))
        sim.advance(PERIOD_NS)
        if sim.time_s > 20.05:
            assert math.isnan(sim.measured().speeds[0])   # the ATO has no speed
            o = sim.odometry
            assert o.speed_mps == pytest.approx(sim.lead_speed(), abs=0.06)
            assert o.max_speed_mps >= sim.lead_speed()      # the accuracy covers the lag
    assert not sim.atp_intervention


def test_without_its_odometry_the_atp_brakes_to_standstill_and_holds():
    sim = TrainSimulation(scenario({'speed': {'failed_from_s': 30.0},
                                    'position': {'failed_from_s': 30.0}}))
    for _ in range(1200):
        sim.apply_command((200e3,))
        sim.advance(PERIOD_NS)
    assert sim.atp_intervention and sim.atp.odometry_lost
    assert sim.lead_speed() == 0.0 and sim.atp.interventions == 1


@pytest.mark.parametrize('accuracy_m, moved_on', [(3.0, True), (0.0, False)])
def test_the_stop_zone_takes_the_confidence_interval(accuracy_m, moved_on):
    """A train standing 3 m short of the stopping point (2.5 m short of its stop zone): with a
    confidence interval of +/-3 m it may be at the station, and its authority moves on after
    the dwell; with an exact odometry it is not."""
    sim = TrainSimulation(scenario(stops=(14000.0, 30000.0),
                                   supervision={'location_accuracy_m': accuracy_m}))
    sim.state = sim.model.initial_state(13997.0, 0.0)
    for _ in range(10 * 31):
        sim.apply_command((0.0,))
        sim.advance(PERIOD_NS)
    odometry = sim.odometry
    assert (odometry.min_safe_front_m, odometry.max_safe_front_m) == (
        13997.0 - accuracy_m, 13997.0 + accuracy_m)
    assert (sim.atp.leg == 1) == moved_on


def test_calibration_needs_two_balise_groups_far_enough_apart():
    settings = SupervisionSettings(constant_deceleration(1.0), constant_deceleration(0.5))
    odometry = Odometry(settings, 0.0, 0.0, 0.01, 0.6)
    odometry.update(0.1, 100.0, 20.0, [(100.0, 100.0)])
    odometry.update(0.1, 100.0 + 0.9 * (CALIBRATION_MIN_M - 1.0), 18.0,
                    [(100.0 + CALIBRATION_MIN_M - 1.0, 100.0 + 0.9 * (CALIBRATION_MIN_M - 1.0))])
    assert odometry.scale == 1.0
    odometry.update(0.1, 100.0 + 0.9 * 1000.0, 18.0, [(1100.0, 100.0 + 0.9 * 1000.0)])
    assert odometry.scale == pytest.approx(0.9)
    assert odometry.speed_mps == pytest.approx(20.0)
    assert odometry.outside_interval == 2  # the interval declared none: every error is outside
