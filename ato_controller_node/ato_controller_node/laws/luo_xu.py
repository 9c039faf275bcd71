"""Luo & Xu, direct adaptive backstepping: Theorem 1 (``luo_xu``) and its robust version with the
projection law, Theorem 2 (``luo_xu_projection``).

Plant (eq 3): x1' = x2, x2' = u/m - theta^T phi(x2), theta = (c0, cv, ca) per kg,
phi = (1, x2, x2^2). Both the mass m and theta are unknown and estimated.

    z1 = x1 - x*,   z2 = x2 - x*' + c1 z1                                   (backstepping errors)
    varphi = c1^2 z1 - (c1 + c2) z2 + x*''                                  (as printed)
    u = m_hat (theta_hat^T phi + varphi)                                    (12)
    theta_hat' = -Gamma phi z2,   m_hat' = -gamma (theta_hat^T phi + varphi) z2    (16)

The law as printed is the default. Its error dynamics are z1' = -c1 z1 + z2,
z2' = -c2 z2 + (parameter errors): stable for any c1, c2 > 0 (the weighted Lyapunov function
V = a z1^2/2 + z2^2/2 + rho m_t^2/(2 gamma) + theta_t^T Gamma^-1 theta_t/2 has
V' = -a c1 z1^2 + a z1 z2 - c2 z2^2, negative definite for 0 < a < 4 c1 c2, with the adaptive
laws (16) unchanged). The gap is in the paper's proof, which takes a = 1 and so needs
4 c1 c2 > 1, not in its law. ``fixed_varphi`` runs the suite's former [FIX],
varphi = (c1^2 - 1) z1 - (c1 + c2) z2 + x*'', for which a = 1 works, but whose error dynamics
e'' + (c1 + c2) e' + (1 + c1 c2) e = 0 have, at c1 = c2 = 0.1, a natural frequency of 1 rad/s
with damping 0.1 (a phase margin of 11 deg, a delay margin of 0.2 s), and whose added "1"
carries s^-2, so the loop's frequency depends on the unit system (docs/papers/luo_xu.md).

Gains. One reading for all of Table 1's gains
(:func:`ato_common.units.luo_xu_adaptation_gains_to_si`): each acts on its estimate in Table
1's unit for it, m in t and theta per tonne with V in km/h, the errors in SI; converted so that
every term of the Lyapunov function (17) is the same number: gamma = 1e5 -> 1e8 kg s^2/m^2,
Gamma = diag(1e4, 1, 0.01) -> D Gamma D = about diag(1e-2, 1.296e-5, 1.68e-6) (D the
per-tonne-to-SI factors of the coefficients). These are the defaults (preset ``paper`` of
:data:`GAIN_PRESETS`); the preset ``earlier_retuning`` is the suite's earlier hand retuning
diag(1e-3, 3e-7, 3e-10) with gamma 1e5 (Gamma_ii ~ theta_i / (phi_i z2 T_adapt),
docs/papers/luo_xu.md). The ``tuned`` configuration of the suite (``ato_controller_node.gains``)
comes from the tuning procedure, not from here.

Deviations, all for a sampled, saturating implementation:
- the adaptive laws (16)/(24) are integrated implicitly (backward Euler) over each control
  period: at sample k the estimates are moved by the rate at the new sample, with the error z2
  at the end of the period taken a posteriori, i.e. corrected for what the change of the
  estimates does to it through the certainty-equivalence control (dz2'/dtheta_hat = phi,
  dz2'/dm_hat = psi/m_hat, psi = theta_hat^T phi + varphi):

      delta = -dt G r z2_k / (1 + dt^2 (phi^T Gamma phi + gamma psi^2 / m_hat))

  with r = (phi, psi) and G = diag(Gamma, gamma); then the control of sample k uses the moved
  estimates. Forward Euler of the same laws (the rate of sample k applied after its control)
  makes the sampled adaptation loop unstable once dt phi^T Gamma phi > c2, which the paper's
  gains exceed at any onboard rate (phi^T Gamma phi ~ 70 1/s^2 at 300 km/h); the implicit step
  is stable for any Gamma and tends to the paper's law as dt -> 0 (the mass law at the paper's
  gamma, 1e8 in SI, forms with z2 an oscillator at sqrt(gamma psi^2 / m), about 2 rad/s at
  cruise, damped by c2 alone, which the 10 Hz hold can tip over). ``forward_euler`` runs the
  earlier explicit step for comparison;
- under saturation the adaptation runs on the augmented error (Karason & Annaswamy's
  anti-windup for adaptive control): an auxiliary copy of the error dynamics of the law that
  runs (8), (15) without the parameter errors (z1' = -c1 z1 + z2 and z2' = -c2 z2 with the
  printed varphi, z2' = -z1 - c2 z2 with ``fixed_varphi``), driven by the force the limits took
  away (commanded - wanted, over m_hat) and stepped exactly (zero-order hold) each period,
  gives the part of (z1, z2) that the saturation caused; the laws adapt on z2 minus that part,
  which only the parameter errors drive. Freezing the adaptation instead
  (``freeze_under_saturation``, the earlier behaviour) is enough at small gains, but at the
  paper's the adaptation loop swings the force onto the traction limit and the frozen, then
  released, estimates go into a limit cycle of hundreds of metres;
- m_hat is projected onto [mass_min_ratio, mass_max_ratio] x nominal mass (the paper does not,
  but a non-positive mass estimate would reverse the control direction); it starts at
  initial_mass_ratio x nominal.

Theorem 2 (Section 4) replaces the theta law by the projection (24) onto the prior set S of
eq (20), g(theta) = (theta - theta*)^T (theta - theta*) <= M0^2, theta* = the nominal Table 2
resistance the train's on-board prior carries (cv corrected from the printed 0.6318 to 0.06318):

    theta_hat' = tau                      inside S, or on its boundary with tau pointing in
    theta_hat' = tau - Gamma grad_g grad_g^T tau / (grad_g^T Gamma grad_g)
                                          on the boundary with tau pointing out     (24), (26)
    tau = -Gamma phi z2,  grad_g = gradient of g at theta_hat

[FIX] The branch conditions printed in (24) are swapped: it projects when (Gamma phi z2)^T grad_g
>= 0, i.e. when the raw update points into S, and lets outward updates through; its proof and
(26) project the outward ones (the paper is not self-consistent there, and the suite follows
its proof). ``paper_as_printed`` runs the printed branches.
Deviations of Theorem 2:
- S is an ellipsoid sum(((theta_i - theta_i*) / (R delta_i))^2) <= 1 with the Table 2 spans
  delta_i, not the single-radius ball of eq (20): a single radius M0 is dominated by c0
  (3.138 N/t against 0.014 and 0.00015) and would not constrain cv and ca at all. The default
  R = sqrt(3) circumscribes the Table 2 box, so the true time-varying theta(t) of eq (34) lies in S
  at all times (its three coefficients vary in phase and reach 1.46 in this norm).
- A step of the period can end a little past the boundary; the estimate is then scaled back onto it
  along the ray from theta* (a projection in the ellipsoid's own coordinates), so that theta_hat
  stays in S at every sample, as the continuous law guarantees. Not done when
  ``paper_as_printed``, whose branches let theta_hat leave S anyway.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ato_common import units
from ato_controller_node.laws.base import ControlLaw, FeedbackGains, LawOutput, setting

#: Luo & Xu Table 1: gamma = 1e5 and Gamma = diag(1e4, 1, 0.01) in the paper's units, exactly
#: in SI (gamma, Gamma_11, Gamma_22, Gamma_33), one reading for all four
PAPER_GAINS = units.luo_xu_adaptation_gains_to_si(1e5, 1e4, 1.0, 0.01)
#: the gain presets: ``paper`` (the default of the settings), ``earlier_retuning`` (the suite's
#: earlier hand retuning, for forward Euler at 10 Hz); give one as the settings' values, e.g.
#: ``run_offline(..., settings={'luo_xu': GAIN_PRESETS['earlier_retuning']})``
GAIN_PRESETS = {
    'paper': {'gamma_mass': PAPER_GAINS[0], 'gamma_c0': PAPER_GAINS[1],
              'gamma_cv': PAPER_GAINS[2], 'gamma_ca': PAPER_GAINS[3]},
    'earlier_retuning': {'gamma_mass': 1e5, 'gamma_c0': 1e-3, 'gamma_cv': 3e-7,
                         'gamma_ca': 3e-10},
}

#: Luo & Xu Table 2: half-widths of the nominal prior, 3.138 N/t, 0.01417 N/t per km/h,
#: 0.000152 N/t per (km/h)^2, here per kg in SI (m/s^2, 1/s, 1/m)
TABLE2_SPANS = units.davis_per_tonne_to_per_kg(3.138, 0.01417, 0.000152)


@dataclass(frozen=True)
class LuoXuSettings:
    c1: float = setting(0.1, minimum=1e-4, maximum=10.0, units='1/s',
                        description='backstepping gain of the position error (paper: 0.1)',
                        admissible=(0.02, 2.0), scale='log')
    c2: float = setting(0.1, minimum=1e-4, maximum=10.0, units='1/s',
                        description='backstepping gain of z2 (paper: 0.1)',
                        admissible=(0.02, 2.0), scale='log')
    gamma_mass: float = setting(PAPER_GAINS[0], minimum=0.0, maximum=1e10, units='kg s^2/m^2',
                                description='adaptation gain gamma of the mass estimate '
                                            '(paper: 1e5 with m in t, 1e8 in SI)',
                                admissible=(1e3, 1e9), scale='log')
    gamma_c0: float = setting(PAPER_GAINS[1], minimum=0.0, maximum=1.0, units='1/s^2',
                              description='adaptation gain Gamma_11 of c0 (paper: 1e4 per '
                                          'tonne, 1e-2 in SI)',
                              admissible=(1e-7, 0.1), scale='log')
    gamma_cv: float = setting(PAPER_GAINS[2], minimum=0.0, maximum=1.0, units='1/m^2',
                              description='adaptation gain Gamma_22 of cv (paper: 1 per tonne '
                                          'with V in km/h, 1.296e-5 in SI)',
                              admissible=(1e-11, 1e-4), scale='log')
    gamma_ca: float = setting(PAPER_GAINS[3], minimum=0.0, maximum=1.0, units='s^2/m^4',
                              description='adaptation gain Gamma_33 of ca (paper: 0.01 per '
                                          'tonne with V in km/h, 1.68e-6 in SI)',
                              admissible=(1e-13, 1e-5), scale='log')
    mass_min_ratio: float = setting(0.7, minimum=0.1, maximum=1.0, units='-',
                                    description='lower bound of m_hat over the nominal mass')
    mass_max_ratio: float = setting(1.5, minimum=1.0, maximum=10.0, units='-',
                                    description='upper bound of m_hat over the nominal mass')
    initial_mass_ratio: float = setting(1.0, minimum=0.1, maximum=10.0, units='-',
                                        description='m_hat at the start over the nominal mass '
                                                    '(clipped to its bounds)')
    forward_euler: bool = setting(False, minimum=0, maximum=1, units='-',
                                  description='integrate (16)/(24) by one explicit Euler step '
                                              'per period instead of the implicit step')
    freeze_under_saturation: bool = setting(False, minimum=0, maximum=1, units='-',
                                            description='freeze the adaptation over a saturated '
                                                        'period instead of adapting on the '
                                                        'augmented error')
    fixed_varphi: bool = setting(False, minimum=0, maximum=1, units='-',
                                 description="the suite's former [FIX] varphi = (c1^2 - 1) z1 - "
                                             "(c1 + c2) z2 + x*'' instead of the printed "
                                             'varphi (a deviation from the paper)')


class LuoXuLaw(ControlLaw):
    name = 'luo_xu'
    paper = 'luo_xu'
    summary = 'Luo & Xu Theorem 1: direct adaptive backstepping estimating m and (c0, cv, ca)'
    Settings = LuoXuSettings

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self._start_from_prior()
        self._pending = None
        self._free = False   # the period now ending is to be integrated at the next sample
        self._aux = (0.0, 0.0)   # (z1, z2) caused by saturation alone (augmented error)
        self._aux_matrices()

    def update_settings(self, settings) -> None:
        super().update_settings(settings)
        self._aux_matrices()

    def _z1_gain(self) -> float:
        """The coefficient of z1 in varphi: c1^2 as printed, c1^2 - 1 with ``fixed_varphi``."""
        c1 = self.settings.c1
        return c1 * c1 - 1.0 if self.settings.fixed_varphi else c1 * c1

    def error_dynamics(self) -> np.ndarray:
        """The error dynamics (z1, z2)' = A (z1, z2) of the law that runs, with the parameter
        errors left out: z1' = -c1 z1 + z2 (8), z2' = (g - c1^2) z1 - c2 z2 with g the
        coefficient of z1 in varphi (from (9) and the certainty-equivalence control (12))."""
        c1, c2 = self.settings.c1, self.settings.c2
        return np.array([[-c1, 1.0], [self._z1_gain() - c1 * c1, -c2]])

    def feedback_gains(self) -> FeedbackGains:
        # F / M = m_hat / M (varphi + ...), varphi = g z1 - (c1 + c2) z2 + x*'' with
        # z1 = -e_x, z2 = -e_v - c1 e_x: kp = c1 (c1 + c2) - g, kd = c1 + c2
        s = self.settings
        nominal = self.train.nominal_mass_kg
        ratio = self._clip_mass(s.initial_mass_ratio * nominal) / nominal
        return FeedbackGains(ratio * (s.c1 * (s.c1 + s.c2) - self._z1_gain()),
                             ratio * (s.c1 + s.c2), 0.0,
                             'adaptation frozen at the initial estimates (the on-board prior)')

    def _aux_matrices(self) -> None:
        """The exact zero-order-hold step of the error dynamics of the law that runs
        (:meth:`error_dynamics`) driven by w, the force the saturation took away over m_hat
        (z2' += w): aux(k+1) = step aux(k) + input w(k)."""
        a = np.zeros((3, 3))
        a[:2, :2] = self.error_dynamics()
        a[1, 2] = 1.0
        zoh = expm(a * self.dt)
        self._aux_step, self._aux_input = zoh[:2, :2], zoh[:2, 2]

    def _clip_mass(self, mass: float) -> float:
        s, nominal = self.settings, self.train.nominal_mass_kg
        return min(max(mass, s.mass_min_ratio * nominal), s.mass_max_ratio * nominal)

    def _start_from_prior(self) -> None:
        self.mass_hat = self._clip_mass(self.settings.initial_mass_ratio
                                        * self.train.nominal_mass_kg)
        self.theta_hat = list(self.train.nominal_davis.per_kg(self.train.nominal_mass_kg))

    def reset(self, measurement, reference, last_force_n):
        # The estimates start from the on-board prior; the host's bumpless offset bridges the
        # difference between the last command and this law's first one.
        self._start_from_prior()
        self._pending = None
        self._free = False
        self._aux = (0.0, 0.0)

    def _specific(self, phi, varphi: float) -> float:
        th = self.theta_hat
        return th[0] * phi[0] + th[1] * phi[1] + th[2] * phi[2] + varphi

    def step(self, measurement, reference):
        s = self.settings
        v = measurement.speed
        z1 = measurement.position - reference.position
        z2 = v - reference.speed + s.c1 * z1
        varphi = self._z1_gain() * z1 - (s.c1 + s.c2) * z2 + reference.acceleration
        phi = (1.0, v, v * v)
        if self._free and not s.forward_euler:
            # implicit step over the period that ends now, before this sample's control
            self._adapt(phi, z2 - self._aux[1], self._specific(phi, varphi), implicit=True)
        self._free = False
        specific = self._specific(phi, varphi)
        force = self.mass_hat * specific                                           # (12)
        self._pending = (phi, z2, specific)
        th = self.theta_hat
        return LawOutput(force, {'mass_hat_kg': self.mass_hat, 'c0_hat_mps2': th[0],
                                 'cv_hat_per_s': th[1], 'ca_hat_per_m': th[2],
                                 'z1_m': z1, 'z2_mps': z2, **self._extra_estimates()})

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        if self._pending is None:
            return
        phi, z2, specific = self._pending
        self._pending = None
        s = self.settings
        excess = commanded_n - wanted_n
        saturated = abs(excess) > 1e-9 * max(1.0, abs(wanted_n))
        if s.freeze_under_saturation and saturated:
            return  # frozen under saturation
        if not s.freeze_under_saturation:
            # the augmented error: the part of (z1, z2) the saturation causes over the period,
            # which the adaptation must not attribute to the parameters
            z2 -= self._aux[1]
            aux = self._aux_step @ np.array(self._aux) + self._aux_input * (excess / self.mass_hat)
            self._aux = (float(aux[0]), float(aux[1])) if np.all(np.isfinite(aux)) else (0., 0.)
        if s.forward_euler:
            self._adapt(phi, z2, specific, implicit=False)
        else:
            self._free = True   # adapt over this period at the next sample

    def _adapt(self, phi, z2: float, specific: float, implicit: bool) -> None:
        """Move the estimates over one period by the rates (16) (or (24) for theta): forward
        Euler, or the implicit step with the a-posteriori error (module docstring)."""
        s, dt = self.settings, self.dt
        gains = (s.gamma_c0, s.gamma_cv, s.gamma_ca)
        raw_rate = [-g * p * z2 for g, p in zip(gains, phi)]                          # (16)
        mass_rate = -s.gamma_mass * specific * z2                                      # (16)
        if implicit:
            stiffness = (sum(g * p * p for g, p in zip(gains, phi))
                         + s.gamma_mass * specific * specific / self.mass_hat)
            weight = 1.0 + dt * dt * stiffness
            if not math.isfinite(weight):
                return   # overflow on absurd input: keep the estimates
            raw_rate = [r / weight for r in raw_rate]
            mass_rate /= weight
        self.theta_hat = self._next_theta(raw_rate, gains)
        self.mass_hat = self._clip_mass(self.mass_hat + dt * mass_rate)

    def _extra_estimates(self) -> dict[str, float]:
        return {}

    def _next_theta(self, raw_rate: list[float], gains: tuple[float, ...]) -> list[float]:
        """theta_hat one period on along the (already integrated) rate (16)."""
        return [th + self.dt * r for th, r in zip(self.theta_hat, raw_rate)]


@dataclass(frozen=True)
class LuoXuProjectionSettings(LuoXuSettings):
    c0_span_mps2: float = setting(TABLE2_SPANS[0], minimum=1e-9, maximum=1.0, units='m/s^2',
                                  description='half-width of the c0 prior (Table 2: 3.138 N/t)')
    cv_span_per_s: float = setting(TABLE2_SPANS[1], minimum=1e-12, maximum=1.0, units='1/s',
                                   description='half-width of the cv prior (Table 2: 0.01417 N/t '
                                               'per km/h)')
    ca_span_per_m: float = setting(TABLE2_SPANS[2], minimum=1e-12, maximum=1.0, units='1/m',
                                   description='half-width of the ca prior (Table 2: 0.000152 N/t '
                                               'per (km/h)^2)')
    prior_radius: float = setting(math.sqrt(3.0), minimum=0.1, maximum=100.0, units='-',
                                  description='radius R of the set S in units of the spans '
                                              '(sqrt(3) circumscribes the Table 2 box)')
    paper_as_printed: bool = setting(False, minimum=0, maximum=1, units='-',
                                     description='the branch conditions of (24) as printed '
                                                 '(swapped against its proof and (26))')


class LuoXuProjectionLaw(LuoXuLaw):
    name = 'luo_xu_projection'
    paper = 'luo_xu'
    summary = ('Luo & Xu Theorem 2: adaptive backstepping with the projection law (24) onto the '
               'Table 2 prior set S')
    Settings = LuoXuProjectionSettings

    def _start_from_prior(self) -> None:
        super()._start_from_prior()
        self.theta_prior = tuple(self.theta_hat)   # theta* of eq (20): the on-board nominal

    def _scales(self) -> tuple[float, float, float]:
        s = self.settings
        r = s.prior_radius
        return (r * s.c0_span_mps2, r * s.cv_span_per_s, r * s.ca_span_per_m)

    def prior_distance(self, theta) -> float:
        """sqrt(g(theta)) in units of the boundary: <= 1 inside S."""
        ratios = [(th - c) / w for th, c, w in zip(theta, self.theta_prior, self._scales())]
        return math.sqrt(sum(r * r for r in ratios))

    def _extra_estimates(self):
        return {'prior_distance': self.prior_distance(self.theta_hat)}

    def _next_theta(self, raw_rate, gains):
        scales = self._scales()
        offset = [th - c for th, c in zip(self.theta_hat, self.theta_prior)]
        grad = [2.0 * d / (w * w) for d, w in zip(offset, scales)]          # grad g, eq (20)
        on_boundary = self.prior_distance(self.theta_hat) >= 1.0
        outward = sum(r * g for r, g in zip(raw_rate, grad)) > 0.0   # (Gamma phi z2)^T grad_g < 0
        printed = self.settings.paper_as_printed
        # (24)/(26): project the outward rate on the boundary; as printed: the inward one
        project = on_boundary and (outward != printed)
        rate = raw_rate
        if project:
            weight = sum(g * gi * gi for g, gi in zip(gains, grad))
            if weight > 0.0:
                along = sum(r * gi for r, gi in zip(raw_rate, grad)) / weight
                rate = [r - g * gi * along for r, g, gi in zip(raw_rate, gains, grad)]  # (24)
        theta = super()._next_theta(rate, gains)
        distance = self.prior_distance(theta)
        if not math.isfinite(distance):
            return list(self.theta_hat)   # overflow on absurd input: keep the estimates
        if distance > 1.0 and not printed:
            # Euler stepped past the boundary: back onto it along the ray from theta*
            theta = [c + (th - c) / distance for th, c in zip(theta, self.theta_prior)]
        return theta
