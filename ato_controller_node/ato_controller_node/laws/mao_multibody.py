"""Mao, Tao, Jiang & Yan: feedback-linearising control of the 4-car multibody train.

Plant (eqs 7-8): cars 1..4 joined by spring-damper couplers, traction on cars 2 and 3, state
x = [z1, z1', x3, z2', x5, z3', x7, z4'] with the coupler extensions x3, x5, x7 (the suite's car
positions are the cars' own, so x3 = z1 - z2 - car length). Outputs y1 = x2 (speed of car 1,
relative degree 2 through F2) and y2 = x6 (speed of car 3, relative degree 1 through F3).
Per-kg coefficients d_pq = d_p/M_q, k_pq = k_p/M_q, m_p = 1/M_p, a_p, b_p, c1.

Input-output form (15)-(16), corrected as in docs/papers/mao_multibody.md [FIX]:
    y1'' = Phi1(x) + F2/theta11,   y2' = Phi2(x) + F3/theta21
    Phi1 = th12 x2 - th13 x2' - 2 th14 x2 x2' + th15 x3 - th16 x4 - th17 x5 + th18 x6 - th19
    Phi2 = th22 x4 + th23 x5 - th24 x6 - th25 x7 + th26 x8 - th27
    theta (57)-(58), (68)-(69): th11 = 1/(d11 m2), th12 = d11 d12 - k11, th13 = d11 + b1,
    th14 = c1, th15 = d11 k12, th16 = d11 (d12 + d22 + b2) - k11, th17 = d11 k22,
    th18 = d11 d22, th19 = d11 a2; th21 = 1/m3, th22 = d23, th23 = k23,
    th24 = d23 + d33 + b3, th25 = k33, th26 = d33, th27 = a3.

Nominal (known parameters): F2 = th11 (nu2 - Phi1) (17), F3 = th21 (nu3 - Phi2) (18),
    nu2 = v_m'' - alpha1 (x2' - v_m') - alpha2 (x2 - v_m)   (51)
    nu3 = v_m' - alpha3 (x6 - v_m)                          (55)
Adaptive (unknown parameters, estimates Theta1_hat, Theta2_hat):
    F2 = th11_hat (nu2 - Phi1_hat) + nu2_bar                (60)
    nu2_bar = -beta1 sign(eps), eps = p12 e2 + p22 e2'      (65),  e2 = x2 - v_m
    Theta1_hat' = -Gamma1 W1 eps                            (64)
    W1 = [nu2 - Phi1_hat, -x2, x2', 2 x2 x2', -x3, x4, x5, -x6, +1]
    F3 = th21_hat (nu3 - Phi2_hat) - beta2 sign(e6)         (71),  e6 = x6 - v_m
    Theta2_hat' = -Gamma2 W2 e6                             (74)
    W2 = [nu3 - Phi2_hat, -x4, -x5, x6, x7, -x8, +1]

[FIX] (docs/papers/mao_multibody.md), each undone by ``paper_as_printed``:
- the constants a2, a3 enter (15)-(16) with the physical sign "-" (the paper prints "+d11 a2",
  "+a3", i.e. (17), (18), (60), (71) add +th19, +th27 and the regressors end in -1);
- (69) prints th27 = a4; it is a3, the constant of car 3's equation;
- the first regressor entries are nu - Phi_hat (the paper writes F2 and F3_hat, a
  state-dependent rescaling that breaks the Lyapunov argument);
- W1 entry 4 is 2 x2 x2' (printed x2 x2'), W2 entry 3 is -x5 (printed +x5).

Deviations for a sampled, saturating implementation (documented in README.md):
- optional boundary layer: sign(s) -> sat(s / width) (the paper's own suggestion, Section VI),
  default on;
- the adaptive laws are integrated by forward Euler at the control period and frozen while an
  actuator is saturated (the error then no longer reflects the parameter error);
- th11_hat and th21_hat (the input gains, mass-like) are projected onto
  [gain_min_ratio, gain_max_ratio] x nominal so that the control direction cannot reverse;
- the car-1 acceleration x2' is the measured one (the paper: "measurable", Section III-A).

Adaptation gains (:data:`GAIN_PRESETS`). The paper's Gamma1 = 2 I9, Gamma2 = 2 I7 are numbers in
its unit system; the default, preset ``paper``, converts them to SI by
:func:`ato_common.units.mao_multibody_adaptation_gains_to_si` for Table II's tonnes with m and s
(forces in kN): gamma11 = gamma21 = 2000 (the input gains th11 [t s], th21 [t] carry a mass),
every per-unit-mass entry 2. Preset ``unscaled_si``: 2 everywhere in SI (the suite's earlier
reading). docs/papers/mao_multibody.md gives the alternatives and why this one.

Option (suite, not in the paper): regulation of the internal force (``regulate_internal_force``).
The paper's zero dynamics keep a zero eigenvalue: x3 + x5 = z1 - z3 - 2 L, whose derivative is
v1 - v3, is not regulated, so the extension of the coupler between the powered cars (the force
they hold against each other) drifts with the history of v1 - v3. With the option, the second
output is
    y2 = x6 - kappa (x3 + x5 - X*),   X* = x3* + x5*  (the quasi-static extension)
(relative degree 1 through F3 as x6), tracked as (55): y2' = nu3 with e6 = y2 - v_m, i.e.
    y2' = Phi2 + F3/th21 - kappa (x2 - x6) + kappa X*'
    F3 = th21 (nu3 + kappa (x2 - x6) - kappa X*' - Phi2)              as (18), (71)
and the adaptive law (74) with that nu3 in W2[0] and that e6 (the Lyapunov argument of (75)-(76)
is unchanged: the added terms are known). Then s = x3 + x5 - X* obeys
s' = e2 - (y2 - v_m) - kappa s: it decays at kappa once the outputs track. X* is the extension
at rigid motion with the reference's acceleration A = v_m' and speed v_m, for the split of the
unit's force F = M A + sum R_p that the actuators can give (saturation-aware: the mass split of
``mao_rigid.split_by_mass``, a share beyond one actuator's limits moved to the other):
x3* = -(M1 A + R1)/k1, x5* = (F2* - (M1 + M2) A - R1 - R2)/k2 (the law does not know the line;
a grade acts in proportion to mass, which the mass split already carries). X*' is the
derivative along the reference (a central difference with v_m''). The commanded forces are
allocated saturation-aware as well: a force beyond one actuator's limits goes to the other car,
up to its own limits; the adaptation freezes whenever the commanded forces differ from the
loops'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ato_common import units
from ato_common.knowledge import TrainKnowledge
from ato_common.types import ReferencePoint
from ato_controller_node.laws.base import (
    ControlLaw,
    FeedbackGains,
    LawOutput,
    Measurement,
    setting,
)
from ato_controller_node.laws.mao_rigid import split_by_mass

CARS = 4

#: the paper's Gamma1 = 2 I9, Gamma2 = 2 I7 (Section VI) in SI, for Table II's tonnes with m, s
PAPER_GAMMA1, PAPER_GAMMA2 = units.mao_multibody_adaptation_gains_to_si(2.0, 2.0)
#: the gain presets: ``paper`` (the default of the settings) and ``unscaled_si`` (2 in SI for
#: every entry, the suite's earlier reading), e.g. ``run_offline(..., settings={
#: 'mao_multibody_adaptive': GAIN_PRESETS['unscaled_si']})``
GAIN_PRESETS = {
    'paper': {'gamma11': PAPER_GAMMA1[0], 'gamma1': PAPER_GAMMA1[1],
              'gamma21': PAPER_GAMMA2[0], 'gamma2': PAPER_GAMMA2[1]},
    'unscaled_si': {'gamma11': 2.0, 'gamma1': 2.0, 'gamma21': 2.0, 'gamma2': 2.0},
}


def _switch(value: float, width: float) -> float:
    """sign(value), or sat(value / width) for a boundary layer of this width (> 0)."""
    if width > 0.0:
        return max(-1.0, min(1.0, value / width))
    return math.copysign(1.0, value) if value != 0.0 else 0.0


def true_parameters(train: TrainKnowledge, as_printed: bool = False
                    ) -> tuple[list[float], list[float]]:
    """(Theta1, Theta2) of the train's per-car data (57)-(58), (68)-(69). ``as_printed``: th27
    = a4 as (69) prints [FIX]."""
    if len(train.cars) != CARS or len(train.couplers) != CARS - 1:
        raise ValueError(f'Mao et al. laws need a 4-car train with 3 couplers, got '
                         f'{len(train.cars)} cars and {len(train.couplers)} couplers')
    m = [c.mass_kg for c in train.cars]
    k = [c.stiffness_n_per_m for c in train.couplers]
    d = [c.damping_n_s_per_m for c in train.couplers]
    a = [c.a_mps2 for c in train.cars]
    b = [c.b_per_s for c in train.cars]
    c1 = train.cars[0].c_per_m
    d11, d12, d22, d23, d33 = d[0] / m[0], d[0] / m[1], d[1] / m[1], d[1] / m[2], d[2] / m[2]
    k11, k12, k22, k23, k33 = k[0] / m[0], k[0] / m[1], k[1] / m[1], k[1] / m[2], k[2] / m[2]
    m2 = 1.0 / m[1]
    theta1 = [1.0 / (d11 * m2), d11 * d12 - k11, d11 + b[0], c1, d11 * k12,          # (57)
              d11 * (d12 + d22 + b[1]) - k11, d11 * k22, d11 * d22, d11 * a[1]]       # (58)
    theta2 = [m[2], d23, k23, d23 + d33 + b[2], k33, d33, a[3] if as_printed else a[2]]  # (68)-(69)
    return theta1, theta2


@dataclass(frozen=True)
class MaoState:
    """x of eq 7 (x3, x5, x7 = coupler extensions) and the measured acceleration x2'."""

    x: tuple[float, ...]
    x2_dot: float

    @classmethod
    def of(cls, m: Measurement, car_length_m: float) -> 'MaoState':
        z, v = m.car_positions, m.car_speeds
        return cls((z[0], v[0], z[0] - z[1] - car_length_m, v[1], z[1] - z[2] - car_length_m,
                    v[2], z[2] - z[3] - car_length_m, v[3]), m.acceleration)


def phi_regressors(s: MaoState, as_printed: bool) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The state functions multiplying th12..th19 in Phi1 and th22..th27 in Phi2 (signs
    included), so Phi1 = sum th1k w1k and Phi2 = sum th2k w2k. The constant's sign: physical
    "-" [FIX], printed "+"."""
    _, x2, x3, x4, x5, x6, x7, x8 = s.x
    xd = s.x2_dot
    const = 1.0 if as_printed else -1.0
    w1 = (x2, -xd, -2.0 * x2 * xd, x3, -x4, -x5, x6, const)
    w2 = (x4, x5, -x6, -x7, x8, const)
    return w1, w2


def nu_signals(s: MaoState, r: ReferencePoint, settings) -> tuple[float, ...]:
    """(nu2, nu3, e2, e2', e6) with (51) and (55); v_m = reference speed, v_m' its
    acceleration, v_m'' its jerk."""
    e2 = s.x[1] - r.speed
    e2_dot = s.x2_dot - r.acceleration
    e6 = s.x[5] - r.speed
    nu2 = r.jerk - settings.alpha1 * e2_dot - settings.alpha2 * e2                    # (51)
    nu3 = r.acceleration - settings.alpha3 * e6                                       # (55)
    return nu2, nu3, e2, e2_dot, e6


def quasi_static_extension(train: TrainKnowledge, speed: float, acceleration: float) -> float:
    """X* = x3* + x5*: the extension of couplers 1 and 2 at rigid motion of the unit with this
    acceleration and speed, when the unit's force F = M A + sum R_p is split between cars 2 and
    3 as the actuators can give it (the mass split, a share beyond one actuator's limits moved
    to the other: ``mao_rigid.split_by_mass``). From (1)-(3) with equal speeds (no damper
    force): car 1, M1 A = -k1 x3 - R1; cars 1 and 2, (M1 + M2) A = F2 - k2 x5 - R1 - R2."""
    cars, couplers = train.cars, train.couplers
    masses = [c.mass_kg for c in cars]
    resistances = [c.mass_kg * (c.a_mps2 + c.b_per_s * speed + c.c_per_m * speed * speed)
                   for c in cars]
    total = sum(masses) * acceleration + math.fsum(resistances)
    limits = train.actuator_limits_at(speed)
    f2, _ = split_by_mass(total, (masses[0] + masses[1]) / sum(masses), limits, limits)
    x3 = -(masses[0] * acceleration + resistances[0]) / couplers[0].stiffness_n_per_m
    x5 = (f2 - (masses[0] + masses[1]) * acceleration - resistances[0] - resistances[1]) \
        / couplers[1].stiffness_n_per_m
    return x3 + x5


def allocate(f2: float, f3: float, limits: tuple[float, float]) -> tuple[float, float]:
    """Saturation-aware allocation of the loops' forces: what one actuator cannot give beyond
    its limits goes to the other car, up to that car's own limits (the unit's force is kept as
    long as it can be)."""
    lowest, highest = limits
    c2, c3 = min(max(f2, lowest), highest), min(max(f3, lowest), highest)
    return (min(max(c2 + (f3 - c3), lowest), highest),
            min(max(c3 + (f2 - c2), lowest), highest))


#: the step of the central difference of X* along the reference [s]
_X_STAR_STEP_S = 1e-2


def internal_regulation(train: TrainKnowledge, s: MaoState, r: ReferencePoint,
                        kappa: float) -> tuple[float, float, float]:
    """(y2 - x6, the terms added to nu3, x3 + x5 - X*) of the regulated second output
    y2 = x6 - kappa (x3 + x5 - X*): y2' = x6' - kappa (x2 - x6) + kappa X*', so nu3 gains
    kappa (x2 - x6) - kappa X*' (see the module's docstring). X*' is the central difference of
    X*(v_m, v_m') along the reference (v_m' and v_m'' as slopes)."""
    h = _X_STAR_STEP_S
    deviation = s.x[2] + s.x[4] - quasi_static_extension(train, r.speed, r.acceleration)
    x_star_rate = (quasi_static_extension(train, r.speed + h * r.acceleration,
                                          r.acceleration + h * r.jerk)
                   - quasi_static_extension(train, r.speed - h * r.acceleration,
                                            r.acceleration - h * r.jerk)) / (2.0 * h)
    return -kappa * deviation, kappa * (s.x[1] - s.x[5]) - kappa * x_star_rate, deviation


def _regulation_settings():
    return (setting(False, minimum=0, maximum=1, units='-',
                    description='regulate the internal force between the powered cars: '
                                'second output y2 = v3 - kappa (x3 + x5 - X*), X* the '
                                'quasi-static extension, saturation-aware allocation (suite '
                                'option; the paper leaves that mode unregulated)'),
            setting(1.0, minimum=1e-3, maximum=100.0, units='1/s',
                    description='kappa of y2 = v3 - kappa (x3 + x5 - X*): the rate at which '
                                'x3 + x5 returns to X*'))


_ALPHAS = {
    'alpha1': ('1/s', 'alpha1 of (51) (not reported; docs/papers/mao_multibody.md: 1; > 0.5 '
                      'for p12 = 2, p22 = 4)'),
    'alpha2': ('1/s^2', 'alpha2 of (51) (not reported; docs/papers/mao_multibody.md: 1)'),
    'alpha3': ('1/s', 'alpha3 of (55) (not reported; docs/papers/mao_multibody.md: 1)'),
}


def _alpha(name: str):
    units, description = _ALPHAS[name]
    return setting(1.0, minimum=1e-3, maximum=100.0, units=units, description=description)


def _max_period():
    return setting(1e-4, minimum=1e-6, maximum=1.0, units='s',
                   description='longest control period accepted: sampled with a zero-order hold '
                               'the feedback linearisation is unstable above ~1e-4 s (it cancels '
                               'the coupler zero at -k1/d1 = -1e4 1/s); raise only to experiment')


@dataclass(frozen=True)
class MaoNominalSettings:
    alpha1: float = _alpha('alpha1')
    alpha2: float = _alpha('alpha2')
    alpha3: float = _alpha('alpha3')
    max_control_period_s: float = _max_period()
    paper_as_printed: bool = setting(False, minimum=0, maximum=1, units='-',
                                     description='printed (17)-(18): +d11 a2 and +a3 instead of '
                                                 'the physical -d11 a2, -a3 [FIX]')
    regulate_internal_force: bool = _regulation_settings()[0]
    kappa: float = _regulation_settings()[1]


class _MaoBase(ControlLaw):
    actuators = 2
    cars = CARS
    requires = ('car_positions', 'car_speeds', 'acceleration')

    def fits(self, train, measured_cars=None):
        reason = super().fits(train, measured_cars)
        if reason is None and not (train.cars[1].powered and train.cars[2].powered):
            reason = f'{self.name} needs traction on cars 2 and 3'
        if reason is None and self.dt > self.settings.max_control_period_s * (1.0 + 1e-9):
            reason = (f'{self.name} needs a control period of at most '
                      f'{self.settings.max_control_period_s:g} s (got {self.dt:g} s): sampled '
                      'slower, the feedback linearisation is unstable (see README)')
        return reason

    def _state(self, m: Measurement) -> MaoState:
        return MaoState.of(m, self.train.car_length_m)

    def _second_output(self, state: MaoState, reference: ReferencePoint, nu3: float, e6: float
                       ) -> tuple[float, float, dict]:
        """(nu3, e6) of the second output: x6 as the paper, or with ``regulate_internal_force``
        y2 = x6 - kappa (x3 + x5 - X*) (see the module's docstring), and what to report."""
        s = self.settings
        if not s.regulate_internal_force:
            return nu3, e6, {}
        offset, nu_extra, deviation = internal_regulation(self.train, state, reference, s.kappa)
        e_y2 = e6 + offset
        # (55) for y2: nu3 = v_m' - alpha3 (y2 - v_m), plus the known terms of y2'
        return (reference.acceleration - s.alpha3 * e_y2 + nu_extra, e_y2,
                {'y2_error_mps': e_y2, 'internal_extension_error_m': deviation})

    def feedback_gains(self) -> FeedbackGains:
        # (51) on car 1's speed through F2 and the rigid unit: F' / M = -alpha1 e' - alpha2 e,
        # e = v - v_m, so F / M = alpha2 e_x + alpha1 e_v (the loop (55) of car 3 left out)
        s = self.settings
        return FeedbackGains(s.alpha2, s.alpha1, 0.0,
                             "approximate: the relative-degree-2 loop (51) of car 1's speed on "
                             'the rigid unit, the loop (55) of car 3 and the couplers left out')

    def _allocate(self, f2: float, f3: float, speed: float) -> tuple[float, float]:
        if not self.settings.regulate_internal_force:
            return f2, f3
        return allocate(f2, f3, self.train.actuator_limits_at(speed))

    def _parameters(self, as_printed: bool):
        """(Theta1, Theta2) of the train, or None for a train the law does not fit (the host
        builds a law before it asks ``fits``)."""
        if len(self.train.cars) != CARS or len(self.train.couplers) != CARS - 1:
            return None
        return true_parameters(self.train, as_printed)


class MaoNominalLaw(_MaoBase):
    """(17), (18) with (51), (55): exact feedback linearisation with the known parameters."""

    name = 'mao_multibody_nominal'
    paper = 'mao_multibody'
    summary = ('Mao, Tao, Jiang & Yan nominal feedback linearisation (17)-(18) of the 4-car '
               'train: speeds of cars 1 and 3 via forces on cars 2 and 3')
    Settings = MaoNominalSettings

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self.theta = self._parameters(self.settings.paper_as_printed)

    def update_settings(self, settings):
        super().update_settings(settings)
        self.theta = self._parameters(settings.paper_as_printed)

    def reset(self, measurement, reference, last_force_n):
        pass  # no state of its own

    def step(self, measurement, reference):
        s = self.settings
        printed = s.paper_as_printed
        theta1, theta2 = self.theta
        state = self._state(measurement)
        w1, w2 = phi_regressors(state, printed)
        phi1 = sum(t * w for t, w in zip(theta1[1:], w1))
        phi2 = sum(t * w for t, w in zip(theta2[1:], w2))
        nu2, nu3, e2, _, e6 = nu_signals(state, reference, s)
        nu3, _, reported = self._second_output(state, reference, nu3, e6)
        f2 = theta1[0] * (nu2 - phi1)                                                  # (17)
        f3 = theta2[0] * (nu3 - phi2)                                                  # (18)
        forces = self._allocate(f2, f3, state.x[5])
        return LawOutput(forces[0] + forces[1], {'e2_mps': e2, 'e6_mps': e6, **reported}, forces,
                         unlimited_force_n=f2 + f3)


@dataclass(frozen=True)
class MaoAdaptiveSettings:
    alpha1: float = _alpha('alpha1')
    alpha2: float = _alpha('alpha2')
    alpha3: float = _alpha('alpha3')
    max_control_period_s: float = _max_period()
    p12: float = setting(2.0, minimum=1e-6, maximum=1e6, units='-',
                         description='P entry p12 in eps = p12 e2 + p22 e2\' (paper: 2)')
    p22: float = setting(4.0, minimum=1e-6, maximum=1e6, units='s',
                         description='P entry p22 in eps (paper: 4)')
    gamma11: float = setting(PAPER_GAMMA1[0], minimum=0.0, maximum=1e12, units='kg s^4/m^2',
                             description='gamma11 of Gamma1 (64), for th11 (paper: 2 in t, m, '
                                         's, i.e. 2000 in SI; preset unscaled_si: 2)')
    gamma1: float = setting(PAPER_GAMMA1[1], minimum=0.0, maximum=1e9, units='SI',
                            description='gamma12 .. gamma19 of Gamma1 (64), per unit mass (paper: '
                                        '2, the same number in SI)')
    gamma21: float = setting(PAPER_GAMMA2[0], minimum=0.0, maximum=1e12, units='kg s^2/m^2',
                             description='gamma21 of Gamma2 (74), for th21 (paper: 2 in t, m, '
                                         's, i.e. 2000 in SI; preset unscaled_si: 2)')
    gamma2: float = setting(PAPER_GAMMA2[1], minimum=0.0, maximum=1e9, units='SI',
                            description='gamma22 .. gamma27 of Gamma2 (74), per unit mass (paper: '
                                        '2, the same number in SI)')
    beta1: float = setting(1000.0, minimum=0.0, maximum=1e6, units='N',
                           description='beta1 of (65) (not reported)')
    beta2: float = setting(1000.0, minimum=0.0, maximum=1e6, units='N',
                           description='beta2 of (71) (not reported)')
    boundary_layer: bool = setting(True, minimum=0, maximum=1, units='-',
                                   description='sat(s/width) instead of sign(s) in (65), (71) '
                                               '(the paper suggests it against chattering)')
    boundary_width1: float = setting(0.01, minimum=1e-9, maximum=100.0, units='m/s',
                                     description='boundary-layer width on eps of (65)')
    boundary_width2: float = setting(0.01, minimum=1e-9, maximum=100.0, units='m/s',
                                     description='boundary-layer width on e6 of (71)')
    initial_estimate_ratio: float = setting(0.95, minimum=0.1, maximum=10.0, units='-',
                                            description='initial estimates over the nominal '
                                                        'values (paper: 0.95)')
    gain_min_ratio: float = setting(0.2, minimum=0.01, maximum=1.0, units='-',
                                    description='lower bound of th11_hat, th21_hat over nominal')
    gain_max_ratio: float = setting(5.0, minimum=1.0, maximum=100.0, units='-',
                                    description='upper bound of th11_hat, th21_hat over nominal')
    paper_as_printed: bool = setting(False, minimum=0, maximum=1, units='-',
                                     description='printed regressors W1, W2 (F2, F3_hat, x2 x2\', '
                                                 '+x5, -1), +th19/+th27 and th27 = a4 [FIX]')
    regulate_internal_force: bool = _regulation_settings()[0]
    kappa: float = _regulation_settings()[1]


class MaoAdaptiveLaw(_MaoBase):
    """(60), (71) with (51), (55), (65) and the adaptive laws (64), (74)."""

    name = 'mao_multibody_adaptive'
    paper = 'mao_multibody'
    summary = ('Mao, Tao, Jiang & Yan adaptive feedback linearisation (60), (71), laws (64), '
               '(74): speeds of cars 1 and 3 via forces on cars 2 and 3')
    Settings = MaoAdaptiveSettings

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self._start_from_prior()

    def _start_from_prior(self) -> None:
        ratio = self.settings.initial_estimate_ratio
        nominal: tuple[tuple[float, ...], tuple[float, ...]] = \
            self._parameters(self.settings.paper_as_printed) or ((), ())
        self.nominal1, self.nominal2 = nominal
        self.theta1_hat = [ratio * t for t in self.nominal1]
        self.theta2_hat = [ratio * t for t in self.nominal2]
        self._pending = None

    def reset(self, measurement, reference, last_force_n):
        # The estimates restart from the prior; the host's bumpless offset bridges the step.
        self._start_from_prior()

    def update_settings(self, settings):
        printed_changed = settings.paper_as_printed != self.settings.paper_as_printed
        super().update_settings(settings)
        if printed_changed:
            self._start_from_prior()

    def step(self, measurement, reference):
        s = self.settings
        printed = s.paper_as_printed
        state = self._state(measurement)
        w1, w2 = phi_regressors(state, printed)
        th1, th2 = self.theta1_hat, self.theta2_hat
        phi1_hat = sum(t * w for t, w in zip(th1[1:], w1))
        phi2_hat = sum(t * w for t, w in zip(th2[1:], w2))
        nu2, nu3, e2, e2_dot, e6 = nu_signals(state, reference, s)
        nu3, e_y2, reported = self._second_output(state, reference, nu3, e6)
        eps = s.p12 * e2 + s.p22 * e2_dot
        nu2_bar = -s.beta1 * _switch(eps, s.boundary_width1 if s.boundary_layer else 0.0)  # (65)
        robust3 = -s.beta2 * _switch(e_y2, s.boundary_width2 if s.boundary_layer else 0.0)
        f2 = th1[0] * (nu2 - phi1_hat) + nu2_bar                                        # (60)
        f3 = th2[0] * (nu3 - phi2_hat) + robust3                                        # (71)
        # Regressors W1 of (61) and W2 of (73): the first entries multiply th11_t, th21_t.
        if printed:
            # As printed: F2 and F3_hat as first entries, x2 x2' (no 2), +x5 for th23_t.
            _, x2, x3, x4, x5, x6, x7, x8 = state.x
            xd = state.x2_dot
            reg1 = (f2, -x2, xd, x2 * xd, -x3, x4, x5, -x6, -1.0)
            reg2 = (f3, -x4, x5, x6, x7, -x8, -1.0)
        else:
            reg1 = (nu2 - phi1_hat, *(-w for w in w1))
            reg2 = (nu3 - phi2_hat, *(-w for w in w2))
        self._pending = (reg1, eps, reg2, e_y2, (f2, f3))
        estimates = {'e2_mps': e2, 'e6_mps': e6, 'eps_mps': eps, **reported}
        estimates.update({f'theta1{k + 1}_hat': t for k, t in enumerate(th1)})
        estimates.update({f'theta2{k + 1}_hat': t for k, t in enumerate(th2)})
        forces = self._allocate(f2, f3, state.x[5])
        return LawOutput(forces[0] + forces[1], estimates, forces, unlimited_force_n=f2 + f3)

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        if self._pending is None:
            return
        reg1, eps, reg2, e6, wanted = self._pending
        self._pending = None
        if any(abs(w - c) > 1e-9 * max(1.0, abs(w)) for w, c in zip(wanted, commanded_forces_n)):
            return  # frozen while an actuator is saturated
        s, dt = self.settings, self.dt
        gains1 = (s.gamma11,) + (s.gamma1,) * (len(reg1) - 1)   # Gamma1 = diag(gamma1q)
        gains2 = (s.gamma21,) + (s.gamma2,) * (len(reg2) - 1)   # Gamma2 = diag(gamma2q)
        self.theta1_hat = [t - dt * g * w * eps                                          # (64)
                           for t, g, w in zip(self.theta1_hat, gains1, reg1)]
        self.theta2_hat = [t - dt * g * w * e6                                           # (74)
                           for t, g, w in zip(self.theta2_hat, gains2, reg2)]
        for theta, nominal in ((self.theta1_hat, self.nominal1[0]),
                               (self.theta2_hat, self.nominal2[0])):
            theta[0] = min(max(theta[0], s.gain_min_ratio * nominal), s.gain_max_ratio * nominal)
