"""Scheduled changes, actuators, failures, sensors and energy balance of the simulated plant."""

import math

import numpy as np
import pytest

from ato_common import units
from ato_common.plant_setup import SPEED_BIAS_FULL_MPS
from ato_common.scenario import parse_scenario
from ato_common.validation import ConfigError
from train_plant_node.simulation import TrainSimulation

PERIOD_NS = 100_000_000
G = units.STANDARD_GRAVITY


def scenario(preset='mao_2017_500t', plant=None, gradients=None, curves=None, tunnels=None):
    line = {'name': 'l', 'length_m': 2e6,
            'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 1.9e6}],
            'speed_limits': [{'start_m': 0, 'speed_kmh': 500}]}
    for key, value in (('gradients', gradients), ('curves', curves), ('tunnels', tunnels)):
        if value:
            line[key] = value
    return parse_scenario({
        'name': 's', 'train': {'preset': preset}, 'line': line,
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}, 'plant': plant})


def run(sim, seconds, command=None, every=None):
    """Advance; ``every(sim)`` after each period collects what a test looks at."""
    out = []
    for _ in range(int(round(seconds * 10))):
        if command is not None:
            sim.apply_command(command(sim) if callable(command) else command)
        sim.advance(PERIOD_NS)
        if every is not None:
            out.append(every(sim))
    return out


def mode_now(sim):
    """The index of the plant's mode now."""
    return sim.setup.mode_index(sim.time_s, sim.lead_position())


MAO_FAILURES = [
    {'actuator': 'motor_2', 'kind': 'stuck', 'start_s': 60, 'end_s': 100, 'force_n': 2e5},
    {'actuator': 'motor_2', 'kind': 'stuck_signal', 'start_s': 100, 'end_s': 120,
     'force_n': 2e5, 'amplitude_n': 2e5, 'omega_rad_per_s': 0.05, 'phase_rad': -30},
    {'actuator': 'motor_2', 'kind': 'loss', 'start_s': 120, 'end_s': 130},
    {'actuator': 'motor_3', 'kind': 'partial', 'start_s': 125, 'effectiveness': 0.25}]


def test_failures_act_at_their_scheduled_times_and_show_in_the_published_force():
    # Mao et al. 2017's failure sequence, time-compressed by 10: stuck at 2e5 N, stuck on
    # 2e5 (1 + sin(0.05 t - 30)) N, total loss; plus a partial loss on another motor.
    sim = TrainSimulation(scenario(plant={'failures': MAO_FAILURES}))
    trace = run(sim, 140, (30e3,) * 4, lambda s: (s.time_s, s.applied, s.truth().forces[0]))
    by_time = {round(t, 1): (applied, total) for t, applied, total in trace}
    assert by_time[59.9][0] == (30e3,) * 4
    assert by_time[60.0][0] == (30e3, 2e5, 30e3, 30e3)       # from its start time on
    assert by_time[99.9][0][1] == 2e5
    assert by_time[110.0][0][1] == pytest.approx(2e5 * (1 + math.sin(0.05 * 110.0 - 30)))
    assert by_time[120.0][0] == (30e3, 0.0, 30e3, 30e3)
    assert by_time[125.0][0] == (30e3, 0.0, 7.5e3, 30e3)
    assert by_time[130.0][0] == (30e3, 30e3, 7.5e3, 30e3)    # motor_2 healthy again
    assert by_time[60.0][1] == pytest.approx(3 * 30e3 + 2e5)  # the train feels the sum
    # the stuck motor accelerates the train beyond what the healthy ones would
    healthy = TrainSimulation(scenario())
    run(healthy, 100, (30e3,) * 4)
    failed = TrainSimulation(scenario(plant={'failures': MAO_FAILURES[:1]}))
    run(failed, 100, (30e3,) * 4)
    gain = failed.lead_speed() - healthy.lead_speed()
    assert gain == pytest.approx((2e5 - 30e3) * 40.0 / 500e3, rel=0.02)


def test_partial_loss_scales_traction_and_braking_by_their_own_shares():
    # A lost converter (traction at 0.5) with the friction brake intact, an isolated brake
    # (braking at 0.25) with the traction intact, and the one share of both of older files.
    failures = [
        {'actuator': 'motor_1', 'kind': 'partial', 'start_s': 0, 'traction_effectiveness': 0.5},
        {'actuator': 'motor_2', 'kind': 'partial', 'start_s': 0, 'brake_effectiveness': 0.25},
        {'actuator': 'motor_3', 'kind': 'partial', 'start_s': 0, 'effectiveness': 0.5}]
    sim = TrainSimulation(scenario(plant={'failures': failures}))
    run(sim, 1, (30e3,) * 4)
    assert sim.applied == (15e3, 30e3, 15e3, 30e3)
    run(sim, 1, (-30e3,) * 4)
    assert sim.applied == (-30e3, -7.5e3, -15e3, -30e3)
    assert sim.truth().forces[0] == pytest.approx(-82.5e3)  # the train feels the sum
    described = {f.actuator: f.describe() for f in sim.actuators.failures}
    assert '0.5 of the healthy traction, 1 of the braking force' in described['motor_1']
    assert '0.5 of the healthy force' in described['motor_3']


@pytest.mark.parametrize('record, message', [
    ({}, "needs 'effectiveness'"),
    ({'brake_effectiveness': 0.0}, 'brake_effectiveness'),
    ({'traction_effectiveness': 1.5}, 'traction_effectiveness')])
def test_a_partial_loss_without_a_valid_share_is_refused(record, message):
    failure = {'actuator': 'motor_1', 'kind': 'partial', 'start_s': 0, **record}
    with pytest.raises(ConfigError, match=message):
        scenario(plant={'failures': [failure]})


@pytest.mark.parametrize('traction, brake, pulled, braked', [
    (0.875, 1.0, 0.875, 1.0),    # a lost converter: the friction brake still brakes
    (1.0, 0.9375, 1.0, 0.9375),  # an isolated brake: the traction is whole
])
def test_drawn_traction_and_brake_effectiveness_act_separately_on_the_plant(traction, brake, pulled,
                                                                      braked):
    from ato_common import uncertainty as u
    from ato_common.scenario import load_scenario
    scenario = load_scenario('short_line')
    values = {name: p.nominal for name, p in u.PARAMETERS.items()}
    values.update(traction_effectiveness=traction, brake_effectiveness=brake)
    sim = TrainSimulation(u.perturbed(scenario, values))
    n = len(sim.actuator_names)
    sim.apply_command((1e4,) * n)
    assert sim.applied == pytest.approx((1e4 * pulled,) * n)
    sim.apply_command((-1e4,) * n)
    assert sim.applied == pytest.approx((-1e4 * braked,) * n)


def test_run_time_injection_replaces_and_repairs():
    from ato_common.plant_setup import ActuatorFailure
    sim = TrainSimulation(scenario())
    run(sim, 10, (20e3,) * 4)
    sim.inject_failures([ActuatorFailure('motor_4', 'stuck', sim.time_s, force_n=-5e4)])
    assert sim.applied[3] == -5e4
    run(sim, 5, (20e3,) * 4)
    assert sim.applied[3] == -5e4 and sim.actuators.active(sim.time_s)['motor_4'].kind == 'stuck'
    sim.inject_failures([], repaired=['motor_4'])
    assert sim.applied == (20e3,) * 4 and not sim.actuators.active(sim.time_s)


def test_modes_switch_at_their_times_and_change_the_dynamics():
    # Mao et al. 2017: the tunnel mode raises c from 3.2e-4 to 9.2e-4 kN/(km/h)^2 at 400 s
    plant = {'modes': [{'from_s': 0, 'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 3.2e-4}},
                       {'from_s': 40, 'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 9.2e-4}},
                       {'from_s': 80, 'grade_sine': 0.015, 'curvature': 0.34,
                        'davis_kn_kmh': {'a': 2.25, 'b': -1.9e-3, 'c': 3.2e-4}}]}
    sim = TrainSimulation(scenario(plant=plant))
    sim.state = sim.model.initial_state(0.0, 50.0)
    force = 120e3
    trace = run(sim, 100, (force / 4,) * 4,
                lambda s: (s.time_s, mode_now(s), s.truth().speeds[0],
                           s.truth().accelerations[0]))
    modes = {round(t, 1): m for t, m, _, _ in trace}
    assert (modes[39.9], modes[40.0], modes[79.9], modes[80.0]) == (0, 1, 1, 2)
    for t, m, v, a in trace:
        mode = sim.setup.modes[m]
        d = mode.davis
        expected = (force - d.a_n - d.b_n_s_per_m * v - d.c_n_s2_per_m2 * v * v) / 500e3 \
            - G * mode.grade_sine - mode.curve_accel_mps2
        assert a == pytest.approx(expected, abs=1e-9), t


def test_abrupt_grade_change_and_varying_resistance_are_in_the_truth():
    plant = {'abrupt_changes': [{'start_s': 10, 'end_s': 11, 'grade_per_mille': 30}],
             'resistance_variation': {'a': {'amplitude': 0.3, 'omega_rad_per_s': 0.1},
                                      'b': {'amplitude': 0.2, 'omega_rad_per_s': 0.1},
                                      'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.1}}}
    sim = TrainSimulation(scenario('crh3_luo_xu', plant, gradients=[{'start_m': 0,
                                                                     'per_mille': 5}]))
    sim.state = sim.model.initial_state(0.0, 60.0)
    force = 100e3  # below the power limit at 60 m/s
    trace = run(sim, 12, (force,), lambda s: (s.time_s, s.truth().speeds[0],
                                              s.truth().accelerations[0]))
    d, mass = sim.scenario.train.davis, sim.scenario.train.mass_kg
    for t, v, a in trace:
        grade = 30.0 if 10.0 <= t < 11.0 else 5.0
        s = math.sin(0.1 * t)
        resistance = (d.a_n * (1 + 0.3 * s) + d.b_n_s_per_m * (1 + 0.2 * s) * v
                      + d.c_n_s2_per_m2 * (1 + 0.1 * s) * v * v)
        expected = (force - resistance) / mass - G * units.per_mille_to_sine(grade)
        assert a == pytest.approx(expected, abs=1e-9), t


def test_actuator_lag_rate_limit_and_power_share():
    sim = TrainSimulation(scenario(plant={'actuators': {'time_constant_s': 2.0}}))
    trace = run(sim, 4, (40e3,) * 4, lambda s: s.applied[0])
    assert trace[19] == pytest.approx(40e3 * (1 - math.exp(-1.0)), rel=1e-9)  # after one tau
    assert sim.commanded == (40e3,) * 4
    sim = TrainSimulation(scenario(plant={'actuators': {'rate_limit_n_per_s': 1e4}}))
    trace = run(sim, 3, (25e3,) * 4, lambda s: s.applied[0])
    assert trace[9] == pytest.approx(1e4) and trace[-1] == pytest.approx(25e3)
    sim = TrainSimulation(scenario())
    sim.state = sim.model.initial_state(0.0, 80.0)
    applied = sim.apply_command((1e6,) * 4)
    traction = sim.scenario.train.traction
    assert applied[0] == pytest.approx(traction.max_traction_power_w / 80.0 / 4)


def test_actuator_dead_time_delays_the_request_exactly_then_the_lag_acts():
    # 0.25 s dead time: a 10 Hz command acts from 0.25 s, within the third period; then the lag
    sim = TrainSimulation(scenario(plant={'actuators': {'dead_time_s': 0.25,
                                                        'time_constant_s': 1.0}}))
    trace = run(sim, 2, (40e3,) * 4, lambda s: s.applied[0])
    assert trace[0] == 0.0 and trace[1] == 0.0  # after 0.1 s and 0.2 s: nothing yet
    assert trace[2] == pytest.approx(40e3 * (1 - math.exp(-0.05)), rel=1e-9)  # 0.05 s of lag
    assert trace[-1] == pytest.approx(40e3 * (1 - math.exp(-1.75)), rel=1e-9)
    # a pure dead time: the force steps 0.3 s after the command (the period after 0.3 s), and
    # back 0.3 s after the command ends
    sim = TrainSimulation(scenario(plant={'actuators': {'dead_time_s': 0.3}}))
    trace = run(sim, 1, lambda s: (40e3,) * 4 if s.time_s < 0.5 else (0.0,) * 4,
                lambda s: s.applied[0])
    assert trace[:4] == [0.0, 0.0, 0.0, 40e3] and trace[7:] == [40e3, 0.0, 0.0]
    with pytest.raises(ConfigError, match='plant.actuators.dead_time_s'):
        scenario(plant={'actuators': {'dead_time_s': -1.0}})


def test_the_traction_limit_applies_after_the_dead_time_at_the_speed_of_then():
    """A request passes the dead time, then the traction characteristic at the speed of the
    moment limits it: full traction asked at standstill delivers what the power allows at the
    speed reached. The request changes only with the command, so a saturated run with a dead
    time and a lag splits a period at most once, where a new request takes effect."""
    sim = TrainSimulation(scenario(plant={'actuators': {'dead_time_s': 0.25,
                                                        'time_constant_s': 0.5}}))
    steps = []
    model_step = sim.model.step

    def counted(*args, **kwargs):
        steps.append(sim.time_s)
        return model_step(*args, **kwargs)
    sim.model.step = counted
    periods = 600
    run(sim, periods / 10, (1e7,) * 4)   # far above the characteristic: saturated throughout
    assert len(steps) <= periods + 1     # the first request's one split
    traction = sim.scenario.train.traction
    speed = sim.lead_speed()
    assert speed > 20.0                  # on the power hyperbola
    limit = traction.max_traction_at(speed) / 4
    assert limit < traction.max_traction_at(0.0) / 4   # below the standstill force
    targets = sim.actuators.targets(sim.commanded, sim.level, sim.lead_speed())
    assert targets == [pytest.approx(limit, rel=1e-12)] * 4
    # the lag follows the limit as it falls with the speed: a little above it
    assert limit < sim.applied[0] < limit * 1.02


def test_odometry_scale_error_reads_speed_and_the_distance_since_the_last_reset():
    sensors = {'position': {'bias': 0.5, 'scale_error': 0.01, 'reset_positions_m': [100.0]},
               'speed': {'scale_error': 0.01}}
    sim = TrainSimulation(scenario(plant={'sensors': sensors}))
    sim.state = sim.model.initial_state(60.0, 20.0)
    m = sim.measured()
    assert m.speeds[0] == pytest.approx(20.2) and m.positions[0] == pytest.approx(60.6 + 0.5)
    sim.state = sim.model.initial_state(300.0, 20.0)  # 200 m since the reset at 100 m
    # the reset corrected the start's bias (the error of the start of mission) too
    assert sim.measured().positions[0] == pytest.approx(302.0)
    assert sim.sensors.position_error(300.0) == pytest.approx(2.0)
    with pytest.raises(ConfigError, match='plant.sensors.position.reset_positions_m'):
        scenario(plant={'sensors': {'position': {'reset_positions_m': ['x']}}})


def test_the_measured_position_integrates_the_measured_speed_under_a_bias():
    """Issue 28 defect 3, the sensors: a speed bias left the measured position unbiased, so
    the measured position's rate was not the measured speed (the identification of Tan et
    al.'s laws saw a contradiction). The odometer integrates what it measures: the position
    drifts by the bias's integral (in full from 30 km/h, in proportion to the speed below), and
    a wheel that stands reads no speed and no drift."""
    sim = TrainSimulation(scenario(plant={'sensors': {'speed': {'bias': 0.1}}}))
    standing = run(sim, 5, (0.0,) * 4, lambda s: s.measured())
    assert all(m.speeds[0] == 0.0 and m.positions[0] == 0.0 for m in standing)
    trace = run(sim, 60, (50e3,) * 4, lambda s: (s.time_s, s.truth(), s.measured()))
    for (t0, _, m0), (t1, _, m1) in zip(trace, trace[1:]):
        rate = (m1.positions[0] - m0.positions[0]) / (t1 - t0)
        assert rate == pytest.approx(0.5 * (m0.speeds[0] + m1.speeds[0]), abs=2e-3)
    t, truth, measured = trace[-1]
    x = [0.0] + [state.positions[0] for _, state, _ in trace]
    drift = sum(0.1 * min(0.1, (b - a) / SPEED_BIAS_FULL_MPS) for a, b in zip(x, x[1:]))
    assert measured.positions[0] - truth.positions[0] == pytest.approx(drift, rel=1e-9)
    assert 0.1 * (t - 5.0) - 1.0 > drift > 0.1 * (t - 5.0) - 5.0  # under 30 km/h for a while


def test_sensors_bias_quantisation_noise_dropout_and_failed_speed_sensor():
    sensors = {'seed': 11,
               'position': {'bias': 2.0, 'quantum': 0.5},
               'speed': {'noise_std': 0.05, 'failed_from_s': 30},
               'acceleration': {'dropout_probability': 0.2}}
    sim = TrainSimulation(scenario(plant={'sensors': sensors}))
    trace = run(sim, 60, (50e3,) * 4, lambda s: (s.time_s, s.truth(), s.measured()))
    for t, truth, measured in trace:
        assert measured.positions[0] == round((truth.positions[0] + 2.0) / 0.5) * 0.5
        if t >= 30.0:
            assert math.isnan(measured.speeds[0])  # failed: not measured, NaN
        assert not math.isnan(truth.speeds[0])      # the truth is untouched
    errors = np.array([m.speeds[0] - tr.speeds[0] for t, tr, m in trace if t < 30.0])
    assert abs(errors.mean()) < 0.02 and errors.std() == pytest.approx(0.05, rel=0.2)
    dropped = np.mean([math.isnan(m.accelerations[0]) for _, _, m in trace])
    assert 0.12 < dropped < 0.28


@pytest.mark.parametrize('preset, model, quantity, cars, message', [
    ('crh2_4car_mao', 'multi_car', 'speed', ['car_2', 'train'],
     "plant.sensors.speed.failed_cars[1]: car 'train' is not a car of the multi_car model; "
     'valid: car_1, car_2, car_3, car_4'),
    ('crh2_4car_mao', 'point_mass', 'position', ['car_2'],
     "plant.sensors.position.failed_cars[0]: car 'car_2' is not a car of the point_mass model; "
     'valid: train'),
])
def test_a_failed_sensor_car_the_model_does_not_have_is_refused(preset, model, quantity, cars,
                                                                 message):
    # The scenario accepts the cars of either model; built for one, the other's would fail
    # nothing without a word.
    plant = {'sensors': {quantity: {'failed_from_s': 1, 'failed_cars': cars}}}
    with pytest.raises(ConfigError) as error:
        TrainSimulation(scenario(preset, plant), model)
    assert str(error.value) == message


@pytest.mark.parametrize('model, cars, failed', [
    ('multi_car', ['car_2'], (False, True, False, False)),
    ('multi_car', [], (True, True, True, True)),
    ('point_mass', ['train'], (True,)),
    ('point_mass', [], (True,)),
])
def test_a_failed_sensor_fails_the_cars_it_names_on_the_model_that_has_them(model, cars, failed):
    plant = {'sensors': {'speed': {'failed_from_s': 1, 'failed_cars': cars}}}
    sim = TrainSimulation(scenario('crh2_4car_mao', plant), model)
    before, after = run(sim, 2, (12e3,) * len(sim.actuator_names),
                        lambda s: s.measured().speeds)[::10]
    assert not any(math.isnan(v) for v in before)
    assert tuple(math.isnan(v) for v in after) == failed


def test_energy_balance_of_the_point_mass():
    # work of traction + disturbance = kinetic energy + resistance + line losses, on a line with
    # grades, a curve and a tunnel, with varying commands, varying resistance and a disturbance
    plant = {'disturbance': {'kind': 'fast', 'amplitude_n': 5e3, 'omega_rad_per_s': 0.3},
             'resistance_variation': {'a': {'amplitude': 0.3, 'omega_rad_per_s': 0.1}}}
    sim = TrainSimulation(scenario('crh3_luo_xu', plant,
                                   gradients=[{'start_m': 0, 'per_mille': 0},
                                              {'start_m': 3000, 'per_mille': 8},
                                              {'start_m': 9000, 'per_mille': -4}],
                                   curves=[{'start_m': 5000, 'length_m': 800, 'radius_m': 4000}],
                                   tunnels=[{'start_m': 7000, 'length_m': 1500}]))
    run(sim, 300, lambda s: (200e3 + 80e3 * math.sin(0.02 * s.time_s),))
    traction, resistance, line, disturbance = sim.model.work
    kinetic = 0.5 * sim.scenario.train.mass_kg * sim.lead_speed() ** 2
    assert sim.lead_position() > 10000  # all the line's features were crossed
    assert traction + disturbance - resistance - line == pytest.approx(kinetic, rel=1e-6)


def test_multi_car_modes_by_region_scale_every_car_and_failures_hit_a_power_car():
    # a tunnel region doubling the aerodynamic term, then a climbing region with a heavier train
    train_davis = scenario('crh2_4car_mao').train.davis
    plant = {'modes': [
        {'from_m': 0},
        {'from_m': 400, 'davis_n': {'a': train_davis.a_n, 'b': train_davis.b_n_s_per_m,
                                    'c': 2 * train_davis.c_n_s2_per_m2}},
        {'from_m': 800, 'mass_kg': 200e3, 'grade_sine': 0.01}],
        'failures': [{'actuator': 'car_3', 'kind': 'loss', 'start_s': 5}]}
    sim = TrainSimulation(scenario('crh2_4car_mao', plant), 'multi_car')
    sim.state = sim.model.initial_state(0.0, 40.0)
    trace = run(sim, 30, (12e3, 12e3), lambda s: (mode_now(s), s.truth(), s.applied))
    assert {m for m, _, _ in trace} == {0, 1, 2}
    cars = sim.scenario.train.cars
    for mode_index, truth, applied in trace:
        mode = sim.setup.modes[mode_index]
        ratio_m = mode.mass_kg / sim.scenario.train.mass_kg
        ratio_c = mode.davis.c_n_s2_per_m2 / train_davis.c_n_s2_per_m2
        # coupler forces cancel in the sum: sum m_p a_p = F - resistances - mode's grade
        momentum_rate = sum(c.mass_kg * ratio_m * a for c, a in zip(cars, truth.accelerations))
        resistance = sum(c.mass_kg * (c.a_mps2 * math.tanh(v / 0.01) + c.b_per_s * v
                                      + ratio_c * c.c_per_m * v * abs(v))
                         for c, v in zip(cars, truth.speeds))
        expected = sum(applied) - resistance - mode.mass_kg * G * mode.grade_sine
        assert momentum_rate == pytest.approx(expected, abs=1e-6 * mode.mass_kg), mode_index
        assert truth.forces == (0.0, applied[0], applied[1], 0.0)
    assert trace[48][2] == (12e3, 12e3) and trace[49][2] == (12e3, 0.0)  # at 4.9 s, at 5 s


@pytest.mark.parametrize('kind', ['none', 'fast', 'slow', 'random'])
def test_the_kernels_read_the_varying_resistance_and_disturbance_as_the_scenario_defines_them(kind):
    # The compiled kernels evaluate Luo & Xu eq (34) and Liu & Li eq (9) from a parameter array
    # (surroundings.env_factors): they must agree with ato_common's definitions.
    from ato_common.plant_setup import Disturbance, ResistanceVariation, Sinusoid
    from ato_common.trains import train_preset
    from train_plant_node.surroundings import Surroundings, nominal_mode
    variation = ResistanceVariation(a=Sinusoid(0.2, 0.3, 0.1), c=Sinusoid(0.1, 0.05),
                                    line=Sinusoid(0.05, 0.7, -1.0))
    disturbance = Disturbance(kind=kind, amplitude_n=3e4, omega_rad_per_s=0.4, phase_rad=0.5,
                              hold_s=2.0, seed=3)
    env = Surroundings(nominal_mode(train_preset('crh3_luo_xu')), 0, resistance_factor=1.3,
                       variation=variation,
                       disturbance=disturbance if kind != 'none' else None)
    for t in (0.0, 1.7, 12.3, 101.0):
        fa, fb, fc, fl = variation.factors(t)
        expected = (1.3 * fa, 1.3 * fb, 1.3 * fc, fl, disturbance.force(t))
        assert env.factors(t) == pytest.approx(expected, rel=1e-14, abs=1e-9)
