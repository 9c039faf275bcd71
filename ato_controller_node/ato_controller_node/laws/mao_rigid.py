"""Mao, Tao, Jiang & Yan at onboard rates: the rigid-coupler (singular-perturbation) reduction of
their 4-car design, adaptive, on the whole unit's force split by mass.

Why a reduction. The feedback linearisation (17)-(18), (60), (71) of ``mao_multibody`` cancels
the coupler zero at -k1/d1 = -1e4 1/s, so as a sampled law it needs periods under about 1e-4 s
(docs/papers/mao_multibody.md). The couplers are the fast subsystem: with k = 6e8 - 8e8 N/m
their modes are at 15 - 36 Hz and the extensions settle, within a few hundredths of a second,
at the quasi-static values that carry each car's share of the acceleration. Letting the
coupler compliance 1/k go to zero in (1)-(6) (the slow manifold of the singular perturbation)
leaves one rigid body, the unit, with the mass-weighted speed v of its cars:

    M v' = F2 + F3 - sum_p M_p (a_p + b_p v) - M1 c1 v^2 - (line force),   M = sum_p M_p
    v' = Phi(v) + F/theta_M,   Phi = -(theta_a + theta_b v + theta_c v^2),
    theta = (M, sum M_p a_p / M (+ the line's specific force), sum M_p b_p / M, M1 c1 / M)

This is the structure of the paper's relative-degree-1 loop (16), (71)-(74), and the same
design applies to it, with v for y2 = x6:

    nu = v_m' - alpha (v - v_m)                                            as (55)
    F = theta_M_hat (nu - Phi_hat) - beta sat(e / width),  e = v - v_m     as (71)
    theta_M_hat' = -gamma_M (nu - Phi_hat) e,   theta_i_hat' = -gamma_i phi_i e,
    phi = (1, v, v^2)                                                       as (74)

With tildes estimate minus true and rho = 1/M, e' + alpha e = rho theta_M_t (nu - Phi_hat) +
theta_t^T phi - rho beta sat(e/width), and V = e^2/2 + rho theta_M_t^2/(2 gamma_M) +
sum_i theta_i_t^2/(2 gamma_i) has V' = -alpha e^2 - rho beta e sat(e/width) <= 0 (as (76)).
The unknown line force (grade, curve, tunnel: the law does not know the line) is a slowly
varying part of theta_a, which the adaptation follows.

Force split (the fast subsystem). The unit's force F is shared by mass: car 2 carries cars 1
and 2, car 3 carries cars 3 and 4, F2 = F (M1 + M2)/M, F3 = F (M3 + M4)/M, so that the
coupler between the powered cars carries no internal force at quasi-static extension (the
mode the paper leaves unregulated). Saturation-aware: when one share exceeds its actuator's
limit, the other car takes the rest up to its own limit, so the unit's force is kept as long
as it can be; the coupler then carries the difference, which is bounded.

Sampled implementation (period dt, 10 - 100 Hz): the adaptive law by forward Euler, frozen
while the unit's force F is not what the actuators are commanded (the error then no longer
reflects the parameter error): the split limits the shares itself, so the law gives the host
its unlimited F (``LawOutput.unlimited_force_n``) and freezes when the host's commanded total
differs from it;
theta_M_hat projected onto [mass_min_ratio, mass_max_ratio] x nominal so that the control
direction cannot reverse. The loop's pole is e' = -alpha e: forward Euler is stable for
alpha dt < 2 (alpha <= max_alpha_dt / dt is checked by ``fits``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ato_controller_node.laws.base import ControlLaw, FeedbackGains, LawOutput, setting

CARS = 4


@dataclass(frozen=True)
class MaoRigidSettings:
    alpha: float = setting(1.0, minimum=1e-3, maximum=100.0, units='1/s',
                           description='alpha of nu = v_m\' - alpha (v - v_m), as alpha3 of '
                                       '(55) (paper: not reported)')
    beta: float = setting(1000.0, minimum=0.0, maximum=1e6, units='N',
                          description='beta of the robust term, as beta2 of (71)')
    boundary_width: float = setting(0.01, minimum=1e-9, maximum=100.0, units='m/s',
                                    description='boundary layer of sat(e / width) (the paper '
                                                'suggests one against chattering)')
    gamma_mass: float = setting(1e6, minimum=0.0, maximum=1e14, units='kg s^2/m^2',
                                description='gamma_M of the mass estimate theta_M_hat')
    gamma_a: float = setting(0.25, minimum=0.0, maximum=1e3, units='1/s^2',
                             description='gamma_a of the constant resistance (and the line '
                                         'force) per kg')
    gamma_b: float = setting(1e-4, minimum=0.0, maximum=1e3, units='1/m^2',
                             description='gamma_b of the linear resistance per kg')
    gamma_c: float = setting(1e-8, minimum=0.0, maximum=1e3, units='s^2/m^4',
                             description='gamma_c of the aerodynamic resistance per kg')
    initial_estimate_ratio: float = setting(0.95, minimum=0.1, maximum=10.0, units='-',
                                            description='initial estimates over the nominal '
                                                        'values (paper: 0.95)')
    mass_min_ratio: float = setting(0.5, minimum=0.01, maximum=1.0, units='-',
                                    description='lower bound of theta_M_hat over nominal')
    mass_max_ratio: float = setting(2.0, minimum=1.0, maximum=100.0, units='-',
                                    description='upper bound of theta_M_hat over nominal')


def rigid_parameters(train) -> tuple[float, float, float, float]:
    """theta = (M, a, b, c) of the rigid unit from the nominal per-car data."""
    if len(train.cars) != CARS:
        raise ValueError(f'the rigid reduction of Mao et al. needs a 4-car train, got '
                         f'{len(train.cars)} cars')
    mass = sum(c.mass_kg for c in train.cars)
    return (mass, sum(c.a_mps2 * c.mass_kg for c in train.cars) / mass,
            sum(c.b_per_s * c.mass_kg for c in train.cars) / mass,
            sum(c.c_per_m * c.mass_kg for c in train.cars) / mass)


def split_by_mass(force: float, share2: float, limits2: tuple[float, float],
                  limits3: tuple[float, float]) -> tuple[float, float]:
    """(F2, F3): ``share2`` of ``force`` on car 2, the rest on car 3; a share beyond its
    actuator's limits goes to the other car, up to that car's own limits."""
    f2 = min(max(force * share2, limits2[0]), limits2[1])
    f3 = min(max(force - f2, limits3[0]), limits3[1])
    f2 = min(max(force - f3, limits2[0]), limits2[1])   # car 3 saturated: car 2 takes the rest
    return f2, f3


class MaoRigidLaw(ControlLaw):
    """The rigid-coupler reduction of Mao et al.'s adaptive design, for 10 - 100 Hz."""

    name = 'mao_multibody_rigid'
    paper = 'mao_multibody'
    summary = ('Mao, Tao, Jiang & Yan at onboard rates: rigid-coupler (singular-perturbation) '
               'reduction, adaptive as (71)-(74) on the unit, force split by mass to cars 2, 3')
    Settings = MaoRigidSettings
    actuators = 2
    cars = CARS
    requires = ('car_speeds',)

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self._start_from_prior()

    def fits(self, train, measured_cars=None):
        reason = super().fits(train, measured_cars)
        if reason is None and not (train.cars[1].powered and train.cars[2].powered):
            reason = f'{self.name} needs traction on cars 2 and 3'
        if reason is None and self.settings.alpha * self.dt >= 1.0:
            reason = (f'{self.name}: alpha dt = {self.settings.alpha * self.dt:g} must be below '
                      '1 (the sampled loop e\' = -alpha e; lower alpha or raise the rate)')
        return reason

    def _start_from_prior(self) -> None:
        if len(self.train.cars) != CARS:
            self.nominal: tuple[float, ...] = ()
            self.theta_hat: list[float] = []
            self._share2 = 0.5
        else:
            self.nominal = rigid_parameters(self.train)
            self.theta_hat = [self.settings.initial_estimate_ratio * t for t in self.nominal]
            masses = [c.mass_kg for c in self.train.cars]
            self._share2 = (masses[0] + masses[1]) / sum(masses)
        self._pending = None

    def update_settings(self, settings):
        ratio_changed = settings.initial_estimate_ratio != self.settings.initial_estimate_ratio
        super().update_settings(settings)
        if ratio_changed:
            self._start_from_prior()

    def feedback_gains(self) -> FeedbackGains:
        # F = M_hat (v_m' - alpha e - Phi_hat) - beta e / width inside the boundary layer
        s = self.settings
        nominal = sum(c.mass_kg for c in self.train.cars) or self.train.nominal_mass_kg
        return FeedbackGains(0.0, s.initial_estimate_ratio * s.alpha
                             + s.beta / (s.boundary_width * nominal), 0.0,
                             'speed loop (55), (71) of the rigid unit, adaptation frozen at the '
                             'initial estimates, inside the boundary layer')

    def reset(self, measurement, reference, last_force_n):
        # the estimates restart from the prior; the host's bumpless offset bridges the step
        self._start_from_prior()

    def step(self, measurement, reference):
        s = self.settings
        masses = [c.mass_kg for c in self.train.cars]
        speed = math.fsum(m * v for m, v in zip(masses, measurement.car_speeds)) / sum(masses)
        mass_hat, a_hat, b_hat, c_hat = self.theta_hat
        e = speed - reference.speed
        # as (55), with the reference's mean acceleration over the coming period (the force is
        # held for dt): v_m' + v_m'' dt / 2
        nu = reference.acceleration + 0.5 * self.dt * reference.jerk - s.alpha * e
        phi_hat = -(a_hat + b_hat * speed + c_hat * speed * speed)
        robust = -s.beta * max(-1.0, min(1.0, e / s.boundary_width))
        force = mass_hat * (nu - phi_hat) + robust                                 # as (71)
        limits = self.train.actuator_limits_at(speed)
        forces = split_by_mass(force, self._share2, limits, limits)
        self._pending = (nu - phi_hat, speed, e)
        estimates = {'e_mps': e, 'mass_hat_kg': mass_hat, 'resistance_a_hat_mps2': a_hat,
                     'resistance_b_hat_per_s': b_hat, 'resistance_c_hat_per_m': c_hat}
        return LawOutput(math.fsum(forces), estimates, forces, unlimited_force_n=force)

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        if self._pending is None:
            return
        regressor, speed, e = self._pending
        self._pending = None
        if abs(wanted_n - commanded_n) > 1e-9 * max(1.0, abs(wanted_n)):
            return  # frozen while the unit does not get the force F it wanted
        s, dt = self.settings, self.dt
        mass_hat, a_hat, b_hat, c_hat = self.theta_hat
        mass_hat -= dt * s.gamma_mass * regressor * e                              # as (74)
        a_hat -= dt * s.gamma_a * e
        b_hat -= dt * s.gamma_b * speed * e
        c_hat -= dt * s.gamma_c * speed * speed * e
        nominal_mass = self.nominal[0]
        mass_hat = min(max(mass_hat, s.mass_min_ratio * nominal_mass),
                       s.mass_max_ratio * nominal_mass)
        self.theta_hat = [mass_hat, a_hat, b_hat, c_hat]
