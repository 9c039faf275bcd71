"""An independent check that the ``timetable`` strategy's curve is energy-optimal: on three
single-leg problems (level, a hill, a speed restriction), its traction energy is within 2 % of
the optimum a dynamic programme over distance and speed finds at the same running time.

The dynamic programme shares only the problem with the planner (the train's nominal resistance
and traction capability, the planning deceleration, the grade over the train's length and the
planner's speed ceiling of each section); its method is its own: the state is the kinetic
energy per unit mass e = v^2 / 2 on a fine grid at every 100 m, a stage's control is the change
of e (a constant force over the stage, so v^2 is linear in x and the stage's time 2 dx / (v0 +
v1) is exact), its cost the positive traction work plus lambda times the time, solved backwards
by Bellman's principle; lambda is bisected to the planner's running time and the energy
interpolated between the two solutions that bracket it (a convex combination, so an upper
bound of the optimum at that time). It has no jerk limit, so the planner's energy can only be
above the true optimum; the check is two-sided all the same (a planner below the programme's
optimum by more than its grid error would be a wrong energy)."""

from __future__ import annotations

import numpy as np
import pytest

from ato_common import units
from ato_common.braking_curves import RunSupervision
from ato_common.scenario import parse_scenario
from profile_node.planner import (
    braking_deceleration,
    leg_sections,
    plan_reference,
    traction_capability,
    train_grade_sine,
)

DX_M = 100.0
DE_M2PS2 = 1.0   # grid step of v^2/2
SUPPLEMENT = 10.0

PROBLEMS = {
    'level': [],
    # A hill the train climbs and descends with traction at its cruise speed (not steep:
    # 4 per mille is less than the resistance at ~200 km/h); on a steep descent the planner
    # holds the speed with the brake where the optimum lets it rise (6 % more at 8 per mille,
    # docs/guide/target-curve.md).
    'hill': [{'start_m': 5000, 'per_mille': 4}, {'start_m': 9000, 'per_mille': -4},
             {'start_m': 13000, 'per_mille': 0}],
    'speed_restriction': [],
}


def scenario_for(name):
    limits = [{'start_m': 0, 'speed_kmh': 250}]
    if name == 'speed_restriction':
        limits = [{'start_m': 0, 'speed_kmh': 250}, {'start_m': 9000, 'speed_kmh': 160},
                  {'start_m': 11000, 'speed_kmh': 250}]
    return parse_scenario({
        'name': name, 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': name, 'length_m': 20000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 20000}],
                 'speed_limits': limits, 'gradients': PROBLEMS[name] or None},
        'planning': {'max_acceleration_mps2': 0.4, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5, 'speed_margin_kmh': 5},
        'timetable': {'strategy': 'timetable', 'supplement_percent': SUPPLEMENT}})


class DynamicProgramme:
    """The problem on the grid; ``solve(lam)`` gives (energy J, time s) of the least
    E + lam T from standstill at A to standstill at B."""

    def __init__(self, scenario):
        train, line = scenario.train, scenario.line
        supervision = RunSupervision.for_scenario(scenario)
        settings = scenario.supervision
        sections = leg_sections(scenario, supervision.legs[0].mrsp, 0.0, line.length_m,
                                settings.service_brake_build_up_s + settings.driver_reaction_s,
                                {})
        xs = np.arange(0.0, line.length_m + 1e-9, DX_M)
        self.stages = len(xs) - 1

        def level_at(x):
            return next(s.level_mps for s in sections if s.start_m <= x < s.end_m
                        or s is sections[-1])
        ceiling = [min(level_at(x) for x in np.linspace(a, b, 5)) for a, b in zip(xs, xs[1:])]
        top = max(ceiling)
        self.e = np.arange(0.0, top * top / 2.0 + DE_M2PS2, DE_M2PS2)
        v = np.sqrt(2.0 * self.e)
        n = len(self.e)
        offsets = np.arange(-int(np.ceil(0.5 * DX_M / DE_M2PS2)) - 1,
                            int(np.ceil(0.5 * DX_M / DE_M2PS2)) + 2)
        self.offsets = offsets
        i = np.arange(n)[:, None]
        j = i + offsets[None, :]
        inside = (j >= 0) & (j < n)
        self.j = np.clip(j, 0, n - 1)
        davis = train.davis_nominal
        cache = {}
        self.stage_data = []
        for k in range(self.stages):
            sine = train_grade_sine(line, 0.5 * (xs[k] + xs[k + 1]), train.length_m)
            before = ceiling[k - 1] if k > 0 else 0.0
            key = (sine, ceiling[k], before)
            if key not in cache:
                capability = traction_capability(scenario, sine)
                cap = np.array([capability(s) for s in v])[:, None]
                brake = braking_deceleration(scenario, sine)
                accel = offsets[None, :] * DE_M2PS2 / DX_M
                v_mean = 0.5 * (v[:, None] + v[self.j])
                ok = inside & (accel <= cap + 1e-12) & (accel >= -brake - 1e-12) \
                    & (v_mean > 0.0) & (v[self.j] <= ceiling[k] + 1e-9) \
                    & (v[:, None] <= before + 1e-9)
                force = accel + davis.force(v_mean) / train.mass_kg \
                    + units.STANDARD_GRAVITY * sine
                energy = np.where(ok, train.mass_kg * np.maximum(force, 0.0) * DX_M, np.inf)
                time = np.where(ok, DX_M / np.maximum(v_mean, 1e-9), np.inf)
                cache[key] = (energy, time)
            self.stage_data.append(cache[key])

    def solve(self, lam: float) -> tuple[float, float]:
        n = len(self.e)
        cost_to_go = np.where(self.e == 0.0, 0.0, np.inf)
        choices = np.zeros((self.stages, n), dtype=int)
        rows = np.arange(n)
        for k in range(self.stages - 1, -1, -1):
            energy, time = self.stage_data[k]
            total = energy + lam * time + cost_to_go[self.j]
            choice = np.argmin(total, axis=1)
            cost_to_go = total[rows, choice]
            choices[k] = choice
        assert np.isfinite(cost_to_go[0]), 'the programme found no path'
        state, energy_j, time_s = 0, 0.0, 0.0
        for k in range(self.stages):
            c = choices[k, state]
            energy, time = self.stage_data[k]
            energy_j += energy[state, c]
            time_s += time[state, c]
            state = self.j[state, c]
        return energy_j, time_s


def optimum_at(scenario, running_time_s: float, cruise_mps: float) -> float:
    """The programme's least energy at ``running_time_s``. The price of time is bracketed
    around the planner's cruise speed's (lambda = m V^2 r'(V), only to start the search) and
    bisected."""
    programme = DynamicProgramme(scenario)
    davis = scenario.train.davis_nominal
    guess = cruise_mps ** 2 * (davis.b_n_s_per_m + 2.0 * davis.c_n_s2_per_m2 * cruise_mps)
    low, high = guess / 4.0, guess * 4.0
    e_low, t_low = programme.solve(low)
    e_high, t_high = programme.solve(high)
    assert t_high < running_time_s < t_low, 'the bracket of the price of time is too narrow'
    for _ in range(10):
        middle = np.sqrt(low * high)
        e_mid, t_mid = programme.solve(middle)
        if t_mid > running_time_s:
            low, e_low, t_low = middle, e_mid, t_mid
        else:
            high, e_high, t_high = middle, e_mid, t_mid
    share = (t_low - running_time_s) / (t_low - t_high)
    return e_low + share * (e_high - e_low)


@pytest.mark.parametrize('name', sorted(PROBLEMS))
def test_the_timetable_curve_is_within_2_percent_of_the_optimum(name):
    scenario = scenario_for(name)
    plan = plan_reference(scenario)
    assert plan.strategy == 'timetable'
    leg = plan.legs[0]
    running = leg.planned_arrival_s - leg.departure_s
    assert running == pytest.approx(leg.shortest_running_s * (1 + SUPPLEMENT / 100), abs=0.2)
    cruise = max(plan.trajectory.at(t).speed for t in np.arange(0.0, running, 5.0))
    optimum = optimum_at(scenario, running, cruise)
    assert plan.forecast_energy_j == pytest.approx(optimum, rel=0.02)
