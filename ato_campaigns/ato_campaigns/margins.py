"""Loop margins as evidence: the phase and delay margins of each law's loop linearised about
cruise, with the scenario's actuator, computed with python-control.

The loop, position error in, position out, per unit of the nominal mass (SI):

    L(s) = C(s) H(s) A(s) P(s)
    C(s) = kp + kd s + ki / s               the law's feedback (``ControlLaw.feedback_gains``)
    H(s) = (1 - exp(-s T)) / (s T)          the controller's zero-order hold at its period T
    A(s) = exp(-s L_d) / (tau s + 1)        the actuator: dead time L_d, first-order lag tau
    P(s) = 1 / (s (s + d))                  the train: d = R'(v) / M, the nominal Davis
                                            resistance's slope at the cruise speed v

An adaptive law is linearised with its adaptation frozen at its nominal (initial) estimates:
its feedback about cruise is then that of its certainty-equivalence control at those estimates
(each law's ``feedback_gains`` says how). python-control computes the margins
(``control.stability_margins``) and the closed loop's poles of L as a transfer function, the
delays by a Pade approximant of order 6 (``control.pade``): the dead time and the hold's phase
lag, a delay of T/2 (the hold's gain, sinc(omega T / 2), differs from 1 by less than 1e-3 at
the crossovers of these loops, below 1 rad/s at 10 Hz; ``Loop.response`` is the exact
response, with which the tests check the approximant). The phase margin is at the gain
crossover, the delay margin is the added dead time the loop tolerates (phase margin /
crossover frequency); the loop is stable when every closed-loop pole is in the left half
plane (a positive phase margin alone does not say it for a loop with an integrator and a
lag).

A law whose loop is unstable at the campaign's largest actuator draw (the upper ends of the
uncertainty's ``actuator_time_constant_s`` and ``actuator_dead_time_s``) cannot cover its
draws: :func:`coverage` says so and gives the largest dead time that law tolerates with that
lag.

API for reports (the campaign report shows these beside the results): :func:`margins` of one
law, configuration and actuator; :func:`coverage` against an uncertainty specification;
:func:`entry_margins` of one law with given settings; :func:`margins_rows` and
:func:`markdown_table` for every law and configuration on a scenario; :func:`campaign_margins`
for every row label of a campaign (the settings it runs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable, Mapping

import numpy as np

from ato_common.knowledge import knowledge_of
from ato_common.scenario import Scenario, load_scenario
from ato_controller_node.gains import GAINS, GainsUnavailable, settings_for
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import FeedbackGains, validated_settings
from ato_simulation.applies import applicable_rate

if TYPE_CHECKING:
    from ato_campaigns.engine import Campaign

#: a frequency grid for the loop's exact response, rad/s
FREQUENCIES = np.logspace(-4.0, 3.0, 4000)
#: the order of the Pade approximant of the delays in the stability check
PADE_ORDER = 6


@dataclass(frozen=True)
class Actuator:
    """The actuator of the loop: first-order lag and dead time, s."""

    time_constant_s: float = 0.0
    dead_time_s: float = 0.0

    def describe(self) -> str:
        return f'lag {self.time_constant_s:g} s, dead time {self.dead_time_s:g} s'


@dataclass(frozen=True)
class Loop:
    """The linearised loop of one law: its feedback, the train about cruise, the hold."""

    gains: FeedbackGains
    damping_per_s: float       # d = R'(v) / M
    period_s: float            # the controller's hold, 0 for a continuous controller
    cruise_speed_mps: float = math.nan

    def response(self, actuator: Actuator, omega: np.ndarray = FREQUENCIES) -> np.ndarray:
        """L(j omega), exactly (delays and hold included)."""
        s = 1j * omega
        g = self.gains
        controller = g.position_per_s2 + g.speed_per_s * s + g.integral_per_s3 / s
        t = self.period_s
        hold = (1.0 - np.exp(-s * t)) / (s * t) if t > 0.0 else 1.0
        drive = np.exp(-s * actuator.dead_time_s) / (actuator.time_constant_s * s + 1.0)
        return controller * hold * drive / (s * (s + self.damping_per_s))

    def rational(self, actuator: Actuator):
        """L(s) as a transfer function, the delays (dead time and half the hold) by a Pade
        approximant: for the closed loop's poles."""
        import control
        g = self.gains
        controller = control.tf([g.speed_per_s, g.position_per_s2, g.integral_per_s3],
                                [1.0, 0.0]) if g.integral_per_s3 else \
            control.tf([g.speed_per_s, g.position_per_s2], [1.0])
        loop = controller * control.tf([1.0], [actuator.time_constant_s, 1.0]) \
            * control.tf([1.0], [1.0, self.damping_per_s, 0.0])
        delay = actuator.dead_time_s + 0.5 * self.period_s
        if delay > 0.0:
            loop = loop * control.tf(*control.pade(delay, PADE_ORDER))
        return loop


@dataclass(frozen=True)
class Margins:
    """The margins of one loop with one actuator. Inf where the loop never crosses."""

    phase_margin_deg: float
    crossover_radps: float
    delay_margin_s: float
    gain_margin: float
    stable: bool
    actuator: Actuator

    def describe(self) -> str:
        if not self.stable:
            return f'unstable with {self.actuator.describe()}'
        return (f'phase margin {self.phase_margin_deg:.1f} deg at {self.crossover_radps:.3g} '
                f'rad/s, delay margin {self.delay_margin_s:.3g} s')


def loop_margins(loop: Loop, actuator: Actuator = Actuator()) -> Margins:
    """The margins of ``loop`` with ``actuator`` (python-control)."""
    import control
    rational = loop.rational(actuator)
    gm, pm, _, _, wgc, _ = control.stability_margins(rational)
    pm, wgc = float(pm), float(wgc)
    delay = math.radians(pm) / wgc if math.isfinite(pm) and wgc > 0.0 else math.inf
    stable = bool(np.all(np.real(control.poles(control.feedback(rational, 1))) < 0.0))
    return Margins(pm, wgc, delay, float(gm), stable, actuator)


def cruise_speed_mps(scenario: Scenario) -> float:
    """The speed the loop is linearised about: the line's highest speed limit less the
    planning margin."""
    top = max(scenario.line.speed_limit_mps.values)
    return top - scenario.planning.speed_margin_mps


def law_loop(law: str, scenario: Scenario, settings: Mapping[str, Any] | None = None,
             rate_hz: float | None = None) -> Loop:
    """The loop of ``law`` with ``settings`` on ``scenario``'s nominal train about cruise, at
    the rate the law runs at there (``ato_simulation.applies``)."""
    knowledge = knowledge_of(scenario)
    if rate_hz is None:
        rate_hz, reason = applicable_rate(law, scenario)
        if rate_hz is None:
            raise ValueError(f'{law} does not run on {scenario.name}: {reason}')
    cls = LAWS[law]
    instance = cls(knowledge, 1.0 / rate_hz, validated_settings(cls.Settings, settings or {}))
    speed = cruise_speed_mps(scenario)
    davis = knowledge.nominal_davis
    slope = (davis.b_n_s_per_m + 2.0 * davis.c_n_s2_per_m2 * speed) / knowledge.nominal_mass_kg
    return Loop(instance.feedback_gains(), slope, 1.0 / rate_hz, speed)


def margins(law: str, configuration: str, scenario: Scenario,
            actuator: Actuator = Actuator()) -> Margins:
    """The margins of ``law`` in ``configuration`` (published or tuned) on ``scenario``."""
    settings = settings_for(law, configuration, scenario.train.name)
    return loop_margins(law_loop(law, scenario, settings), actuator)


def largest_actuator(spec: Mapping[str, Any]) -> Actuator:
    """The largest lag and dead time an uncertainty specification draws (the upper ends of
    ``actuator_time_constant_s`` and ``actuator_dead_time_s``)."""
    return Actuator(_upper(spec['actuator_time_constant_s']),
                    _upper(spec['actuator_dead_time_s']))


def _upper(distribution) -> float:
    """The largest value a distribution draws (its bound; ``fixed``: its value)."""
    if distribution.dist == 'fixed':
        return distribution.a
    if distribution.dist == 'uniform':
        return distribution.b
    if distribution.dist == 'choice':
        return max(distribution.values)
    if math.isfinite(distribution.high):
        return distribution.high
    raise ValueError(f'{distribution.describe()} has no largest value: give the actuator '
                     'draws a bounded distribution (uniform, truncated_normal, choice)')


@dataclass(frozen=True)
class Coverage:
    """Whether a law's loop stays stable over a campaign's actuator draws."""

    covered: bool
    worst: Margins           # at the largest lag and dead time drawn
    tolerated_dead_time_s: float   # the largest dead time stable with the largest lag
    reason: str


def coverage(loop: Loop, spec: Mapping[str, Any]) -> Coverage:
    """Does ``loop`` stay stable at the largest actuator the specification ``spec`` draws?
    The answer names the margins there and the largest dead time the law tolerates."""
    worst_actuator = largest_actuator(spec)
    worst = loop_margins(loop, worst_actuator)
    lagged = loop_margins(loop, Actuator(worst_actuator.time_constant_s, 0.0))
    tolerated = lagged.delay_margin_s if lagged.stable else 0.0
    if worst.stable:
        reason = (f'covers the actuator draws: at the largest ({worst_actuator.describe()}) '
                  f'{worst.describe()}')
    else:
        reason = (f'cannot cover the actuator draws: unstable at the largest '
                  f'({worst_actuator.describe()}); with that lag it tolerates a dead time of '
                  f'{tolerated:.3g} s at most')
    return Coverage(worst.stable, worst, tolerated, reason)


def entry_margins(law: str, scenario: Scenario, settings: Mapping[str, Any],
                  spec: Mapping[str, Any], rate_hz: float | None = None) -> dict[str, Any]:
    """The margins of ``law`` with ``settings`` on ``scenario`` (at ``rate_hz``, default the
    rate it runs at there): without an actuator (the hold only, the nominal plant), at the
    largest actuator draw of ``spec``, and whether the law covers the draws (``note``: why,
    in a sentence). A loop that cannot be built or judged is a row whose note says why."""
    try:
        loop = law_loop(law, scenario, settings, rate_hz)
        bare = loop_margins(loop)
        cover = coverage(loop, spec)
    except (ValueError, KeyError) as error:
        return {'note': f'no margins: {error}'}
    return {'kp_per_s2': loop.gains.position_per_s2, 'kd_per_s': loop.gains.speed_per_s,
            'ki_per_s3': loop.gains.integral_per_s3,
            'phase_margin_deg': bare.phase_margin_deg, 'delay_margin_s': bare.delay_margin_s,
            'stable_nominal': bare.stable,
            'worst_phase_margin_deg': cover.worst.phase_margin_deg,
            'worst_delay_margin_s': cover.worst.delay_margin_s,
            'covers_actuator_draws': cover.covered,
            'tolerated_dead_time_s': cover.tolerated_dead_time_s,
            'coverage': cover.reason, 'note': f'{cover.reason}; {loop.gains.note}'}


def margins_rows(laws: Iterable[str], scenario: Scenario, spec: Mapping[str, Any],
                 configurations: Iterable[str] = GAINS) -> list[dict[str, Any]]:
    """One row per law and configuration: the margins without an actuator (the hold only),
    at the largest actuator draw of ``spec``, and whether the law covers the draws. A
    configuration a law has no settings for (no tuned artefact) is a row saying so."""
    rows = []
    for law in laws:
        for configuration in configurations:
            row: dict[str, Any] = {'law': law, 'configuration': configuration}
            try:
                settings = settings_for(law, configuration, scenario.train.name)
            except GainsUnavailable as error:
                rows.append({**row, 'note': str(error)})
                continue
            rows.append({**row, **entry_margins(law, scenario, settings, spec)})
    return rows


def campaign_margins(campaign: Campaign):
    """The margins of every row label of a campaign on each of its scenarios, with the
    settings the label runs (its configuration's and its own), at its rate, against its
    scenario's uncertainty: a DataFrame of columns scenario, law (the label), configuration
    and those of :func:`entry_margins` (``report.write_report``'s ``law_columns``)."""
    import pandas as pd
    rows = []
    for key in campaign.scenarios:
        scenario = load_scenario(key)
        for entry in campaign.laws:
            rows.append({'scenario': key, 'law': entry.label,
                         'configuration': entry.configuration, **entry_margins(
                             entry.law, scenario, campaign.settings_of(key, entry),
                             campaign.specs[key], campaign.rates_hz[(key, entry.label)])})
    return pd.DataFrame(rows)


def markdown_table(rows: list[dict[str, Any]], worst: Actuator) -> str:
    """The rows of :func:`margins_rows` as a markdown table."""
    lines = ['| law | gains | phase margin, hold only (deg) | delay margin (s) | phase margin '
             f'at {worst.describe()} (deg) | covers the actuator draws | largest dead time '
             'tolerated (s) |', '|---|---|---|---|---|---|---|']
    for r in rows:
        if 'phase_margin_deg' not in r:
            lines.append(f"| `{r['law']}` | {r['configuration']} | - | - | - | - | "
                         f"{r['note']} |")
            continue
        worst_pm = (f"{r['worst_phase_margin_deg']:.1f}" if r['covers_actuator_draws']
                    else 'unstable')
        lines.append(f"| `{r['law']}` | {r['configuration']} | {r['phase_margin_deg']:.1f} | "
                     f"{r['delay_margin_s']:.3g} | {worst_pm} | "
                     f"{'yes' if r['covers_actuator_draws'] else 'no'} | "
                     f"{r['tolerated_dead_time_s']:.3g} |")
    return '\n'.join(lines)
