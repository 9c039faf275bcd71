"""Tan, Jiang & Chen (2025): second-level adaptation with fixed identification models, and the
three multiple-model methods its Section 4.3 compares it with, all on the same five models.

Plant (5)-(8): x = (s, v), x' = A x + B [G u + Z], G = theta_G = 1/M,
Z = phi_Z^T theta_Z, phi_Z = (-1, -v, -v^2), theta_Z = (a + g sin(grade) + 0.004 D, b, c) per kg.
Reference model (9): x_m' = Am x_m + Bm r, Am = [[0, 1], [am1, am2]], Bm = (0, bm); the target
curves are x_m = (s*, v*), so r = (v*' - am1 s* - am2 v*) / bm (Remark 2). Matching (10):
k1* = (am1, am2), k2* = bm. bm cancels in k2* r, so the control does not depend on it (paper:
bm = 1) and it is not a setting.

Identification models (17), k = 1..5, one parameter vector theta_k = (theta_Gk, theta_Zk) each:
    xhat_k' = Am xhat_k + (A - Am) x + B [G_k u + Z_k],   e_k = xhat_k - x               (17), (18)

The five models (not given in the paper; docs/papers/tan_jiang_chen.md) are the corner
simplex of a box [theta_min, theta_max] of R^4: theta_5 = theta_min and
theta_k = theta_min + 4 (theta_max,k - theta_min,k) e_k, so every point of the box is a convex
combination of them (Lemma 2). The box: mass within [mass_low_ratio, mass_high_ratio] x nominal
(theta_G = 1/M), the nominal Davis coefficients per kg within +/- davis_uncertainty, and the line
resistance (grade, plus curve and tunnel as equivalent grade) within
[grade_min_per_mille, grade_max_per_mille]; the default box covers the 12 per mille base run,
the 30 per mille grade jump and mass +/- 20 %.

Laws (one class each, registry names in brackets):
- SecondLevelFixedLaw [tan_second_level]: the paper's method. Convex-combination update (23)
  alpha' = -Gamma_a E^T (E alpha - h), E = [e1-e5 .. e4-e5], h = -e5, alpha_5 = 1 - sum; control
  (24) with theta_hat = sum alpha_k theta_k; projection (25).
- SecondLevelAdaptiveLaw [tan_second_level_adaptive]: Narendra & Han's second-level adaptation
  with adaptive identification models (Han & Narendra 2012; Zhou & Zhang 2014 for trains): each
  theta_k adapts by the Lyapunov law theta_k' = -Gamma omega B^T P e_k, omega = (u, phi_Z),
  Am^T P + P Am = -I; alpha and the control as above.
- SwitchingMultipleModelLaw [tan_switching_mm]: Narendra & Balakrishnan (1994) switching among
  the fixed models by the index J_k = c1 |e_k|^2 + c2 int exp(-lambda (t - tau)) |e_k|^2 dtau,
  with hysteresis; the controller (24) of the selected model (alpha = its unit vector).
- WeightedMultipleModelLaw [tan_weighted_mm]: classical weighted multiple-model control: the
  controllers of the five models weighted by the recursive weighting algorithm
  w_k(n) = w_k(n-1) l_k / sum_j w_j(n-1) l_j, l_k = 1 - J_k / sum_j J_j, from equal weights,
  each weight kept above weight_floor so a model can come back after a change.

Options of the comparison (Section 4.3), all settings:
- ``initial_alpha_1..4``: alpha at t = 0 (paper: 0.2 each). With ``alpha_gain`` 0 and those the
  barycentric coordinates of a parameter vector in the simplex, tan_second_level is law (24)
  with that vector, never updated (the reproduction's "no adaptation" reference).
- ``adaptive_models`` of methods (3) and (4): the paper says all four methods start their models
  from the same initial values, which suggests (3) and (4) adapt their models too; with the
  option set their five models adapt by the law of tan_second_level_adaptive (same
  ``identification_gain``) and the index or weights rank the adapting models. Off by default
  (the fixed models of Narendra & Balakrishnan's switching and of classical weighting).

Integration at the control period dt (documented deviations from the continuous-time paper):
- The identification models (17) are linear with the stable Am: they are advanced exactly over
  each period with u held (zero-order hold, as the actuators apply it) and the measured x and
  Z_k(v) interpolated linearly between samples (first-order hold); a held x would put an error of
  am1 v dt (0.8 m/s^2 at 300 km/h) into the model. u is the force actually commanded after the
  actuator limits, so the models see what the plant sees and saturation cannot wind the
  estimates up (no freezing needed: nothing here integrates the tracking error).
- The alpha law (23) is stiff: E^T E scales with the squared identification errors (metres),
  and forward Euler diverges once dt Gamma_a |E|^2 > 2. It is integrated by backward Euler,
  (I + dt Gamma_a E^T E) alpha_n+1 = alpha_n + dt Gamma_a E^T h, unconditionally stable, with
  the same fixed points, and |alpha_n+1 - alpha_bar| <= |alpha_n - alpha_bar| as in the
  continuous V_s of (26)-(27).
- The adaptive models' parameters move by forward Euler with the error at the new sample.
- If a period is skipped (the host held the command on a missing measurement), the models
  restart from the measured state, as Lemma 3 requires identical initial conditions.

[FIX] (25) freezes alpha whenever sum alpha_k G_k <= 0; it can deadlock and lets the divisor
approach zero. Here alpha is projected (Euclidean, the metric of V_s) onto
sum alpha_k G_k >= G_min = 1/M_max, the box's heaviest train; the true alpha satisfies it, so V_s
still does not increase. ``paper_freeze`` runs the printed rule (a step that would make the sum
non-positive is not taken); even then the division is guarded by a floor of 1e-3 G_min.
"""

from __future__ import annotations

import math
import sys
from abc import abstractmethod
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, solve_continuous_lyapunov

from ato_common import units
from ato_controller_node.laws.base import ControlLaw, FeedbackGains, LawOutput, setting

MODELS = 5
ALPHA_INITIAL = 0.2   # Tan et al. Section 4.1: equal initial convex-combination coefficients


@dataclass(frozen=True)
class TanSettings:
    am1: float = setting(-0.1, minimum=-100.0, maximum=-1e-6, units='1/s^2',
                         description='reference model Am = [[0, 1], [am1, am2]] (paper: -0.1)',
                         admissible=(-1.0, -0.005), scale='log')
    am2: float = setting(-0.1, minimum=-100.0, maximum=-1e-6, units='1/s',
                         description='reference model Am = [[0, 1], [am1, am2]] (paper: -0.1)',
                         admissible=(-3.0, -0.05), scale='log')
    mass_low_ratio: float = setting(0.8, minimum=0.1, maximum=1.0, units='-',
                                    description='lightest train of the model box / nominal mass')
    mass_high_ratio: float = setting(1.2, minimum=1.0, maximum=10.0, units='-',
                                     description='heaviest train of the model box / nominal mass')
    davis_uncertainty: float = setting(0.3, minimum=0.0, maximum=0.9, units='-',
                                       description='relative half-width of the Davis '
                                                   'coefficients in the model box')
    grade_min_per_mille: float = setting(-20.0, minimum=-100.0, maximum=100.0,
                                         units='per mille', description='lowest equivalent '
                                         'grade (grade + curve + tunnel) of the model box')
    grade_max_per_mille: float = setting(35.0, minimum=-100.0, maximum=100.0,
                                         units='per mille', description='highest equivalent '
                                         'grade of the model box (covers the 30 per mille jump)')
    model_actuator_lag_s: float = setting(0.0, minimum=0.0, maximum=10.0, units='s',
                                          description='deviation (not in the paper, which has '
                                          'the force act at once): the identification models '
                                          'see the commanded force through a first-order lag '
                                          'of this time constant')
    model_actuator_dead_time_s: float = setting(0.0, minimum=0.0, maximum=5.0, units='s',
                                                description='deviation (not in the paper): ... '
                                                'and this dead time, in whole control periods')


def _initial_alpha(k: int):
    return setting(ALPHA_INITIAL, minimum=-10.0, maximum=10.0, units='-',
                   description=f'alpha_{k} at t = 0, initial convex-combination '
                               f'coefficient of model {k} (paper: 0.2; alpha_5 = 1 - the sum '
                               'of the four)')


def _identification_gain():
    return setting(0.1, minimum=0.0, maximum=1e6, units='-',
                   description='gamma of the adaptive identification models, Gamma = gamma '
                               'diag(box width^2) in the units of theta (not in the paper)',
                   admissible=(1e-4, 10.0), scale='log')


@dataclass(frozen=True)
class SecondLevelSettings(TanSettings):
    alpha_gain: float = setting(1.0, minimum=0.0, maximum=1e6, units='1/(m^2 s)',
                                description='Gamma_a of the convex-combination law (23) '
                                            '(paper: identity; 0 keeps the initial alpha: '
                                            'law (24) with fixed parameters)',
                                admissible=(1e-3, 1e3), scale='log')
    initial_alpha_1: float = _initial_alpha(1)
    initial_alpha_2: float = _initial_alpha(2)
    initial_alpha_3: float = _initial_alpha(3)
    initial_alpha_4: float = _initial_alpha(4)
    paper_freeze: bool = setting(False, minimum=0, maximum=1, units='-',
                                 description='run the printed (25): freeze alpha when '
                                             'sum alpha_k G_k <= 0, instead of projecting onto '
                                             'sum alpha_k G_k >= 1/M_max')


@dataclass(frozen=True)
class AdaptiveModelSettings(SecondLevelSettings):
    identification_gain: float = _identification_gain()


@dataclass(frozen=True)
class IndexSettings(TanSettings):
    index_instant: float = setting(1.0, minimum=0.0, maximum=1e6, units='1/m^2',
                                   description='c1: weight of |e_k|^2 now in the index J_k')
    index_memory: float = setting(1.0, minimum=0.0, maximum=1e6, units='1/(m^2 s)',
                                  description='c2: weight of the discounted integral of |e_k|^2 '
                                              '(only c2/c1 matters: c1 is not tuned)',
                                  admissible=(1e-3, 1e3), scale='log')
    forgetting_per_s: float = setting(0.1, minimum=0.0, maximum=100.0, units='1/s',
                                      description='lambda: forgetting rate of the index memory',
                                      admissible=(0.01, 1.0), scale='log')
    adaptive_models: bool = setting(False, minimum=0, maximum=1, units='-',
                                    description='the five models adapt their parameters (the '
                                                'law of tan_second_level_adaptive) instead of '
                                                'staying fixed: a reading of Section 4.3')
    identification_gain: float = _identification_gain()


@dataclass(frozen=True)
class SwitchingSettings(IndexSettings):
    hysteresis: float = setting(0.1, minimum=0.0, maximum=0.99, units='-',
                                description='switch only to a model whose index is lower by '
                                            'this fraction', admissible=(0.01, 0.5), scale='log')


@dataclass(frozen=True)
class WeightedSettings(IndexSettings):
    weight_floor: float = setting(1e-3, minimum=0.0, maximum=0.19, units='-',
                                  description='lowest weight of a model (lets it come back)',
                                  admissible=(1e-4, 0.1), scale='log')
    adaptive_models: bool = setting(True, minimum=0, maximum=1, units='-',
                                    description='the five models adapt their parameters (the '
                                                'law of tan_second_level_adaptive; Section '
                                                '4.3: all four methods start their models '
                                                'from the same values); false: fixed corner '
                                                'models, onto one of which the weights lock')


def model_box(train, s: TanSettings) -> tuple[np.ndarray, np.ndarray]:
    """(theta_min, theta_max) in R^4, theta = (1/M, a + g sin(grade), b, c) per kg."""
    mass = train.nominal_mass_kg
    a, b, c = train.nominal_davis.per_kg(mass)
    low, high = 1.0 - s.davis_uncertainty, 1.0 + s.davis_uncertainty
    g = units.STANDARD_GRAVITY
    grades = sorted((s.grade_min_per_mille, s.grade_max_per_mille))
    theta_min = np.array([1.0 / (s.mass_high_ratio * mass),
                          a * low + g * units.per_mille_to_sine(grades[0]), b * low, c * low])
    theta_max = np.array([1.0 / (s.mass_low_ratio * mass),
                          a * high + g * units.per_mille_to_sine(grades[1]), b * high, c * high])
    return theta_min, theta_max


def corner_simplex(theta_min: np.ndarray, theta_max: np.ndarray) -> np.ndarray:
    """Five parameter vectors (rows) whose convex hull contains the box: theta_5 = theta_min,
    theta_k = theta_min + 4 (theta_max - theta_min)_k e_k (docs/papers/tan_jiang_chen.md)."""
    thetas = np.tile(theta_min, (MODELS, 1))
    for k in range(MODELS - 1):
        thetas[k, k] += (MODELS - 1) * (theta_max[k] - theta_min[k])
    return thetas


class IdentificationBank:
    """The five identification models (17), advanced together and exactly over one period.
    Plain floats inside: five 2-state models are cheaper in Python than in small numpy arrays."""

    def __init__(self, am1: float, am2: float, dt: float, thetas: np.ndarray):
        self.am1, self.am2, self.dt = am1, am2, dt
        self.thetas = thetas
        am = np.array([[0.0, 1.0], [am1, am2]])
        # exp of the augmented matrix gives Phi = e^(Am dt) and, for the B column, the ZOH and
        # FOH input matrices: int_0^dt e^(Am s) ds B and int_0^dt e^(Am (dt - s)) (s/dt) ds B
        augmented = np.zeros((4, 4))
        augmented[:2, :2] = am * dt
        augmented[:2, 2] = (0.0, dt)
        augmented[2, 3] = 1.0
        blocks = expm(augmented)
        self._phi = blocks[:2, :2].tolist()
        hold, ramp = blocks[:2, 2], blocks[:2, 3]
        self._zoh = (hold - ramp).tolist()   # weight of the input at the start of the period
        self._ramp = ramp.tolist()           # weight of the input at its end
        self._states = [(0.0, 0.0)] * MODELS

    @property
    def thetas(self) -> np.ndarray:
        """One row (theta_G, theta_Z1, theta_Z2, theta_Z3) per model."""
        return np.array(self._thetas)

    @thetas.setter
    def thetas(self, values) -> None:
        self._thetas = [tuple(float(x) for x in row) for row in values]

    def parameter_rows(self) -> list[tuple[float, ...]]:
        return self._thetas

    def model_gains(self) -> list[float]:
        """G_k = theta_Gk of each model."""
        return [row[0] for row in self._thetas]

    @property
    def xhat(self) -> np.ndarray:
        return np.array(self._states)

    def reset(self, x: tuple[float, float]) -> None:
        self._states = [(float(x[0]), float(x[1]))] * MODELS          # xhat_k(0) = x(0)

    def advance(self, x_start, x_end, force: float) -> None:
        """(17) over one period: u held, x and Z_k(v) linear between the two samples."""
        (p00, p01), (p10, p11) = self._phi
        z0, z1 = self._zoh
        r0, r1 = self._ramp
        s0, v0 = x_start
        s1, v1 = x_end
        base0 = -self.am1 * s0 - self.am2 * v0        # (A - Am) x, second row
        base1 = -self.am1 * s1 - self.am2 * v1
        states = []
        for (s, v), (g, a, b, c) in zip(self._states, self._thetas):
            w0 = base0 + g * force - a - b * v0 - c * v0 * v0     # + B [G_k u + Z_k], (16)
            w1 = base1 + g * force - a - b * v1 - c * v1 * v1
            states.append((p00 * s + p01 * v + z0 * w0 + r0 * w1,
                           p10 * s + p11 * v + z1 * w0 + r1 * w1))
        self._states = states

    def error_rows(self, x) -> list[tuple[float, float]]:
        s, v = x
        return [(sk - s, vk - v) for sk, vk in self._states]          # e_k = xhat_k - x

    def errors(self, x) -> np.ndarray:
        return np.array(self.error_rows(x))


class _MultipleModelLaw(ControlLaw):
    """The share of the four laws: the bank of five models on (s, v, u) and the controller (24)
    of a parameter vector. Subclasses update their weights from the identification errors."""

    requires = ('position', 'speed')

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self._build()

    def update_settings(self, settings) -> None:
        rebuild = any(getattr(settings, f) != getattr(self.settings, f)
                      for f in ('am1', 'am2', 'mass_low_ratio', 'mass_high_ratio',
                                'davis_uncertainty', 'grade_min_per_mille', 'grade_max_per_mille',
                                'model_actuator_lag_s', 'model_actuator_dead_time_s'))
        super().update_settings(settings)
        if rebuild:   # other models: they start again from the next measured state
            self._build()

    def _build(self) -> None:
        s = self.settings
        self.theta_min, self.theta_max = model_box(self.train, s)
        self.initial_thetas = corner_simplex(self.theta_min, self.theta_max)
        self.bank = IdentificationBank(s.am1, s.am2, self.dt, self.initial_thetas)
        self.g_min = float(self.theta_min[0])          # 1/M_max
        am = np.array([[0.0, 1.0], [s.am1, s.am2]])
        p = solve_continuous_lyapunov(am.T, -np.eye(2))       # Am^T P + P Am = -I
        self._pb = p[:, 1].tolist()                            # P B
        self._gamma = ((self.theta_max - self.theta_min) ** 2).tolist()
        self._last_x = None
        self._last_time = None
        self._last_force = 0.0
        self._delay_periods = round(s.model_actuator_dead_time_s / self.dt)
        lag = s.model_actuator_lag_s
        decay = math.exp(-self.dt / lag) if lag > 0.0 else 0.0
        # the lag's output over a period with its input held: end = u + (F0 - u) decay, mean =
        # u + (F0 - u) mean_weight
        self._lag = (decay, lag / self.dt * (1.0 - decay) if lag > 0.0 else 0.0)
        self._start_actuator_model(0.0)
        self._start_weights()

    def _start_actuator_model(self, force: float) -> None:
        self._asked = deque([force] * self._delay_periods)   # the dead time's commands
        self._acting = force                                 # the lag's output

    def reset(self, measurement, reference, last_force_n):
        self.bank.thetas = self.initial_thetas.copy()
        self._last_x = None
        self._last_force = 0.0 if last_force_n is None else last_force_n
        self._start_actuator_model(self._last_force)
        self._start_weights()

    def step(self, measurement, reference):
        x = (measurement.position, measurement.speed)
        if self._last_x is not None and \
                abs(measurement.time_s - self._last_time - self.dt) <= 0.5 * self.dt:
            self.bank.advance(self._last_x, x, self._last_force)
        else:
            # first step, or a gap (a held command): (re)start the models from the measured
            # state, as Lemma 3 requires identical initial conditions
            self.bank.reset(x)
        errors = self.bank.error_rows(x)
        if not all(math.isfinite(e) for row in errors for e in row):
            self.bank.reset(x)   # overflow on absurd input: restart rather than poison
            errors = self.bank.error_rows(x)
        self._update(errors, x)
        force, estimates = self._control(x, reference)
        self._last_x, self._last_time, self._last_force = x, measurement.time_s, force
        return LawOutput(force, estimates)

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        # the models see the force the plant gets (the host's bumpless offset included), the
        # paper's way at once, or through the model actuator (the mean over the coming period)
        force = commanded_n if applied_n is None else applied_n
        if self._delay_periods:
            self._asked.append(force)
            force = self._asked.popleft()
        decay, mean_weight = self._lag
        if decay:
            start = self._acting
            self._acting = force + (start - force) * decay
            force += (start - force) * mean_weight
        self._last_force = force

    def feedback_gains(self) -> FeedbackGains:
        # (24) at the nominal train (G_hat = 1/M_nom, Z_hat = Z): F / M = -am1 e_x - am2 e_v
        s = self.settings
        return FeedbackGains(-s.am1, -s.am2, 0.0, 'control (24) with the identification and '
                             'the weights frozen at the nominal train (G_hat = 1/M_nom)')

    def _controller(self, x, reference, theta, g_floor: float) -> float:
        """(24) for one parameter vector: u = (k1*^T x + k2* r - Z) / G, written with the
        tracking error to avoid cancelling am1 s against am1 s* (s is up to 1e5 m here):
        k1*^T x + bm r = am1 (s - s*) + am2 (v - v*) + v*'."""
        s = self.settings
        v = x[1]
        model_z = -theta[1] - theta[2] * v - theta[3] * v * v        # Z = phi_Z^T theta_Z
        wanted = (s.am1 * (x[0] - reference.position) + s.am2 * (v - reference.speed)
                  + reference.acceleration)
        return (wanted - model_z) / max(theta[0], g_floor)                     # (24)

    def _estimates(self, theta) -> dict[str, float]:
        return {'mass_hat_kg': 1.0 / max(theta[0], 1e-3 * self.g_min),
                'resistance_a_hat_mps2': float(theta[1]), 'resistance_b_hat_per_s': float(theta[2]),
                'resistance_c_hat_per_m': float(theta[3])}

    def _adapt_models(self, errors, x) -> None:
        """Adaptive identification models (Narendra & Han): theta_k' = -Gamma omega B^T P e_k,
        omega = (u, phi_Z), Gamma = identification_gain diag(box width^2), at the new errors
        (forward Euler)."""
        v = x[1]
        omega = (self._last_force, -1.0, -v, -v * v)
        step = self.dt * self.settings.identification_gain
        scaled = [step * g * w for g, w in zip(self._gamma, omega)]
        pb0, pb1 = self._pb
        rows = []
        for (e0, e1), row in zip(errors, self.bank.parameter_rows()):
            drive = pb0 * e0 + pb1 * e1                                  # B^T P e_k
            rows.append(tuple(t - drive * c for t, c in zip(row, scaled)))
        if all(math.isfinite(t) for row in rows for t in row):
            self.bank.thetas = rows   # (overflow on absurd input: keep the last parameters)

    @abstractmethod
    def _start_weights(self) -> None:
        """Set the method's weights (or index) to their initial values."""

    @abstractmethod
    def _update(self, errors: list[tuple[float, float]], x) -> None:
        """One control period of the method's weight (or index) update from the models'
        identification errors."""

    @abstractmethod
    def _control(self, x, reference) -> tuple[float, dict[str, float]]:
        """The force wanted now and the estimates to report."""


class SecondLevelFixedLaw(_MultipleModelLaw):
    name = 'tan_second_level'
    paper = 'tan_jiang_chen'
    summary = ('Tan, Jiang & Chen: second-level adaptation over five fixed identification '
               'models (17), convex-combination law (23) with projection (25), control (24)')
    Settings = SecondLevelSettings

    def _start_weights(self) -> None:
        s = self.settings                                    # alpha_1..4; alpha_5 = 1 - sum
        self.alpha = np.array([s.initial_alpha_1, s.initial_alpha_2, s.initial_alpha_3,
                               s.initial_alpha_4])
        self._combined_error = 0.0

    def alphas(self) -> np.ndarray:
        return np.array(self._alpha_list())

    def _alpha_list(self) -> list[float]:
        alpha = self.alpha.tolist()
        return alpha + [1.0 - sum(alpha)]                          # alpha_5 = 1 - sum

    def _update(self, errors, x) -> None:
        s = self.settings
        step = self.dt * s.alpha_gain
        p5, v5 = errors[MODELS - 1]
        columns = [(p - p5, v - v5) for p, v in errors[:MODELS - 1]]   # E = [e_k - e_5], 2 x 4
        h0, h1 = -p5, -v5                                                # h = -e_5
        # (23) alpha' = -Gamma_a E^T (E alpha - h), backward Euler (stiff, see module doc):
        # (I + step E^T E) alpha_new = alpha + step E^T h, solved through the 2 x 2 system
        # I + step E E^T (Woodbury identity; E^T E has rank 2, det(I + step E E^T) >= 1)
        rhs = [a + step * (c0 * h0 + c1 * h1) for a, (c0, c1) in zip(self.alpha.tolist(), columns)]
        e00 = sum(c0 * c0 for c0, _ in columns)
        e11 = sum(c1 * c1 for _, c1 in columns)
        e01 = sum(c0 * c1 for c0, c1 in columns)
        i00, i11, i01 = 1.0 + step * e00, 1.0 + step * e11, step * e01
        y0 = sum(c0 * r for (c0, _), r in zip(columns, rhs))
        y1 = sum(c1 * r for (_, c1), r in zip(columns, rhs))
        # det = 1 + step tr(E E^T) + step^2 det(E E^T), the last by Lagrange's identity so that
        # nearly parallel columns cannot cancel it below 1
        minors = [columns[i][0] * columns[j][1] - columns[j][0] * columns[i][1]
                  for i in range(MODELS - 1) for j in range(i + 1, MODELS - 1)]
        gram = sum(m * m for m in minors)
        determinant = 1.0 + step * (e00 + e11) + step * step * gram
        if not (math.isfinite(determinant) and math.isfinite(y0) and math.isfinite(y1)):
            return   # overflow on absurd input: keep the last combination
        q0 = (i11 * y0 - i01 * y1) / determinant
        q1 = (i00 * y1 - i01 * y0) / determinant
        alpha = [r - step * (c0 * q0 + c1 * q1) for r, (c0, c1) in zip(rhs, columns)]
        if not all(math.isfinite(a) for a in alpha):
            return   # overflow on absurd input: keep the last combination
        gains = self.bank.model_gains()
        direction = [g - gains[MODELS - 1] for g in gains[:MODELS - 1]]
        # sum alpha_k G_k = G_5 + direction . alpha_1..4
        total = gains[MODELS - 1] + sum(d * a for d, a in zip(direction, alpha))
        if s.paper_freeze:
            before = gains[MODELS - 1] + sum(d * a for d, a in zip(direction, self.alpha.tolist()))
            if before <= 0.0 or total <= 0.0:
                return                                # (25) as printed: alpha' = 0
        elif total < self.g_min:
            norm = sum(d * d for d in direction)
            if norm > 0.0:
                # [FIX] (25): Euclidean projection onto sum alpha_k G_k >= G_min
                shift = (self.g_min - total) / norm
                alpha = [a + shift * d for a, d in zip(alpha, direction)]
        self.alpha = np.array(alpha)
        weights = alpha + [1.0 - sum(alpha)]
        combined = math.hypot(sum(w * e[0] for w, e in zip(weights, errors)),
                              sum(w * e[1] for w, e in zip(weights, errors)))   # (20)
        self._combined_error = combined if math.isfinite(combined) else sys.float_info.max

    def _control(self, x, reference):
        alphas = self._alpha_list()
        rows = self.bank.parameter_rows()
        theta = [sum(a * row[i] for a, row in zip(alphas, rows)) for i in range(4)]
        # sum alpha_k theta_k gives sum alpha_k G_k and sum alpha_k Z_k of (24)
        force = self._controller(x, reference, theta, 1e-3 * self.g_min)
        estimates = {f'alpha_{k + 1}': a for k, a in enumerate(alphas)}
        estimates.update(self._estimates(theta))
        estimates['combined_identification_error_m'] = self._combined_error
        return force, estimates


class SecondLevelAdaptiveLaw(SecondLevelFixedLaw):
    name = 'tan_second_level_adaptive'
    paper = 'tan_jiang_chen'
    summary = ('Second-level adaptation with adaptive identification models (Narendra & Han), '
               'the comparison method (2) of Tan et al. Section 4.3')
    Settings = AdaptiveModelSettings

    def _update(self, errors, x) -> None:
        # identification models first, then the combination as for fixed models
        self._adapt_models(errors, x)
        super()._update(errors, x)


class _IndexedLaw(_MultipleModelLaw):
    """Laws that rank the fixed models by the performance index J_k."""

    def _start_weights(self) -> None:
        self.memory = [0.0] * MODELS

    def _indices(self, errors) -> list[float]:
        s = self.settings
        decay = math.exp(-s.forgetting_per_s * self.dt)
        squared = [p * p + v * v for p, v in errors]                       # |e_k|^2
        memory = [m * decay + self.dt * q for m, q in zip(self.memory, squared)]
        index = [s.index_instant * q + s.index_memory * m for q, m in zip(squared, memory)]
        if not all(math.isfinite(j) for j in index):   # overflow on absurd input: start again
            self.memory = [0.0] * MODELS
            return [0.0] * MODELS
        self.memory = memory
        return index


class SwitchingMultipleModelLaw(_IndexedLaw):
    name = 'tan_switching_mm'
    paper = 'tan_jiang_chen'
    summary = ('Switching multiple-model adaptive control (Narendra & Balakrishnan) over the '
               'five fixed models, comparison method (3) of Tan et al.')
    Settings = SwitchingSettings

    def _start_weights(self) -> None:
        super()._start_weights()
        self.selected = MODELS - 1      # start on theta_min (no index yet to choose by)

    def _update(self, errors, x) -> None:
        if self.settings.adaptive_models:
            self._adapt_models(errors, x)
        index = self._indices(errors)
        best = min(range(MODELS), key=index.__getitem__)
        if index[best] < (1.0 - self.settings.hysteresis) * index[self.selected]:
            self.selected = best

    def _control(self, x, reference):
        theta = self.bank.parameter_rows()[self.selected]
        force = self._controller(x, reference, theta, 1e-3 * self.g_min)
        estimates = {'selected_model': float(self.selected + 1)}
        estimates.update(self._estimates(theta))
        return force, estimates


class WeightedMultipleModelLaw(_IndexedLaw):
    name = 'tan_weighted_mm'
    paper = 'tan_jiang_chen'
    summary = ('Classical weighted multiple-model adaptive control over the five fixed models, '
               'comparison method (4) of Tan et al.')
    Settings = WeightedSettings

    def _start_weights(self) -> None:
        super()._start_weights()
        self.weights = [1.0 / MODELS] * MODELS

    def _update(self, errors, x) -> None:
        if self.settings.adaptive_models:
            self._adapt_models(errors, x)
        index = self._indices(errors)
        total = sum(index)
        if total <= 0.0:
            return                      # no information yet (all models agree)
        weights = [w * (1.0 - j / total) for w, j in zip(self.weights, index)]   # w_k l_k
        norm = sum(weights)
        if not norm > 0.0:
            return
        weights = [max(w / norm, self.settings.weight_floor) for w in weights]
        norm = sum(weights)
        self.weights = [w / norm for w in weights]

    def _control(self, x, reference):
        rows = self.bank.parameter_rows()
        floor = 1e-3 * self.g_min
        force = sum(w * self._controller(x, reference, theta, floor)
                    for w, theta in zip(self.weights, rows))                 # sum w_k u_k
        estimates = {f'weight_{k + 1}': w for k, w in enumerate(self.weights)}
        estimates.update(self._estimates(
            [sum(w * row[i] for w, row in zip(self.weights, rows)) for i in range(4)]))
        return force, estimates
