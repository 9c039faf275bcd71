"""Accuracy of the plant against a tight-tolerance reference solution (scipy DOP853, rtol and
atol 1e-12), used by the tests and by bench/bench.py. The reference integrates each command
period separately (zero-order hold) with the models' own right-hand sides, which look the line
force up at each car's position (no segment splitting) and the varying parameters at each time;
the multi-car reference runs in the lead car's frame (coupler extensions as states).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.integrate import solve_ivp

from ato_common.scenario import Scenario, parse_scenario
from train_plant_node.simulation import TrainSimulation


def accuracy_scenario(preset: str) -> Scenario:
    """A line whose forces jump at segment boundaries in its first 2.4 km (and vary inside a
    transition curve), and a slowly varying aerodynamic coefficient (Luo & Xu eq 34)."""
    return parse_scenario({
        'name': 'acc', 'train': {'preset': preset},
        'line': {'name': 'l', 'length_m': 1e5,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9e4}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 400}],
                 'gradients': [{'start_m': 0, 'per_mille': 0}, {'start_m': 700, 'per_mille': 9},
                               {'start_m': 2100, 'per_mille': -6}],
                 'curves': [{'start_m': 900, 'length_m': 200, 'radius_m': 5000,
                             'end_radius_m': 2000},   # a transition: force linear in position
                            {'start_m': 1200, 'length_m': 500, 'radius_m': 3000}],
                 'tunnels': [{'start_m': 1500, 'length_m': 900}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5},
        'plant': {'resistance_variation': {'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.1}}}})


def worst_speed_error(scenario: Scenario, model: str, seconds: float, command_period_s: float,
                      command: Callable[[float, int], tuple], initial_speed_mps: float = 40.0,
                      control_period_ns: int = 100_000_000) -> tuple[float, TrainSimulation]:
    """Largest speed error of any car at the end of each command period, m/s, and the
    simulation (commands must stay within the traction characteristic: the plant re-evaluates
    its power limit at every step, the reference holds the force; and within the supervision:
    an ATP intervention is a ValueError, as the reference has none)."""
    sim = TrainSimulation(scenario, model)
    sim.state = sim.model.initial_state(scenario.run.initial_position_m, initial_speed_mps)
    env = sim.surroundings()
    state = np.asarray(sim.state, dtype=float)
    n = len(state) // 2
    if model == 'point_mass':
        def rhs(t, y, forces):
            return [y[1], sim.model.acceleration(y[0], y[1], sum(forces), t, env)]

        def to_state(y):
            return y
        reference = state.copy()
    else:
        # The reference runs in the lead car's frame, as the paper's state (Mao et al. eq 7):
        # [z_1, extensions y_p - y_p+1, speeds]. In absolute positions of tens of kilometres
        # rtol 1e-12 would allow 1e-8 m errors per position, i.e. coupler forces of tens of N.
        def relative(y):
            return np.concatenate([[0.0], -np.cumsum(y[1:n]), y[n:]])

        def rhs(t, y, forces):
            derivative = sim.model.derivative(relative(y), forces, t, env, shift=y[0])
            v = y[n:]
            return np.concatenate([[v[0]], v[:-1] - v[1:], derivative[n:]])

        def to_state(y):
            absolute = relative(y)
            absolute[:n] += y[0]
            return absolute
        reference = np.concatenate([[state[0]], state[:n - 1] - state[1:n], state[n:]])
    periods = int(round(command_period_s * 1e9 / control_period_ns))
    worst = 0.0
    for _ in range(int(round(seconds / command_period_s))):
        t0 = sim.time_s
        forces = sim.apply_command(command(t0, len(sim.actuator_names)))
        for _ in range(periods):
            sim.advance(control_period_ns)
        solution = solve_ivp(rhs, (t0, sim.time_s), reference, args=(forces,),
                             method='DOP853', rtol=1e-12, atol=1e-12)
        reference = solution.y[:, -1]
        error = np.asarray(sim.state)[n:] - to_state(reference)[n:]
        worst = max(worst, float(np.max(np.abs(error))))
        if sim.atp_interventions or sim.emergency_brake:
            # The reference has no supervision: past this the comparison measures the ATP.
            raise ValueError(f'the ATP intervened at {sim.time_s:.1f} s ('
                             f'{sim.lead_speed() * 3.6:.1f} km/h at {sim.lead_position():.0f} m): '
                             'the commands drive the train beyond its supervision, which the '
                             'DOP853 reference does not model; keep them lower')
    return worst, sim
