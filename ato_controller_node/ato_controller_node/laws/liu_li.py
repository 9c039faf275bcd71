"""Liu & Li 2020: RBF neural-network adaptive speed observer (12)-(21) and sliding-mode RBF
controller with adaptive robust bounds (22)-(35); output feedback from the position only.

[REC] RECONSTRUCTION. The paper's displayed equations were lost in extraction; every equation
below is the reconstruction of docs/papers/liu_li.md (plant, observer, controller), built from the
surviving prose, the equation numbering and numerical checks against Tables 2-4. Equation
numbers refer to that reconstruction. Lumped specific resistance f = (f_r + f_a - d)/M.

Observer, errors s_t = s - s_hat, v_t = v - v_hat (11):
    s_hat' = v_hat + k1 s_t                                                  (12)
    v_hat' = u/M0 - W1_hat^T S1(Z1_hat) + k2 s_t + D1                         (12), (16)
    S1_j(Z) = exp(-||Z - c1_j||^2 / b1^2)                                    (15)
    W1_hat' = -Gamma1 (S1 s_t + sigma1 (W1_hat - W1_0))                      (18)-(19)
    D1 = rho1_hat tanh(s_t/eps1)                                            (20)
    rho1_hat' = gamma1 (s_t tanh(s_t/eps1) - kappa1 (rho1_hat - rho1_0))     (21)
Controller:
    e1 = s - s_d, e2 = v_hat - v_d (22);  r = e2 + lambda e1 (23)
    u = -K r - W2_hat^T S2(Z2_hat) - D2                                      (31)
    W2_hat' = Gamma2 (S2 r - sigma2 (W2_hat - W2_0))                         (32)
    D2 = rho2_hat tanh(r/eps2)                                              (34)
    rho2_hat' = gamma2 (r tanh(r/eps2) - kappa2 (rho2_hat - rho2_0))         (35)

Choices of the reconstruction (docs/papers/liu_li.md, design parameters and ambiguities, [REC]):
- NN1 input Z1 = v_hat / speed_scale, 11 centres evenly on [-1, 1] (the 1-D option: the
  on-board law does not know the line's additional resistance a_add(s) of the 3-D option; the
  reconstruction normalises to "about [-1, 1]": packed on [0, 1] the nodes overlap so much that
  the weight loop of Values 7 and 9 is unstable, k1 k2 < Gamma1 sum S1^2);
  NN2 input Z2 = (v_hat / speed_scale, v_d' / accel_scale), 6 x 5 centres on [0, 1] x [-1, 1];
- a-priori values W1_0, W2_0, rho1_0, rho2_0 = 0; initial weights 0; s_hat, v_hat start from
  the measured position and the measured speed (else the reference speed);
- M0 = the nominal mass of the train the law is told.

Sampled implementation (a deviation the paper, simulated in continuous time, does not need):
- the observer is integrated over each control period with the commanded force held and the
  position innovation s_t of the last sample held (continuous-discrete observer), by
  semi-implicit Euler (v_hat first) in fixed internal steps of at most observer_step_s. Its
  discrete error dynamics are stable only if k1 dt is well under 2, so the law refuses a control
  period longer than max_k1_period / k1 (Value 10, k1 = 140 1/s: 7 ms at the default 1.0);
- the weight and bound laws (19), (21), (32), (35) are integrated exactly over a step with
  their drive held (exponential leakage): forward Euler goes unstable once rate x leakage x dt
  > 2 (Gamma2 sigma2 = 200 1/s with the recommended values: at 20 Hz);
- while the command is saturated, (32) and (35) run only when they move the command back
  toward the limit (directional freezing: no wind-up, and no lock-up in saturation); the
  observer keeps running on the force actually commanded;
- the measured speed is never used (``requires = ('position',)``): the law runs with a failed
  speed sensor and reports its observed speed as ``speed_hat_mps``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ato_controller_node.laws.base import ControlLaw, FeedbackGains, LawOutput, setting


def leaky_step(x, rate: float, drive, leak: float, dt: float):
    """x after dt of x' = rate (drive - leak x) with the drive held: the exact solution, stable
    for any dt (forward Euler is unstable once rate leak dt > 2, e.g. Gamma2 sigma2 = 200 1/s at
    20 Hz). Works on floats and numpy arrays."""
    decay = rate * leak * dt
    if decay == 0.0:
        return x + rate * dt * drive
    kept = math.exp(-decay)
    return x * kept + drive * ((1.0 - kept) / leak)


def _bounded(z: float) -> float:
    """A normalised NN input clipped to [-10, 10]: every Gaussian node is 0 beyond, and an
    absurd input must not overflow the square."""
    return max(-10.0, min(10.0, z))


NN1_CENTRES = np.linspace(-1.0, 1.0, 11)                                  # m = 11 nodes
_G1, _G2 = np.meshgrid(np.linspace(0.0, 1.0, 6), np.linspace(-1.0, 1.0, 5), indexing='ij')
NN2_CENTRES = np.column_stack([_G1.ravel(), _G2.ravel()])                   # q = 30 nodes


@dataclass(frozen=True)
class LiuLiSettings:
    # Table 2, Value 10 (the Case-3 set) [SRC values, NUM row-to-symbol mapping]
    k1: float = setting(140.0, minimum=1e-4, maximum=1e4, units='1/s',
                        description='observer gain on s_t in s_hat\' (Table 2 row 1, Value 10)')
    k2: float = setting(35.0, minimum=1e-4, maximum=1e5, units='1/s^2',
                        description='observer gain on s_t in v_hat\' (Table 2 row 2, Value 10)')
    Gamma1: float = setting(175.0, minimum=0.0, maximum=1e6, units='1/s^3',
                            description='NN1 learning rate (Table 2 row 3, Value 10)')
    lam: float = setting(28.0, minimum=1e-4, maximum=1e3, units='1/s',
                         description='filtered-error slope lambda (Table 2 row 4, Value 10)')
    K: float = setting(3.115e6, minimum=0.0, maximum=1e9, units='N s/m',
                       description='filtered-error gain K (Table 2 row 5, Value 10)')
    # The eight designed parameters the paper fixes but lost: docs/papers/liu_li.md [REC]
    b1: float = setting(0.15, minimum=1e-3, maximum=10.0, units='-',
                        description='NN1 RBF width (normalised input) [REC]')
    b2: float = setting(0.35, minimum=1e-3, maximum=10.0, units='-',
                        description='NN2 RBF width (normalised inputs) [REC]')
    sigma1: float = setting(1e-3, minimum=0.0, maximum=10.0, units='s^2',
                            description='NN1 sigma-modification leakage [REC]')
    sigma2: float = setting(1e-3, minimum=0.0, maximum=10.0, units='m/(N s)',
                            description='NN2 sigma-modification leakage [REC]')
    gamma1: float = setting(0.0, minimum=0.0, maximum=1e3, units='1/s^3',
                            description='observer robust-bound learning rate '
                                        '(docs/papers/liu_li.md: 0 to 1e-3; larger values kill '
                                        'the Case-1 trend) [REC]')
    eps1: float = setting(1.0, minimum=1e-6, maximum=1e3, units='m',
                          description='observer tanh width [REC]')
    kappa1: float = setting(0.1, minimum=0.0, maximum=10.0, units='s^2',
                            description='observer robust-bound leakage [REC]')
    Gamma2: float = setting(2e5, minimum=0.0, maximum=1e9, units='N/m',
                            description='NN2 learning rate (force units) [REC]')
    gamma2: float = setting(1e4, minimum=0.0, maximum=1e9, units='N/m',
                            description='controller robust-bound learning rate [REC]')
    eps2: float = setting(0.1, minimum=1e-6, maximum=100.0, units='m/s',
                          description='controller tanh width [REC]')
    kappa2: float = setting(0.01, minimum=0.0, maximum=100.0, units='m/(N s)',
                            description='controller robust-bound leakage [REC]')
    speed_scale_mps: float = setting(100.0, minimum=1.0, maximum=1000.0, units='m/s',
                                     description='speed that normalises the NN inputs to ~[0, 1]')
    accel_scale_mps2: float = setting(0.3, minimum=0.01, maximum=10.0, units='m/s^2',
                                      description='reference acceleration that normalises the NN2 '
                                                  'input to ~[-1, 1]')
    observer_step_s: float = setting(1e-3, minimum=1e-5, maximum=0.1, units='s',
                                     description='longest internal step of the observer')
    max_k1_period: float = setting(1.0, minimum=0.01, maximum=2.0, units='-',
                                   description='largest k1 x control period accepted (the sampled '
                                               'observer is unstable near 2)')
    error_from_estimate: bool = setting(False, minimum=0, maximum=1, units='-',
                                        description='e1 = s_hat - s_d instead of s - s_d (the '
                                                    'alternative reading of (22) in '
                                                    'docs/papers/liu_li.md) [REC]')


class LiuLiLaw(ControlLaw):
    name = 'liu_li'
    paper = 'liu_li'
    summary = ('Liu & Li 2020 [REC]: RBF-NN adaptive speed observer from position and '
               'sliding-mode RBF controller with adaptive robust bounds (output feedback)')
    Settings = LiuLiSettings
    requires = ('position',)

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self.mass = train.nominal_mass_kg        # M0
        self._initialise(0.0, 0.0)

    def fits(self, train, measured_cars=None):
        reason = super().fits(train, measured_cars)
        limit = self.settings.max_k1_period / self.settings.k1
        if reason is None and self.dt > limit * (1.0 + 1e-9):
            reason = (f'{self.name}: the observer gain k1 = {self.settings.k1:g} 1/s needs a '
                      f'control period of at most {limit:.3g} s (got {self.dt:g} s); raise the '
                      'controller rate or lower k1')
        return reason

    def _initialise(self, position: float, speed: float) -> None:
        self.s_hat, self.v_hat = position, speed
        self.w1 = np.zeros(len(NN1_CENTRES))
        self.w2 = np.zeros(len(NN2_CENTRES))
        self.rho1 = self.rho2 = 0.0
        self._pending = None

    def feedback_gains(self) -> FeedbackGains:
        # (31) with the observer exact (v_hat = v), NN2 and D2 at their initial 0:
        # F = -K r = K (e_v + lambda e_x)
        s = self.settings
        return FeedbackGains(s.K * s.lam / self.mass, s.K / self.mass, 0.0,
                             'control (31) with the observer taken as exact and the networks '
                             'and robust terms at their initial zero')

    def reset(self, measurement, reference, last_force_n):
        speed = measurement.speed if math.isfinite(measurement.speed) else reference.speed
        self._initialise(measurement.position, speed)

    def _s1(self, v_hat: float) -> np.ndarray:
        z = _bounded(v_hat / self.settings.speed_scale_mps)
        return np.exp(-((z - NN1_CENTRES) ** 2) / self.settings.b1 ** 2)          # (15)

    def _s2(self, v_hat: float, ref_accel: float) -> np.ndarray:
        s = self.settings
        d = NN2_CENTRES - (_bounded(v_hat / s.speed_scale_mps),
                           _bounded(ref_accel / s.accel_scale_mps2))
        return np.exp(-np.einsum('ij,ij->i', d, d) / s.b2 ** 2)                   # (15) for NN2

    def step(self, measurement, reference):
        s = self.settings
        s_tilde = measurement.position - self.s_hat                                # (11)
        e1 = (self.s_hat if s.error_from_estimate else measurement.position) - reference.position
        e2 = self.v_hat - reference.speed                                          # (22)
        r = e2 + s.lam * e1                                                        # (23)
        s2 = self._s2(self.v_hat, reference.acceleration)
        d2 = self.rho2 * math.tanh(r / s.eps2)                                     # (34)
        force = -s.K * r - float(self.w2 @ s2) - d2                                # (31)
        self._pending = (s_tilde, r, s2)
        return LawOutput(force, {
            'speed_hat_mps': self.v_hat, 'position_hat_m': self.s_hat,
            'position_innovation_m': s_tilde, 'filtered_error_mps': r,
            'resistance_hat_mps2': float(self.w1 @ self._s1(self.v_hat)),
            'rho1_hat': self.rho1, 'rho2_hat_n': self.rho2})

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        if self._pending is None:
            return
        s_tilde, r, s2 = self._pending
        self._pending = None
        s, dt = self.settings, self.dt
        excess = wanted_n - commanded_n
        # Both updates move u by about -(positive) * r: under saturation, adapt only if that
        # brings u back toward the limit (directional freezing; a full freeze can lock the law
        # in saturation with weights it can no longer unlearn).
        if abs(excess) <= 1e-9 * max(1.0, abs(wanted_n)) or excess * r > 0.0:
            self.w2 = leaky_step(self.w2, s.Gamma2, s2 * r, s.sigma2, dt)           # (32), W2_0 = 0
            self.rho2 = leaky_step(self.rho2, s.gamma2, r * math.tanh(r / s.eps2),  # (35)
                                   s.kappa2, dt)
        # the observer integrates the force the plant gets (the bumpless offset included)
        self._observe(commanded_n if applied_n is None else applied_n, s_tilde)

    def _observe(self, force_n: float, s_tilde: float) -> None:
        """Integrate the observer over one control period: force and innovation held."""
        s = self.settings
        steps = max(1, math.ceil(self.dt / s.observer_step_s - 1e-9))
        h = self.dt / steps
        specific_force = force_n / self.mass
        switch = math.tanh(s_tilde / s.eps1)
        d1 = self.rho1 * switch                                                    # (20)
        for _ in range(steps):
            s1 = self._s1(self.v_hat)
            self.v_hat += h * (specific_force - float(self.w1 @ s1) + s.k2 * s_tilde + d1)  # (12)
            self.s_hat += h * (self.v_hat + s.k1 * s_tilde)                        # (12)
            self.w1 = leaky_step(self.w1, s.Gamma1, -s1 * s_tilde, s.sigma1, h)     # (19), W1_0 = 0
        self.rho1 = leaky_step(self.rho1, s.gamma1, s_tilde * switch, s.kappa1, self.dt)  # (21)
