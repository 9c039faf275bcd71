"""The multi-car model: exact coupler dynamics, steady running (agreement with a tight
reference solution: test_plant_accuracy.py)."""

import math

import numpy as np
import pytest

from ato_common.scenario import parse_scenario
from ato_common.trains import CarParameters, Coupler, train_preset
from train_plant_node.models.multi_car import MultiCarModel
from train_plant_node.simulation import TrainSimulation


def flat_line(preset='crh2_4car_mao'):
    return parse_scenario({
        'name': 'flat', 'train': {'preset': preset},
        'line': {'name': 'flat', 'length_m': 1e6,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9e5}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 400}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}})


def two_cars(k=7e8, d=0.0, m1=45e3, m2=50e3):
    base = train_preset('crh2_4car_mao')
    return base.__class__(**{**base.__dict__, 'cars': (
        CarParameters('car_1', m1, 0.0, 0.0, 0.0, powered=True),
        CarParameters('car_2', m2, 0.0, 0.0, 0.0)), 'couplers': (Coupler(k, d),),
        'actuator_names': ('car_1',)})


def test_free_two_car_coupler_oscillates_at_the_analytic_frequency():
    k, m1, m2 = 7e8, 45e3, 50e3
    model = MultiCarModel(two_cars(k, 0.0, m1, m2), flat_line().line)
    omega = math.sqrt(k * (1.0 / m1 + 1.0 / m2))
    assert 16.0 < omega / (2 * math.pi) < 39.0  # coupler modes: docs/papers/mao_multibody.md
    state = model.initial_state(1000.0, 0.0)
    state[0] += 0.002  # a 2 mm extension, released
    period = 2 * math.pi / omega
    after = model.step(state, period, (0.0,))
    half = model.step(state, period / 2, (0.0,))
    assert after[0] - after[1] == pytest.approx(0.002, abs=1e-9)
    assert half[0] - half[1] == pytest.approx(-0.002, abs=1e-9)


def test_four_car_unit_runs_steadily_with_bounded_constant_spacing():
    scenario = flat_line()
    train = scenario.train
    model = MultiCarModel(train, scenario.line)
    v = 60.0
    total = sum(c.mass_kg * (c.a_mps2 + c.b_per_s * v + c.c_per_m * v * v) for c in train.cars)
    state = model.initial_state(0.0, v)
    extensions = []
    for _ in range(3000):
        state = model.step(state, 0.1, (total / 2, total / 2))
        extensions.append(state[:3] - state[1:4])
    speeds = state[4:]
    assert np.allclose(speeds, v, atol=1e-6)  # cars 1 and 3 (and all) at the same speed
    late = np.array(extensions[-100:])
    assert np.max(np.abs(late)) < 1e-3 and np.ptp(late, axis=0).max() < 1e-9


def test_the_simulation_drives_the_powered_cars_and_reports_every_car():
    sim = TrainSimulation(flat_line(), 'multi_car')
    assert sim.actuator_names == ('car_2', 'car_3')
    sim.apply_command((40e3, 40e3))
    for _ in range(100):
        sim.advance(100_000_000)
    truth = sim.truth()
    assert truth.car_names == ('car_1', 'car_2', 'car_3', 'car_4')
    assert truth.forces == (0.0, 40e3, 40e3, 0.0)
    assert all(s > 0 for s in truth.speeds)
    assert truth.positions[0] - truth.positions[3] == pytest.approx(75.0, abs=0.01)


def test_a_single_mass_train_is_refused_with_the_reason():
    with pytest.raises(ValueError, match='no multi-car description'):
        MultiCarModel(train_preset('crh3_luo_xu'), flat_line().line)


def test_energy_balance_of_the_four_car_unit():
    # work of traction = kinetic + coupler spring energy + resistance, grade and damper losses;
    # the powers are integrated with composite Simpson on the model's own 1 ms steps
    scenario = parse_scenario({
        'name': 'climb', 'train': {'preset': 'crh2_4car_mao'},
        'line': {'name': 'l', 'length_m': 1e5,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9e4}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 400}],
                 'gradients': [{'start_m': 0, 'per_mille': 5}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}})
    train = scenario.train
    model = MultiCarModel(train, scenario.line, max_substep_s=0.001)
    cars, n = train.cars, 4
    m = np.array([c.mass_kg for c in cars])
    k = np.array([c.stiffness_n_per_m for c in train.couplers])
    d = np.array([c.damping_n_s_per_m for c in train.couplers])
    grade = 9.80665 * math.sin(math.atan(0.005))

    def energy(x):
        extension = x[:n - 1] - x[1:n]
        return 0.5 * np.sum(m * x[n:] ** 2) + 0.5 * np.sum(k * extension ** 2)

    def powers(x, forces):
        v = x[n:]
        traction = forces[0] * v[1] + forces[1] * v[2]
        resistance = sum(c.mass_kg * (c.a_mps2 * math.tanh(s / 0.01) + c.b_per_s * s
                                      + c.c_per_m * s * abs(s)) * s for c, s in zip(cars, v))
        losses = resistance + float(np.sum(m * grade * v)) + float(np.sum(d * np.diff(v) ** 2))
        return traction, losses

    x = model.initial_state(100.0, 30.0)
    start = energy(x)
    work, lost = 0.0, 0.0
    for period in range(200):  # 20 s, the command changes every 0.1 s
        forces = (12e3 + 8e3 * math.sin(0.7 * period), 10e3 + 9e3 * math.cos(0.5 * period))
        samples = [powers(x, forces)]
        for _ in range(100):
            x = model.step(x, 0.001, forces)
            samples.append(powers(x, forces))
        weights = [1] + [4 if i % 2 else 2 for i in range(1, 100)] + [1]
        work += 0.001 / 3 * sum(w * p[0] for w, p in zip(weights, samples))
        lost += 0.001 / 3 * sum(w * p[1] for w, p in zip(weights, samples))
    assert work > 1e6
    # 1e-9 of the work (the issue asks 1e-6): tight enough to see the damper losses
    assert work - lost == pytest.approx(energy(x) - start, rel=0.0, abs=1e-9 * work)


def test_brakes_hold_a_standing_train_and_never_push_it_backwards():
    """The ATP's holding brake at a dwell and its emergency brake at standstill: the 4-car
    unit stays where it stands (it used to be pushed backwards, away from its stop zone);
    traction above the static friction still starts it."""
    scenario = flat_line()
    model = MultiCarModel(scenario.train, scenario.line)
    state = model.initial_state(1000.0, 0.0)
    braked = state
    for _ in range(100):  # 10 s of full emergency braking on both powered cars
        braked = model.step(braked, 0.1, (-2e5, -2e5))
    assert np.allclose(braked[4:], 0.0) and np.allclose(braked[:4], state[:4], atol=1e-9)
    assert model.held(state, (-2e5, -2e5)) and not model.held(state, (1e5, 1e5))
    started = model.step(state, 0.1, (1e5, 1e5))
    assert np.all(started[4:] > 0.0)
