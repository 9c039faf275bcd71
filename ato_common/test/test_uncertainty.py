"""The uncertainty of a campaign (ato_common.uncertainty): reproducible draws, common random
numbers, the perturbed truth, and bad specifications named with their field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ato_common import uncertainty as u
from ato_common.knowledge import knowledge_of
from ato_common.scenario import load_scenario
from ato_common.validation import ConfigError


def test_a_draw_depends_on_seed_and_index_only():
    spec = u.parse_uncertainty('default')
    first = u.draw(spec, 7, 3)
    assert u.draw(u.parse_uncertainty('default'), 7, 3) == first
    assert u.draw(spec, 7, 4) != first
    assert u.draw(spec, 8, 3) != first
    assert set(first) == set(u.PARAMETERS)


def test_overriding_one_parameter_leaves_the_others_as_they_were():
    base = u.draw(u.parse_uncertainty('default'), 1, 5)
    other = u.draw(u.parse_uncertainty({'wind_mps': 4.0}), 1, 5)
    assert other['wind_mps'] == 4.0
    assert {k: v for k, v in other.items() if k != 'wind_mps'} == \
        {k: v for k, v in base.items() if k != 'wind_mps'}


def test_each_distribution_samples_inside_its_bounds_with_its_moments():
    spec = u.parse_uncertainty({
        'defaults': False,
        'mass_factor': {'dist': 'uniform', 'low': 1.0, 'high': 1.2},
        'wind_mps': {'dist': 'normal', 'mean': 1.0, 'std': 2.0},
        'davis_a_factor': {'dist': 'truncated_normal', 'mean': 1.0, 'std': 0.5, 'low': 0.9,
                           'high': 1.3},
        'davis_c_factor': {'dist': 'lognormal', 'median': 1.0, 'sigma': 0.1},
        'adhesion': {'dist': 'choice', 'values': [0.3, 0.15], 'weights': [3, 1]}})
    draws = [u.draw(spec, 0, i) for i in range(2000)]
    mass = np.array([d['mass_factor'] for d in draws])
    wind = np.array([d['wind_mps'] for d in draws])
    a = np.array([d['davis_a_factor'] for d in draws])
    c = np.array([d['davis_c_factor'] for d in draws])
    mu = np.array([d['adhesion'] for d in draws])
    assert mass.min() >= 1.0 and mass.max() <= 1.2 and abs(mass.mean() - 1.1) < 0.005
    assert abs(wind.mean() - 1.0) < 0.15 and abs(wind.std() - 2.0) < 0.15
    assert a.min() >= 0.9 and a.max() <= 1.3
    assert abs(np.median(c) - 1.0) < 0.01 and abs(np.log(c).std() - 0.1) < 0.01
    assert set(mu) == {0.3, 0.15} and abs(np.mean(mu == 0.3) - 0.75) < 0.04
    assert all(d['speed_noise_mps'] == 0.0 for d in draws[:5])  # defaults: false -> nominal


@pytest.mark.parametrize('spec, field, words', [
    ({'wind_speed': 3.0}, 'uncertainty.wind_speed', 'unknown parameter'),
    ({'mass_factor': {'dist': 'uniform', 'low': 1.2, 'high': 1.1}}, 'uncertainty.mass_factor',
     'must be above low'),
    ({'mass_factor': {'dist': 'uniform', 'low': 0.1, 'high': 1.1}},
     'uncertainty.mass_factor.low', 'must be >= 0.5'),
    ({'wind_mps': {'dist': 'truncated_normal', 'mean': 0, 'std': 0, 'low': -1, 'high': 1}},
     'uncertainty.wind_mps.std', 'must be > 0'),
    ({'wind_mps': {'dist': 'normal', 'mean': 0, 'std': 10}}, 'uncertainty.wind_mps',
     'truncated_normal'),
    # a mean outside the kept interval piles the draws up at one bound
    ({'wind_mps': {'dist': 'truncated_normal', 'mean': 12, 'std': 3, 'low': -10, 'high': 10}},
     'uncertainty.wind_mps.mean', '12 must lie within [low, high] = [-10, 10]'),
    ({'adhesion': {'dist': 'choice', 'values': [0.3, 0.1], 'weights': [1]}},
     'uncertainty.adhesion.weights', '2 numbers'),
    ({'adhesion': {'dist': 'beta'}}, 'uncertainty.adhesion.dist', "'beta' is not valid"),
    ({'adhesion': {'dist': 'uniform', 'low': 0.1, 'high': 0.2, 'mode': 1}},
     'uncertainty.adhesion', 'unknown field(s) mode'),
    ({'traction_effectiveness': 1.5}, 'uncertainty.traction_effectiveness',
     'must be a finite number in'),
    ({'brake_effectiveness': {'dist': 'uniform', 'low': 0.0, 'high': 1.0}},
     'uncertainty.brake_effectiveness.low', 'must be >= 0.05'),
    # the one share of both of older files is refused, naming the two that replaced it
    ({'effectiveness': 0.9}, 'uncertainty.effectiveness',
     'replaced by traction_effectiveness and brake_effectiveness'),
    ({'defaults': 'yes'}, 'uncertainty.defaults', 'true or false'),
    ({'gradient_known': 0.5}, 'uncertainty.gradient_known', '0.5 is not one of its values'),
    ({'gradient_known': {'dist': 'uniform', 'low': 0, 'high': 1}},
     'uncertainty.gradient_known', 'takes only the values 0, 1'),
])
def test_a_bad_specification_names_its_field(spec, field, words):
    with pytest.raises(ConfigError) as error:
        u.parse_uncertainty(spec)
    assert field in str(error.value) and words in str(error.value)


def test_the_nominal_draw_is_the_scenario_itself():
    scenario = load_scenario('short_line')
    values = u.draw(u.parse_uncertainty('nominal'), 1, 0)
    assert u.perturbed(scenario, values) is scenario


def test_the_truth_is_perturbed_and_the_nominal_scenario_and_its_knowledge_are_not():
    scenario = load_scenario('short_line')
    known = knowledge_of(scenario)
    values = {name: p.nominal for name, p in u.PARAMETERS.items()}
    values.update(mass_factor=1.1, rotating_mass_factor=0.09, davis_a_factor=1.2,
                  davis_b_factor=0.8, davis_c_factor=1.05, wind_mps=5.0,
                  actuator_time_constant_s=0.5, actuator_dead_time_s=0.3,
                  traction_effectiveness=0.875, brake_effectiveness=0.9375, adhesion=0.02,
                  speed_noise_mps=0.03, speed_bias_mps=0.1, position_bias_m=-1.0,
                  odometry_scale_error=0.002, disturbance_per_weight=0.001)
    truth = u.perturbed(scenario, values)
    train, d = scenario.train, scenario.train.davis
    inertia = 1.1 * 1.09 / 1.06
    assert truth.train.mass_kg == pytest.approx(train.mass_kg * inertia, rel=1e-12)
    c = d.c_n_s2_per_m2 * 1.05  # c (v + w)^2 = c v^2 + 2 c w v + c w^2
    assert truth.train.davis.c_n_s2_per_m2 == pytest.approx(c)
    assert truth.train.davis.b_n_s_per_m == pytest.approx(d.b_n_s_per_m * 1.1 * 0.8 + 2 * c * 5)
    assert truth.train.davis.a_n == pytest.approx(d.a_n * 1.1 * 1.2 + c * 25)
    limit = 0.02 * train.mass_kg * 1.1 * 9.80665
    assert truth.train.traction.max_traction_force_n == pytest.approx(limit)
    assert truth.train.traction.max_emergency_brake_force_n == pytest.approx(limit)
    assert truth.plant.actuators.time_constant_s == 0.5
    assert truth.plant.actuators.dead_time_s == 0.3
    assert [(f.actuator, f.kind, f.effectiveness, f.braking_share, f.start_s)
            for f in truth.plant.failures] == [('traction', 'partial', 0.875, 0.9375, 0.0)]
    assert truth.plant.disturbance.kind == 'random'
    assert truth.plant.disturbance.amplitude_n == pytest.approx(
        0.001 * train.mass_kg * inertia * 9.80665)
    assert truth.plant.sensors.speed.noise_std == pytest.approx(0.03)
    assert truth.plant.sensors.speed.bias == 0.1
    assert truth.plant.sensors.position.bias == -1.0
    position, speed = truth.plant.sensors.position, truth.plant.sensors.speed
    assert position.scale_error == pytest.approx(0.002) and speed.scale_error == \
        pytest.approx(0.002)
    # the line's balise groups correct the odometer (the plant's sensors reset the ATO's
    # reading there, the odometry relocates): a draw adds no reset points of its own
    assert position.reset_positions_m == scenario.plant.sensors.position.reset_positions_m
    assert scenario.line.balise_groups_m and truth.line == scenario.line
    # the nominal scenario (the controller's) is untouched, and so is its knowledge
    assert knowledge_of(scenario) == known
    assert known.nominal_mass_kg == train.mass_kg and not math.isclose(
        knowledge_of(truth).nominal_mass_kg, train.mass_kg)


def test_modes_of_the_truth_are_perturbed_and_the_known_modes_stay_nominal():
    scenario = load_scenario('mao_2017_modes')
    values = {name: p.nominal for name, p in u.PARAMETERS.items()}
    values['mass_factor'] = 1.1
    truth = u.perturbed(scenario, values)
    assert [m.mass_kg for m in truth.plant.modes] == pytest.approx(
        [m.mass_kg * 1.1 for m in scenario.plant.modes])
    assert [m.mass_kg for m in knowledge_of(scenario).modes] == \
        [m.mass_kg for m in scenario.plant.modes]


def test_the_new_parameters_have_cited_defaults_inside_their_valid_ranges():
    for name in ('actuator_dead_time_s', 'odometry_scale_error'):
        p = u.PARAMETERS[name]
        assert p.source and p.minimum <= p.nominal <= p.maximum
        values = [u.draw(u.DEFAULTS, 3, i)[name] for i in range(200)]
        assert min(values) >= p.minimum and max(values) <= p.maximum
        assert np.std(values) > 0.0



def test_hiding_the_gradient_acts_on_the_knowledge_only():
    scenario = load_scenario('short_line')
    for value in (False, 0, {'dist': 'choice', 'values': [False]}):
        spec = u.parse_uncertainty({'defaults': False, 'gradient_known': value})
        values = u.draw(spec, 1, 0)
        assert values['gradient_known'] == 0.0
        assert u.knowledge_options(values) == {'hide_gradient': True}
        assert u.perturbed(scenario, values) is scenario   # the plant: the nominal truth
    assert u.knowledge_options(None) == {'hide_gradient': False}
    assert u.draw(u.DEFAULTS, 1, 0)['gradient_known'] == 1.0   # known by default
    # the truth of a draw is the same whatever the controller is told (seeds included)
    drawn = u.draw(u.DEFAULTS, 5, 2)
    assert u.perturbed(scenario, dict(drawn, gradient_known=0.0)) == \
        u.perturbed(scenario, drawn)
    assert u.KNOWLEDGE_PARAMETERS == ('gradient_known',)
