"""The lubrication-corrected mobility M_lub = (M^-1 + Delta_R)^-1 as a problem of the package's one solve.

``M`` is the far-field 6N x 6N mobility of single blobs (translational and rotational Rotne-Prager-Blake
above the wall, Rotne-Prager-Yamakawa in free space: the grand product of a ``mobility.interface.BlobMobility``,
:func:`far_field_mobility`), ``Delta_R`` the sparse near-field correction
(:mod:`lubrication.assembly`).  Velocities ``U = M_lub F`` (and more generally ``U = (I + M Delta_R)^-1
(X + M F)``) come from the published formulation: GMRES on ``(I + M Delta_R) U = X + M F`` (the package's one
solve, through a ``multi_bodies.solver.solves.Solver``), preconditioned by ``P^-1 = (R_sup + s I)^-1 R_MB``
(``s = 6 pi eta a * tolerance``), since ``I + M Delta_R ~ M R_sup`` where ``M^-1 ~ R_MB``.  The published
code factors ``R_sup + s I`` with CHOLMOD; here the package's sparse block LDL^T where built, else SciPy's sparse
LU (:mod:`lubrication.sparse_factor`), no extra dependency.

Vector layout ``[F1 T1 F2 T2 ...]`` (forces, torques) and ``[U1 W1 U2 W2 ...]`` (velocities, angular
velocities); the problem's ``solution`` gives velocities (N, 6) rows ``[U W]``.
"""
import numpy as np
import scipy.sparse as sp

from mobility.interface import (Geometry, from_implementation_name, implementation_geometry, implementation_name,
                                preferred_backend)
from multi_bodies.files.input_options import DEFAULTS
from multi_bodies.solver.body_solver import SolutionParts
from multi_bodies.solver.linear_map import LinearMap, LinearProblem
from multi_bodies.solver.solves import Solver
from utils import UserInputError

from . import assembly, resistance, sparse_factor

try:  # SciPy's own CSR kernel (what ``csr_matrix @ vector`` calls), reached without the operator's argument handling
    from scipy.sparse._sparsetools import csr_matvec as _csr_matvec
except ImportError:  # pragma: no cover - a SciPy without it: the operator is used
    _csr_matvec = None
_CSR_TYPES = tuple(getattr(sp, name) for name in ('csr_matrix', 'csr_array') if hasattr(sp, name))


def compressed_rows_times(size, indptr, indices, data, x):
    """``A @ x`` (size,) of the square CSR matrix A (size, size) given by its arrays (int32 ``indptr``, ``indices``,
    float64 ``data``) and x (size,) float64, by SciPy's kernel (a ``csr_matrix`` where it cannot be reached)."""
    if x.shape != (size,):
        raise ValueError('a vector of %d entries was expected, got shape %s' % (size, x.shape))
    if _csr_matvec is None or x.dtype != np.float64 or not x.flags.c_contiguous:
        return sp.csr_matrix((data, indices, indptr), shape=(size, size)) @ x
    out = np.zeros(size)
    _csr_matvec(size, size, indptr, indices, data, x, out)
    return out


def csr_times(matrix, x):
    """``matrix @ x`` (m,) for a sparse matrix (m, n) and a vector x (n,): for a float64 CSR matrix and a contiguous
    float64 vector SciPy's kernel is called directly (the same kernel and numbers as ``@``, without its dozen Python
    calls of argument handling: a Krylov iteration of a step makes several such products); else ``matrix @ x``."""
    if _csr_matvec is None or not isinstance(matrix, _CSR_TYPES) or not isinstance(x, np.ndarray):
        return matrix @ x
    rows, columns = matrix.shape
    data = matrix.data
    if data.dtype != np.float64 or x.dtype != np.float64 or x.shape != (columns,) or not x.flags.c_contiguous:
        return matrix @ x
    out = np.zeros(rows)
    _csr_matvec(rows, columns, matrix.indptr, matrix.indices, data, x, out)
    return out


def far_field_implementation(implementation, wall):
    """The implementation name for ``implementation`` (a backend of the registry that sums blob pairs: 'python',
    'C++', 'pycuda', or 'numba', with or without ``_no_wall``; None: the first usable CPU backend of the registry's
    preference order, C++ where it is built) with the wall (``wall``) or in free space."""
    geometry = Geometry('single_wall' if wall else 'free_space')
    if implementation is None:
        return implementation_name(preferred_backend(geometry, device='cpu'), geometry)
    try:
        backend, named = implementation_geometry(implementation)
    except UserInputError:
        named = None
    if named is None or named.kind == 'free_surface' or implementation.startswith('radii_'):
        raise UserInputError('lubrication: far-field implementation %r is not one of python, C++, pycuda (with or '
                             'without _no_wall)' % implementation)
    return implementation_name(backend, geometry)


def far_field_mobility(eta, a, periodic_length=(0.0, 0.0, 0.0), wall=True, implementation=None):
    """The far-field ``BlobMobility`` of spheres of radius ``a``: RPB above the wall at z = 0 (``wall=True``), RPY in
    free space, with the box ``periodic_length``; ``implementation`` as :func:`far_field_implementation`."""
    return from_implementation_name(far_field_implementation(implementation, wall), eta, a, periodic_length)


def far_field_product(r_vectors, mobility):
    """``f(x (6N,)) -> M x (6N,)``: the grand product of ``mobility`` (:func:`far_field_mobility`) at r_vectors (N, 3).

    x and the result in the layout ``[F1 T1 F2 T2 ...]`` -> ``[U1 W1 U2 W2 ...]`` (``BlobMobility.product``:
    ``U = M_UF F + M_UT T``, ``W = M_WF F + M_WT T``).
    """
    r_vectors = np.ascontiguousarray(np.asarray(r_vectors, dtype=float).reshape(-1, 3))
    n = r_vectors.shape[0]

    def apply(x):
        ft = np.asarray(x, dtype=float).reshape(n, 6)
        U, W = mobility.product(r_vectors, ft[:, :3].ravel(), ft[:, 3:].ravel())  # contiguous copies
        return np.concatenate((U.reshape(n, 3), W.reshape(n, 3)), axis=1).reshape(-1)
    return apply


class LubricationPreconditioner(LinearMap):
    """``P^-1 x = (R_sup + s I)^-1 R_MB x`` (the published preconditioner of ``I + M Delta_R``).

    matrices : :data:`lubrication.assembly.LubricationMatrices`; shift : ``s`` (force per velocity; the
    published ``6 pi eta a * tolerance``).  Isolated spheres (no neighbour, far from the wall) are left
    alone (identity), as published.  ``operator`` is a LinearOperator (6N, 6N); ``factor_time`` counts
    nothing: the factorisation is made once here (:func:`lubrication.sparse_factor.factorise`, 6 x 6 blocks).
    """

    def __init__(self, matrices, shift):
        size = matrices.R_sup.shape[0]
        self.R_MB = matrices.R_MB
        self.isolated_rows = np.repeat(np.asarray(matrices.isolated, dtype=bool), 6)
        self.any_isolated = bool(self.isolated_rows.any())  # the masks below are skipped when none is
        # R_sup + s I is symmetric positive definite: LDL^T without pivoting (SuperLU where not built)
        self.factor = sparse_factor.factorise(matrices.R_sup, float(shift), block=6) if size else None
        self.size = size

    def apply(self, x):
        x = np.asarray(x, dtype=float).reshape(-1)
        if self.factor is None:
            return x.copy()
        rhs = csr_times(self.R_MB, x)
        if not self.any_isolated:
            return self.factor.solve(rhs)
        rhs[self.isolated_rows] = 0.0
        y = self.factor.solve(rhs)
        y[self.isolated_rows] = x[self.isolated_rows]
        return y


class LubricationProblem(LinearProblem):
    """``(I + M Delta_R) U = X + M F`` of N spheres at one configuration: a problem of the one solve.

    Parameters
    ----------
    locations : (N, 3) sphere centres (length units; the wall, if any, at z = 0).
    a, eta : sphere radius and viscosity.
    wall : True above a no-slip wall (RPB far field and wall terms), False in free space.
    cutoff : pair cutoff in units of a (``Lub_Cut``, default 4.5).
    periodic_length : (3,) box lengths, 0 for non-periodic axes.
    firm_delta : gap clamp in units of a (default 1e-4).
    implementation : far-field blob products ('python', 'C++', 'pycuda'; None: C++ when built).
    matrices : :data:`lubrication.assembly.LubricationMatrices` already built at ``locations`` (else built).
    handover : ``'published'`` or ``'smooth'`` (the switches between formulas; :mod:`lubrication.resistance`).
    far_field : the far-field ``BlobMobility`` (None: :func:`far_field_mobility` of a, eta, the box, the wall and
        ``implementation``); ``self.far_field`` holds it and ``self.mobility_product`` is its grand product here.

    Protocol of ``multi_bodies.solver.body_solver.solve``: ``size`` (6N), ``operator`` (``x + M Delta_R x``),
    ``prepare_rhs`` (unchanged), ``solution(x)`` -> ``SolutionParts(None, velocities (N, 6), None)``.
    ``rhs(force_torque, velocity)`` builds ``X + M F``; ``preconditioner(tolerance)`` the published one.
    """

    def __init__(self, locations, a, eta, wall=True, cutoff=assembly.DEFAULT_CUTOFF, periodic_length=(0.0, 0.0, 0.0),
                 firm_delta=resistance.DEFAULT_FIRM_DELTA, implementation=None, matrices=None,
                 handover=DEFAULTS.lubrication_handover, far_field=None):
        locations, a, eta, cutoff, L = assembly.check_geometry(locations, a, eta, cutoff, periodic_length)
        if wall and np.any(locations[:, 2] <= 0):
            below = int(np.argmax(locations[:, 2] <= 0))
            raise UserInputError('lubrication: sphere %d is at or below the wall (z = %g); the spheres must be above '
                                 'z = 0' % (below, locations[below, 2]))
        self.locations, self.a, self.eta, self.cutoff, self.periodic_length = locations, a, eta, cutoff, L
        self.wall = bool(wall)
        if matrices is None:
            matrices = assembly.resistance_matrices(locations, a, eta, cutoff, L, wall, firm_delta, handover)
        self.matrices = matrices
        self.Delta_R = matrices.Delta_R
        self.num_bodies = locations.shape[0]
        self.size = 6 * self.num_bodies
        self.far_field = far_field if far_field is not None else far_field_mobility(eta, a, L, wall, implementation)
        self.mobility_product = far_field_product(locations, self.far_field)

    def matvec(self, x):
        """``(I + M Delta_R) x`` for x (6N,)."""
        x = np.asarray(x, dtype=float).reshape(-1)
        return x + self.mobility_product(csr_times(self.Delta_R, x))

    def rhs(self, force_torque=None, velocity=None):
        """``X + M F`` (6N,): force_torque F (N, 6) or (6N,) [F T per sphere], velocity X likewise (either None)."""
        out = np.zeros(self.size)
        if force_torque is not None:
            out += self.mobility_product(np.asarray(force_torque, dtype=float).reshape(-1))
        if velocity is not None:
            out += np.asarray(velocity, dtype=float).reshape(-1)
        return out

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, x):
        return SolutionParts(None, np.asarray(x, dtype=float).reshape(self.num_bodies, 6), None)

    def preconditioner(self, tolerance):
        """The published preconditioner at this configuration, shift ``6 pi eta a * tolerance`` (the solves'
        relative tolerance)."""
        return LubricationPreconditioner(self.matrices, 6.0 * np.pi * self.eta * self.a * tolerance)


def solver_and_tolerance(solver, tolerance, minimal_residual=False):
    """(solver, tolerance) of a lubrication function: ``solver`` (a ``multi_bodies.solver.solves.Solver``: a step's,
    which counts its solves and stops the run at one that does not converge), or when None one that stops at such
    a solve, with ``minimal_residual``; ``tolerance`` None is the solver's (the option table's ``solver_tolerance``
    for a new one)."""
    if solver is None:
        solver = Solver(tolerance, minimal_residual=minimal_residual)
    return solver, solver.tolerance if tolerance is None else float(tolerance)


def lubricated_velocities(locations, force_torque, a, eta, tolerance=None, x0=None, solver=None, **options):
    """Velocities ``M_lub F`` of spheres at ``locations`` (N, 3) under force_torque (N, 6): a ``SolveResult``.

    ``options`` go to :class:`LubricationProblem` (wall, cutoff, periodic_length, firm_delta,
    implementation).  ``result.velocities`` is (N, 6) ``[U W]``; ``result.iterations`` the GMRES count.
    tolerance : None is the solver's; solver : see :func:`solver_and_tolerance` (a solve that does not converge
    raises ``utils.SimulationStopped`` unless the solver flags it).
    """
    solver, tolerance = solver_and_tolerance(solver, tolerance)
    problem = LubricationProblem(locations, a, eta, **options)
    return solver.solve(problem, problem.rhs(force_torque), problem.preconditioner(tolerance), x0=x0,
                        tolerance=tolerance, kind='lubrication', what='the lubrication problem')


def dense_far_field_mobility(problem):
    """The far-field M (6N, 6N) of a problem, column by column (small N: tests and checks)."""
    identity = np.eye(problem.size)
    M = np.column_stack([problem.mobility_product(column) for column in identity])
    return 0.5 * (M + M.T)


def dense_lubricated_mobility(problem):
    """``M_lub = (M^-1 + Delta_R)^-1`` (6N, 6N) by dense algebra (small N: tests and checks)."""
    M = dense_far_field_mobility(problem)
    M_lub = np.linalg.inv(np.linalg.inv(M) + problem.Delta_R.toarray())
    return 0.5 * (M_lub + M_lub.T)
