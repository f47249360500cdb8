"""Brownian increments and thermal drift of the lubrication-corrected mobility M_lub = (M^-1 + Delta_R)^-1.

Method of Sprinkle, van der Wee, Luo, Driscoll and Donev (Soft Matter 16, 7982, 2020), written from the
equations (not the published code):

* **Increment.** With ``W_far, W_near ~ N(0, I)`` (6N each),
  ``X = sqrt(2 kT/dt) M^1/2 W_far`` (the package's Lanczos, :func:`stochastic_forcing.lanczos_square_root`,
  preconditioned by each sphere's wall self-mobility: :func:`far_field_root`)
  and ``F_B = sqrt(2 kT/dt) Delta_R^1/2 W_near``, the velocities
  ``U_B = (I + M Delta_R)^-1 (X + M F_B)`` have covariance
  ``(2kT/dt) (I + M Delta_R)^-1 (M + M Delta_R M) (I + Delta_R M)^-1 = (2kT/dt) M_lub``.
* **Near-field root** ``Delta_R^1/2 W`` without CHOLMOD (:class:`NearFieldRoot`):

  - ``'cholesky'``: a sparse LU of ``Delta_R + s I`` by SciPy's SuperLU in symmetric mode with diagonal
    pivots (so ``P (Delta_R + s I) P^T = L D L^T``), root ``C = P^T L D^1/2``.  Covariance
    ``Delta_R + s I``: the shift ``s = 6 pi eta a * tolerance`` (the published choice, needed because
    ``Delta_R`` is only semidefinite) adds ``s`` to the friction, a relative change of order ``tolerance``.
    One factorisation per configuration, then one triangular product per draw.
  - ``'lanczos'``: the package's Lanczos on the sparse ``Delta_R`` itself (no shift, covariance
    ``Delta_R`` to the Lanczos tolerance); products with a sparse matrix are cheap but the spread of
    ``Delta_R``'s eigenvalues (contact ~ 1/gap against far pairs ~ 1e-5) costs tens to hundreds of them.

* **Drift** ``kT div M_lub`` by a random finite difference (Delong et al. 2015): with ``W`` the
  translational part of a Gaussian 6N vector (its rotational part set to zero: spheres' M_lub does not
  depend on orientation, so the mean is the same and the variance lower) and ``V = (I + Delta_R M)^-1 W``,
  ``d M_lub W = (I + M Delta_R)^-1 [dM V - M dDelta_R M V]`` (differentiating ``(M^-1 + Delta_R)^-1``),
  both differences taken between ``q +- delta/2 W``.  ``delta`` is absolute (``1e-3`` length units, as
  published) unless ``rfd_scaled_by_a`` (then ``delta * a``; advised when ``a`` is far from 1).  Where the
  resistance formulas hand over with a jump (r = 2.006 a, h = 1.1 a, the cutoff) the difference picks up
  the jump divided by ``delta``; the divergence is only meaningful away from them.

Vector layout ``[F1 T1 F2 T2 ...]`` / ``[U1 W1 U2 W2 ...]``; velocities (N, 6) rows ``[U W]``.
"""
from collections import namedtuple
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from multi_bodies.files.input_options import DEFAULTS
from multi_bodies.solver.body_solver import SolutionParts
from multi_bodies.solver.linear_map import FunctionMap, LinearProblem
from multi_bodies.solver.solves import SOLVER_TOLERANCE
from stochastic_forcing import lanczos_square_root
from utils import UserInputError

from . import assembly, resistance
from .problem import (LubricationProblem, compressed_rows_times, csr_times, far_field_mobility, far_field_product,
                      solver_and_tolerance)

NEAR_FIELD_ROOTS = ('cholesky', 'lanczos')
PUBLISHED_RFD_DELTA = DEFAULTS.rf_delta  # the RFD step of the published lubrication code: rf_delta's default
_FAR_FIELDS = {}  # (eta, a, periodic_length, wall, implementation) -> the far-field BlobMobility


class LubricationSettings(namedtuple('LubricationSettings', [
        'a', 'eta', 'wall', 'cutoff', 'periodic_length', 'firm_delta', 'implementation', 'handover',
        'near_field_root', 'rfd_delta', 'rfd_scaled_by_a'])):
    """What a lubrication step needs besides the configuration (a value; lengths in the user's units).

    a : sphere radius; eta : viscosity; wall : a no-slip wall at z = 0; cutoff : ``Lub_Cut`` (units of a);
    periodic_length : (3,) box; firm_delta : gap clamp (units of a); implementation : far-field backend name
    (None: C++ when built); handover : ``'published'`` or ``'smooth'`` (:mod:`lubrication.resistance`);
    near_field_root : ``'cholesky'`` or ``'lanczos'``;
    rfd_delta : RFD step (length units, or units of a with ``rfd_scaled_by_a``).
    """

    def far_field(self):
        """The far-field ``mobility.interface.BlobMobility`` (``lubrication.problem.far_field_mobility``), made
        once per set of its parameters (a step asks for it four times; the mobility holds no configuration)."""
        key = (float(self.eta), float(self.a), tuple(float(x) for x in np.ravel(self.periodic_length)),
               bool(self.wall), self.implementation)
        mobility = _FAR_FIELDS.get(key)
        if mobility is None:
            mobility = _FAR_FIELDS[key] = far_field_mobility(self.eta, self.a, self.periodic_length, self.wall,
                                                             self.implementation)
        return mobility

    def problem(self, locations, matrices=None):
        """The :class:`LubricationProblem` at locations (N, 3)."""
        return LubricationProblem(locations, self.a, self.eta, wall=self.wall, cutoff=self.cutoff,
                                  periodic_length=self.periodic_length, firm_delta=self.firm_delta,
                                  matrices=matrices, handover=self.handover, far_field=self.far_field())

    def matrices(self, locations):
        """:data:`lubrication.assembly.LubricationMatrices` at locations (N, 3)."""
        return assembly.resistance_matrices(locations, self.a, self.eta, self.cutoff, self.periodic_length,
                                            self.wall, self.firm_delta, self.handover)

    @property
    def delta(self):
        """The RFD step in length units."""
        return self.rfd_delta * (self.a if self.rfd_scaled_by_a else 1.0)

    def shift(self, tolerance):
        """``6 pi eta a * tolerance``: the published shift of ``R_sup`` and ``Delta_R`` (force per velocity)."""
        return 6.0 * np.pi * self.eta * self.a * tolerance


def lubrication_settings(a, eta, wall=True, cutoff=assembly.DEFAULT_CUTOFF, periodic_length=(0.0, 0.0, 0.0),
                         firm_delta=resistance.DEFAULT_FIRM_DELTA, implementation=None,
                         handover=DEFAULTS.lubrication_handover, near_field_root='lanczos',
                         rfd_delta=PUBLISHED_RFD_DELTA, rfd_scaled_by_a=False):
    """Checked :class:`LubricationSettings` (UserInputError names the bad option)."""
    if near_field_root not in NEAR_FIELD_ROOTS:
        raise UserInputError('lubrication: near_field_root %r is not one of %s' % (near_field_root,
                                                                                  ', '.join(NEAR_FIELD_ROOTS)))
    if not (np.isfinite(rfd_delta) and rfd_delta > 0):
        raise UserInputError('lubrication: rfd_delta = %r must be a positive number (published 1e-3)' % rfd_delta)
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    return LubricationSettings(float(a), float(eta), bool(wall), float(cutoff), tuple(L), firm_delta,
                               implementation, handover, near_field_root, float(rfd_delta), bool(rfd_scaled_by_a))


class NearFieldRoot:
    """``Delta_R^1/2 W`` for W (6N,) at one configuration (see the module note for the two methods).

    Delta_R : sparse (6N, 6N) symmetric positive semidefinite; method : ``'cholesky'`` or ``'lanczos'``;
    shift : ``s`` of the Cholesky (force per velocity); tolerance : of the Lanczos iteration (None: the option
    table's ``solver_tolerance``).
    Counters: ``factorisations`` (0 or 1), ``products`` (sparse products of the Lanczos).
    """

    def __init__(self, Delta_R, method='cholesky', shift=0.0, tolerance=None):
        self.Delta_R = Delta_R.tocsr()
        self.size = Delta_R.shape[0]
        self.method, self.tolerance = method, SOLVER_TOLERANCE if tolerance is None else float(tolerance)
        self.factorisations, self.products = 0, 0
        self.root = None
        if method == 'cholesky' and self.size:
            self.root = self._cholesky_root(shift)
        elif method not in NEAR_FIELD_ROOTS:
            raise UserInputError('lubrication: near_field_root %r is not one of %s' % (method,
                                                                                      ', '.join(NEAR_FIELD_ROOTS)))

    def _cholesky_root(self, shift):
        shifted = (self.Delta_R + float(shift) * sp.identity(self.size, format='csr')).tocsc()
        factor = spla.splu(shifted, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                           options={'SymmetricMode': True})
        self.factorisations += 1
        if not np.array_equal(factor.perm_r, factor.perm_c):
            raise RuntimeError('lubrication: the symmetric-mode LU of Delta_R + sI pivoted off the diagonal; '
                               'use near_field_root = lanczos')
        d = factor.U.diagonal()
        if np.any(d <= 0):
            raise RuntimeError('lubrication: Delta_R + sI is not positive definite (pivot %g); use '
                               'near_field_root = lanczos' % d.min())
        # SciPy: (Pr A Pc)[perm_r[i], perm_c[j]] = A[i, j] and Pr A Pc = L U with U = D L^T here, so with
        # p = perm_r = perm_c: A[i, j] = (L D L^T)[p[i], p[j]], root = rows p of L D^1/2.
        return (factor.L @ sp.diags(np.sqrt(d))).tocsr()[factor.perm_c, :]

    def apply(self, W):
        """``Delta_R^1/2 W`` (6N,) (a root of ``Delta_R + s I`` for the Cholesky)."""
        W = np.asarray(W, dtype=float).reshape(-1)
        if not self.size:
            return np.zeros(0)
        if self.root is not None:
            return self.root @ W
        result = lanczos_square_root(self._product, W, self.tolerance)
        return result.noise

    def _product(self, x):
        self.products += 1
        return csr_times(self.Delta_R, x)


class TransposedLubricationProblem(LinearProblem):
    """``(I + Delta_R M) V = W`` at one configuration (the drift's first solve): a problem of the one solve.

    Built on a :class:`LubricationProblem` (its M and Delta_R); ``preconditioner(tolerance)``:
    ``R_MB (R_sup + s I)^-1`` (the transpose of the published one), isolated spheres left alone.
    ``solution(x)`` gives ``SolutionParts(None, V (N, 6), None)``.
    """

    def __init__(self, problem):
        self.problem, self.size, self.num_bodies = problem, problem.size, problem.num_bodies

    def matvec(self, x):
        x = np.asarray(x, dtype=float).reshape(-1)
        return x + csr_times(self.problem.Delta_R, self.problem.mobility_product(x))

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, x):
        return SolutionParts(None, np.asarray(x, dtype=float).reshape(self.num_bodies, 6), None)

    def preconditioner(self, tolerance, forward=None):
        """The transpose of ``forward`` (a :class:`LubricationPreconditioner`; None: the published one at this
        problem's configuration), a LinearOperator."""
        forward = self.problem.preconditioner(tolerance) if forward is None else forward
        isolated = forward.isolated_rows

        def apply(x):
            x = np.asarray(x, dtype=float).reshape(-1)
            if forward.factor is None:
                return x.copy()
            if not forward.any_isolated:
                return csr_times(forward.R_MB, forward.factor.solve(x))
            rhs = x.copy()
            rhs[isolated] = 0.0
            y = csr_times(forward.R_MB, forward.factor.solve(rhs))
            y[isolated] = x[isolated]
            return y
        return FunctionMap(self.size, apply)


BrownianIncrement = namedtuple('BrownianIncrement', ['velocities', 'noise_rhs', 'lanczos_iterations',
                                                     'gmres_iterations'])
BrownianIncrement.__doc__ = """Result of :func:`brownian_velocities`.

velocities : (N, 6) ``U_B = (I + M Delta_R)^-1 N`` (velocity units), covariance (2 kT/dt) M_lub.
noise_rhs : (6N,) ``N = X + M F_B`` (kept by the trapezoidal scheme: its corrector reuses it).
lanczos_iterations : far-field Lanczos products; gmres_iterations : of the solve."""


def wall_self_mobility_blocks(heights, a, eta, wall=True):
    """Each sphere's self-mobility (N, 6, 6) above a no-slip wall, ``[[M_tt, M_tr], [M_rt, M_rr]]`` (velocity per
    force, velocity per torque, angular velocity per torque): the single sphere's terms of the Rotne-Prager-Blake
    mobility to the orders of Swan and Brady (Phys. Fluids 19, 113306, 2007), with h = max(z, a) / a (heights
    below a raised to a, as the far field regularises them).  With ``wall`` False, the free-space values
    ``1/(6 pi eta a)`` and ``1/(8 pi eta a^3)``.  heights : (N,) sphere centres' z (length)."""
    h = np.maximum(np.asarray(heights, dtype=float).reshape(-1), a) / a
    blocks = np.zeros((h.size, 6, 6))
    translation, rotation = 1.0 / (6.0 * np.pi * eta * a), 1.0 / (8.0 * np.pi * eta * a ** 3)
    if not wall:
        h = np.full(h.size, np.inf)
    blocks[:, 0, 0] = blocks[:, 1, 1] = translation * (1.0 - (9.0 / h - 2.0 / h ** 3 + 1.0 / h ** 5) / 16.0)
    blocks[:, 2, 2] = translation * (1.0 - (9.0 / h - 4.0 / h ** 3 + 1.0 / h ** 5) / 8.0)
    blocks[:, 3, 3] = blocks[:, 4, 4] = rotation * (1.0 - (5.0 / 16.0) / h ** 3)
    blocks[:, 5, 5] = rotation * (1.0 - (1.0 / 8.0) / h ** 3)
    coupling = (3.0 / 32.0) / (6.0 * np.pi * eta * a ** 2) / h ** 4  # angular velocity (x, y) from force (y, x)
    blocks[:, 3, 1] = blocks[:, 1, 3] = -coupling
    blocks[:, 4, 0] = blocks[:, 0, 4] = coupling
    return blocks


class BlockRoot:
    """``L = blockdiag(C_1 .. C_N)`` (6N, 6N) with ``C_i C_i^T`` the i-th sphere's wall self-mobility
    (:func:`wall_self_mobility_blocks`): the preconditioner of the far-field Lanczos root.  ``apply(x) = L x``,
    ``apply_inverse(x) = L^-1 x``, ``apply_inverse_transpose(x) = L^-T x`` for x (6N,).

    ``factor`` (N, 6, 6) holds the lower Cholesky factors C_i and ``inverse`` (N, 6, 6) their inverses, both in
    closed form: a self-mobility couples only the pairs (U_x, W_y) and (U_y, W_x) (``[[t, c], [c, r]]`` and
    ``[[t, -c], [-c, r]]``) and leaves U_z and W_z alone, so ``C_i`` has the diagonal ``sqrt`` of the first pivots,
    ``c / sqrt(t)`` below them and ``sqrt(r - c^2 / t)`` after them (the Cholesky factor, to rounding; no LAPACK
    call per sphere)."""

    def __init__(self, locations, a, eta, wall=True):
        blocks = wall_self_mobility_blocks(np.asarray(locations, dtype=float).reshape(-1, 3)[:, 2], a, eta, wall)
        n = blocks.shape[0]
        factor = np.zeros((n, 6, 6))
        inverse = np.zeros((n, 6, 6))
        diagonal = np.sqrt(blocks[:, (0, 1, 2, 5), (0, 1, 2, 5)])  # U_x, U_y, U_z, W_z: their own pivots
        factor[:, (0, 1, 2, 5), (0, 1, 2, 5)] = diagonal
        below = blocks[:, (4, 3), (0, 1)] / diagonal[:, :2]  # W_y from U_x, W_x from U_y
        rotation = np.sqrt(blocks[:, (4, 3), (4, 3)] - below * below)
        factor[:, (4, 3), (0, 1)] = below
        factor[:, (4, 3), (4, 3)] = rotation
        inverse[:, (0, 1, 2, 5), (0, 1, 2, 5)] = 1.0 / diagonal
        inverse[:, (4, 3), (4, 3)] = 1.0 / rotation
        inverse[:, (4, 3), (0, 1)] = -below / (diagonal[:, :2] * rotation)
        self.factor, self.inverse, self.num_bodies = factor, inverse, n
        # the three maps as sparse matrices of the entries above (8 per sphere; the patterns made once per N): one
        # compiled product each, where a batched (N, 6, 6) product iterates over 6 x 6 blocks
        lower, upper = _block_diagonal_pattern(n, False), _block_diagonal_pattern(n, True)
        self._L = lower + (factor[:, _LOWER_ROWS, _LOWER_COLUMNS].reshape(-1),)
        self._L_inverse = lower + (inverse[:, _LOWER_ROWS, _LOWER_COLUMNS].reshape(-1),)
        # entry (r, c) of a transposed block is entry (c, r) of the block
        self._L_inverse_transpose = upper + (inverse[:, _UPPER_COLUMNS, _UPPER_ROWS].reshape(-1),)

    def _times(self, matrix, x):
        indptr, indices, data = matrix
        return compressed_rows_times(6 * self.num_bodies, indptr, indices, data,
                                     np.ascontiguousarray(x, dtype=float).reshape(-1))

    def apply(self, x):
        return self._times(self._L, x)

    def apply_inverse(self, x):
        return self._times(self._L_inverse, x)

    def apply_inverse_transpose(self, x):
        return self._times(self._L_inverse_transpose, x)


# (row, column) of the entries of a lower triangular block C_i or C_i^-1 and of an upper one (their transposes),
# sorted by row, then column
_LOWER_ROWS, _LOWER_COLUMNS = np.array([0, 1, 2, 3, 3, 4, 4, 5]), np.array([0, 1, 2, 1, 3, 0, 4, 5])
_UPPER_ROWS, _UPPER_COLUMNS = np.array([0, 0, 1, 1, 2, 3, 4, 5]), np.array([0, 4, 1, 3, 2, 3, 4, 5])


@lru_cache(maxsize=16)
def _block_diagonal_pattern(n, upper):
    """(indptr (6N + 1,), indices (8N,)), int32 and read-only (shared): the CSR pattern of N diagonal 6 x 6 blocks
    with the entries of :data:`_UPPER_ROWS`, :data:`_UPPER_COLUMNS` (``upper``) or of the lower ones."""
    rows, columns = (_UPPER_ROWS, _UPPER_COLUMNS) if upper else (_LOWER_ROWS, _LOWER_COLUMNS)
    indptr = np.concatenate(([0], np.cumsum(np.tile(np.bincount(rows, minlength=6), n)))).astype(np.int32)
    indices = (6 * np.arange(n)[:, None] + columns).reshape(-1).astype(np.int32)
    indptr.flags.writeable = indices.flags.writeable = False
    return indptr, indices


def far_field_root(problem, W, tolerance, factor=1.0, preconditioned=True):
    """``factor M^1/2 W`` of the far-field M of ``problem`` (a :class:`LubricationProblem`) by Lanczos: a
    ``stochastic_forcing.LanczosResult``.

    preconditioned : with the wall self-mobility (:class:`BlockRoot` L, ``L L^T`` the block diagonal of M) the
        iteration runs on ``L^-1 M L^-T`` and the result is ``factor L (L^-1 M L^-T)^1/2 W``: a different root
        of M, so for Gaussian W the same distribution N(0, factor^2 M), in fewer products where the spheres'
        self-mobilities differ (heights near the wall, translation against rotation).  False: ``M^1/2 W`` (the
        published root, the same numbers for the same W).
    """
    if not preconditioned or problem.size == 0:
        return lanczos_square_root(problem.mobility_product, W, tolerance, factor=factor)
    root = BlockRoot(problem.locations, problem.a, problem.eta, problem.wall)
    return lanczos_square_root(lambda x: root.apply_inverse(problem.mobility_product(root.apply_inverse_transpose(x))),
                               W, tolerance, factor=factor, L_mult=root.apply)


def brownian_rhs(problem, near_root, W_far, W_near, kT, dt, tolerance, preconditioned=True):
    """``N = sqrt(2kT/dt) (M^1/2 W_far + M Delta_R^1/2 W_near)`` (6N,) and the Lanczos iteration count.

    problem : :class:`LubricationProblem`; near_root : :class:`NearFieldRoot` at the same configuration;
    W_far, W_near : (6N,) standard Gaussians drawn by the caller; kT (energy), dt (time); preconditioned : the
    far-field root preconditioned by the wall self-mobility (:func:`far_field_root`).
    """
    factor = np.sqrt(2.0 * kT / dt)
    far = far_field_root(problem, W_far, tolerance, factor=factor, preconditioned=preconditioned)
    near_force = factor * near_root.apply(W_near)
    return problem.rhs(force_torque=near_force, velocity=far.noise), far.iterations


def brownian_velocities(problem, near_root, W_far, W_near, kT, dt, tolerance=None, preconditioner=None, solver=None):
    """:data:`BrownianIncrement` of ``problem`` (see :func:`brownian_rhs`), by the package's one solve (``solver``,
    ``tolerance``: see :func:`lubrication.problem.solver_and_tolerance`)."""
    solver, tolerance = solver_and_tolerance(solver, tolerance)
    rhs, lanczos = brownian_rhs(problem, near_root, W_far, W_near, kT, dt, tolerance)
    if preconditioner is None:
        preconditioner = problem.preconditioner(tolerance)
    result = solver.solve(problem, rhs, preconditioner, tolerance=tolerance, kind='lubrication',
                          what='the lubrication problem')
    return BrownianIncrement(result.velocities, rhs, lanczos, result.iterations)


def translational_direction(W):
    """W (6N,) with its rotational parts set to zero (the direction of the RFD displacement)."""
    W = np.array(W, dtype=float).reshape(-1, 6)
    W[:, 3:] = 0.0
    return W.reshape(-1)


def thermal_drift(settings, locations, W, kT, tolerance=None, problem=None, preconditioner=None, solver=None):
    """``kT div M_lub`` estimated by one random finite difference: (N, 6) velocities (mean over W is the drift).

    settings : :class:`LubricationSettings`; locations : (N, 3); W : (6N,) standard Gaussian (only its
    translational parts are used); kT : energy.  Three solves (one transposed, one for the difference) and
    four far-field products, two assemblies of Delta_R.  ``problem`` at ``locations`` is reused if given;
    ``preconditioner`` (a :class:`LubricationPreconditioner`, e.g. one kept from a configuration nearby) serves
    both solves, transposed for the first (None: the published one built at ``locations``, twice).
    ``solver``, ``tolerance``: see :func:`lubrication.problem.solver_and_tolerance`; both solves take the published
    GMRES iterates (as this drift has always been solved).
    """
    solver, tolerance = solver_and_tolerance(solver, tolerance)
    solver = solver.replace(minimal_residual=False)
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    if problem is None:
        problem = settings.problem(locations)
    W = translational_direction(W)
    delta = settings.delta
    transposed = TransposedLubricationProblem(problem)
    V = solver.solve(transposed, W, transposed.preconditioner(tolerance, preconditioner), tolerance=tolerance,
                     kind='lubrication', what='the transposed lubrication problem').velocities.reshape(-1)
    move = W.reshape(-1, 6)[:, :3]
    plus = settings.problem(locations + 0.5 * delta * move)
    minus = settings.problem(locations - 0.5 * delta * move)
    dM_V = (plus.mobility_product(V) - minus.mobility_product(V)) / delta
    MV = problem.mobility_product(V)
    dDeltaR_MV = (plus.Delta_R @ MV - minus.Delta_R @ MV) / delta
    rhs = kT * problem.rhs(force_torque=-dDeltaR_MV, velocity=dM_V)
    if preconditioner is None:
        preconditioner = problem.preconditioner(tolerance)
    return solver.solve(problem, rhs, preconditioner, tolerance=tolerance, kind='lubrication',
                        what='the lubrication problem').velocities


def far_field_drift(settings, locations, W, kT):
    """``kT (M(q + delta/2 W) - M(q - delta/2 W)) W / delta`` (N, 6): the RFD of the far-field M only
    (mean ``kT div M``), W (6N,) translational parts used for the displacement and the product."""
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    W = translational_direction(W)
    delta = settings.delta
    move = W.reshape(-1, 6)[:, :3]
    plus = _far_field(settings, locations + 0.5 * delta * move)
    minus = _far_field(settings, locations - 0.5 * delta * move)
    return (kT * (plus(W) - minus(W)) / delta).reshape(-1, 6)


def _far_field(settings, locations):
    return far_field_product(locations, settings.far_field())
