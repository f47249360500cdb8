"""Rigid bodies whose surface has a Navier slip length: the modified saddle-point problem (floor 3).

Each blob of such a body carries a lab-frame normal ``n_i`` (its ``.slip_length``
file's body-frame normal turned with the body, not renormalised), a slip
length ``l_i`` ([L], 0 is no slip) and a quadrature weight ``w_i`` ([L]^2).
The unknowns are ``X = [lambda (3N); U (6Nb); u (3N)]``: blob forces, body
velocities and the surface slip velocity of every blob.  With
``xi_i = l_i / (eta w_i)``, ``P_i = I - n_i n_i^T`` and the Stokes double
layer ``D`` of :func:`double_layer` the equations are (the published FreeSlip
formulation, doc/phoretic.md)::

    M lambda - (I/2 + D)(K U) - (I/2 + D) u = s_RHS
    -K^T lambda                              = -F
    Xi P lambda + u                          = 0      (Navier: u = -(l / (eta w)) P lambda)

with ``s_RHS = s - s_rig / 2 + D[s_rig]`` for a prescribed slip ``s``, where
``s_rig`` is the rigid motion ``m_k + o_k x (r_i - x_k)`` with
``(m_k, o_k) = K_k^T s_k / N_k``.  For ``l = 0`` the slip ``u`` vanishes but
``(I/2 + D) K U`` stays in place of ``K U``: the solution differs from the
ordinary rigid one by a discretisation error (``D`` of a rigid motion is
about half of it on a closed surface), which the tests measure.

``D`` is the free-space operator: the published code uses it whatever the
domain, and this package refuses slip-length bodies when the hydrodynamics
sees a wall (``multi_bodies.solver.surface``).
"""
import numpy as np

from body.body import K_dot, K_matrices
from multi_bodies.solver import neighbour_preconditioner as neighbours
from multi_bodies.solver.body_solver import (MobilityProblem, SolutionParts, blob_mobility, one_radius,
                                             radius_of_blobs, spd_inverse)
from multi_bodies.solver.linear_map import LinearMap, LinearProblem

PAIRS_PER_CHUNK = 1 << 19
SELF_DISTANCE = 1e-14  # pairs closer than this are skipped (the published self term)


try:  # the compiled pair loop (multi_bodies/solver/cpp/surface_module.cpp, OpenMP); NumPy without it
    from multi_bodies.solver import _surface_cpp
except ImportError:  # pragma: no cover - a build without a C++ compiler
    _surface_cpp = None


def double_layer(x, normals, weights, blob_radius, v, backend=None):
    """:func:`double_layer_numpy` (the reference), or the same sums by the compiled pair loop.

    backend : 'C++', 'python' or None (C++ when built).
    """
    if backend == 'python' or (backend is None and _surface_cpp is None):
        return double_layer_numpy(x, normals, weights, blob_radius, v)
    if _surface_cpp is None:
        raise RuntimeError('the C++ surface kernels are not built (python3 -m pip install --no-build-isolation '
                           '--no-deps -e .)')
    return _surface_cpp.stokes_double_layer(np.ascontiguousarray(x, dtype=float).reshape(-1, 3),
                                            np.ascontiguousarray(normals, dtype=float).reshape(-1, 3),
                                            np.ascontiguousarray(weights, dtype=float).reshape(-1),
                                            float(blob_radius), np.ascontiguousarray(v, dtype=float).reshape(-1, 3))


def double_layer_numpy(x, normals, weights, blob_radius, v):
    """The regularised Stokes double layer ``(D v)_i`` (N, 3) of blob vectors v (N, 3) or (3N,).

    ``(D v)_i = -(3 / 4 pi) sum_{j, r >= 1e-14} w_j / r^5 [ (1 - 10 a^2 / (3 r^2)) (r.n_j)(r.v_j) r
    + (2 a^2 / 3) ((n_j.v_j) r + (r.v_j) n_j + (r.n_j) v_j) ]`` with ``r = x_i - x_j``: the
    free-space stresslet double layer ``T_ilm = -(3 / 4 pi) r_i r_l r_m / r^5`` (no 1/eta) with the
    RPY-like correction ``(1 + a^2/3 grad^2)``.  x, normals (N, 3); weights (N,); blob_radius a.
    """
    x = np.ascontiguousarray(x, dtype=float).reshape(-1, 3)
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    v = np.asarray(v, dtype=float).reshape(-1, 3)
    w = np.asarray(weights, dtype=float).reshape(-1)
    a2 = float(blob_radius) ** 2
    N = x.shape[0]
    out = np.zeros((N, 3))
    nv = np.einsum('ij,ij->i', n, v) * w
    wn, wv = n * w[:, None], v * w[:, None]
    step = max(1, PAIRS_PER_CHUNK // max(1, N))
    for start in range(0, N, step):
        rows = slice(start, min(N, start + step))
        r = x[rows, None, :] - x[None, :, :]
        d2 = np.einsum('ijk,ijk->ij', r, r)
        far = d2 >= SELF_DISTANCE ** 2
        inv_d2 = np.divide(1.0, d2, out=np.zeros_like(d2), where=far)
        inv_r5 = inv_d2 * inv_d2 * np.sqrt(inv_d2)
        rn = np.einsum('ijk,jk->ij', r, n)
        rv = np.einsum('ijk,jk->ij', r, v)
        radial = inv_r5 * ((1.0 - (10.0 / 3.0) * a2 * inv_d2) * rn * rv * w[None, :] + (2.0 / 3.0) * a2 * nv[None, :])
        out[rows] = (np.einsum('ij,ijk->ik', radial, r)
                     + (2.0 / 3.0) * a2 * ((inv_r5 * rv) @ wn + (inv_r5 * rn) @ wv))
    return -(3.0 / (4.0 * np.pi)) * out


def navier_coefficients(slip_lengths, eta, weights):
    """``xi_i = l_i / (eta w_i)`` (N,) of slip lengths ``l`` (N,) [L], the viscosity ``eta`` and the quadrature
    weights ``w`` (N,) [L]^2: the Navier condition of blob i is ``u_i = -xi_i P_i lambda_i`` (``lambda_i / w_i`` the
    traction).  The one place the slip-length term is written: the problem and its preconditioners take it here."""
    return np.asarray(slip_lengths, dtype=float).reshape(-1) / (eta * np.asarray(weights, dtype=float).reshape(-1))


class SlipLengthProblem(LinearProblem):
    """The slip-length saddle-point problem of all bodies at one configuration (the problem protocol).

    Parameters
    ----------
    rigid : body_solver.MobilityProblem at the configuration (its ``M``, ``K`` and ``K^T`` products)
    normals : (N, 3) lab-frame normals; slip_lengths, weights : (N,)

    ``size`` = 6N + 6Nb; ``solution(x)`` gives ``SolutionParts(lambda (N, 3), U (Nb, 6), None)`` and
    :meth:`surface_slip` the surface slip velocity ``u`` (N, 3) of a solution.
    """

    def __init__(self, rigid, normals, slip_lengths, weights):
        self.rigid = rigid
        self.r_vectors = rigid.r_vectors  # (N, 3) lab-frame blob positions
        self.normals = np.asarray(normals, dtype=float).reshape(-1, 3)
        self.weights = np.asarray(weights, dtype=float).reshape(-1)
        self.slip_lengths = np.asarray(slip_lengths, dtype=float).reshape(-1)
        self.xi = navier_coefficients(self.slip_lengths, rigid.eta, self.weights)
        self.num_blobs, self.num_bodies = rigid.num_blobs, rigid.num_bodies
        self.size = 6 * self.num_blobs + 6 * self.num_bodies

    def D_dot(self, v):
        """``D v`` (N, 3) of blob vectors v (N, 3)."""
        return double_layer(self.rigid.r_vectors, self.normals, self.weights, self.rigid.blob_radius, v)

    def tangential(self, v):
        """``P v = v - n (n.v)`` (N, 3) of blob vectors v."""
        v = np.asarray(v, dtype=float).reshape(-1, 3)
        return v - self.normals * np.einsum('ij,ij->i', self.normals, v)[:, None]

    def split(self, x):
        """(lambda (N, 3), U (Nb, 6), u (N, 3)) of a vector of the layout ``[lambda; U; u]``."""
        x = np.asarray(x, dtype=float).reshape(-1)
        n3, nb6 = 3 * self.num_blobs, 6 * self.num_bodies
        return x[:n3].reshape(-1, 3), x[n3:n3 + nb6].reshape(-1, 6), x[n3 + nb6:].reshape(-1, 3)

    def matvec(self, x):
        lam, U, u = self.split(x)
        moving = self.rigid.K_dot(U) + u
        first = self.rigid.M_dot(lam).reshape(-1, 3) - 0.5 * moving - self.D_dot(moving)
        second = -self.rigid.KT_dot(lam).reshape(-1)
        third = self.xi[:, None] * self.tangential(lam) + u
        return np.concatenate((first.reshape(-1), second, third.reshape(-1)))

    def rhs(self, slip=None, force_torque=None):
        """``[s - s_rig/2 + D[s_rig]; -F; 0]`` (size,) of slip (N, 3) and force_torque (Nb, 6) (None: zero)."""
        rhs = np.zeros(self.size)
        n3, nb6 = 3 * self.num_blobs, 6 * self.num_bodies
        if slip is not None and np.any(slip):
            slip = np.asarray(slip, dtype=float).reshape(-1, 3)
            counts = np.diff(self.rigid.body_arrays.blob_offsets)
            mean_motion = self.rigid.KT_dot(slip).reshape(-1, 6) / counts[:, None]
            rigid_slip = self.rigid.K_dot(mean_motion).reshape(-1, 3)
            rhs[:n3] = (slip - 0.5 * rigid_slip + self.D_dot(rigid_slip)).reshape(-1)
        if force_torque is not None:
            rhs[n3:n3 + nb6] = -np.asarray(force_torque, dtype=float).reshape(-1)
        return rhs

    def prepare_rhs(self, rhs):
        n3, nb6 = 3 * self.num_blobs, 6 * self.num_bodies
        if self.num_bodies:
            rhs[n3:n3 + nb6] = self.rigid.project_forces(rhs[n3:n3 + nb6]).reshape(-1)
        return rhs

    def solution(self, x):
        lam, U, _ = self.split(x)
        return SolutionParts(lam, U, None)

    def surface_slip(self, x):
        """The surface slip velocity ``u`` (N, 3) of a solution x (size,)."""
        return self.split(x)[2]

    def without_prescribed_motion(self, velocities):
        return velocities


def double_layer_blocks(targets, sources, normals, weights, blob_radius, backend=None):
    """Dense blocks of :func:`double_layer` from the blobs ``sources`` to the points ``targets``.

    targets (..., nt, 3); sources, normals (..., ns, 3) and weights (..., ns) of the source blobs (the same
    leading dimensions: a stack of pairs, or none).  Returns (..., 3 nt, 3 ns): block ``(i, j)`` is
    ``-(3 / 4 pi) w_j / r^5 [ (1 - 10 a^2 / (3 r^2)) (r.n_j) r r^T + (2 a^2 / 3) (r n_j^T + n_j r^T + (r.n_j) I) ]``
    with ``r = x_i - x_j``, zero for ``r < 1e-14``.  backend : 'C++' (the compiled pair loop), 'python'
    (:func:`double_layer_blocks_numpy`, the reference) or None (C++ when built).
    """
    if backend == 'python' or (backend is None and _surface_cpp is None):
        return double_layer_blocks_numpy(targets, sources, normals, weights, blob_radius)
    x_t = np.asarray(targets, dtype=float)
    x_s = np.asarray(sources, dtype=float)
    lead = x_t.shape[:-2]
    if x_s.shape[:-2] != lead:
        raise ValueError('targets and sources must have the same leading dimensions, got %s and %s'
                         % (x_t.shape, x_s.shape))
    nt, ns = x_t.shape[-2], x_s.shape[-2]
    stack = int(np.prod(lead, dtype=int))
    blocks = _surface_cpp.stokes_double_layer_blocks(
        np.ascontiguousarray(x_t.reshape(stack, nt, 3)), np.ascontiguousarray(x_s.reshape(stack, ns, 3)),
        np.ascontiguousarray(np.asarray(normals, dtype=float).reshape(stack, ns, 3)),
        np.ascontiguousarray(np.asarray(weights, dtype=float).reshape(stack, ns)), float(blob_radius))
    return blocks.reshape(lead + (3 * nt, 3 * ns))


def double_layer_blocks_numpy(targets, sources, normals, weights, blob_radius):
    """:func:`double_layer_blocks` in NumPy (the reference of the compiled loop; leading dimensions broadcast)."""
    x_t = np.asarray(targets, dtype=float)
    x_s = np.asarray(sources, dtype=float)
    n = np.asarray(normals, dtype=float)
    w = np.asarray(weights, dtype=float)
    a2 = float(blob_radius) ** 2
    r = x_t[..., :, None, :] - x_s[..., None, :, :]
    d2 = np.einsum('...k,...k->...', r, r)
    far = d2 >= SELF_DISTANCE ** 2
    inv_d2 = np.divide(1.0, d2, out=np.zeros_like(d2), where=far)
    scale = -(3.0 / (4.0 * np.pi)) * w[..., None, :] * inv_d2 * inv_d2 * np.sqrt(inv_d2)
    rn = np.einsum('...ijk,...jk->...ij', r, n)
    nj = np.broadcast_to(n[..., None, :, :], r.shape)
    blocks = (((1.0 - (10.0 / 3.0) * a2 * inv_d2) * rn)[..., None, None] * r[..., :, None] * r[..., None, :]
              + (2.0 / 3.0) * a2 * (r[..., :, None] * nj[..., None, :] + nj[..., :, None] * r[..., None, :]
                                    + rn[..., None, None] * np.eye(3)))
    blocks *= scale[..., None, None]
    nt, ns = r.shape[-3], r.shape[-2]
    return np.swapaxes(blocks, -3, -2).reshape(r.shape[:-3] + (3 * nt, 3 * ns))


def double_layer_matrix(x, normals, weights, blob_radius):
    """Dense ``D`` (3n, 3n) of :func:`double_layer` among blobs x (n, 3) (one body: the preconditioner's blocks);
    the blocks of :func:`double_layer_blocks`."""
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    return double_layer_blocks(x, x, np.asarray(normals, dtype=float).reshape(-1, 3),
                               np.asarray(weights, dtype=float).reshape(-1), blob_radius)


class SlipLengthPreconditioner(LinearMap):
    """Block-diagonal preconditioner of :class:`SlipLengthProblem`: each body alone, solved exactly.

    mobility : the BlobMobility of the dense blocks (the model's blobs mobility), or a function of the published
    form ``f(r (nb, n, 3), eta, a) -> (nb, 3n, 3n)`` with eta and blob_radius (the radius of the double layer is
    ``blob_radius``, else the mobility's one radius, else the body arrays').
    normals : (N, 3) body-frame normals (turned with the bodies at ``configuration`` here); slip_lengths,
    weights : (N,).  ``kind='double_layer'`` (the default): per body, with ``B_k = I/2 + D_k`` (the body's
    own double layer, dense) and ``A_k = M_k + B_k Xi_k P_k`` (LU inverse), applied to ``y = [y1; y2; y3]``::

        U = -S_k^+ (y2 + K^T A^-1 (y1 + B y3)),  S_k = K^T A^-1 B K,
        lambda = A^-1 (y1 + B y3 + B K U),        u = y3 - Xi P lambda,

    the exact inverse of the system of one body (a single body converges in one or two iterations).
    ``kind='published'``: the published preconditioner, ``B = I`` and ``y1`` alone in the first solve (exact
    only without ``D`` and when ``y3 = 0``).  Both give the same solution to the solver tolerance; the
    published one needs a few more iterations (measured, 42-blob shells in random orientations: one shell 5
    against 1, ten shells 14 against 9, at l = 1 and l = 1e3).
    """

    def __init__(self, body_arrays, configuration, mobility, eta=None, blob_radius=None, normals=None,
                 slip_lengths=None, weights=None, kind='double_layer'):
        if kind not in ('double_layer', 'published'):
            raise ValueError("kind must be 'double_layer' or 'published', got %r" % (kind,))
        self.body_arrays, self.kind = body_arrays, kind
        mobility = blob_mobility(body_arrays, mobility, eta, blob_radius, role='stacked_dense_matrix')
        eta, blob_radius = mobility.eta, one_radius(mobility, body_arrays, blob_radius)
        r_vectors = body_arrays.blob_positions(configuration)
        locations = configuration.locations
        from multi_bodies.solver.phoretic import lab_normals
        normals = lab_normals(body_arrays, configuration, np.asarray(normals, dtype=float).reshape(-1, 3))
        weights = np.asarray(weights, dtype=float).reshape(-1)
        self.xi = navier_coefficients(slip_lengths, eta, weights)
        self.normals, self.weights, self.configuration = normals, weights, configuration
        self.blocks = []
        for (bodies, blobs), n_blobs in zip(body_arrays.type_slices, body_arrays.type_blobs):
            nb = bodies.stop - bodies.start
            if nb == 0:
                self.blocks.append(None)
                continue
            r_type = r_vectors[blobs].reshape(nb, n_blobs, 3)
            M = np.array(mobility.replace(blob_radius=radius_of_blobs(mobility, blobs, (nb, n_blobs))).dense_matrix(
                r_type), dtype=float)
            n = normals[blobs].reshape(nb, n_blobs, 3)
            xiP = self.xi[blobs].reshape(nb, n_blobs, 1, 1) * (np.eye(3) - n[:, :, :, None] * n[:, :, None, :])
            XiP = np.zeros_like(M)
            for i in range(n_blobs):  # the 3x3 diagonal blocks (a loop over a body's blobs, set-up only)
                XiP[:, 3 * i:3 * i + 3, 3 * i:3 * i + 3] = xiP[:, i]
            if kind == 'published':
                B = np.broadcast_to(np.eye(3 * n_blobs), M.shape)
                A_inv = np.stack([spd_inverse(block) for block in M + XiP])
            else:
                w_type = weights[blobs].reshape(nb, n_blobs)
                B = np.stack([0.5 * np.eye(3 * n_blobs) + double_layer_matrix(r_type[k], n[k], w_type[k], blob_radius)
                              for k in range(nb)])
                A_inv = np.linalg.inv(M + B @ XiP)
            K = K_matrices(r_type, locations[bodies])
            A_inv_B = A_inv @ B
            A_inv_BK = A_inv_B @ K
            S_inv = np.linalg.pinv(np.swapaxes(K, 1, 2) @ A_inv_BK, rcond=1e-14)
            self.blocks.append((A_inv, A_inv_B, A_inv_BK, K, S_inv))
        self.size = 6 * body_arrays.num_blobs + 6 * body_arrays.num_bodies

    def apply(self, y):
        y = np.asarray(y, dtype=float).reshape(-1)
        n3, nb6 = 3 * self.body_arrays.num_blobs, 6 * self.body_arrays.num_bodies
        y1, y2, y3 = y[:n3].reshape(-1, 3), y[n3:n3 + nb6].reshape(-1, 6), y[n3 + nb6:].reshape(-1, 3)
        lam, U = np.zeros_like(y1), np.zeros_like(y2)
        slip_rows = bool(np.any(y3))  # zero in the neighbour correction's second application: half the work
        for (bodies, blobs), block in zip(self.body_arrays.type_slices, self.blocks):
            if block is None:
                continue
            A_inv, A_inv_B, A_inv_BK, K, S_inv = block
            nb = bodies.stop - bodies.start
            first = A_inv @ y1[blobs].reshape(nb, -1, 1)
            if self.kind != 'published' and slip_rows:
                first = first + A_inv_B @ y3[blobs].reshape(nb, -1, 1)
            U_k = -S_inv @ (y2[bodies][:, :, None] + np.swapaxes(K, 1, 2) @ first)
            lam[blobs] = (first + A_inv_BK @ U_k).reshape(-1, 3)
            U[bodies] = U_k[:, :, 0]
        P_lam = lam - self.normals * np.einsum('ij,ij->i', self.normals, lam)[:, None]
        u = y3 - self.xi[:, None] * P_lam
        return np.concatenate((lam.reshape(-1), U.reshape(-1), u.reshape(-1)))


# preconditioner auto: the neighbour correction is used when its near pairs (bodies whose bounding spheres come
# within the gap) hold at most this share of the blob pairs, its cost per application against one product.
# Measured (doc/preconditioners.md, benchmarks/bench_phoretic.py): a solve was faster at shares 0.03-0.15, as fast
# at 0.22 and slower at 0.38.
AUTO_MAX_COST_RATIO = 0.2


class SlipLengthNeighbourPreconditioner(LinearMap):
    """:class:`SlipLengthPreconditioner` corrected for the couplings of neighbouring bodies, to first order.

    With ``A = A_0 + O`` (``A_0`` every body alone, inverted exactly by the base preconditioner ``P``; ``O`` the
    couplings of different bodies, which enter the first rows only: ``(O x)_i = sum_j M_ij lambda_j - D_ij v_j``
    with ``v_j = K_j U_j + u_j`` body j's surface velocity) this applies

        z = P (r - O_near P r)

    the first-order elimination of the neighbours' unknowns (one Jacobi sweep on the near field), with
    ``O_near`` the blocks of the bodies whose blobs come within ``gap`` of each other
    (``neighbour_preconditioner.neighbour_pairs``).  The star Schur complement's second-order terms, which
    the rigid problem's :class:`~multi_bodies.solver.neighbour_preconditioner.NeighbourPreconditioner` adds,
    changed no iteration count measured here (doc/preconditioners.md), so they are left out.

    Parameters
    ----------
    base : SlipLengthPreconditioner at the configuration.
    mobility, eta, blob_radius, periodic_length, body_lengths, cross_blocks, max_cost_ratio :
        as :class:`~multi_bodies.solver.neighbour_preconditioner.NeighbourPreconditioner` takes them (the pair
        blocks ``M_ij`` come the same way; the model passes its blobs mobility, a ``BlobMobility``, alone).  ``D`` is the free-space double layer whatever the domain
        (:class:`SlipLengthProblem`), so only pairs that meet without a periodic shift get blocks ``D_ij``.
    gap : float or None (``DEFAULT_GAP_IN_RADII`` blob radii), surface-to-surface distance of neighbours.

    ``pairs`` (P, 2) holds the neighbour pairs (empty: the base preconditioner alone, e.g. when
    ``cost_ratio`` exceeded ``max_cost_ratio``).
    """

    def __init__(self, base, mobility, eta=None, blob_radius=None, periodic_length=(0.0, 0.0, 0.0), gap=None,
                 body_lengths=None, cross_blocks=None, max_cost_ratio=None, backend=None):
        if backend not in (None, 'C++', 'python'):
            raise ValueError("backend must be 'C++', 'python' or None, got %r" % (backend,))
        self.base = base
        mobility = blob_mobility(base.body_arrays, mobility, eta, blob_radius, role='stacked_dense_matrix',
                                 cross_blocks=cross_blocks)
        arrays, configuration, r_vectors, radii = neighbours.blobs_of(base, mobility.blob_radius)
        self.body_arrays, self.configuration, self.r_vectors = arrays, configuration, r_vectors
        if gap is None:
            gap = neighbours.DEFAULT_GAP_IN_RADII * float(np.max(radii)) if radii.size else 0.0
        self.gap = float(gap)
        self.num_blobs, self.num_bodies = arrays.num_blobs, arrays.num_bodies
        offsets = arrays.blob_offsets
        sizes = np.diff(offsets)
        candidates = neighbours.candidate_pairs(r_vectors, offsets, radii, configuration.locations, self.gap,
                                                periodic_length, body_lengths)
        self.cost_ratio = float(np.sum(sizes[candidates[0][:, 0]] * sizes[candidates[0][:, 1]])) / max(
            self.num_blobs, 1) ** 2
        if max_cost_ratio is not None and self.cost_ratio > max_cost_ratio:
            candidates = neighbours._no_pairs()
        self.pairs, shifts, _ = neighbours.neighbour_pairs(r_vectors, arrays.blob_body_index, radii,
                                                           configuration.locations, self.gap, periodic_length,
                                                           body_lengths, candidates=candidates)
        self.size = base.operator.shape[0]
        self.mobility_groups, self.double_layer_groups = [], []
        normals, weights, a = base.normals, base.weights, float(np.max(radii)) if radii.size else 0.0
        self.eta, self.blob_radius = mobility.eta, a
        unshifted = ~np.any(shifts != 0.0, axis=1)
        self.has_neighbours = bool(self.pairs.size)
        # the near field from the positions (compiled, uniform radii), else from stored pair blocks
        self.on_the_fly = backend != 'python' and _surface_cpp is not None and bool(radii.size) and np.ptp(radii) == 0
        if backend == 'C++' and not self.on_the_fly:
            raise RuntimeError('the compiled slip-length near field needs the C++ surface kernels and blobs of one '
                               'radius')
        if self.on_the_fly:
            # every pair in both directions, ordered by target body: (target, partner, shift added to the partner)
            targets = np.concatenate((self.pairs[:, 0], self.pairs[:, 1]))
            partners = np.concatenate((self.pairs[:, 1], self.pairs[:, 0]))
            both_shifts = np.concatenate((shifts, -shifts)).reshape(-1, 3)
            order = np.argsort(targets, kind='stable')
            # the compiled loop's arguments, made once: positions, normals, weights, radius, eta, body offsets and the
            # partner lists (its own range of partners per target body, each partner's shift and double-layer flag)
            self.near_field_arguments = (
                np.ascontiguousarray(r_vectors, dtype=float), np.ascontiguousarray(normals, dtype=float),
                np.ascontiguousarray(weights, dtype=float), a, self.eta,
                np.ascontiguousarray(offsets, dtype=np.int64),
                np.searchsorted(targets[order], np.arange(self.num_bodies + 1)).astype(np.int64),
                partners[order].astype(np.int64), np.ascontiguousarray(both_shifts[order]),
                np.concatenate((unshifted, unshifted))[order].astype(np.int64))
            return
        for chosen, t_i, t_j, O in neighbours.pair_blocks(arrays, r_vectors, radii, self.pairs, shifts, mobility):
            i, j = self.pairs[chosen, 0], self.pairs[chosen, 1]
            first_i, first_j = (3 * offsets[i]).astype(np.int64), (3 * offsets[j]).astype(np.int64)
            self.mobility_groups.append((first_i, first_j, O))
            use = np.flatnonzero(unshifted[chosen])
            if use.size == 0:
                continue
            blobs_i = offsets[i[use]][:, None] + np.arange(arrays.type_blobs[t_i])[None, :]
            blobs_j = offsets[j[use]][:, None] + np.arange(arrays.type_blobs[t_j])[None, :]
            n3 = 3 * self.num_blobs
            # the two directions, in the layout of near_field_product: target rows offset by 3N
            self.double_layer_groups.append((n3 + first_i[use], first_j[use], double_layer_blocks(
                r_vectors[blobs_i], r_vectors[blobs_j], normals[blobs_j], weights[blobs_j], a)))
            self.double_layer_groups.append((n3 + first_j[use], first_i[use], double_layer_blocks(
                r_vectors[blobs_j], r_vectors[blobs_i], normals[blobs_i], weights[blobs_i], a)))

    def near_field_product(self, lam, v):
        """``(O_near x)`` in the first rows (3N,): ``sum_j M_ij lambda_j - D_ij v_j`` over the neighbour pairs.

        lam (N, 3) blob forces; v (N, 3) surface velocities ``K U + u``.
        """
        if self.on_the_fly:
            return _surface_cpp.slip_length_near_field(
                *self.near_field_arguments, np.ascontiguousarray(lam, dtype=float).reshape(-1, 3),
                np.ascontiguousarray(v, dtype=float).reshape(-1, 3)).reshape(-1)
        n3 = 3 * self.num_blobs
        out = neighbours.symmetric_pair_product(self.mobility_groups, lam)
        if self.double_layer_groups:
            # D is not symmetric: each direction of a pair goes through the compiled symmetric pair loop with its
            # target rows moved past the end of the vector, where the input is zero (so the transposed half adds
            # nothing) and the output lands apart
            extended = np.concatenate((-np.asarray(v, dtype=float).reshape(-1), np.zeros(n3)))
            out = out + neighbours.symmetric_pair_product(self.double_layer_groups, extended)[n3:]
        return out

    def apply(self, y):
        """The preconditioner applied to ``y = [y1 (3N); y2 (6Nb); y3 (3N)]`` (the problem's layout)."""
        y = np.asarray(y, dtype=float).reshape(-1)
        z = self.base.apply(y)
        if not self.has_neighbours:
            return z
        n3, nb6 = 3 * self.num_blobs, 6 * self.num_bodies
        lam, U, u = z[:n3].reshape(-1, 3), z[n3:n3 + nb6].reshape(-1, 6), z[n3 + nb6:].reshape(-1, 3)
        v = K_dot(self.r_vectors, self.configuration.locations, self.body_arrays.blob_body_index, U) + u
        s = y.copy()
        s[:n3] -= self.near_field_product(lam, v)
        return self.base.apply(s)


def slip_length_problem(body_arrays, configuration, mobility, eta=None, blob_radius=None, periodic_length=None,
                        reference_normals=None, slip_lengths=None, weights=None):
    """The :class:`SlipLengthProblem` at ``configuration`` (normals turned with the bodies); ``mobility``, ``eta``,
    ``blob_radius`` and ``periodic_length`` as :class:`body_solver.MobilityProblem` takes them."""
    from multi_bodies.solver.phoretic import lab_normals
    rigid = MobilityProblem(body_arrays, configuration, mobility, eta, blob_radius, periodic_length)
    return SlipLengthProblem(rigid, lab_normals(body_arrays, rigid.configuration, reference_normals),
                             slip_lengths, weights)
