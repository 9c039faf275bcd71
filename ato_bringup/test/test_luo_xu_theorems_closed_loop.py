"""Luo & Xu in the offline closed loop on luo_xu_crh3: Theorem 1, and Theorem 2 (the projection
law (24) onto the prior set S of eq (20) with the Table 2 prior) under the time-varying
resistance of eq (34). (The projection's unit tests: ato_controller_node/test.)"""

from dataclasses import replace

import numpy as np

from ato_bringup.offline import run_offline
from ato_common.evidence import Claim, record
from ato_common.plant_setup import parse_plant_setup
from ato_common.scenario import load_scenario
from ato_controller_node.laws.base import TrainKnowledge
from ato_controller_node.laws.luo_xu import LuoXuProjectionLaw


def luo_xu_crh3(varying: bool):
    """The luo_xu_crh3 preset, with Section 4.3's time-varying resistance (eq 34) if asked:
    c0, cv, ca vary by 30 %, 20 %, 10 % at 0.1 rad/s."""
    scenario = load_scenario('luo_xu_crh3')
    if not varying:
        return scenario
    eq34 = {'resistance_variation': {
        'a': {'amplitude': 0.3, 'omega_rad_per_s': 0.1},
        'b': {'amplitude': 0.2, 'omega_rad_per_s': 0.1},
        'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.1}}}
    return replace(scenario, plant=parse_plant_setup(eq34, scenario.train, 'plant'))


def run_law(scenario, law, gain_scale=1.0):
    """(times, |z1|, distance of theta_hat to S's centre in units of its radius, mass_hat, run)."""
    defaults = LuoXuProjectionLaw.Settings()
    gains = {name: getattr(defaults, name) * gain_scale
             for name in ('gamma_c0', 'gamma_cv', 'gamma_ca')}
    run = run_offline(scenario, law, settings={law: gains})
    probe = LuoXuProjectionLaw(TrainKnowledge.of(scenario.train), 0.1)
    thetas = zip(run.estimate('c0_hat_mps2'), run.estimate('cv_hat_per_s'),
                 run.estimate('ca_hat_per_m'))
    distance = np.array([probe.prior_distance(theta) for theta in thetas])
    return run.times_s, np.abs(run.estimate('z1_m')), distance, run.estimate('mass_hat_kg'), run


def test_theorem1_on_luo_xu_crh3_error_converges_and_estimates_stay_bounded():
    scenario = luo_xu_crh3(varying=False)
    times, z1, distance, mass, run = run_law(scenario, 'luo_xu')
    nominal = scenario.train.mass_kg
    # measured: max |z1| 7.0 cm (grades are unmodelled), 1.0 cm over the last 300 s
    assert z1.max() < 0.15
    assert z1[times > times[-1] - 300.0].max() < 0.025
    assert 0.7 * nominal <= mass.min() and mass.max() <= 1.5 * nominal
    assert distance.max() < 1.0   # estimates stay within the Table 2 prior (measured 0.31)
    stop = run.metrics().stop_errors_m['Tianjin']
    assert abs(stop) < 0.05
    record(Claim(
        'luo_xu', 'Theorem 1: the position error converges and the estimates stay bounded',
        'z1 -> 0, m_hat and theta_hat bounded',
        f'max |z1| {z1.max() * 100:.1f} cm, {z1[times > times[-1] - 300.0].max() * 100:.1f} cm '
        f'over the last 300 s; m_hat {mass.min() / nominal:.3f} .. {mass.max() / nominal:.3f} '
        f'of nominal; theta_hat at {distance.max():.2f} of the prior radius; stop {stop:+.3f} m',
        'luo_xu_crh3, point mass, 10 Hz, constant Davis (Table 1), SI-retuned Gamma',
        'partly reproduced', 'bounded, but a residual of centimetres remains: the line has '
        'grades, which the paper\'s model (3) has not'))


def test_theorem2_under_eq34_keeps_estimates_in_S_and_error_in_a_small_residual_set():
    times, z1, distance, mass, _ = run_law(luo_xu_crh3(varying=True), 'luo_xu_projection')
    assert distance.max() <= 1.0 + 1e-9   # measured 0.28: the projection does not act
    # residual set: measured max |z1| 8.9 cm, 1.8 cm over the last 300 s
    assert z1.max() < 0.15
    assert z1[times > times[-1] - 300.0].max() < 0.03
    record(Claim(
        'luo_xu', 'Theorem 2: under the time-varying resistance (34) the projected estimates '
        'stay in S and the error in a small residual set',
        'theta_hat in S, bounded residual error',
        f'theta_hat at most {distance.max():.2f} of the radius of S; max |z1| '
        f'{z1.max() * 100:.1f} cm, {z1[times > times[-1] - 300.0].max() * 100:.1f} cm over the '
        'last 300 s',
        'luo_xu_crh3, eq (34) in the plant (c0, cv, ca +/- 30, 20, 10 % at 0.1 rad/s), 10 Hz, '
        'SI-retuned Gamma', 'reproduced'))


def test_fast_adaptation_under_eq34_unprojected_leaves_S_and_tracks_worse():
    """At the default gains both laws coincide (theta_hat stays at 28 % of S's radius). With the
    adaptation gains 300x the defaults the unprojected law's estimates leave S (measured 79x its
    radius), the command rides the traction limit and |z1| reaches 6 m; the projection keeps the
    estimates in S and |z1| under 4 cm. The same happens with constant theta: at 10 Hz it is the
    sampled gradient law that goes astray at these gains, and the projection that bounds it."""
    scenario = luo_xu_crh3(varying=True)
    _, z1_p, dist_p, _, _ = run_law(scenario, 'luo_xu_projection', 300.0)
    _, z1_u, dist_u, _, _ = run_law(scenario, 'luo_xu', 300.0)
    assert dist_p.max() <= 1.0 + 1e-9 and z1_p.max() < 0.08
    assert dist_u.max() > 10.0
    assert z1_u.max() > 20.0 * z1_p.max()
    record(Claim(
        'luo_xu', 'Section 4.3: without the projection the estimates drift under (34); with it '
        'they stay in S',
        'unprojected estimates drift, projected ones stay bounded',
        f'gains x300: unprojected theta_hat at {dist_u.max():.0f}x the radius of S, max |z1| '
        f'{z1_u.max():.2f} m; projected {dist_p.max():.2f}, {z1_p.max() * 100:.1f} cm',
        'luo_xu_crh3, eq (34), 10 Hz, adaptation gains 300x the SI-retuned defaults',
        'partly reproduced', 'only at 300x the gains, where the same happens with constant '
        'theta: at 10 Hz it is the sampled gradient law that goes astray, not eq (34) that '
        'makes the estimates drift; at the default gains both laws stay well inside S'))
