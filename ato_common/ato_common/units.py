"""SI units everywhere; the papers' units are converted here, once, by named functions.

The Chinese traction-calculation literature writes Davis coefficients per tonne of train mass
with the speed V in km/h (N/t, N/(t km/h), N/(t (km/h)^2)) or per kN of train weight (N/kN);
grades in per mille; masses in t; forces in kN; speeds in km/h.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    import numpy as np

STANDARD_GRAVITY = 9.80665  # m/s^2, used unless a paper fixes another g
KMH_PER_MPS = 3.6


def kmh_to_mps(speed_kmh: float) -> float:
    return speed_kmh / KMH_PER_MPS


def mps_to_kmh(speed_mps: float) -> float:
    return speed_mps * KMH_PER_MPS


def tonnes_to_kg(mass_t: float) -> float:
    return mass_t * 1000.0


def kn_to_n(force_kn: float) -> float:
    return force_kn * 1000.0


def kw_to_w(power_kw: float) -> float:
    return power_kw * 1000.0


#: an energy or an array of them (a cumulative energy, sample by sample)
Energy = TypeVar('Energy', float, 'np.ndarray')


def joules_to_kwh(energy_j: Energy) -> Energy:
    return energy_j / 3.6e6


def per_mille_to_sine(grade_per_mille: float) -> float:
    """Sine of the track angle for a grade given in per mille (rise per 1000 m of run)."""
    return math.sin(math.atan(grade_per_mille / 1000.0))


def davis_per_tonne_to_per_kg(a_n_per_t: float, b_n_per_t_kmh: float,
                              c_n_per_t_kmh2: float) -> tuple[float, float, float]:
    """Davis coefficients per tonne with V in km/h -> specific resistance per kg with v in m/s.

    Returns (a [m/s^2], b [1/s], c [1/m]) so that the resistance per kg is a + b v + c v^2.
    """
    return (a_n_per_t / 1000.0,
            b_n_per_t_kmh * KMH_PER_MPS / 1000.0,
            c_n_per_t_kmh2 * KMH_PER_MPS ** 2 / 1000.0)


def davis_per_kn_to_per_kg(a_n_per_kn: float, b_n_per_kn_kmh: float, c_n_per_kn_kmh2: float,
                           gravity: float = STANDARD_GRAVITY) -> tuple[float, float, float]:
    """Davis coefficients per kN of train weight with V in km/h -> per kg with v in m/s."""
    per_tonne = gravity  # 1 t weighs g kN, so N/kN * g = N/t
    return davis_per_tonne_to_per_kg(a_n_per_kn * per_tonne, b_n_per_kn_kmh * per_tonne,
                                     c_n_per_kn_kmh2 * per_tonne)


def davis_kn_kmh_to_n(a_kn: float, b_kn_per_kmh: float,
                      c_kn_per_kmh2: float) -> tuple[float, float, float]:
    """Whole-train Davis coefficients in kN with V in km/h -> N with v in m/s.

    Returns (a [N], b [N s/m], c [N s^2/m^2]) so that the resistance is a + b v + c v^2.
    """
    return (kn_to_n(a_kn), kn_to_n(b_kn_per_kmh) * KMH_PER_MPS,
            kn_to_n(c_kn_per_kmh2) * KMH_PER_MPS ** 2)


def davis_adaptation_gains_per_tonne_to_si(
        gamma_a: float, gamma_b: float, gamma_c: float) -> tuple[float, float, float]:
    """A diagonal adaptation gain Gamma of Davis coefficients per tonne with V in km/h (the
    gradient law theta' = -Gamma phi e of e.g. Luo & Xu (16)) -> the same law in SI.

    Derivation. The per-tonne coefficients theta_p = (a [N/t], b [N/(t km/h)], c [N/(t (km/h)^2)])
    and the SI ones theta = (a [m/s^2], b [1/s], c [1/m]) are related by theta = D theta_p with
    D = diag(1/1000, 3.6/1000, 3.6^2/1000) (:func:`davis_per_tonne_to_per_kg`). The regressor
    multiplies theta into an acceleration, theta_p^T phi_p = theta^T phi, so phi_p = D phi
    (phi = (1, v, v^2) with v in m/s, the errors e in SI, the mass in kg). Then

        theta' = D theta_p' = -D Gamma_p phi_p e = -(D Gamma_p D) phi e,

    i.e. Gamma = D Gamma_p D: each entry scales by D_ii^2 = (1e-6, 1.296e-5, 1.6796e-4). The
    Lyapunov term theta_t^T Gamma^-1 theta_t / 2 is then the same number in both unit systems,
    so the closed loop is the paper's, not a retuned one. Luo & Xu's diag(1e4, 1, 0.01) becomes
    diag(1e-2, 1.296e-5, 1.6796e-6).
    """
    scale = davis_per_tonne_to_per_kg(1.0, 1.0, 1.0)   # the diagonal of D
    return (gamma_a * scale[0] ** 2, gamma_b * scale[1] ** 2, gamma_c * scale[2] ** 2)


def mass_adaptation_gain_per_tonne_to_si(gamma: float) -> float:
    """The gain gamma of a mass estimate's gradient law m' = -gamma psi e (e.g. Luo & Xu (16):
    m_hat' = -gamma (theta_hat^T phi + varphi) z2) with the mass in tonnes -> the same law with
    the mass in kg (psi an acceleration and e a speed, both in SI, in either reading).

    Derivation. m = 1000 m_t, so m' = 1000 m_t' = -1000 gamma_t psi e: gamma = 1000 gamma_t.
    The Lyapunov term rho m_t^2 / (2 gamma) = m_tilde^2 / (2 m gamma) of Luo & Xu (17) is then
    the same number in both (10^6 m_tilde_t^2 / (2 10^3 m_t 10^3 gamma_t)). Luo & Xu's
    gamma = 1e5 (m in t) becomes 1e8 kg s^2/m^2.
    """
    return gamma * tonnes_to_kg(1.0)


def luo_xu_adaptation_gains_to_si(gamma: float, gamma_c0: float, gamma_cv: float,
                                  gamma_ca: float) -> tuple[float, float, float, float]:
    """Luo & Xu's Table 1 adaptation gains (gamma of m_hat, Gamma = diag(gamma_c0, gamma_cv,
    gamma_ca) of theta_hat, law (16)) -> (gamma [kg s^2/m^2], Gamma_11 [1/s^2], Gamma_22
    [1/m^2], Gamma_33 [s^2/m^4]) in SI.

    One reading for every gain: each gain acts on its estimate in the unit Table 1 gives that
    estimate, m in t and the resistance coefficients per tonne with V in km/h (N/t,
    N/(t km/h), N/(t (km/h)^2)); the errors z, the accelerations and time are SI (the paper's
    states and target curve are in m and m/s). Then gamma by
    :func:`mass_adaptation_gain_per_tonne_to_si` (x 1000) and Gamma by
    :func:`davis_adaptation_gains_per_tonne_to_si` (D Gamma D): every term of the Lyapunov
    function (17) is the same number in SI as in Table 1's units, so the adaptive loop is the
    paper's. Table 1's gamma = 1e5, Gamma = diag(1e4, 1, 0.01) become 1e8 and
    diag(1e-2, 1.296e-5, 1.6796e-6).
    """
    return (mass_adaptation_gain_per_tonne_to_si(gamma),
            *davis_adaptation_gains_per_tonne_to_si(gamma_c0, gamma_cv, gamma_ca))


def curvature_term_to_curve_radius_m(curvature_d: float, coefficient: float = 0.004,
                                     gravity: float = STANDARD_GRAVITY) -> float:
    """A curvature term written as a specific force ``coefficient * D`` [m/s^2] (Tan, Jiang &
    Chen (5)-(6): f_c = 0.004 D M, Table 1: D = 0.35) -> the radius R [m] of the constant curve
    that the suite's line model (curve resistance 600/R N/kN, ``ato_common.line``) turns into
    the same force.

    Derivation. The line model's curve force per kg is g w_c / 1000 with w_c = 600/R N/kN, so
    g 600 / (1000 R) = coefficient D, i.e. R = 0.6 g / (coefficient D). For D = 0.35:
    0.004 D = 1.4e-3 m/s^2 and R = 0.6 * 9.80665 / 1.4e-3 = 4202.85 m.
    """
    if not curvature_d > 0.0:
        raise ValueError(f'the curvature term D must be positive, got {curvature_d!r}')
    return 0.6 * gravity / (coefficient * curvature_d)


#: dimensions (mass, length, time exponents) of Mao, Tao, Jiang & Yan's parameters Theta1 of
#: (57)-(58) and Theta2 of (68)-(69), of their regressors W1 (after (61)) and W2 (after (73)),
#: and of the errors eps = p12 e2 + p22 e2' of (64) and e6 of (74)
MAO_MULTIBODY_THETA1_DIMENSIONS = ((1, 0, 1), (0, 0, -2), (0, 0, -1), (0, -1, 0), (0, 0, -3),
                                   (0, 0, -2), (0, 0, -3), (0, 0, -2), (0, 1, -3))
MAO_MULTIBODY_W1_DIMENSIONS = ((0, 1, -3), (0, 1, -1), (0, 1, -2), (0, 2, -3), (0, 1, 0),
                               (0, 1, -1), (0, 1, 0), (0, 1, -1), (0, 0, 0))
MAO_MULTIBODY_THETA2_DIMENSIONS = ((1, 0, 0), (0, 0, -1), (0, 0, -2), (0, 0, -1), (0, 0, -2),
                                   (0, 0, -1), (0, 1, -2))
MAO_MULTIBODY_W2_DIMENSIONS = ((0, 1, -2), (0, 1, -1), (0, 1, 0), (0, 1, -1), (0, 1, 0),
                               (0, 1, -1), (0, 0, 0))
MAO_MULTIBODY_ERROR_DIMENSIONS = (0, 1, -1)   # eps and e6: speeds (p12 is a number, p22 in s)


def adaptation_gain_to_si(gamma: float, theta: tuple[int, int, int],
                          regressor: tuple[int, int, int], error: tuple[int, int, int],
                          mass_unit_kg: float = 1.0, length_unit_m: float = 1.0,
                          time_unit_s: float = 1.0) -> float:
    """One diagonal entry gamma of a gradient adaptive law theta' = -gamma w e, given in a
    coherent unit system (mass, length and time units in kg, m and s) -> the same law in SI.

    Derivation. The law fixes the gain's unit: ``[gamma] = [theta] / ([w] [e] [t])``. A
    quantity of dimension M^a L^b T^c is ``mass_unit_kg^a length_unit_m^b time_unit_s^c`` times
    its number in SI, so with f(q) that factor, theta_SI = f(theta) theta_u, w_SI = f(w) w_u,
    e_SI = f(e) e_u and t_SI = f(T) t_u give

        theta_SI' = f(theta)/f(T) theta_u' = -f(theta)/f(T) gamma_u w_u e_u
                  = -[f(theta) / (f(w) f(e) f(T))] gamma_u w_SI e_SI,

    i.e. gamma_SI = gamma_u f(theta) / (f(w) f(e) f(T)): the same law, the same trajectories
    and the same Lyapunov function theta_t^2/(2 gamma), only written in SI. ``theta``,
    ``regressor`` and ``error`` are the (mass, length, time) exponents of the three factors.
    """
    for name, unit in (('mass', mass_unit_kg), ('length', length_unit_m),
                       ('time', time_unit_s)):
        if not (unit > 0.0 and math.isfinite(unit)):
            raise ValueError(f'the {name} unit must be a positive finite number, got {unit!r}')

    def factor(dimension):
        mass, length, time = dimension
        return mass_unit_kg ** mass * length_unit_m ** length * time_unit_s ** time

    return gamma * factor(theta) / (factor(regressor) * factor(error) * time_unit_s)


def mao_multibody_adaptation_gains_to_si(
        gamma1: float, gamma2: float, mass_unit_kg: float = 1000.0, length_unit_m: float = 1.0,
        time_unit_s: float = 1.0) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Mao, Tao, Jiang & Yan's Gamma1 = gamma1 I9 of (64) and Gamma2 = gamma2 I7 of (74), in a
    coherent unit system -> the diagonals of Gamma1 and Gamma2 in SI (kg, m, s).

    Each entry by :func:`adaptation_gain_to_si` from the dimensions of its parameter, its
    regressor entry and its error (:data:`MAO_MULTIBODY_THETA1_DIMENSIONS` and the tables
    beside it). The parameters are (57)-(58), (68)-(69): th11 = M1 M2/d1 [M T], th21 = M3 [M]
    (the input gains); th12, th16 = d11 d12 - k11, ... [T^-2]; th13, th22, th24, th26 [T^-1];
    th14 = c1 [L^-1]; th15, th17 = d11 k12, d11 k22 [T^-3]; th23, th25 = k23, k33 [T^-2];
    th19 = d11 a2 [L T^-3]; th27 = a3 [L T^-2]. Each product th_k W_k is the output's
    derivative (y1'' [L T^-3], y2' [L T^-2]); the input-gain entries give a force, th11
    (nu2 - Phi1_hat) and th21 (nu3 - Phi2_hat). The errors eps and e6 are speeds.

    The default is the reading docs/papers/mao_multibody.md argues for: Table II's masses in
    tonnes, lengths in m and time in s as the paper's states and figures are (x(0) in m and
    m/s), hence forces in kN. Only the entries with a mass in them change: gamma11 and gamma21
    are multiplied by 1000 (th11 in t s is 1000 times its number in kg s; the regressors and
    errors carry no mass), every other entry is per unit mass and is the same number in SI:
    (2000, 2, ..., 2) and (2000, 2, ..., 2) for the paper's gains of 2.
    """
    error = MAO_MULTIBODY_ERROR_DIMENSIONS
    units_ = dict(mass_unit_kg=mass_unit_kg, length_unit_m=length_unit_m,
                  time_unit_s=time_unit_s)
    first = tuple(adaptation_gain_to_si(gamma1, theta, w, error, **units_) for theta, w in
                  zip(MAO_MULTIBODY_THETA1_DIMENSIONS, MAO_MULTIBODY_W1_DIMENSIONS))
    second = tuple(adaptation_gain_to_si(gamma2, theta, w, error, **units_) for theta, w in
                   zip(MAO_MULTIBODY_THETA2_DIMENSIONS, MAO_MULTIBODY_W2_DIMENSIONS))
    return first, second
