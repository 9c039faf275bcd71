"""The host's side of the law interface: per-actuator output and limits, required inputs, and
the refusal of a law that does not fit the train or the running plant."""

import math
from dataclasses import dataclass

import pytest

from ato_common.scenario import load_scenario
from ato_common.trains import train_preset
from ato_common.types import ReferencePoint
from ato_controller_node import host as host_module
from ato_controller_node.host import ControllerHost, LawRejected
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import (
    ControlLaw,
    FeedbackGains,
    LawOutput,
    Measurement,
    TrainKnowledge,
)


@dataclass(frozen=True)
class _NoSettings:
    pass


class _PerActuatorProbe(ControlLaw):
    """Drives two actuators with fixed, unequal forces; records what the host reports back."""

    name = 'probe_two_cars'
    summary = 'test probe'
    Settings = _NoSettings
    actuators = 2
    cars = 4
    requires = ('car_speeds',)
    wanted = (1e9, -5e3)

    def reset(self, measurement, reference, last_force_n):
        self.reported = None

    def feedback_gains(self):
        return FeedbackGains(0.0, 1.0)

    def step(self, measurement, reference):
        return LawOutput(sum(self.wanted), {}, self.wanted)

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        self.reported = (wanted_n, commanded_n, commanded_forces_n, applied_n)


@pytest.fixture
def probe_registered(monkeypatch):
    monkeypatch.setitem(LAWS, _PerActuatorProbe.name, _PerActuatorProbe)
    monkeypatch.setattr(host_module, 'LAWS', LAWS)


def four_car_measurement(speed=20.0, cars=4):
    return Measurement(0.0, 0.0, speed, 0.0, tuple(-25.0 * i for i in range(cars)),
                       (speed,) * cars)


def test_per_actuator_forces_are_saturated_each_and_reported_back(probe_registered):
    train = TrainKnowledge.of(train_preset('crh2_4car_mao'))
    host = ControllerHost(train, 0.1, _PerActuatorProbe.name)
    result = host.step(four_car_measurement(), ReferencePoint(0.0, 0.0, 20.0, 0.0))
    lowest, highest = train.actuator_limits_at(20.0)
    assert result.forces_n == (highest, -5e3)
    assert result.total_force_n == pytest.approx(highest - 5e3)
    assert result.saturated
    wanted, commanded, forces, applied = host.law.reported
    assert wanted == pytest.approx(1e9 - 5e3) and commanded == pytest.approx(highest - 5e3)
    assert forces == (highest, -5e3)
    assert applied == result.total_force_n  # no bumpless offset before the first command


def test_a_law_needing_four_cars_is_refused_on_a_single_mass_plant(probe_registered):
    train = TrainKnowledge.of(train_preset('crh2_4car_mao'))
    host = ControllerHost(train, 0.1, 'pid')
    host.step(four_car_measurement(cars=1), ReferencePoint(0.0, 0.0, 20.0, 0.0))
    with pytest.raises(LawRejected, match='needs the measurements of 4 cars but the plant '
                                          'publishes 1'):
        host.check(_PerActuatorProbe.name)
    host.step(four_car_measurement(cars=4), ReferencePoint(0.0, 0.0, 20.0, 0.0))
    host.check(_PerActuatorProbe.name)


def test_a_law_is_refused_on_a_train_without_per_car_data(probe_registered):
    train = TrainKnowledge.of(load_scenario('short_line').train)
    with pytest.raises(LawRejected, match='drives 2 actuators but the train has 1'):
        ControllerHost(train, 0.1, _PerActuatorProbe.name)


def test_missing_required_input_holds_the_command_and_names_it(probe_registered):
    train = TrainKnowledge.of(train_preset('crh2_4car_mao'))
    host = ControllerHost(train, 0.1, _PerActuatorProbe.name)
    ref = ReferencePoint(0.0, 0.0, 20.0, 0.0)
    first = host.step(four_car_measurement(), ref)
    failed = Measurement(0.1, 0.0, math.nan, 0.0, (0.0, -25.0, -50.0, -75.0),
                         (20.0, math.nan, 20.0, 20.0))
    held = host.step(failed, ref)
    assert 'needs the measured car speeds' in held.fault
    assert held.forces_n == first.forces_n


def test_pid_ignores_a_missing_acceleration_but_not_a_missing_speed():
    train = TrainKnowledge.of(load_scenario('short_line').train)
    host = ControllerHost(train, 0.1, 'pid')
    ref = ReferencePoint(0.0, 0.0, 10.0, 0.0, 0.01)
    assert not host.step(Measurement(0.0, 0.0, 10.0, math.nan), ref).fault
    assert 'needs the measured speed' in host.step(Measurement(0.1, 1.0, math.nan), ref).fault
    assert 'non-finite reference' in host.step(
        Measurement(0.2, 1.0, 10.0), ReferencePoint(0.2, 0.0, 10.0, 0.0, math.nan)).fault


def test_a_law_whose_output_turns_non_finite_is_restarted_not_held_forever():
    train = TrainKnowledge.of(load_scenario('short_line').train)
    host = ControllerHost(train, 0.1, 'luo_xu')
    ref = ReferencePoint(0.0, 100.0, 10.0, 0.0)
    host.step(Measurement(0.0, 100.0, 10.0), ref)
    host.law.mass_hat = math.nan  # its state poisoned (e.g. by an overflow)
    assert 'non-finite force' in host.step(Measurement(0.1, 101.0, 10.0), ref).fault
    recovered = host.step(Measurement(0.2, 102.0, 10.0), ref)  # reset from its prior
    assert not recovered.fault and math.isfinite(recovered.total_force_n)


def test_a_law_requiring_an_unknown_measurement_is_refused_with_the_valid_names(
        probe_registered, monkeypatch):
    monkeypatch.setattr(_PerActuatorProbe, 'requires', ('car_speed',))
    train = TrainKnowledge.of(train_preset('crh2_4car_mao'))
    with pytest.raises(LawRejected, match=r"unknown measurements \['car_speed'\]; valid: "):
        ControllerHost(train, 0.1, _PerActuatorProbe.name)


def test_the_fit_is_asked_again_when_the_measured_cars_change(probe_registered):
    """The host checks ``fits`` once per law and measured cars: a plant that starts publishing
    one car after four has the per-car law held from that step, and released when four return."""
    train = TrainKnowledge.of(train_preset('crh2_4car_mao'))
    host = ControllerHost(train, 0.1, _PerActuatorProbe.name)
    reference = ReferencePoint(0.0, 0.0, 20.0, 0.0)
    assert host.step(four_car_measurement(cars=4), reference).fault == ''
    held = host.step(four_car_measurement(cars=1), reference)
    assert 'needs the measurements of 4 cars but the plant publishes 1' in held.fault
    assert host.step(four_car_measurement(cars=4), reference).fault == ''
    assert host.faults == 1


def test_the_bumpless_offset_decays_with_the_time_constant_in_force_at_each_step():
    """The decay per step follows ``bumpless_time_constant_s`` when the node changes it while
    running (and ``dt``): exp(-dt / tau) of the values in force at that step."""
    train = TrainKnowledge.of(train_preset('crh3_luo_xu'))
    host = ControllerHost(train, 0.1, 'pid', {'pid': {'ki_position': 0.0}})
    measurement = Measurement(0.0, 0.0, 20.0)
    reference = ReferencePoint(0.0, 0.0, 20.0, 0.0)
    host.step(measurement, reference)
    host._offset_n = 5e4  # as a switch leaves it: the step between the last and the new law
    offsets = [host._offset_n]
    for tau in (3.0, 3.0, 0.5, 0.5, 10.0):
        host.bumpless_time_constant_s = tau
        host.step(measurement, reference)
        offsets.append(host._offset_n)
    for before, after, tau in zip(offsets, offsets[1:], (3.0, 3.0, 0.5, 0.5, 10.0)):
        assert after == before * math.exp(-0.1 / tau)
