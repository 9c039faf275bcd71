"""Multi-car train (Mao, Tao, Jiang & Yan eqs 1-7): n cars joined by spring-damper couplers,
traction on the powered cars, resistance a_p + b_p v_p on every car, the aerodynamic c v^2 on
the lead car, and the line force (grade, curve, tunnel) of each car at its own position:

    M_p v_p' = F_p - M_p (a_p + b_p v_p + c_p v_p |v_p|) - M_p g_line(z_p)
               - k_p (y_p - y_p+1) - d_p (v_p - v_p+1) + k_p-1 (y_p-1 - y_p) + d_p-1 (v_p-1 - v_p)
               + M_p d(t) / M

with y_p = z_p + (p - 1) L the position of car p shifted by the rest spacing, so that a coupler's
extension is y_p - y_p+1. The disturbance d(t) is shared by the cars in proportion to their mass.
A mode (Mao et al. 2017) scales every car's mass and its a, b, c by the ratio of the mode's
whole-train values to the train's, and adds its grade and curve term to every car.

Numerics: the couplers (5e8-8e8 N/m on ~45 t cars) ring at tens of Hz with about 1 % damping.
The linear part x' = A x + B F (couplers, b_p v_p, forces) is integrated exactly by its matrix
exponential; the rest (constant and aerodynamic resistance, line forces, the time-varying parts,
the disturbance) by the fourth-order exponential Runge-Kutta scheme ETDRK4 of Cox & Matthews
(2002), whose phi-function matrices come from one augmented matrix exponential per step length
and mode (Van Loan 1978; Higham & Al-Mohy), cached. Steps are split where a car crosses a line
segment boundary (see line_segments.py).

The step runs in compiled kernels (train_plant_node.jit) on preallocated arrays: the line
table, each mode's per-car parameters (``_ModeMatrices.cars``) and propagators (one array per
step length), and the parameter array of the surroundings (layout below).

The constant resistance a_p is applied as a_p tanh(v_p / 0.01 m/s): a smooth sign, so that the
coupler oscillation around standstill does not make it chatter. A train at rest stays at rest
while what pushes it (drives, line forces, disturbance) does not overcome that static friction
(``held``): brakes hold a train, they never push it backwards, and it does not roll back, as in
the point-mass model; its couplers still ring about its resting centre of mass.
"""

from __future__ import annotations

import cmath
import math
from typing import Sequence

import numpy as np
from scipy.linalg import expm

from ato_common import units
from ato_common.line import Line
from ato_common.plant_setup import Mode
from ato_common.trains import TrainParameters
from train_plant_node.jit import kernel
from train_plant_node.models.line_segments import (
    SLOPE,
    START,
    LineSegments,
    boundary_between,
    crossing_time,
    segment_accel,
    segment_index,
)
from train_plant_node.surroundings import (
    DISTURBANCE_VALUE,
    ENV_SIZE,
    HAS_OVERRIDE,
    OVERRIDE_SINE,
    Surroundings,
    env_factors,
    nominal_mode,
)

STANDSTILL_SPEED_MPS = 0.01

# The kernels' parameter array: the mode's extra grade and curve term (m/s^2), its total mass,
# gravity, then the surroundings (surroundings.py). Rows of _ModeMatrices.cars: each car's a, b,
# c per kg, 1 / mass, rest offset (m) and the index of its actuator's force (-1: unpowered).
# Propagator array (one per step length): e^(Ah/2), its phi_1 map on the velocities, e^(Ah), and
# the three ETDRK4 maps of the non-linear terms (velocity columns).
EXTRA_ACCEL, TOTAL_MASS, GRAVITY, ENV = range(4)
PARAMETERS = ENV + ENV_SIZE
CAR_A, CAR_B, CAR_C, CAR_INVERSE_MASS, CAR_OFFSET, CAR_ACTUATOR = range(6)
E_HALF, PHI1_HALF, E_FULL, F1, F2, F3 = range(6)


def phi_functions(matrix: np.ndarray, order: int = 3) -> list[np.ndarray]:
    """``[phi_0 .. phi_order](matrix)``, phi_0 = exp,
    phi_k(Z) = int_0^1 e^{(1-s)Z} s^(k-1)/(k-1)! ds, from the exponential of one
    block-companion matrix (Higham & Al-Mohy, Sidje 1998)."""
    m = matrix.shape[0]
    size = m * (order + 1)
    augmented = np.zeros((size, size))
    augmented[:m, :m] = matrix
    for k in range(order):
        augmented[m * k:m * (k + 1), m * (k + 1):m * (k + 2)] = np.eye(m)
    e = expm(augmented)
    return [e[:m, m * k:m * (k + 1)] for k in range(order + 1)]


@kernel
def _phi(z, k):
    """phi_k of a complex scalar: the closed form, or its Taylor series near 0 (cancellation)."""
    factorial = 1.0
    for j in range(2, k + 1):
        factorial *= j
    if abs(z) < 0.5:
        total = 0j
        term = 1.0 / factorial + 0j
        for j in range(1, 25):
            total += term
            term = term * z / (j + k)
        return total
    value = cmath.exp(z)
    factorial = 1.0  # j!
    for j in range(k):
        value = (value - 1.0 / factorial) / z
        factorial *= j + 1
    return value


@kernel
def _pack(e_half, phi1_half, e_full, phi1, phi2, phi3, h):
    """The propagator array of step h from phi_k(A h) and phi_k(A h / 2); only the velocity
    columns of the nonlinear-term maps are kept (the non-linear term has no position rows).
    Cox & Matthews (2002) eq (26): f1 = phi1 - 3 phi2 + 4 phi3, f2 = phi2 - 2 phi3,
    f3 = -phi2 + 4 phi3 (their h^-2 L^-3 forms, written with phi functions)."""
    m = e_full.shape[0]
    n = m // 2
    out = np.zeros((6, m, m))
    out[E_HALF] = e_half
    out[E_FULL] = e_full
    for i in range(m):
        for j in range(n):
            c = n + j
            out[PHI1_HALF, i, j] = h / 2 * phi1_half[i, c]
            out[F1, i, j] = h * (phi1[i, c] - 3.0 * phi2[i, c] + 4.0 * phi3[i, c])
            out[F2, i, j] = 2.0 * h * (phi2[i, c] - 2.0 * phi3[i, c])
            out[F3, i, j] = h * (4.0 * phi3[i, c] - phi2[i, c])
    return out


@kernel
def _phi_matrix(values, left, right, z_scale, k):
    """Re(left diag(phi_k(values z_scale)) right) = phi_k(A z_scale) for A = left diag right."""
    m = values.shape[0]
    weights = np.empty(m, np.complex128)
    for i in range(m):
        weights[i] = _phi(values[i] * z_scale, k)
    out = np.empty((m, m))
    for r in range(m):
        for c in range(m):
            total = 0j
            for i in range(m):
                total += left[r, i] * weights[i] * right[i, c]
            out[r, c] = total.real
    return out


@kernel
def eigen_propagators(values, left, right, h):
    """The propagator array of step h from the eigen-decomposition of A (a few small products
    instead of two matrix exponentials): for the odd step lengths of line-boundary crossings."""
    return _pack(_phi_matrix(values, left, right, h / 2, 0),
                 _phi_matrix(values, left, right, h / 2, 1),
                 _phi_matrix(values, left, right, h, 0), _phi_matrix(values, left, right, h, 1),
                 _phi_matrix(values, left, right, h, 2), _phi_matrix(values, left, right, h, 3),
                 h)


class _ModeMatrices:
    """Per-mode car parameters and the linear dynamics."""

    def __init__(self, model: 'MultiCarModel', mode: Mode):
        self.mode = mode
        train, cars, n = model.train, model.train.cars, model.n
        d, nominal = mode.davis, train.davis

        def ratio(new: float, old: float) -> float:
            return new / old if old else 0.0
        mass_ratio = mode.mass_kg / train.mass_kg
        self.masses = np.array([c.mass_kg for c in cars]) * mass_ratio
        self.weights = self.masses / self.masses.sum()  # for the train's mean speed and position
        # Resistance forces per car scale with the whole-train coefficients, then per kg.
        ra = ratio(d.a_n, nominal.a_n)
        rb = ratio(d.b_n_s_per_m, nominal.b_n_s_per_m)
        rc = ratio(d.c_n_s2_per_m2, nominal.c_n_s2_per_m2)
        self.a = [c.a_mps2 * c.mass_kg * ra / m for c, m in zip(cars, self.masses)]
        self.b = [c.b_per_s * c.mass_kg * rb / m for c, m in zip(cars, self.masses)]
        self.c = [c.c_per_m * c.mass_kg * rc / m for c, m in zip(cars, self.masses)]
        if not nominal.a_n and d.a_n:  # the train has none: share the mode's by mass
            self.a = [d.a_n / mode.mass_kg] * n
        if not nominal.b_n_s_per_m and d.b_n_s_per_m:
            self.b = [d.b_n_s_per_m / mode.mass_kg] * n
        if not nominal.c_n_s2_per_m2 and d.c_n_s2_per_m2:
            self.c = [d.c_n_s2_per_m2 / self.masses[0]] + [0.0] * (n - 1)
        self.extra = mode.grade_sine * model.gravity + mode.curve_accel_mps2
        stiffness = np.zeros((n, n))
        damping = np.zeros((n, n))
        for j, coupler in enumerate(train.couplers):
            for matrix, value in ((stiffness, coupler.stiffness_n_per_m),
                                  (damping, coupler.damping_n_s_per_m)):
                matrix[j, j] += value
                matrix[j + 1, j + 1] += value
                matrix[j, j + 1] -= value
                matrix[j + 1, j] -= value
        inverse_mass = np.diag(1.0 / self.masses)
        self.A = np.zeros((2 * n, 2 * n))
        self.A[:n, n:] = np.eye(n)
        self.A[n:, :n] = -inverse_mass @ stiffness
        self.A[n:, n:] = -inverse_mass @ damping - np.diag(self.b)
        self.inverse_mass = 1.0 / self.masses
        self.total_mass = float(np.sum(self.masses))
        actuator = [-1.0] * n
        for j, i in enumerate(model.powered):
            actuator[i] = float(j)
        self.cars = np.array([self.a, self.b, self.c, self.inverse_mass, model.offsets, actuator],
                             dtype=float)
        self._propagators: dict[float, np.ndarray] = {}

    def _balancing(self):
        """Positions scaled by the highest coupler frequency against speeds, so that matrix
        functions are computed to full relative accuracy: phi_k(D^-1 A D h) = D^-1 phi_k(A h) D."""
        n = self.A.shape[0] // 2
        omega = math.sqrt(float(np.max(np.abs(self.A[n:, :n])))) or 1.0
        scale = np.concatenate([np.full(n, 1.0 / omega), np.ones(n)])
        return scale, self.A * scale[None, :] / scale[:, None]

    def _eigen_decomposition(self):
        """(eigenvalues, vectors, inverse) of A, complex, or None if A is (nearly) defective;
        from the balanced A."""
        if not hasattr(self, '_eigen'):
            scale, balanced = self._balancing()
            values, vectors = np.linalg.eig(balanced)
            self._eigen = None
            if np.linalg.cond(vectors) < 1e8:
                self._eigen = tuple(np.ascontiguousarray(a, dtype=complex) for a in (
                    values, vectors * scale[:, None], np.linalg.inv(vectors) / scale[None, :]))
        return self._eigen

    def propagators(self, h: float, cache: bool = True) -> np.ndarray:
        """ETDRK4 matrices for step h (see ``_pack``). Cached step lengths: from the matrix
        exponential of the balanced augmented matrix; others: from eigenvectors."""
        found = self._propagators.get(h)
        if found is not None:
            return found
        eigen = None if cache else self._eigen_decomposition()
        if eigen is not None:
            return eigen_propagators(*eigen, float(h))
        scale, balanced = self._balancing()

        def unbalanced(phis):
            return [np.ascontiguousarray(p * scale[:, None] / scale[None, :]) for p in phis]
        e_half, phi1_half = unbalanced(phi_functions(balanced * (h / 2), 1))
        e_full, phi1, phi2, phi3 = unbalanced(phi_functions(balanced * h, 3))
        result = _pack(e_half, phi1_half, e_full, phi1, phi2, phi3, float(h))
        if cache:
            self._propagators[h] = result
        return result


@kernel
def _matvec(matrix, x, columns):
    """matrix[:, :columns] @ x (loops: faster than BLAS on 8 x 8)."""
    rows = matrix.shape[0]
    out = np.zeros(rows)
    for i in range(rows):
        total = 0.0
        for j in range(columns):
            total += matrix[i, j] * x[j]
        out[i] = total
    return out


@kernel
def _add_matvec(out, matrix, x, alpha, y, beta, columns):
    """out += matrix[:, :columns] @ (alpha x + beta y), in place."""
    for i in range(out.shape[0]):
        total = 0.0
        for j in range(columns):
            total += matrix[i, j] * (alpha * x[j] + beta * y[j])
        out[i] += total


@kernel
def weighted_speed(x, weights):
    """The cars' mean speed weighted by ``weights`` (the velocity half of the state ``x``)."""
    n = weights.shape[0]
    total = 0.0
    for q in range(n):
        total += weights[q] * x[n + q]
    return total


@kernel
def segment_indices(x, table, cars):
    """Each car's line segment (positions shifted by the rest spacing)."""
    n = x.shape[0] // 2
    out = np.empty(n, np.int64)
    for q in range(n):
        out[q] = segment_index(table, x[q] - cars[CAR_OFFSET, q], x[n + q] < 0.0)
    return out


@kernel
def _step_line(indices, table, cars, shift, p):
    """Each car's line force in its segment: at the segment start, its slope per metre and
    where the slope is anchored in the state's coordinates (positions relative to ``shift``)."""
    n = indices.shape[0]
    line = np.empty((3, n))  # accelerations, slopes, anchors
    has_override = p[ENV + HAS_OVERRIDE] != 0.0
    override_accel = p[GRAVITY] * p[ENV + OVERRIDE_SINE]
    for q in range(n):
        i = indices[q]
        line[0, q] = segment_accel(table, i, has_override, override_accel)
        line[1, q] = table[SLOPE, i]
        line[2, q] = table[START, i] + cars[CAR_OFFSET, q] - shift
    return line


@kernel
def _nonlinear(x, time_s, forces, line, cars, p):
    """Specific forces outside the exact linear part (velocity rows), m/s^2; the actuator
    forces are included here (constant over the step, so phi_1 integrates them exactly)."""
    n = x.shape[0] // 2
    fa, fb, fc, fl, dist = env_factors(p, ENV, time_s)
    base = dist / p[TOTAL_MASS] - p[EXTRA_ACCEL]
    out = np.empty(n)
    for q in range(n):
        v = x[n + q]
        accel = line[0, q]
        if line[1, q] != 0.0:  # a transition curve: the force follows the car's position
            accel += line[1, q] * (x[q] - line[2, q])
        out[q] = (base - fa * cars[CAR_A, q] * math.tanh(v / STANDSTILL_SPEED_MPS)
                  - (fb - 1.0) * cars[CAR_B, q] * v - fc * cars[CAR_C, q] * v * abs(v)
                  - fl * accel)
        actuator = int(cars[CAR_ACTUATOR, q])
        if actuator >= 0:
            out[q] += forces[actuator] * cars[CAR_INVERSE_MASS, q]
    return out


@kernel
def etdrk4_kernel(x, t, h, props, forces, indices, table, cars, p):
    """Cox & Matthews (2002) ETDRK4, eqs (26). The line forces of the step are given, so
    the non-linear term does not depend on positions; a uniform shift of the positions is
    invariant under the linear part (unstretched couplers), so the step runs relative to
    the lead car's position: no round-off from positions of tens of kilometres."""
    m = x.shape[0]
    n = m // 2
    shift = x[0]
    y = x.copy()
    for q in range(n):
        y[q] -= shift
    line = _step_line(indices, table, cars, shift, p)
    n_x = _nonlinear(y, t, forces, line, cars, p)
    ex = _matvec(props[E_HALF], y, m)
    a = ex.copy()
    _add_matvec(a, props[PHI1_HALF], n_x, 1.0, n_x, 0.0, n)
    n_a = _nonlinear(a, t + h / 2, forces, line, cars, p)
    b = ex
    _add_matvec(b, props[PHI1_HALF], n_a, 1.0, n_a, 0.0, n)
    n_b = _nonlinear(b, t + h / 2, forces, line, cars, p)
    c = _matvec(props[E_HALF], a, m)
    _add_matvec(c, props[PHI1_HALF], n_b, 2.0, n_x, -1.0, n)
    n_c = _nonlinear(c, t + h, forces, line, cars, p)
    out = _matvec(props[E_FULL], y, m)
    _add_matvec(out, props[F1], n_x, 1.0, n_x, 0.0, n)
    _add_matvec(out, props[F2], n_a, 1.0, n_b, 1.0, n)
    _add_matvec(out, props[F3], n_c, 1.0, n_c, 0.0, n)
    for q in range(n):
        out[q] += shift
    return out


@kernel
def substep_kernel(x, out, t, h, props, forces, table, cars, p):
    """One ETDRK4 step in the cars' current segments into ``out`` (allocated by the caller:
    cheaper than returning a new array); returns whether a car has reached another segment."""
    indices = segment_indices(x, table, cars)
    out[:] = etdrk4_kernel(x, t, h, props, forces, indices, table, cars, p)
    after = segment_indices(out, table, cars)
    crossed = False
    for q in range(indices.shape[0]):
        if after[q] != indices[q]:
            crossed = True
    return crossed


@kernel
def derivative_kernel(state, shift, time_s, linear, forces, table, cars, p):
    """x' at one instant, the line forces looked up at the cars' positions (``state`` holds
    positions relative to ``shift``)."""
    m = state.shape[0]
    n = m // 2
    absolute = state.copy()
    for q in range(n):
        absolute[q] += shift
    line = _step_line(segment_indices(absolute, table, cars), table, cars, shift, p)
    # The couplers see only differences of positions: relative to the lead car's, their forces
    # do not lose digits to positions of kilometres (stiffness x position ~ 1e7 m/s^2 each).
    relative = state.copy()
    for q in range(n):
        relative[q] -= state[0]
    out = _matvec(linear, relative, m)
    out[n:] += _nonlinear(state, time_s, forces, line, cars, p)
    return out


@kernel
def outputs_kernel(state, out, time_s, linear, forces, table, cars, p):
    """[positions of the cars, their speeds, their accelerations] into ``out``."""
    n = state.shape[0] // 2
    derivative = derivative_kernel(state, 0.0, time_s, linear, forces, table, cars, p)
    for q in range(n):
        out[q] = state[q] - cars[CAR_OFFSET, q]
        out[n + q] = state[n + q]
        out[2 * n + q] = derivative[n + q]


class MultiCarModel:
    def __init__(self, train: TrainParameters, line: Line, gravity: float = units.STANDARD_GRAVITY,
                 max_substep_s: float = 0.1):
        if len(train.cars) < 2 or len(train.couplers) != len(train.cars) - 1:
            raise ValueError(f"train '{train.name}' has no multi-car description "
                             f'({len(train.cars)} cars, {len(train.couplers)} couplers)')
        if not max_substep_s > 0.0:
            raise ValueError(f'max_substep_s must be > 0, got {max_substep_s}')
        self.train, self.line, self.gravity = train, line, gravity
        self.max_substep_s = max_substep_s
        cars = train.cars
        n = self.n = len(cars)
        self.car_names = tuple(c.name for c in cars)
        self.actuator_names = tuple(c.name for c in cars if c.powered)
        if self.actuator_names != tuple(train.actuator_names):
            raise ValueError(f'actuators {train.actuator_names} are not the powered cars '
                             f'{self.actuator_names}')
        self.offsets = np.arange(n) * train.car_length_m
        self.powered = [i for i, c in enumerate(cars) if c.powered]
        self.segments = LineSegments(line, gravity)
        self.nominal = Surroundings(nominal_mode(train), 0)
        self._modes: dict[int, _ModeMatrices] = {}
        self.A = self.mode_matrices(self.nominal).A  # the nominal linear dynamics
        self.parameters = np.zeros(PARAMETERS)
        # the surroundings ``parameters`` holds, and their matrices
        self._parameters_of: Surroundings | None = None
        self._matrices_of_parameters: _ModeMatrices | None = None
        self._outputs = np.empty(3 * n)  # outputs_kernel's
        self._forces: tuple = ()
        self._forces_array = np.zeros(0)
        self._warm_up()

    def _warm_up(self) -> None:
        """Call every kernel once (compiled, or loaded from numba's cache, on first use in a
        process: that takes from a tenth of a second to seconds), so that no lockstep step pays
        it. Changes nothing."""
        mm, p = self._prepare(self.nominal, 0.0, 0.0)
        table = self.segments.table
        x = self.initial_state(0.0, 1.0)
        forces = np.zeros(len(self.actuator_names))
        props = mm.propagators(self.max_substep_s)
        if mm._eigen_decomposition() is not None:
            eigen_propagators(*mm._eigen_decomposition(), self.max_substep_s)
        indices = segment_indices(x, table, mm.cars)
        substep_kernel(x, np.empty_like(x), 0.0, self.max_substep_s, props, forces, table,
                       mm.cars, p)
        etdrk4_kernel(x, 0.0, self.max_substep_s, props, forces, indices, table, mm.cars, p)
        derivative_kernel(x, 0.0, 0.0, mm.A, forces, table, mm.cars, p)
        weighted_speed(x, mm.weights)
        outputs_kernel(x, self._outputs, 0.0, mm.A, forces, table, mm.cars, p)
        boundary_between(table, 0, 0)
        crossing_time(0.0, 1.0, 1.0, 1.0, 1.0, 0.5)

    def mode_matrices(self, env: Surroundings) -> _ModeMatrices:
        found = self._modes.get(env.mode_key)
        if found is None or (found.mode is not env.mode and found.mode != env.mode):
            found = _ModeMatrices(self, env.mode)
            self._modes[env.mode_key] = found
        found.mode = env.mode  # equal: identical from now on, a cheaper comparison
        return found

    def _prepare(self, env: Surroundings, time_s: float, duration_s: float
                 ) -> tuple[_ModeMatrices, np.ndarray]:
        """The mode's matrices and the kernels' parameter array for a step in ``env``."""
        p = self.parameters
        if env is not self._parameters_of:
            mm = self.mode_matrices(env)
            p[:ENV] = (mm.extra, mm.total_mass, self.gravity)
            env.write_parameters(p, ENV)
            self._parameters_of, self._matrices_of_parameters = env, mm
        if env.disturbance is not None and env.held_disturbance:  # constant within the step
            p[ENV + DISTURBANCE_VALUE] = env.disturbance.force(time_s + 0.5 * duration_s)
        matrices = self._matrices_of_parameters
        assert matrices is not None  # set with ``_parameters_of``
        return matrices, p

    def kernel_inputs(self, env: Surroundings, duration_s: float) -> tuple:
        """What ``periods.run_multi_car_periods`` reads of the model under ``env`` (without a
        held disturbance) for steps of ``duration_s``: ``step``'s propagators, line table,
        per-car parameters, parameter array, and ``outputs``' linear dynamics."""
        mm, p = self._prepare(env, 0.0, 0.0)
        return mm.propagators(duration_s), self.segments.table, mm.cars, p, mm.A

    def _force_array(self, forces: Sequence[float] | np.ndarray) -> np.ndarray:
        """The actuator forces as the kernels read them (the last array, if they are equal)."""
        if type(forces) is not tuple or forces != self._forces:
            self._forces = tuple(forces)
            self._forces_array = np.array(self._forces, dtype=float)
        return self._forces_array

    def initial_state(self, position_m: float, speed_mps: float = 0.0) -> np.ndarray:
        return np.concatenate([np.full(self.n, position_m), np.full(self.n, speed_mps)])

    def lead_speed(self, state) -> float:
        return float(state[self.n])

    def standing(self, state, env: Surroundings | None = None) -> bool:
        """The train stands: the mean speed of its cars, weighted by their masses, is at most
        the standstill speed (a train braked to rest within a step may end it a little
        backwards: its brakes hold it, as the next step does)."""
        weights = self.mode_matrices(env or self.nominal).weights
        return weighted_speed(np.asarray(state, dtype=float), weights) <= STANDSTILL_SPEED_MPS

    def held(self, state: np.ndarray, forces: Sequence[float], time_s: float = 0.0,
             env: Surroundings | None = None) -> bool:
        """A standing train stays at rest (module docstring): the resultant of the drives and
        brakes, the line forces and the disturbance on its cars at rest does not exceed the
        static friction (the constant Davis term) of the whole train. Brakes never push a
        train backwards, and a train does not roll back (as in the point-mass model)."""
        if not self.standing(state, env):
            return False
        mm, p = self._prepare(env or self.nominal, time_s, 0.0)
        n = self.n
        rest = np.array(state, dtype=float)
        rest[n:] = 0.0
        masses = mm.masses
        accelerations = self.derivative(rest, forces, time_s, env)[n:]
        friction = env_factors(p, ENV, time_s)[0] * float(np.dot(masses, mm.cars[CAR_A]))
        return float(np.dot(masses, accelerations)) <= friction

    def step(self, state: np.ndarray, duration_s: float, forces: Sequence[float],
             time_s: float = 0.0, env: Surroundings | None = None) -> np.ndarray:
        """State after ``duration_s`` with the forces held (zero-order hold) from ``time_s``.
        A train ``held`` at rest stays where it stands: its brakes exert no force beyond
        holding it, and its centre of mass does not move (its couplers still ring)."""
        if self.held(state, forces, time_s, env):
            start = np.asarray(state, dtype=float)
            moved = self._integrate(start, duration_s, tuple(max(f, 0.0) for f in forces),
                                    time_s, env)
            n = self.n
            weights = self.mode_matrices(env or self.nominal).weights
            moved[:n] -= float(np.dot(weights, moved[:n] - start[:n]))
            moved[n:] -= float(np.dot(weights, moved[n:]))
            return moved
        return self._integrate(state, duration_s, forces, time_s, env)

    def _integrate(self, state: np.ndarray, duration_s: float,
                   forces: Sequence[float] | np.ndarray,
                   time_s: float, env: Surroundings | None) -> np.ndarray:
        """``step``'s integration: ETDRK4 steps of at most ``max_substep_s``, split where a car
        reaches another line segment."""
        mm, p = self._prepare(env or self.nominal, time_s, duration_s)
        forces = self._force_array(forces)
        substeps = max(1, math.ceil(duration_s / self.max_substep_s - 1e-9))
        h_max = duration_s / substeps
        x = np.asarray(state, dtype=float)
        t, end = float(time_s), time_s + duration_s
        n = self.n
        table, cars = self.segments.table, mm.cars
        while end - t > 1e-12 * max(1.0, abs(end)):
            h = h_max if end - t > h_max * (1.0 - 1e-9) else end - t
            x1 = np.empty(2 * n)
            crossed = substep_kernel(x, x1, t, h, mm.propagators(h, h == h_max), forces, table,
                                     cars, p)
            if crossed:  # a car reaches another segment: stop the step there
                indices = segment_indices(x, table, cars)
                after = segment_indices(x1, table, cars)
                crossings = []
                for q, (i0, i1) in enumerate(zip(indices.tolist(), after.tolist())):
                    if i0 != i1:
                        boundary = boundary_between(table, i0, i1) + self.offsets[q]
                        crossings.append((crossing_time(x[q], x[n + q], x1[q], x1[n + q], h,
                                                        boundary), q, boundary))
                h, q, boundary = min(crossings)

                def etdrk4(h):
                    return etdrk4_kernel(x, t, h, mm.propagators(h, False), forces, indices,
                                         table, cars, p)
                x1 = etdrk4(h)
                for _ in range(3):  # Newton on the crossing time, with the car's speed
                    miss = float(x1[q]) - boundary
                    if abs(miss) < 1e-8 or x1[n + q] == 0.0:
                        break
                    h = min(max(h - miss / float(x1[n + q]), 0.0), end - t)
                    x1 = etdrk4(h)
            x, t = x1, t + h
        return x

    def derivative(self, state: np.ndarray, forces: Sequence[float], time_s: float = 0.0,
                   env: Surroundings | None = None, shift: float = 0.0) -> np.ndarray:
        """x' at one instant (line forces looked up at the cars' positions). ``state`` may hold
        positions relative to ``shift`` (e.g. the lead car's), which keeps the coupler
        extensions exact when the positions are tens of kilometres."""
        mm, p = self._prepare(env or self.nominal, time_s, 0.0)
        return derivative_kernel(np.asarray(state, dtype=float), float(shift), float(time_s),
                                 mm.A, self._force_array(forces), self.segments.table, mm.cars,
                                 p)

    def outputs(self, state: np.ndarray, forces: Sequence[float], time_s: float = 0.0,
                env: Surroundings | None = None):
        n = self.n
        mm, p = self._prepare(env or self.nominal, time_s, 0.0)
        outputs_kernel(np.asarray(state, dtype=float), self._outputs, float(time_s), mm.A,
                       self._force_array(forces), self.segments.table, mm.cars, p)
        values = self._outputs.tolist()
        applied = [0.0] * n
        for force, i in zip(forces, self.powered):
            applied[i] = float(force)
        return (tuple(values[:n]), tuple(values[n:2 * n]), tuple(values[2 * n:]),
                tuple(applied))
