"""What an odometer's errors mean (issue 29's odometry, the sensors): a speed bias that never
reads a moving train as standing or running backwards (the reading itself:
``ato_common/test/test_speed_reading.py``), a start position error that the first balise group
corrects, and a speed bias whose integral the balise groups keep bounded, in the ATO's reading
as in the ATP's odometry (no ROS)."""

import pytest

from ato_common.scenario import parse_scenario
from ato_common.validation import ConfigError
from train_plant_node.simulation import TrainSimulation

PERIOD_NS = 100_000_000


def scenario(sensors, balise_groups=None):
    line = {'name': 'l', 'length_m': 20000,
            'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 15000}],
            'speed_limits': [{'start_m': 0, 'speed_kmh': 200}]}
    if balise_groups is not None:
        line['balise_groups'] = [{'position_m': x} for x in balise_groups]
    return parse_scenario({
        'name': 's', 'train': {'preset': 'crh3_luo_xu'}, 'line': line,
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}, 'plant': {'sensors': sensors}})


def test_a_creeping_train_reads_as_moving_forwards_under_a_negative_bias():
    """On the starting commit a speed bias of -0.2 m/s read a train creeping at 0.05 m/s as
    running backwards at 0.15 m/s (and the odometer's count ran backwards with it)."""
    sim = TrainSimulation(scenario({'speed': {'bias': -0.2}}, balise_groups=[]))
    sim.state = sim.model.initial_state(100.0, 0.05)
    reading = sim.measured().speeds[0]
    assert 0.0 < reading < 0.05
    count, speed = sim.sensors.odometer(0.0, 100.0, 0.05)
    assert speed > 0.0


def run_to(sim, position_m):
    """Moderate traction until the train's front passes ``position_m``; the errors on the way
    (the ATO's reading, the ATP's odometry), each less the truth."""
    errors = []
    while sim.lead_position() < position_m:
        sim.apply_command((100e3,))
        sim.advance(PERIOD_NS)
        x = sim.lead_position()
        errors.append((x, sim.measured().positions[0] - x, sim.odometry.position_m - x))
    return errors


def test_the_first_balise_group_corrects_a_start_position_error_in_both_readings():
    """A position bias is the error of the position the train starts its mission with: on the
    starting commit the ATO's reading kept it for the whole run, past every balise group."""
    sim = TrainSimulation(scenario({'position': {'bias': -200.0}}, balise_groups=[1000, 2500]))
    errors = run_to(sim, 3000.0)
    assert all(ato == pytest.approx(-200.0) and atp == pytest.approx(-200.0)
               for x, ato, atp in errors if x < 1000.0)
    assert all(ato == pytest.approx(0.0, abs=1e-9) and atp == pytest.approx(0.0, abs=1e-9)
               for x, ato, atp in errors if x > 1000.0)


def test_the_balise_groups_bound_the_drift_of_a_speed_bias():
    """A speed bias alone: the position it integrates is corrected at each balise group, so
    the error is at most the bias over the time since the last group (the campaign's draws of
    a speed bias alone used to drift without bound on a line without groups: every line has
    them now, ``ato_common/test/test_balise_groups.py``)."""
    groups = [1500.0 * k for k in range(1, 13)]
    sim = TrainSimulation(scenario({'speed': {'bias': 0.2}}, balise_groups=groups))
    errors = run_to(sim, 15000.0)
    worst = max(abs(ato) for x, ato, _ in errors if x > 3000.0)
    assert 0.0 < worst < 0.2 * 1500.0 / 20.0   # the groups lie < 1500 m apart, run at > 20 m/s
    assert all(abs(atp) <= abs(ato) + 1e-9 for x, ato, atp in errors if x > 3000.0)


def test_a_speed_bias_that_could_reverse_a_reading_is_refused():
    with pytest.raises(ConfigError, match=r'plant.sensors.speed.bias: at most 5 m/s'):
        scenario({'speed': {'bias': -6.0}})
