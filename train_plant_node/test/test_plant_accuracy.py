"""Both models against tight-tolerance reference solutions (scipy DOP853, rtol 1e-12), with
zero-order-hold commands that vary and a line whose grade, curve and tunnel forces jump at
segment boundaries. bench/bench.py runs the multi-car check over 600 s as well."""

import math

import pytest

from train_plant_node.accuracy import accuracy_scenario, worst_speed_error


def compare(preset, model, seconds, command_period_s, command):
    return worst_speed_error(accuracy_scenario(preset), model, seconds, command_period_s, command)


def varying(t, n):
    # below the power limit of the traction characteristic (which would change the force
    # within a command period, as the speed changes)
    return (((60e3 + 40e3 * math.sin(0.05 * t)) / n),) * n


def test_point_mass_speed_error_below_1e_6_over_600_s():
    worst, sim = compare('crh3_luo_xu', 'point_mass', 600.0, 1.0, varying)
    assert sim.lead_position() > 2500, sim.lead_position()  # it crossed every segment boundary
    assert worst < 1e-6


def test_multi_car_speed_error_below_1e_6():
    worst, sim = compare('crh2_4car_mao', 'multi_car', 40.0, 1.0,
                         lambda t, n: ((10e3 + 5e3 * math.sin(0.3 * t)),
                                       (8e3 + 6e3 * math.cos(0.2 * t))))
    assert min(sim.truth().positions) > 1100, sim.truth().positions
    assert worst < 1e-6


def test_a_run_the_atp_stops_is_not_taken_for_an_accuracy_figure():
    """The DOP853 reference has no supervision: commands that drive the train into an ATP
    intervention (past its 250 km/h design speed) are refused, not measured."""
    def command(t, n):
        return (30e3 / n,) * n
    with pytest.raises(ValueError, match='the ATP intervened'):
        worst_speed_error(accuracy_scenario('crh2_4car_mao'), 'multi_car', 600.0, 1.0, command)
