"""Mao, Tao, Jiang, Yan & Zhong (IFAC 2017): adaptive actuator-failure compensation for
position tracking on a piecewise-constant train model.

Plant (eq 8, piecewise-constant with known mode indicators chi_i):
    x1' = x2,  x2' = m_i F - a_i - b_i x2 - c_i x2^2 - g vartheta_i - 0.004 D_i   (mode i)
    F = k_nu nu0 + xi^T varpi(t)
m_i is the input gain 1/mass of mode i; every healthy motor gets the same signal nu0, k_nu is the
number of healthy motors, xi the failure magnitudes on the known basis varpi(t) = (1,
sin(omega t + phase)) (the paper's failure pattern, Section 4).

Control (backstepping, Section 3):
    z1 = x1 - x_m,  alpha1 = -r1 z1 + x_m',  z2 = x2 - alpha1                     (21)-(23)
    eta = z1 + r1 (x2 - x_m') - x_m''
    zeta_i = a_i^ + b_i^ x2 + c_i^ x2^2 + g vartheta_i^ + 0.004 D_i^
    nu0 = -rho_knu^ xi^^T varpi + sum_i chi_i rho_i^ (zeta_i - eta - r2 z2)          (34)
with rho_knu = 1/k_nu and rho_i = 1/(m_i k_nu) = mass_i / k_nu, and the adaptive laws
    xi^'       =  gamma_xi z2 varpi                                                (28)
    a_i^'      = -gamma_a z2 chi_i          b_i^' = -gamma_b z2 chi_i x2           (29), (30)
    c_i^'      = -gamma_c z2 chi_i x2^2     vartheta_i^' = -gamma_vartheta z2 chi_i g   (31), (32)
    D_i^'      = -gamma_D z2 chi_i 0.004                                           (33)
    rho_knu^'  = +gamma_knu z2 xi^^T varpi        [FIX: printed with "-"]           (35)
    rho_i^'    = -gamma_m z2 chi_i (zeta_i - eta - r2 z2)                          (36)

[FIX] (35): with the "+" sign the rho_knu error terms cancel in V2' (the controller term is
-rho_knu^ xi^^T varpi; docs/papers/mao_2017.md). ``paper_as_printed`` runs the printed
"-" sign, which feeds the failure-compensation error back with the wrong sign.

Units: SI throughout (reading (A) of docs/papers/mao_2017.md: the paper's Davis numbers are
whole-train kN with V in km/h, converted in the train preset and the scenario's plant section).
a_i in m/s^2, b_i in 1/s, c_i in 1/m, vartheta_i the sine of the grade, D_i such that 0.004 D_i
is in m/s^2, rho_i in kg, xi in N. The paper gives no gains; the defaults are "unit-scaled":
each gamma is about (size of the parameter) / (z2 of 0.1 m/s x its regressor x a 10 to 100 s
adaptation time).

The modes (mass, Davis, grade, curve per mode) come from the scenario's plant section through
``TrainKnowledge.modes``; the estimates start at ``initial_estimate_ratio`` (paper: 95 %) of
those values, the failure estimates xi^ at zero and rho_knu^ at the ratio of 1/n (n motors,
none failed). Without modes the law runs with one mode, the train's nominal mass and Davis.

Deviations, all for a sampled, saturating implementation (also in README.md):
- the adaptive laws are integrated with forward Euler at the control period;
- adaptation is frozen while any actuator command is saturated (the error then no longer
  reflects the parameter errors; integrating it would wind the estimates up);
- rho_knu^ is projected onto [1/n, 1] x [rho_min_ratio, rho_max_ratio] and rho_i^ onto
  mass_i x [1/n, 1] x [rho_min_ratio, rho_max_ratio]: k_nu lies in 1..n, and a non-positive
  rho_i^ would reverse the control direction (the paper does not project).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ato_common.units import STANDARD_GRAVITY
from ato_controller_node.laws.base import ControlLaw, FeedbackGains, LawOutput, setting

#: the coefficient of the curve parameter D in the paper's model (eq 8)
CURVE_COEFFICIENT = 0.004


@dataclass(frozen=True)
class Mao2017Settings:
    r1: float = setting(0.5, minimum=1e-3, maximum=10.0, units='1/s',
                        description='backstepping gain of the position error z1 (paper: not '
                                    'given; docs/papers/mao_2017.md: 0.5)')
    r2: float = setting(1.0, minimum=1e-3, maximum=10.0, units='1/s',
                        description='backstepping gain of z2 (paper: not given; '
                                    'docs/papers/mao_2017.md: 1)')
    gamma_xi: float = setting(2e5, minimum=0.0, maximum=1e9, units='N/m',
                              description='adaptation gain of the failure magnitudes xi (28)')
    gamma_a: float = setting(1e-3, minimum=0.0, maximum=1.0, units='1/s^2',
                             description='adaptation gain of a_i (29)')
    gamma_b: float = setting(1e-6, minimum=0.0, maximum=1.0, units='1/m^2',
                             description='adaptation gain of b_i (30)')
    gamma_c: float = setting(1e-9, minimum=0.0, maximum=1.0, units='s^2/m^4',
                             description='adaptation gain of c_i (31)')
    gamma_vartheta: float = setting(1e-5, minimum=0.0, maximum=1.0, units='s^2/m^2',
                                    description='adaptation gain of the grade sine vartheta_i (32)')
    gamma_d: float = setting(10.0, minimum=0.0, maximum=1e4, units='1/s^2',
                             description='adaptation gain of the curve parameter D_i (33)')
    gamma_knu: float = setting(1e-6, minimum=0.0, maximum=1.0, units='1/(N m)',
                               description='adaptation gain of rho_knu = 1/k_nu (35)')
    gamma_m: float = setting(1e5, minimum=0.0, maximum=1e9, units='kg s^2/m^2',
                             description='adaptation gain of rho_i = mass_i/k_nu (36)')
    failure_basis_omega_radps: float = setting(
        0.05, minimum=0.0, maximum=10.0, units='rad/s',
        description='angular frequency of the failure basis varpi = (1, sin(omega t + phase)) '
                    '(paper: 0.05)')
    failure_basis_phase_rad: float = setting(
        -30.0, minimum=-1000.0, maximum=1000.0, units='rad',
        description='phase of the failure basis (paper: -30)')
    initial_estimate_ratio: float = setting(
        0.95, minimum=0.1, maximum=2.0, units='-',
        description='initial estimates as a fraction of the known mode values (paper: 0.95)')
    rho_min_ratio: float = setting(0.5, minimum=0.01, maximum=1.0, units='-',
                                   description='lower projection bound of rho_knu^, rho_i^ '
                                               '(fraction of their smallest possible value)')
    rho_max_ratio: float = setting(2.0, minimum=1.0, maximum=100.0, units='-',
                                   description='upper projection bound of rho_knu^, rho_i^ '
                                               '(multiple of their largest possible value)')
    paper_as_printed: bool = setting(False, minimum=0, maximum=1, units='-',
                                     description='use the printed "-" sign of the rho_knu law '
                                                 '(35) instead of the corrected "+"')


@dataclass(frozen=True)
class _Mode:
    """One known mode as the law uses it: (mass [kg], a, b, c, vartheta, D) of eq 8."""

    mass_kg: float
    parameters: tuple[float, float, float, float, float]

    @classmethod
    def of(cls, mode) -> '_Mode':
        a, b, c = mode.davis.per_kg(mode.mass_kg)
        return cls(mode.mass_kg, (a, b, c, mode.grade_sine,
                                  mode.curve_accel_mps2 / CURVE_COEFFICIENT))


class Mao2017Law(ControlLaw):
    name = 'mao_2017'
    paper = 'mao_2017'
    summary = ('Mao et al. 2017: adaptive actuator-failure compensation on the piecewise-constant '
               'model, one signal to all 4 motors')
    Settings = Mao2017Settings
    actuators = 4

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        known = train.modes
        if known:
            self.modes = tuple(_Mode.of(mode) for mode in known)
        else:
            davis = train.nominal_davis.per_kg(train.nominal_mass_kg)
            self.modes = (_Mode(train.nominal_mass_kg, (*davis, 0.0, 0.0)),)
        self._start_from_prior()

    def _start_from_prior(self) -> None:
        ratio, n = self.settings.initial_estimate_ratio, self.actuators
        self.xi_hat = [0.0, 0.0]
        self.rho_knu_hat = ratio / n
        # theta_hat[i] = [a, b, c, vartheta, D] of mode i; rho_hat[i] = mass_i / k_nu
        self.theta_hat = [[ratio * p for p in mode.parameters] for mode in self.modes]
        self.rho_hat = [ratio * mode.mass_kg / n for mode in self.modes]
        self._pending = None

    def _mode_index(self, measurement) -> int:
        if len(self.modes) == 1:
            return 0  # one known mode: the law treats the plant as time-invariant
        if not 0 <= measurement.mode < len(self.modes):
            raise ValueError(f'{self.name}: measured mode {measurement.mode} is not one of the '
                             f'{len(self.modes)} known modes')
        return measurement.mode

    def basis(self, time_s: float) -> tuple[float, float]:
        """The known failure basis varpi(t) (Section 4: 1 and sin(0.05 t - 30))."""
        s = self.settings
        return 1.0, math.sin(s.failure_basis_omega_radps * time_s + s.failure_basis_phase_rad)

    def feedback_gains(self) -> FeedbackGains:
        # n nu0 = n rho_hat (zeta - eta - r2 z2): with z1 = -e_x, z2 = -e_v - r1 e_x,
        # -eta - r2 z2 = (1 + r1 r2) e_x + (r1 + r2) e_v + x_m''; n rho_hat = ratio x mass
        s = self.settings
        ratio = s.initial_estimate_ratio
        return FeedbackGains(ratio * (1.0 + s.r1 * s.r2), ratio * (s.r1 + s.r2), 0.0,
                             'control (34) with every motor healthy and the adaptation frozen '
                             'at the initial estimates')

    def reset(self, measurement, reference, last_force_n):
        # Estimates restart from the known modes; the host's bumpless offset bridges the step.
        self._start_from_prior()

    def step(self, measurement, reference):
        s = self.settings
        i = self._mode_index(measurement)
        x2 = measurement.speed
        z1 = measurement.position - reference.position
        z2 = x2 + s.r1 * z1 - reference.speed                                     # (22), (23)
        eta = z1 + s.r1 * (x2 - reference.speed) - reference.acceleration
        a, b, c, vartheta, d = self.theta_hat[i]
        g = STANDARD_GRAVITY
        zeta = a + b * x2 + c * x2 * x2 + g * vartheta + CURVE_COEFFICIENT * d
        varpi = self.basis(measurement.time_s)
        failure = self.xi_hat[0] * varpi[0] + self.xi_hat[1] * varpi[1]
        shaped = zeta - eta - s.r2 * z2
        nu0 = -self.rho_knu_hat * failure + self.rho_hat[i] * shaped                 # (34)
        self._pending = (i, x2, z2, varpi, failure, shaped)
        n = self.actuators
        estimates = {'z1_m': z1, 'z2_mps': z2, 'nu0_n': nu0, 'mode': float(i),
                     'rho_knu_hat': self.rho_knu_hat, 'k_nu_hat': 1.0 / self.rho_knu_hat,
                     'rho_hat_kg': self.rho_hat[i], 'xi0_hat_n': self.xi_hat[0],
                     'xi1_hat_n': self.xi_hat[1], 'a_hat_mps2': a, 'b_hat_per_s': b,
                     'c_hat_per_m': c, 'vartheta_hat': vartheta, 'd_hat': d}
        return LawOutput(n * nu0, estimates, (nu0,) * n)

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        if self._pending is None:
            return
        i, x2, z2, varpi, failure, shaped = self._pending
        self._pending = None
        if abs(wanted_n - commanded_n) > 1e-9 * max(1.0, abs(wanted_n)):
            return  # frozen under saturation
        s, dt, g = self.settings, self.dt, STANDARD_GRAVITY
        xi_hat = [xi + dt * s.gamma_xi * z2 * w for xi, w in zip(self.xi_hat, varpi)]    # (28)
        regressors = (1.0, x2, x2 * x2, g, CURVE_COEFFICIENT)
        gains = (s.gamma_a, s.gamma_b, s.gamma_c, s.gamma_vartheta, s.gamma_d)
        theta_hat = [th - dt * k * z2 * r for th, k, r                            # (29)-(33)
                     in zip(self.theta_hat[i], gains, regressors)]
        if not all(math.isfinite(value) for value in (*xi_hat, *theta_hat)):
            return  # an absurd sample (overflow) must not poison the estimates
        self.xi_hat, self.theta_hat[i] = xi_hat, theta_hat
        sign = -1.0 if s.paper_as_printed else 1.0
        n = self.actuators
        low, high = s.rho_min_ratio / n, s.rho_max_ratio
        rho_knu = self.rho_knu_hat + sign * dt * s.gamma_knu * z2 * failure            # (35)
        self.rho_knu_hat = min(max(rho_knu, low), high)
        mass = self.modes[i].mass_kg
        rho = self.rho_hat[i] - dt * s.gamma_m * z2 * shaped                           # (36)
        self.rho_hat[i] = min(max(rho, low * mass), high * mass)
