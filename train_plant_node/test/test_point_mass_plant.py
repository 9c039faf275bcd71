import math

import numpy as np
import pytest

from ato_common.scenario import load_scenario, parse_scenario
from ato_common.trains import steady_speed
from train_plant_node.models import make_model
from train_plant_node.simulation import CommandRejected, SensorSettings, TrainSimulation


def flat_scenario(grade_per_mille=0.0):
    return parse_scenario({
        'name': 'flat', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'flat', 'length_m': 1e6,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 9e5}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 400}],
                 'gradients': [{'start_m': 0, 'per_mille': grade_per_mille}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}})


def test_steady_speed_where_traction_equals_resistance():
    scenario = flat_scenario()
    force = 100e3
    v_steady = steady_speed(scenario.train, force)
    model = make_model('point_mass', scenario.train, scenario.line)
    state = model.initial_state(0.0, v_steady)
    for _ in range(600):
        state = model.step(state, 1.0, (force,))
    assert state[1] == pytest.approx(v_steady, abs=1e-9)
    # and from rest it converges to the same speed
    state = model.initial_state(0.0, 0.0)
    for _ in range(20000):
        state = model.step(state, 1.0, (force,))
    assert state[1] == pytest.approx(v_steady, rel=1e-6)


@pytest.mark.parametrize('grade, sign', [(10.0, -1.0), (-10.0, 1.0)])
def test_grade_force_sign_uphill_decelerates_downhill_accelerates(grade, sign):
    level, sloped = flat_scenario(0.0), flat_scenario(grade)
    v = 50.0
    force = level.train.davis.force(v)  # exactly balances resistance on the level
    a_level = make_model('point_mass', level.train, level.line).acceleration(100.0, v, force)
    a_slope = make_model('point_mass', sloped.train, sloped.line).acceleration(100.0, v, force)
    assert a_level == pytest.approx(0.0, abs=1e-12)
    assert a_slope == pytest.approx(sign * 9.80665 * math.sin(math.atan(abs(grade) / 1000)))


def test_train_does_not_roll_backwards_and_needs_breakaway_force():
    scenario = flat_scenario(5.0)
    model = make_model('point_mass', scenario.train, scenario.line)
    state = model.step(model.initial_state(0.0, 0.0), 10.0, (0.0,))
    assert state[1] == 0.0 and state[0] == 0.0
    # on the 5 per mille climb it takes the grade force plus the constant Davis term to start
    holding = scenario.train.mass_kg * 9.80665 * math.sin(math.atan(0.005)) + \
        scenario.train.davis.a_n
    assert model.step(model.initial_state(0.0, 0.0), 10.0, (0.99 * holding,))[1] == 0.0
    assert model.step(model.initial_state(0.0, 0.0), 10.0, (1.01 * holding,))[1] > 0.0
    state = model.step(model.initial_state(0.0, 1.0), 60.0, (-200e3,))
    assert state[1] == 0.0


def test_rk4_step_matches_a_fine_reference_solution():
    scenario = load_scenario('short_line')
    coarse = make_model('point_mass', scenario.train, scenario.line, max_substep_s=0.1)
    fine = make_model("point_mass", scenario.train, scenario.line, max_substep_s=0.005)
    a = coarse.initial_state(100.0, 30.0)
    b = fine.initial_state(100.0, 30.0)
    for _ in range(6000):  # 600 s with a constant force, crossing grade changes
        a = coarse.step(a, 0.1, (150e3,))
        b = fine.step(b, 0.1, (150e3,))
    assert a[1] == pytest.approx(b[1], abs=1e-3)


def test_energy_balance_of_traction_resistance_and_grade():
    scenario = flat_scenario(0.0)
    model = make_model('point_mass', scenario.train, scenario.line, max_substep_s=0.01)
    state = model.initial_state(0.0, 20.0)
    force, dt = 150e3, 0.01
    work = losses = 0.0
    m = scenario.train.mass_kg
    for _ in range(20000):
        s0, v0 = state
        state = model.step(state, dt, (force,))
        v_mid = 0.5 * (v0 + state[1])
        work += force * (state[0] - s0)
        losses += scenario.train.davis.force(v_mid) * (state[0] - s0)
    kinetic = 0.5 * m * (state[1] ** 2 - 20.0 ** 2)
    assert work == pytest.approx(kinetic + losses, rel=1e-5)


def test_simulation_rejects_bad_commands_and_keeps_the_last_one():
    sim = TrainSimulation(load_scenario('short_line'))
    sim.apply_command((100e3,))
    with pytest.raises(CommandRejected, match='non-finite'):
        sim.apply_command((float('nan'),))
    with pytest.raises(CommandRejected, match='2 forces for 1 actuators'):
        sim.apply_command((1.0, 2.0))
    assert sim.applied == (100e3,)
    assert sim.rejected_commands == 2
    sim.advance(100_000_000)
    assert all(math.isfinite(x) for x in sim.truth().positions + sim.truth().speeds)


def test_actuator_limits_saturate_the_applied_force():
    scenario = load_scenario('short_line')
    sim = TrainSimulation(scenario)
    applied = sim.apply_command((10e6,))
    assert applied == (scenario.train.traction.max_traction_force_n,)
    applied = sim.apply_command((-10e6,))
    assert applied == (-scenario.train.traction.max_emergency_brake_force_n,)
    assert sim.commanded == (-10e6,)


def test_time_is_exact_integer_nanoseconds_and_runs_are_deterministic():
    def run():
        sim = TrainSimulation(load_scenario('short_line'), sensors=SensorSettings(0.5, 0.05, 7))
        out = []
        for k in range(1000):
            sim.apply_command((200e3 if k < 600 else -100e3,))
            sim.advance(100_000_000)
            out.append(sim.measured().positions + sim.measured().speeds)
        return sim.stamp_ns, np.array(out)
    stamp_a, a = run()
    stamp_b, b = run()
    assert stamp_a == stamp_b == 100_000_000_000
    assert np.array_equal(a, b)


def test_sensor_noise_is_seeded_and_truth_is_separate():
    sim = TrainSimulation(load_scenario('short_line'), sensors=SensorSettings(1.0, 0.1, 3))
    sim.apply_command((200e3,))
    sim.advance(10 * 10**9)
    truth = sim.truth()
    measured = sim.measured(truth)
    assert measured.positions != truth.positions
    assert abs(measured.positions[0] - truth.positions[0]) < 10.0
