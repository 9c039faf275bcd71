"""Both models against tight-tolerance reference solutions (scipy DOP853, rtol 1e-12), with
zero-order-hold commands that vary and a line whose grade, curve and tunnel forces jump at
segment boundaries. bench/bench.py repeats the check over 600 s for both models."""

import math

import numpy as np
from scipy.integrate import solve_ivp

from ato_common.scenario import parse_scenario
from train_plant_node.simulation import TrainSimulation

PERIOD_NS = 100_000_000


def line_scenario(preset):
    return parse_scenario({
        'name': 'acc', 'train': {'preset': preset},
        'line': {'name': 'l', 'length_m': 1e5,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9e4}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 400}],
                 'gradients': [{'start_m': 0, 'per_mille': 0}, {'start_m': 700, 'per_mille': 9},
                               {'start_m': 2100, 'per_mille': -6}],
                 'curves': [{'start_m': 1200, 'length_m': 500, 'radius_m': 3000}],
                 'tunnels': [{'start_m': 1500, 'length_m': 900}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5},
        'plant': {'resistance_variation': {'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.1}}}})


def compare(preset, model, seconds, command_period_s, command):
    """Largest speed error of the plant against the reference at every command change."""
    sim = TrainSimulation(line_scenario(preset), model)
    sim.state = sim.model.initial_state(0.0, 40.0)
    reference = np.array(sim.state, dtype=float)
    env = sim.surroundings()
    if model == 'point_mass':
        def rhs(t, y, forces):
            return [y[1], sim.model.acceleration(y[0], y[1], sum(forces), t, env)]
    else:
        def rhs(t, y, forces):
            return sim.model.derivative(y, forces, t, env)
    per_command = int(round(command_period_s * 10))
    worst = 0.0
    for k in range(int(seconds / command_period_s)):
        t0 = k * command_period_s
        forces = sim.apply_command(command(t0, len(sim.actuator_names)))
        for _ in range(per_command):
            sim.advance(PERIOD_NS)
        solution = solve_ivp(rhs, (t0, t0 + command_period_s), reference, args=(forces,),
                             method='DOP853', rtol=1e-12, atol=1e-12)
        reference = solution.y[:, -1]
        n = len(reference) // 2
        worst = max(worst, float(np.max(np.abs(np.asarray(sim.state)[n:] - reference[n:]))))
    return worst, sim


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
    assert min(sim.truth().positions) > 710, sim.truth().positions
    assert worst < 1e-6
