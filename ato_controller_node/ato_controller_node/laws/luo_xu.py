"""Luo & Xu, direct adaptive backstepping, Theorem 1.

Plant (eq 3): x1' = x2, x2' = u/m - theta^T phi(x2), theta = (c0, cv, ca) per kg,
phi = (1, x2, x2^2). Both the mass m and theta are unknown and estimated.

    z1 = x1 - x*,   z2 = x2 - x*' + c1 z1                                   (backstepping errors)
    varphi = (c1^2 - 1) z1 - (c1 + c2) z2 + x*''                            [FIX, see below]
    u = m_hat (theta_hat^T phi + varphi)                                    (12)
    theta_hat' = -Gamma phi z2,   m_hat' = -gamma (theta_hat^T phi + varphi) z2    (16)

[FIX] The paper's varphi omits the "-1" in the z1 term; then V2' keeps a +z1 z2 cross term and
is negative definite only if 4 c1 c2 > 1, which its own c1 = c2 = 0.1 violate. With the fix
V2' = -c1 z1^2 - c2 z2^2 (shared/papers/README.md, paper 000). ``paper_as_printed`` runs the
printed law.

Deviations, all for a sampled, saturating implementation:
- the adaptive laws (16) are integrated with forward Euler at the control period;
- adaptation is frozen while the command is saturated (the error then no longer reflects the
  parameter error, and integrating it winds the estimates up);
- m_hat is projected onto [mass_min_ratio, mass_max_ratio] x nominal mass (the paper does not,
  but a non-positive mass estimate would reverse the control direction).
- Gamma and gamma are given in SI (theta per kg, m in kg); the paper's Gamma = diag(1e4, 1, 0.01)
  is tied to its unit choice, so the defaults are retuned as the notes recommend
  (Gamma_ii ~ theta_i / (phi_i z2 T_adapt)); gamma keeps the paper's 1e5.
"""

from __future__ import annotations

from dataclasses import dataclass

from ato_controller_node.laws.base import ControlLaw, LawOutput, setting


@dataclass(frozen=True)
class LuoXuSettings:
    c1: float = setting(0.1, minimum=1e-4, maximum=10.0, units='1/s',
                        description='backstepping gain of the position error (paper: 0.1)')
    c2: float = setting(0.1, minimum=1e-4, maximum=10.0, units='1/s',
                        description='backstepping gain of z2 (paper: 0.1)')
    gamma_mass: float = setting(1e5, minimum=0.0, maximum=1e9, units='kg s^2/m^2',
                                description='adaptation gain gamma of the mass estimate (paper: 1e5)')
    gamma_c0: float = setting(1e-3, minimum=0.0, maximum=1.0, units='1/s^2',
                              description='adaptation gain Gamma_11 of c0 (retuned for SI)')
    gamma_cv: float = setting(3e-7, minimum=0.0, maximum=1.0, units='1/m^2',
                              description='adaptation gain Gamma_22 of cv (retuned for SI)')
    gamma_ca: float = setting(3e-10, minimum=0.0, maximum=1.0, units='s^2/m^4',
                              description='adaptation gain Gamma_33 of ca (retuned for SI)')
    mass_min_ratio: float = setting(0.7, minimum=0.1, maximum=1.0, units='-',
                                    description='lower bound of m_hat over the nominal mass')
    mass_max_ratio: float = setting(1.5, minimum=1.0, maximum=10.0, units='-',
                                    description='upper bound of m_hat over the nominal mass')
    paper_as_printed: bool = setting(False, minimum=0, maximum=1, units='-',
                                     description='use the printed varphi without the -z1 fix')


class LuoXuLaw(ControlLaw):
    name = 'luo_xu'
    summary = 'Luo & Xu Theorem 1: direct adaptive backstepping estimating m and (c0, cv, ca)'
    Settings = LuoXuSettings

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self._start_from_prior()
        self._pending = None

    def _start_from_prior(self) -> None:
        self.mass_hat = self.train.nominal_mass_kg
        self.theta_hat = list(self.train.nominal_davis.per_kg(self.train.nominal_mass_kg))

    def reset(self, measurement, reference, last_force_n):
        # The estimates start from the on-board prior; the host's bumpless offset bridges the
        # difference between the last command and this law's first one.
        self._start_from_prior()
        self._pending = None

    def step(self, measurement, reference):
        s = self.settings
        v = measurement.speed
        z1 = measurement.position - reference.position
        z2 = v - reference.speed + s.c1 * z1
        z1_gain = s.c1 * s.c1 if s.paper_as_printed else s.c1 * s.c1 - 1.0
        varphi = z1_gain * z1 - (s.c1 + s.c2) * z2 + reference.acceleration
        phi = (1.0, v, v * v)
        th = self.theta_hat
        specific = th[0] * phi[0] + th[1] * phi[1] + th[2] * phi[2] + varphi
        force = self.mass_hat * specific                                           # (12)
        self._pending = (phi, z2, specific)
        return LawOutput(force, {'mass_hat_kg': self.mass_hat, 'c0_hat_mps2': th[0],
                                 'cv_hat_per_s': th[1], 'ca_hat_per_m': th[2],
                                 'z1_m': z1, 'z2_mps': z2})

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=()):
        if self._pending is None:
            return
        phi, z2, specific = self._pending
        self._pending = None
        if abs(wanted_n - commanded_n) > 1e-9 * max(1.0, abs(wanted_n)):
            return  # frozen under saturation
        s, dt = self.settings, self.dt
        gains = (s.gamma_c0, s.gamma_cv, s.gamma_ca)
        self.theta_hat = [th - dt * g * p * z2 for th, g, p in zip(self.theta_hat, gains, phi)]  # (16)
        nominal = self.train.nominal_mass_kg
        mass = self.mass_hat - dt * s.gamma_mass * specific * z2                              # (16)
        self.mass_hat = min(max(mass, s.mass_min_ratio * nominal), s.mass_max_ratio * nominal)
