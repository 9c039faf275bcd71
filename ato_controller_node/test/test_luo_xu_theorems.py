"""Luo & Xu: Theorem 1 on its scenario, and Theorem 2, the projection law (24) onto the prior
set S of eq (20) with the Table 2 prior: unit tests of the projection. The closed loops on
luo_xu_crh3 under the time-varying resistance of eq (34) are in
ato_bringup/test/test_luo_xu_theorems_closed_loop.py."""

import pytest

from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.luo_xu import TABLE2_SPANS, LuoXuLaw, LuoXuProjectionLaw


@pytest.fixture(scope='module')
def scenario():
    return load_scenario('short_line')   # the CRH3 of Luo & Xu (Tables 1 and 2)


@pytest.fixture
def train(scenario):
    return TrainKnowledge.of(scenario.train)


def law_on_boundary(train, printed=False):
    """A projection law whose theta_hat sits on the boundary of S, displaced along +c0."""
    settings = validated_settings(LuoXuProjectionLaw.Settings, {'paper_as_printed': printed})
    law = LuoXuProjectionLaw(train, 0.1, settings)
    radius = settings.prior_radius * settings.c0_span_mps2 * (1.0 + 1e-12)
    law.theta_hat = [law.theta_prior[0] + radius, law.theta_prior[1], law.theta_prior[2]]
    assert law.prior_distance(law.theta_hat) == pytest.approx(1.0) and law.prior_distance(
        law.theta_hat) >= 1.0
    return law


def adapt_once(law, z2):
    """One adaptation step with the regressor at 60 m/s and the given z2 (no saturation)."""
    speed = 60.0
    reference = ReferencePoint(0.0, 0.0, speed - z2, 0.0)   # z1 = 0, so z2 = v - v*
    out = law.step(Measurement(0.0, 0.0, speed), reference)
    law.after_saturation(out.force_n, out.force_n)


def test_table2_prior_is_the_corrected_nominal_with_its_spans(train):
    law = LuoXuProjectionLaw(train, 0.1)
    # Table 2 nominal per kg: 7.85 N/t, 0.06318 N/t/(km/h) (printed 0.6318), 0.00127 N/t/(km/h)^2
    assert law.theta_prior == pytest.approx((7.85e-3, 0.06318 * 3.6e-3, 0.00127 * 12.96e-3))
    assert TABLE2_SPANS == pytest.approx((3.138e-3, 0.01417 * 3.6e-3, 0.000152 * 12.96e-3))


def test_outward_update_on_the_boundary_is_projected_onto_the_tangent_plane(train):
    law, free = law_on_boundary(train), LuoXuLaw(train, 0.1)
    free.theta_hat = list(law.theta_hat)
    before = list(law.theta_hat)
    adapt_once(law, -0.5)   # z2 < 0: the raw law (16) raises every estimate, i.e. outward along c0
    adapt_once(free, -0.5)
    assert law.prior_distance(law.theta_hat) <= 1.0 + 1e-12
    # the tangent plane at +c0 is c0 = const: c0 held (up to the pull back onto the curved
    # boundary), cv and ca adapt as without projection
    assert abs(law.theta_hat[0] - before[0]) < 0.05 * (free.theta_hat[0] - before[0])
    assert law.theta_hat[1:] == pytest.approx(free.theta_hat[1:], rel=1e-6)


def test_inward_update_on_the_boundary_is_not_modified(train):
    law, free = law_on_boundary(train), LuoXuLaw(train, 0.1)
    free.theta_hat = list(law.theta_hat)
    adapt_once(law, 0.5)
    adapt_once(free, 0.5)
    assert law.theta_hat == pytest.approx(free.theta_hat, rel=1e-12)
    assert law.prior_distance(law.theta_hat) < 1.0


def test_paper_as_printed_runs_the_swapped_branches(train):
    outward = law_on_boundary(train, printed=True)
    adapt_once(outward, -0.5)
    assert outward.prior_distance(outward.theta_hat) > 1.0   # printed (24) lets it leave S
    inward, free = law_on_boundary(train, printed=True), LuoXuLaw(train, 0.1)
    free.theta_hat = list(inward.theta_hat)
    adapt_once(inward, 0.5)
    adapt_once(free, 0.5)
    assert inward.theta_hat[0] != pytest.approx(free.theta_hat[0], rel=1e-9)  # projected
