"""Loop margins (ato_campaigns.margins) against analytic cases: a PD on a mass, the former
luo_xu [FIX] of issue 28, a pure dead time; the Pade approximant against the exact response;
the coverage of the campaign's actuator draws."""

import math

import numpy as np
import pytest

from ato_campaigns import margins as m
from ato_common.scenario import load_scenario
from ato_common.uncertainty import DEFAULTS, Distribution
from ato_controller_node.laws.base import FeedbackGains


def pd_on_a_mass(kp: float, kd: float) -> tuple[float, float]:
    """(crossover rad/s, phase margin deg) of (kp + kd s) / s^2: |L| = 1 at
    w^4 = kp^2 + kd^2 w^2, and the phase there is -180 deg + atan(kd w / kp)."""
    w = math.sqrt((kd * kd + math.sqrt(kd ** 4 + 4.0 * kp * kp)) / 2.0)
    return w, math.degrees(math.atan(kd * w / kp))


@pytest.mark.parametrize('kp, kd', [(0.16, 0.8), (0.48, 1.2), (1.01, 0.2), (0.01, 0.2)])
def test_a_pd_on_a_mass_has_its_analytic_phase_margin(kp, kd):
    result = m.loop_margins(m.Loop(FeedbackGains(kp, kd), 0.0, 0.0))
    crossover, phase = pd_on_a_mass(kp, kd)
    assert result.crossover_radps == pytest.approx(crossover, rel=1e-6)
    assert result.phase_margin_deg == pytest.approx(phase, rel=1e-6)
    assert result.delay_margin_s == pytest.approx(math.radians(phase) / crossover, rel=1e-6)
    assert result.stable


def test_the_former_luo_xu_fix_has_the_margins_the_issue_states():
    """e'' + (c1 + c2) e' + (1 + c1 c2) e = 0 at c1 = c2 = 0.1: phase margin 11.4 deg, delay
    margin 0.20 s (issue 28, defect 1), from the law's own feedback about cruise."""
    from ato_common.knowledge import knowledge_of
    from ato_controller_node.laws.luo_xu import LuoXuLaw
    knowledge = knowledge_of(load_scenario('short_line'))
    fixed = LuoXuLaw(knowledge, 0.1, LuoXuLaw.Settings(fixed_varphi=True)).feedback_gains()
    assert (fixed.position_per_s2, fixed.speed_per_s) == pytest.approx((1.01, 0.2))
    result = m.loop_margins(m.Loop(fixed, 0.0, 0.0))
    assert result.phase_margin_deg == pytest.approx(11.4, abs=0.05)
    assert result.delay_margin_s == pytest.approx(0.20, abs=0.005)
    # as printed (kp = c1 c2): the same c1, c2 leave a wide margin
    printed = LuoXuLaw(knowledge, 0.1).feedback_gains()
    assert m.loop_margins(m.Loop(printed, 0.0, 0.0)).phase_margin_deg > 70.0


def test_a_dead_time_takes_its_phase_at_the_crossover_and_past_the_margin_the_loop_fails():
    loop = m.Loop(FeedbackGains(0.16, 0.8), 0.0, 0.0)
    bare = m.loop_margins(loop)
    delayed = m.loop_margins(loop, m.Actuator(0.0, 0.3))
    assert delayed.crossover_radps == pytest.approx(bare.crossover_radps, rel=1e-9)
    lost = math.degrees(bare.crossover_radps * 0.3)
    assert delayed.phase_margin_deg == pytest.approx(bare.phase_margin_deg - lost, abs=0.01)
    assert m.loop_margins(loop, m.Actuator(0.0, 0.95 * bare.delay_margin_s)).stable
    assert not m.loop_margins(loop, m.Actuator(0.0, 1.05 * bare.delay_margin_s)).stable


def test_the_rational_loop_is_the_exact_response_at_the_crossover():
    import control
    loop = m.Loop(FeedbackGains(0.48, 1.2, 0.064), 0.003, 0.1)
    actuator = m.Actuator(1.0, 0.5)
    w = np.array([0.3, 0.6, 1.0])
    exact = loop.response(actuator, w)
    approximate = np.array([complex(control.evalfr(loop.rational(actuator), 1j * x)) for x in w])
    assert np.degrees(np.abs(np.angle(approximate / exact))).max() < 0.1
    assert np.abs(np.abs(approximate / exact) - 1.0).max() < 1e-3   # the hold's gain


def test_coverage_of_the_campaigns_actuator_draws():
    assert m.largest_actuator(DEFAULTS) == m.Actuator(1.0, 0.5)
    scenario = load_scenario('short_line')
    tan = m.coverage(m.law_loop('tan_second_level_adaptive', scenario), DEFAULTS)
    assert not tan.covered and 'cannot cover the actuator draws' in tan.reason
    luo = m.coverage(m.law_loop('luo_xu', scenario), DEFAULTS)
    assert luo.covered and luo.worst.phase_margin_deg > 30.0
    pid = m.coverage(m.law_loop('pid', scenario), DEFAULTS)
    assert not pid.covered and 0.3 < pid.tolerated_dead_time_s < 0.5
    with pytest.raises(ValueError, match='no largest value'):
        m.largest_actuator({**DEFAULTS, 'actuator_dead_time_s': Distribution('normal', 0.3,
                                                                             0.01)})


def test_the_margins_table_of_a_campaign():
    scenario = load_scenario('short_line')
    rows = m.margins_rows(['pid', 'luo_xu'], scenario, DEFAULTS)
    assert [(r['law'], r['configuration']) for r in rows] == [
        ('pid', 'published'), ('pid', 'tuned'), ('luo_xu', 'published'), ('luo_xu', 'tuned')]
    published = rows[0]
    assert published['kp_per_s2'] == 0.48 and published['covers_actuator_draws'] is False
    table = m.markdown_table(rows, m.largest_actuator(DEFAULTS))
    assert '| `pid` | published | 67.' in table
