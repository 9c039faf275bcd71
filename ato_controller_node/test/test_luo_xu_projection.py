"""Luo & Xu Theorem 2: the projection law (24) onto the prior set S of eq (20), Table 2 prior.

Unit tests of the projection, and a closed loop under the time-varying resistance of eq (34)
(c0, cv, ca varying by 30 %, 20 %, 10 % at 0.1 rad/s). The loop integrates eq (3) with eq (34)
here (RK4, two substeps per control period) and drives the law through the controller host:
the plant's ``plant:`` section with eq (34) has not landed yet.
"""

import math

import numpy as np
import pytest

from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws.base import Measurement, TrainKnowledge, validated_settings
from ato_controller_node.laws.luo_xu import LuoXuLaw, LuoXuProjectionLaw, TABLE2_SPANS
from profile_node.planner import plan_reference


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


def closed_loop_under_eq34(scenario, law, gain_scale=1.0, varying=True, dt=0.1):
    """Eq (3) with the time-varying theta(t) of eq (34), tracking the short_line reference.
    Returns (times, z1 samples, theta_hat rows, prior distance of theta_hat, saturated count)."""
    plan = plan_reference(scenario)
    train = scenario.train
    mass = train.mass_kg
    c0, cv, ca = train.davis.per_kg(mass)
    defaults = LuoXuProjectionLaw.Settings()
    gains = {name: getattr(defaults, name) * gain_scale
             for name in ('gamma_c0', 'gamma_cv', 'gamma_ca')}
    host = ControllerHost(TrainKnowledge.of(train), dt, law, {law: gains})
    probe = LuoXuProjectionLaw(TrainKnowledge.of(train), dt)   # measures the distance to S

    def acceleration(t, v, force):
        w = math.sin(0.1 * t) if varying else 0.0                                   # eq (34)
        a, b, c = c0 * (1 + 0.3 * w), cv * (1 + 0.2 * w), ca * (1 + 0.1 * w)
        if v <= 0.0 and force / mass <= a:
            return 0.0   # standstill: friction and brakes hold the train
        return force / mass - (a + b * v + c * v * v)                                # eq (3)

    s = v = 0.0
    times, z1, thetas, saturated = [], [], [], 0
    for k in range(int(plan.trajectory.end_time / dt)):
        t = k * dt
        reference = plan.trajectory.at(t)
        result = host.step(Measurement(t, s, v), reference)
        est = result.estimates
        times.append(t)
        z1.append(s - reference.position)
        thetas.append((est['c0_hat_mps2'], est['cv_hat_per_s'], est['ca_hat_per_m']))
        saturated += result.saturated
        force, h = result.total_force_n, dt / 2
        for j in range(2):
            t0 = t + j * h
            k1 = acceleration(t0, v, force)
            k2 = acceleration(t0 + h / 2, v + h / 2 * k1, force)
            k3 = acceleration(t0 + h / 2, v + h / 2 * k2, force)
            k4 = acceleration(t0 + h, v + h * k3, force)
            s += h / 6 * (v + 2 * (v + h / 2 * k1) + 2 * (v + h / 2 * k2) + v + h * k3)
            v = max(0.0, v + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
    distance = np.array([probe.prior_distance(th) for th in thetas])
    return np.array(times), np.abs(np.array(z1)), np.array(thetas), distance, saturated


def test_theorem2_keeps_estimates_in_S_and_error_in_a_small_residual_set(scenario):
    times, z1, _, distance, saturated = closed_loop_under_eq34(scenario, 'luo_xu_projection')
    assert distance.max() <= 1.0 + 1e-9
    assert saturated == 0
    # residual set: measured max |z1| 2.1 cm over the whole run (1.0 cm with constant theta)
    assert z1.max() < 0.05
    assert z1[times > 100.0].max() < 0.05


def test_fast_adaptation_unprojected_leaves_S_and_tracks_worse(scenario):
    """With the adaptation gains 300x the defaults (fast enough to follow eq 34's variation),
    the unprojected law's estimates leave S (measured 26x its radius) and its error grows
    (max |z1| 0.24 m, saturating); the projection keeps them in S and |z1| under 2 cm.
    At the default gains both laws coincide (theta_hat stays within 1.2 % of S's radius)."""
    _, z1_p, _, dist_p, _ = closed_loop_under_eq34(scenario, 'luo_xu_projection', 300.0)
    _, z1_u, _, dist_u, saturated_u = closed_loop_under_eq34(scenario, 'luo_xu', 300.0)
    assert dist_p.max() <= 1.0 + 1e-9 and z1_p.max() < 0.03
    assert dist_u.max() > 5.0
    assert z1_u.max() > 5.0 * z1_p.max()
    assert saturated_u > 0
