"""The line between the plant's truth and the controller's knowledge (ato_common.knowledge)."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from ato_common.knowledge import KnownGradient, KnownMode, TrainKnowledge, knowledge_of
from ato_common.plant_setup import (
    AbruptChange,
    ActuatorFailure,
    ActuatorSettings,
    Disturbance,
    QuantitySensor,
    ResistanceVariation,
    SensorSetup,
    Sinusoid,
)
from ato_common.scenario import builtin_scenarios, load_scenario
from ato_common.trains import DavisResistance


def with_other_truth(scenario):
    """The same scenario but for what only the plant simulates: the simulated resistance,
    resistance variation, abrupt changes, disturbance, actuator lag, failures, sensors."""
    train = scenario.train
    davis = train.davis
    plant = replace(
        scenario.plant,
        resistance_variation=ResistanceVariation(Sinusoid(0.3, 0.1), Sinusoid(0.2, 0.1, 1.0),
                                                 Sinusoid(0.1, 0.05), Sinusoid(0.05, 0.02)),
        abrupt_changes=(AbruptChange(100.0, 200.0, 0.01, 2.0),),
        disturbance=Disturbance('random', 1e4, hold_s=2.0, seed=3),
        actuators=ActuatorSettings(0.5, 1e5),
        failures=(ActuatorFailure(train.actuator_names[0], 'loss', 10.0),
                  ActuatorFailure(train.actuator_names[-1], 'stuck', 50.0, 60.0, 1e4)),
        sensors=SensorSetup(QuantitySensor(noise_std=0.1, dropout_probability=0.1),
                            QuantitySensor(noise_std=0.01, bias=0.02, failed_from_s=50.0),
                            QuantitySensor(quantum=0.01, failed_from_s=0.0), seed=5))
    return replace(scenario, plant=plant, train=replace(train, davis=DavisResistance(
        2.0 * davis.a_n + 1.0, 1.5 * davis.b_n_s_per_m + 1.0, 1.2 * davis.c_n_s2_per_m2)))


@pytest.mark.parametrize('name', builtin_scenarios())
def test_the_plant_truth_does_not_reach_the_knowledge(name):
    scenario = load_scenario(name)
    other = with_other_truth(scenario)
    assert other != scenario and other.plant != scenario.plant
    assert knowledge_of(other) == knowledge_of(scenario)


def test_a_different_nominal_train_is_different_knowledge():
    scenario = load_scenario('mao_2017_modes')
    knowledge, train = knowledge_of(scenario), scenario.train
    davis = train.davis_nominal
    for other in (replace(train, mass_kg=1.1 * train.mass_kg),
                  replace(train, davis_nominal=DavisResistance(davis.a_n * 1.1, davis.b_n_s_per_m,
                                                               davis.c_n_s2_per_m2)),
                  replace(train, traction=replace(train.traction, max_traction_force_n=1.0)),
                  replace(train, actuator_names=train.actuator_names[:-1])):
        assert knowledge_of(replace(scenario, train=other)) != knowledge
    assert knowledge_of(load_scenario('short_line')) != knowledge
    # The known modes are knowledge too.
    fewer = replace(scenario, plant=replace(scenario.plant, modes=scenario.plant.modes[:2]))
    assert knowledge_of(fewer) != knowledge


def test_the_knowledge_copies_the_nominal_train_and_the_modes():
    scenario = load_scenario('mao_2017_modes')
    knowledge = knowledge_of(scenario)
    train = scenario.train
    assert knowledge == TrainKnowledge.of(train, scenario.plant.modes, 'time',
                                          KnownGradient.of(scenario.line.grade_sine))
    assert knowledge.nominal_mass_kg == train.mass_kg
    assert knowledge.nominal_davis == train.davis_nominal
    assert knowledge.actuator_names == train.actuator_names
    assert knowledge.mode_switch == scenario.plant.mode_switch == 'time'
    assert all(type(m) is KnownMode for m in knowledge.modes)  # no object of the plant's
    for known, mode in zip(knowledge.modes, scenario.plant.modes, strict=True):
        assert (known.name, known.start, known.mass_kg, known.davis, known.grade_sine,
                known.curve_accel_mps2) == (mode.name, mode.start, mode.mass_kg, mode.davis,
                                            mode.grade_sine, mode.curve_accel_mps2)
    # Without modes: always mode 0.
    plain = knowledge_of(load_scenario('short_line'))
    assert plain.modes == () and plain.known_mode(1e4, math.nan, 0) == 0


def lookups(plant, knowledge, times, positions):
    rng = np.random.default_rng(7)
    for t, x in zip(times, positions):
        previous = int(rng.integers(0, max(len(plant.modes), 1)))
        assert knowledge.known_mode(t, x, previous) == plant.known_mode(t, x, previous), (t, x)


def test_the_known_mode_is_the_plants_on_mao_2017_modes():
    scenario = load_scenario('mao_2017_modes')
    knowledge = knowledge_of(scenario)
    times = np.concatenate([np.linspace(0.0, 2500.0, 2001), [399.999, 400.0, 800.0, 1400.0]])
    positions = np.linspace(0.0, 90000.0, times.size)
    positions[::7] = math.nan  # the position is not measured
    lookups(scenario.plant, knowledge, times, positions)
    seen = {knowledge.known_mode(t, 0.0, 0) for t in times}
    assert seen == set(range(len(scenario.plant.modes)))

    # The same modes switching by region (from_m): a missing position keeps the previous mode.
    by_region = replace(scenario, plant=replace(scenario.plant, mode_switch='position'))
    knowledge = knowledge_of(by_region)
    assert knowledge.mode_switch == 'position'
    lookups(by_region.plant, knowledge, times, np.linspace(0.0, 2500.0, times.size))
    lookups(by_region.plant, knowledge, times[::-1], positions)
    assert knowledge.known_mode(5.0, math.nan, 2) == 2
    assert knowledge.known_mode(5.0, 900.0, 0) == 2


def test_an_unknown_mode_switch_is_refused():
    scenario = load_scenario('mao_2017_modes')
    with pytest.raises(ValueError, match="mode switch 'space' is not valid"):
        TrainKnowledge.of(scenario.train, scenario.plant.modes, 'space')


def test_modes_given_without_a_start_have_no_schedule():
    """Records with only the mode values (as a law's test gives them, feeding the mode index
    itself) are known modes, but there is no schedule to look the mode up."""
    scenario = load_scenario('mao_2017_modes')
    records = [SimpleNamespace(mass_kg=m.mass_kg, davis=m.davis, grade_sine=m.grade_sine,
                               curve_accel_mps2=m.curve_accel_mps2) for m in scenario.plant.modes]
    knowledge = TrainKnowledge.of(scenario.train, records)
    assert [m.name for m in knowledge.modes] == ['mode 1', 'mode 2', 'mode 3', 'mode 4']
    assert [m.davis for m in knowledge.modes] == [m.davis for m in scenario.plant.modes]
    with pytest.raises(ValueError, match='no start'):
        knowledge.known_mode(0.0, 0.0, 0)


def test_the_knowledge_copies_the_gradient_profile_or_hides_it_and_the_truth_keeps_it():
    from ato_common.knowledge import HIDDEN_GRADIENT
    scenario = load_scenario('short_line')
    grades = scenario.line.grade_sine
    known = knowledge_of(scenario)
    hidden = knowledge_of(scenario, hide_gradient=True)
    positions = np.linspace(0.0, scenario.line.length_m, 2001)
    assert [known.gradient.sine_at(x) for x in positions] == [grades(x) for x in positions]
    assert any(grades(x) != 0.0 for x in positions)
    # hidden: a flat line, zero grade (and grade force) everywhere
    assert hidden.gradient == HIDDEN_GRADIENT and hidden.gradient.hidden
    assert all(hidden.gradient.sine_at(x) == 0.0 for x in positions)
    assert all(hidden.grade_force_n(x) == 0.0 for x in positions)
    assert known.grade_force_n(20000.0) == pytest.approx(   # the whole train on the grade
        known.nominal_mass_kg * 9.80665 * grades(20000.0))
    # everything else is the same knowledge; the scenario (the plant's truth) is untouched
    assert replace(hidden, gradient=known.gradient) == known
    assert scenario.line.grade_sine is grades and grades(20000.0) > 0.0


def test_a_multi_car_train_knows_the_grade_force_car_by_car():
    scenario = load_scenario('mao_4car')
    known = replace(knowledge_of(scenario), gradient=KnownGradient((0.0, 100.0), (0.0, 0.01)))
    cars = known.cars
    # the lead car on the grade, the others before it
    positions = (150.0, 50.0, 25.0, 0.0)
    assert known.grade_force_n(positions) == pytest.approx(9.80665 * 0.01 * cars[0].mass_kg)
    # one position: the whole train's mass spread over its length, half of it on the grade
    assert known.length_m == scenario.train.length_m == 100.0
    assert known.grade_force_n(150.0) == pytest.approx(
        9.80665 * 0.005 * known.nominal_mass_kg)


def test_the_mean_grade_under_a_train_is_the_exact_mean_of_the_profile():
    gradient = KnownGradient((0.0, 100.0, 130.0), (0.001, 0.01, -0.002))
    assert gradient.mean_sine(90.0, 50.0) == 0.001          # all on the first segment
    assert gradient.mean_sine(150.0, 100.0) == pytest.approx(
        (50 * 0.001 + 30 * 0.01 + 20 * -0.002) / 100)      # over three segments
    assert gradient.mean_sine(120.0, 0.0) == 0.01           # a point: the sine there
    assert gradient.mean_sine(10.0, 200.0) == pytest.approx(0.001)  # before the start: level 1
    assert KnownGradient().mean_sine(120.0, 100.0) == 0.0
