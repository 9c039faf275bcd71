"""The rigid-coupler reduction of Mao et al. (mao_multibody_rigid), without ROS."""

import math

import pytest

from ato_common.knowledge import knowledge_of
from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.laws.base import Measurement
from ato_controller_node.laws.mao_rigid import MaoRigidLaw, rigid_parameters, split_by_mass


@pytest.fixture(scope='module')
def train():
    return knowledge_of(load_scenario('mao_4car'))


def _measure(speed, t=0.0):
    return Measurement(t, 0.0, speed, 0.0, (0.0, -25.0, -50.0, -75.0), (speed,) * 4)


def _reference(speed, acceleration=0.0):
    return ReferencePoint(0.0, 0.0, speed, acceleration)


def test_rigid_parameters_are_the_mass_weighted_unit(train):
    mass, a, b, c = rigid_parameters(train)
    assert mass == pytest.approx(179300.0)
    assert a * mass == pytest.approx(sum(car.a_mps2 * car.mass_kg for car in train.cars))
    assert c * mass == pytest.approx(train.cars[0].c_per_m * train.cars[0].mass_kg)


def test_split_by_mass_and_saturation():
    assert split_by_mass(100.0, 0.5, (-80, 80), (-80, 80)) == (50.0, 50.0)
    assert split_by_mass(100.0, 0.9, (-60, 60), (-80, 80)) == (60.0, 40.0)   # car 2 limited
    assert split_by_mass(100.0, 0.1, (-80, 80), (-60, 60)) == (40.0, 60.0)   # car 3 limited
    assert split_by_mass(500.0, 0.5, (-80, 80), (-80, 80)) == (80.0, 80.0)   # both saturated


def test_force_at_steady_speed_is_the_estimated_resistance(train):
    law = MaoRigidLaw(train, 0.1)
    out = law.step(_measure(50.0), _reference(50.0))
    mass, a, b, c = rigid_parameters(train)
    assert out.force_n == pytest.approx(0.95 * mass * 0.95 * (a + b * 50 + c * 2500))
    masses = [car.mass_kg for car in train.cars]
    assert out.forces_n[0] / out.force_n == pytest.approx((masses[0] + masses[1]) / mass)


def test_adaptation_signs_and_freeze(train):
    law = MaoRigidLaw(train, 0.1)
    before = list(law.theta_hat)
    out = law.step(_measure(49.9), _reference(50.0, 0.3))   # too slow while accelerating
    law.after_saturation(out.force_n, out.force_n, out.forces_n)
    assert law.theta_hat[0] > before[0] and law.theta_hat[1] > before[1]
    frozen = list(law.theta_hat)
    out = law.step(_measure(49.9), _reference(50.0, 0.3))
    law.after_saturation(out.force_n, 0.5 * out.force_n, tuple(0.5 * f for f in out.forces_n))
    assert law.theta_hat == frozen                         # saturated: no update


def test_fits_refuses_a_too_slow_rate_and_a_single_mass_train(train):
    assert MaoRigidLaw(train, 0.1).fits(train, 4) is None
    slow = MaoRigidLaw(train, 2.0)
    assert 'alpha dt' in slow.fits(train, 4)
    point = knowledge_of(load_scenario('short_line'))
    assert 'actuators' in MaoRigidLaw(point, 0.1).fits(point)
    assert math.isfinite(MaoRigidLaw(train, 0.01).step(_measure(0.0), _reference(0.0)).force_n)


def test_its_own_clamping_freezes_the_adaptation_and_counts_as_saturated(train):
    """split_by_mass limits the shares inside step(): the law must give the host its unlimited
    force, so that the host counts the step as saturated and the freeze compares the force the
    unit wanted with the one it gets (not the clamped shares with themselves)."""
    from ato_controller_node.host import ControllerHost
    host = ControllerHost(train, 0.1, 'mao_multibody_rigid')
    law = host.law
    before = list(law.theta_hat)
    # far too slow while the reference accelerates hard: the unit wants more than both cars give
    result = host.step(_measure(20.0), _reference(40.0, 2.0))
    lowest, highest = train.actuator_limits_at(20.0)
    assert result.forces_n == (highest, highest)
    assert result.wanted_force_n > 2.0 * highest
    assert result.saturated                                  # honest: the wish was cut
    host.step(_measure(20.0, 0.1), _reference(40.0, 2.0))
    assert law.theta_hat == before                           # frozen on its own clamping
    # within the limits it adapts as before
    host.step(_measure(39.9, 0.2), _reference(40.0, 0.01))
    assert not host.step(_measure(39.9, 0.3), _reference(40.0, 0.01)).saturated
    assert law.theta_hat != before
