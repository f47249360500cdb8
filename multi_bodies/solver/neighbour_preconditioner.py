"""A block-diagonal preconditioner corrected for the hydrodynamic coupling of neighbouring bodies.

The block-diagonal preconditioner ``P`` (:class:`body_solver.BlockDiagonalPreconditioner`) inverts the
saddle-point system of every body alone.  With ``M = D + O`` (``D`` the bodies' own blob mobilities,
``O`` the blob-blob couplings between bodies) the preconditioned operator is ``A P^{-1} = I + [O Q; 0]``
with ``Q_k`` the blob-blob block of ``P_k^{-1}``: the force-free, torque-free response of body ``k`` to a
flow.  GMRES converges as fast as the spectrum of ``I + O Q`` clusters at 1, and in a suspension its
outliers come from bodies that nearly touch (dense-matrix measurements: ``doc/preconditioners.md``).

This preconditioner keeps, for every body ``i``, the couplings to its neighbours ``j`` (bodies whose blobs
come within ``gap`` of body ``i``'s): eliminating the neighbours' unknowns to first order in ``O`` gives
the local system

    T_i x_i = r_i - sum_j O_ij (P^{-1} r)_j,    T_i = P_i - sum_j O_ij Q_j O_ji   (in the blob rows),

which is the exact Schur complement of the star ``{i} + neighbours`` when the neighbours do not see each
other.  ``T_i^{-1}`` is applied to first order in ``W_i = sum_j O_ij Q_j O_ji`` (Sherman-Morrison-Woodbury
with ``(I - W_i Q_i)^{-1} ~ I``): ``T_i^{-1} s ~ z + P_i^{-1} [W_i z_lambda; 0]`` with ``z = P_i^{-1} s``.
The exact Woodbury factor gave the same GMRES iteration counts in every scene measured, at the cost of a
batched solve; and only the pairs closer than ``strong_gap`` need their terms in ``W_i`` (the others enter
through the right-hand side alone, at the same iteration counts).  So the base preconditioner is used as it
is (any body kind it handles); for the bodies with a close neighbour ``P_i^{-1} [W_i; 0]`` is stored.  One
application costs two applications of the base preconditioner, one near-field product ``O_near`` and one
product with those stored blocks.  With the C++ blob mobility (one radius, a wall or free space) the
near field is computed again from the blob positions at every application by a compiled loop over the
neighbour pairs' blobs (``_preconditioner_cpp.rigid_near_field``); otherwise the pair blocks ``O_ij`` are
stored and read once per application (``_preconditioner_cpp.pair_product``).

Bodies of prescribed motion (obstacles) have unknown net forces, which couple at long range; their rigid
modes are coupled exactly by a small Galerkin system (:class:`_ObstacleCoarseCorrection`), also where no
pair is a neighbour.

The Lanczos noise keeps the base preconditioner's Cholesky factors (SPEC decision 1): only the GMRES
preconditioner changes, and GMRES converges to the same solution within ``solver_tolerance``.
"""
import numpy as np

from multi_bodies.solver.body_solver import blob_mobility, blob_radius_argument
from multi_bodies.solver.linear_map import WrapsPreconditioner

try:
    from multi_bodies.solver import _preconditioner_cpp
except ImportError:  # pragma: no cover - the compiled kernels are built by the install
    _preconditioner_cpp = None

# Blob surfaces of two bodies closer than this many (largest) blob radii make them neighbours; closer than
# the second, their second-order terms W enter too (measured: doc/preconditioners.md).
DEFAULT_GAP_IN_RADII = 8.0
DEFAULT_STRONG_GAP_IN_RADII = 2.0
# preconditioner auto: the correction is built only when the candidate pairs (bodies whose bounding spheres come
# within the gap) hold at most this fraction of all blob pairs (sum n_i n_j / N^2), an estimate of the ratio of
# its build cost to one M f product known before any blob distance is computed.  Measured (doc/preconditioners.md):
# a step was faster with the correction at 0.034 (100 boomerangs) and 0.0038 (1,000), slower at 0.087 (pillars),
# 0.12 (packed boomerangs) and 0.15 (articulated bacteria).
AUTO_MAX_COST_RATIO = 0.06


def _no_pairs():
    return np.zeros((0, 2), dtype=int), np.zeros((0, 3)), np.zeros(0)


def candidate_pairs(r_vectors, blob_offsets, radii, locations, gap, periodic_length=(0.0, 0.0, 0.0),
                    body_lengths=None):
    """Pairs of bodies whose bounding spheres come within the pair's gap limit (body-level search).

    r_vectors (N, 3) with each body's blobs contiguous (``blob_offsets`` (Nb + 1,)), radii (N,), locations
    (Nb, 3), gap (length), periodic_length (3,), body_lengths (Nb,) or None (the limit of a pair is
    ``min(gap, smaller body length)``).  Returns (pairs (P, 2) with ``i < j``, shifts (P, 3): the image
    displacement added to body ``j``'s blobs (periodic directions), limits (P,)).  In a periodic box a pair
    that meets through two images is listed twice, with each shift.
    """
    from scipy.spatial import cKDTree
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    num_bodies = locations.shape[0]
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    periodic = L > 0
    offsets = np.asarray(blob_offsets)
    sizes = np.diff(offsets)
    if num_bodies < 2 or np.any(sizes == 0):
        return _no_pairs()
    body_of_blob = np.repeat(np.arange(num_bodies), sizes)
    # bounding radius of every body about its location (blob surfaces included)
    bounding = np.maximum.reduceat(np.linalg.norm(r_vectors - locations[body_of_blob], axis=1) + radii,
                                   offsets[:-1])
    lengths = np.full(num_bodies, np.inf) if body_lengths is None else np.asarray(body_lengths, float).reshape(-1)
    reach = 2.0 * float(bounding.max()) + min(gap, float(lengths.max()))
    # the periodic images to search: every combination of -L, 0, L in the periodic directions (a pair may meet
    # through two images in a small box: it is then two pairs, whose couplings add)
    centres = locations.copy()
    centres[:, periodic] = np.mod(centres[:, periodic], L[periodic])
    wrap = centres - locations
    steps = [np.array([-1.0, 0.0, 1.0]) if periodic[k] else np.zeros(1) for k in range(3)]
    images = np.stack(np.meshgrid(*steps, indexing='ij'), axis=-1).reshape(-1, 3) * np.where(periodic, L, 0.0)
    tree = cKDTree(centres)
    found = []
    for image in images:
        if not np.any(image):
            pairs = tree.query_pairs(reach, output_type='ndarray')
        else:
            near = tree.query_ball_point(centres + image, reach)
            counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=num_bodies)
            pairs = np.stack((np.concatenate([np.asarray(n, dtype=np.int64) for n in near] or [np.zeros(0, int)]),
                              np.repeat(np.arange(num_bodies), counts)), axis=1) if counts.sum() else \
                np.zeros((0, 2), dtype=np.int64)
        pairs = pairs[pairs[:, 0] < pairs[:, 1]]  # i < j; the opposite image gives the reversed pairs
        found.append((pairs, np.broadcast_to(image, (pairs.shape[0], 3))))
    pairs = np.concatenate([f[0] for f in found]).astype(int)
    image = np.concatenate([f[1] for f in found])
    if pairs.size == 0:
        return _no_pairs()
    i, j = pairs[:, 0], pairs[:, 1]
    shifts = wrap[j] - wrap[i] + image  # added to body j's blobs (as given) to sit next to body i's
    limits = np.minimum(gap, np.minimum(lengths[i], lengths[j]))
    keep = np.linalg.norm(locations[j] + shifts - locations[i], axis=1) < bounding[i] + bounding[j] + limits
    pairs, shifts, limits = pairs[keep], shifts[keep], limits[keep]
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order], shifts[order], limits[order]


def neighbour_pairs(r_vectors, blob_body_index, radii, locations, gap, periodic_length=(0.0, 0.0, 0.0),
                    body_lengths=None, candidates=None):
    """Pairs of bodies whose blobs come within ``gap`` of each other (surface to surface).

    r_vectors (N, 3), blob_body_index (N,) (each body's blobs contiguous), radii (N,) blob radii, locations
    (Nb, 3) body locations, gap : float (length), periodic_length (3,) (0: not periodic; periodic directions
    use the minimum image of the body locations), body_lengths (Nb,) or None: a pair's gap must also be below
    the smaller of its two body lengths (small bodies, single blobs above all, feel their neighbours only when
    they nearly touch); candidates: the result of :func:`candidate_pairs` (None: computed here).
    Returns (pairs (P, 2) int with ``i < j``, shifts (P, 3): the image displacement added to body ``j``'s
    blobs so that they sit next to body ``i``'s, gaps (P,): the smallest surface-to-surface distance).
    """
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    radii = np.broadcast_to(np.asarray(radii, dtype=float), (r_vectors.shape[0],))
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    blob_body_index = np.asarray(blob_body_index)
    offsets = np.searchsorted(blob_body_index, np.arange(locations.shape[0] + 1))
    if candidates is None:
        candidates = candidate_pairs(r_vectors, offsets, radii, locations, gap, periodic_length, body_lengths)
    pairs, shifts, limits = candidates
    if pairs.size == 0:
        return _no_pairs()
    sizes = np.diff(offsets)
    gaps = np.empty(pairs.shape[0])
    uniform = bool(np.ptp(radii) == 0)
    keys = sizes[pairs[:, 0]] * (int(sizes.max()) + 1) + sizes[pairs[:, 1]]
    for key in np.unique(keys):  # the blob distances of the candidates, by stacks of equal sizes
        chosen = np.flatnonzero(keys == key)
        i, j = pairs[chosen, 0], pairs[chosen, 1]
        blobs_i = offsets[i][:, None] + np.arange(sizes[i[0]])[None, :]
        blobs_j = offsets[j][:, None] + np.arange(sizes[j[0]])[None, :]
        # squared distances |a|^2 + |b|^2 - 2 a.b by one batched product, about body i's location (small numbers)
        origin = locations[i][:, None, :]
        own, partners = r_vectors[blobs_i] - origin, r_vectors[blobs_j] + shifts[chosen][:, None, :] - origin
        squared = (np.einsum('pak,pak->pa', own, own)[:, :, None] + np.einsum('pbk,pbk->pb', partners, partners)[
            :, None, :] - 2.0 * np.matmul(own, np.swapaxes(partners, 1, 2)))
        if uniform:
            gaps[chosen] = np.sqrt(np.maximum(squared.reshape(chosen.size, -1).min(axis=1), 0.0)) - 2.0 * radii[0]
        else:
            surface = np.sqrt(np.maximum(squared, 0.0)) - radii[blobs_i][:, :, None] - radii[blobs_j][:, None, :]
            gaps[chosen] = surface.reshape(chosen.size, -1).min(axis=1)
    close = gaps < limits
    return pairs[close].astype(int), shifts[close], gaps[close]


def blobs_of(base, blob_radius):
    """(body arrays, configuration, blob positions (N, 3), blob radii (N,)) of a preconditioner ``base``."""
    arrays = base.body_arrays
    configuration = base.configuration
    radii = np.broadcast_to(np.asarray(blob_radius_argument(arrays, blob_radius), dtype=float), (arrays.num_blobs,))
    return arrays, configuration, arrays.blob_positions(configuration), radii


def body_types(body_arrays):
    """(structure type of every body (Nb,), index of every body within its type (Nb,))."""
    body_type = np.zeros(body_arrays.num_bodies, dtype=int)
    local = np.zeros(body_arrays.num_bodies, dtype=int)
    for t, (bodies, _) in enumerate(body_arrays.type_slices):
        body_type[bodies] = t
        local[bodies] = np.arange(bodies.stop - bodies.start)
    return body_type, local


def cross_or_stacked_blocks(mobility, r_i, r_j, radius, radii_i=None, radii_j=None):
    """The off-diagonal blocks (P, 3ni, 3nj) of the blob mobility of pairs of bodies r_i (P, ni, 3), r_j (P, nj, 3).

    radius : the one radius of every blob, or None: then radii_i (P, ni) and radii_j (P, nj) are the pairs'.
    With one radius ``mobility.cross_blocks`` where the backend builds them; else (or when it does not) the
    off-diagonal blocks of ``dense_matrix`` of the pairs' stacks (four times the work).
    """
    O = None
    if radius is not None:
        O = mobility.replace(blob_radius=radius).cross_blocks(r_i, r_j)
    if O is None:
        n_i = r_i.shape[1]
        stack_radius = radius if radius is not None else np.concatenate((radii_i, radii_j), axis=1)
        O = mobility.replace(blob_radius=stack_radius).dense_matrix(np.concatenate((r_i, r_j), axis=1))[
            :, :3 * n_i, 3 * n_i:]
    return O


def pair_blocks(body_arrays, r_vectors, radii, pairs, shifts, mobility, body_type=None):
    """The blob mobility blocks ``M_ij`` of body pairs, by groups of pairs of the same two structure types.

    r_vectors (N, 3), radii (N,), pairs (P, 2) and shifts (P, 3) as :func:`neighbour_pairs` returns them;
    mobility the BlobMobility of the dense blocks (:func:`cross_or_stacked_blocks`); body_type (Nb,) or None.
    Yields (chosen (p,): the group's rows of ``pairs``, t_i, t_j: the two types, O (p, 3 n_i, 3 n_j): rows of
    body ``pairs[chosen, 0]``'s blobs, columns of ``pairs[chosen, 1]``'s, shifted by ``shifts``).
    """
    if body_type is None:
        body_type = body_types(body_arrays)[0]
    offsets = body_arrays.blob_offsets
    num_types = len(body_arrays.type_blobs)
    keys = body_type[pairs[:, 0]] * num_types + body_type[pairs[:, 1]]
    for key in np.unique(keys):
        chosen = np.flatnonzero(keys == key)
        i, j = pairs[chosen, 0], pairs[chosen, 1]
        t_i, t_j = divmod(int(key), num_types)
        n_i, n_j = body_arrays.type_blobs[t_i], body_arrays.type_blobs[t_j]
        blobs_i = offsets[i][:, None] + np.arange(n_i)[None, :]
        blobs_j = offsets[j][:, None] + np.arange(n_j)[None, :]
        r_i, r_j = r_vectors[blobs_i], r_vectors[blobs_j] + shifts[chosen][:, None, :]
        if np.ptp(radii) == 0:
            O = cross_or_stacked_blocks(mobility, r_i, r_j, float(radii[0]))
        else:
            O = cross_or_stacked_blocks(mobility, r_i, r_j, None, radii[blobs_i], radii[blobs_j])
        yield chosen, t_i, t_j, np.ascontiguousarray(O)


def symmetric_pair_product(groups, blob_vector):
    """``sum over pairs`` of ``O_ij v_j`` (into body i's rows) and ``O_ij^T v_i`` (into body j's): (3N,).

    groups : (first_i (P,), first_j (P,), O (P, 3 n_i, 3 n_j)) of pairs of two structure types, ``first_*`` the
    first row (3 times the first blob) of each body; blob_vector (3N,).  A compiled loop that reads every block
    once (``_preconditioner_cpp.pair_product``), NumPy without it.
    """
    vector = np.ascontiguousarray(blob_vector, dtype=float).reshape(-1)
    out = np.zeros_like(vector)
    for first_i, first_j, O in groups:
        if _preconditioner_cpp is not None:
            _preconditioner_cpp.pair_product(O, first_i, first_j, vector, out)
            continue
        rows_i = first_i[:, None] + np.arange(O.shape[1])[None, :]
        rows_j = first_j[:, None] + np.arange(O.shape[2])[None, :]
        np.add.at(out, rows_i, np.matmul(O, vector[rows_j][:, :, None])[:, :, 0])
        np.add.at(out, rows_j, np.matmul(vector[rows_i][:, None, :], O)[:, 0, :])
    return out


# the obstacles' coarse correction is built for at most this many bodies of prescribed motion (a dense 6F x 6F
# system; its pair blocks grow as F^2)
MAX_COARSE_OBSTACLES = 200


class _ObstacleCoarseCorrection:
    """The couplings of the rigid modes of bodies of prescribed motion (obstacles), solved together.

    An obstacle's net force and torque are unknowns (the constraint rows do not fix them), so its blob forces
    couple to the other obstacles' at long range (1/r), beyond any neighbour gap.  With ``Phi_k = M_k^{-1} K_k``
    (the blob forces of obstacle ``k`` alone moving rigidly) the Galerkin matrix of those modes is
    ``E_kl = Phi_k^T M_kl Phi_l`` (``E_kk = R_k = K_k^T M_k^{-1} K_k``); the base preconditioner inverts its
    diagonal.  The correction adds ``Phi (E^{-1} - diag(R_k)^{-1}) Phi^T s`` to the obstacles' blob forces
    (and ``K_k^T`` of it to their constraint force-torque rows), so that the preconditioner is exact on those
    modes.  Measured (doc/preconditioners.md): 16 pillars among 84 spheres, 23 -> 18 iterations from zero.
    """

    def __init__(self, base, fixed, r_vectors, radii, mobility, periodic_length):
        arrays = base.body_arrays
        offsets = arrays.blob_offsets
        locations = base.configuration.locations
        L = np.asarray(periodic_length, dtype=float).reshape(3)
        self.blob_rows, self.body_rows, self.Phi, self.K = [], [], [], []
        resistances = []
        for body in fixed:
            t = next(k for k, (bodies, _) in enumerate(arrays.type_slices) if bodies.start <= body < bodies.stop)
            local = body - arrays.type_slices[t][0].start
            Phi = base.inverse_mobility_times_K[t][local]
            K = base.K[t][local]
            self.blob_rows.append(np.arange(3 * offsets[body], 3 * offsets[body + 1]))
            self.body_rows.append(3 * arrays.num_blobs + 6 * body + np.arange(6))
            self.Phi.append(Phi)
            self.K.append(K)
            resistances.append(K.T @ Phi)
        F = fixed.size
        memo = getattr(base, 'memo', None)  # the model's memo of the obstacles (obstacles.MixedPreconditioner)
        key = None
        if memo is not None:
            key = ('coarse', r_vectors[np.concatenate([np.arange(offsets[b], offsets[b + 1]) for b in fixed])].tobytes(),
                   locations[fixed].tobytes(), radii.tobytes(), L.tobytes(), float(mobility.eta))
            if key in memo.get('coarse', {}):  # the obstacles have not moved since the last build: the same matrix
                self.D = memo['coarse'][key]
                return
        E = np.zeros((6 * F, 6 * F))
        for a in range(F):
            E[6 * a:6 * a + 6, 6 * a:6 * a + 6] = resistances[a]
        radius = float(radii[0]) if np.ptp(radii) == 0 else None  # one radius, else the pairs' radii
        for a in range(F):
            for b in range(a + 1, F):
                i, j = fixed[a], fixed[b]
                r_i = r_vectors[offsets[i]:offsets[i + 1]]
                shift = np.zeros(3)
                periodic = L > 0
                shift[periodic] = -L[periodic] * np.round((locations[j] - locations[i])[periodic] / L[periodic])
                r_j = r_vectors[offsets[j]:offsets[j + 1]] + shift
                O = cross_or_stacked_blocks(mobility, r_i[None], r_j[None], radius,
                                            radii[None, offsets[i]:offsets[i + 1]],
                                            radii[None, offsets[j]:offsets[j + 1]])
                block = self.Phi[a].T @ O[0] @ self.Phi[b]
                E[6 * a:6 * a + 6, 6 * b:6 * b + 6] = block
                E[6 * b:6 * b + 6, 6 * a:6 * a + 6] = block.T
        diagonal = np.zeros_like(E)
        for a in range(F):
            diagonal[6 * a:6 * a + 6, 6 * a:6 * a + 6] = np.linalg.pinv(resistances[a], hermitian=True)
        self.D = np.linalg.pinv(E, hermitian=True) - diagonal
        if key is not None:
            memo['coarse'] = {key: self.D}  # the last build's only

    def add_to(self, x, z):
        """Add the correction of the input ``x`` (the base's layout) to the output ``z`` in place."""
        y = np.concatenate([Phi.T @ x[rows] for Phi, rows in zip(self.Phi, self.blob_rows)])
        c = self.D @ y
        for a, (Phi, K, blob_rows, body_rows) in enumerate(zip(self.Phi, self.K, self.blob_rows, self.body_rows)):
            correction = Phi @ c[6 * a:6 * a + 6]
            z[blob_rows] += correction
            z[body_rows] += K.T @ correction


class NeighbourPreconditioner(WrapsPreconditioner):
    """The base block-diagonal preconditioner with the couplings of neighbouring bodies (module docstring).

    Parameters
    ----------
    base : body_solver.BlockDiagonalPreconditioner (or a subclass: obstacles.MixedPreconditioner)
        Built at the same configuration.  It must provide ``apply``, ``blob_blocks()`` (the blob-blob blocks
        ``Q_k`` of its inverse, per structure type (nb, 3n, 3n)) and ``blob_body_blocks()`` (the body rows of
        its blob columns, (nb, 6, 3n)).
    mobility : mobility.interface.BlobMobility, the one the base preconditioner is built from (the model's blobs
        mobility: its ``dense_matrix`` of stacks of pairs, ``cross_blocks`` and ``near_field_domain``); or a
        function of the published form ``f(r (npairs, n, 3), eta, a) -> (npairs, 3n, 3n)`` with
    eta, blob_radius : float (blob_radius: or per-blob radii through the base's body arrays), and the functions
        ``cross_blocks`` and ``near_field_domain`` below (given with a function only).
    periodic_length : (3,) floats, the box in which neighbours are found (the minimum image of every pair)
    gap : float, surface-to-surface distance (length) below which two bodies are neighbours (None:
        DEFAULT_GAP_IN_RADII blob radii); their coupling enters to first order.
    strong_gap : float, the distance below which the pair's second-order terms ``W`` enter too (None:
        DEFAULT_STRONG_GAP_IN_RADII blob radii).
    body_lengths : (Nb,) or None, the bodies' length scales (``Model.body_lengths``): a pair is a neighbour
        pair only when its gap is also below the smaller body's length.
    cross_blocks : callable ``f(r_i (P, ni, 3), r_j (P, nj, 3), eta, a) -> (P, 3ni, 3nj)`` or None (returning
        None where it cannot): the pair blocks without the bodies' own blocks (``BlobMobility.cross_blocks``);
        None takes them from the dense blocks of the pairs (four times the work).
    max_cost_ratio : float or None, build the correction only when ``sum of n_i n_j / N^2`` over the candidate
        pairs (:func:`candidate_pairs`) is at most this (``preconditioner auto``); otherwise it is the base
        preconditioner (``pairs`` then empty and ``cost_ratio`` says why).  None: always.
    near_field_domain : 'single_wall', 'no_wall' or None: the domain of the blob mobility (that of
        ``cross_blocks``, the C++ backend's: ``BlobMobility.near_field_domain``) when the near field may be
        computed again from the positions at every
        application by the compiled loop (``_preconditioner_cpp.rigid_near_field``), storing the pair blocks of
        the strongly coupled pairs only; None (or blobs of several radii, or no compiled module): every
        neighbour pair's block is stored.  Both give the same preconditioner to rounding.
    exact_woodbury : bool, apply ``T_i^{-1}`` exactly (``G_i = (I - W_i Q_i)^{-1} W_i``, a batched solve)
        instead of to first order; then two bodies alone are preconditioned by the exact inverse.

    Every attribute the base preconditioner has (Cholesky factors for Lanczos, ``body_mobilities``, ...)
    is read through to it; ``apply`` and ``operator`` are this preconditioner's.  ``pairs`` (P, 2) holds
    the neighbour pairs.
    """

    def __init__(self, base, mobility, eta=None, blob_radius=None, periodic_length=(0.0, 0.0, 0.0), gap=None,
                 strong_gap=None, exact_woodbury=False, body_lengths=None, cross_blocks=None, max_cost_ratio=None,
                 near_field_domain=None):
        self.base = base
        mobility = blob_mobility(base.body_arrays, mobility, eta, blob_radius, role='stacked_dense_matrix',
                                 cross_blocks=cross_blocks, near_field_domain=near_field_domain)
        near_field_domain, eta = mobility.near_field_domain, mobility.eta
        arrays, configuration, r_vectors, radii = blobs_of(base, mobility.blob_radius)
        if gap is None:
            gap = DEFAULT_GAP_IN_RADII * float(np.max(radii)) if radii.size else 0.0
        if strong_gap is None:
            strong_gap = DEFAULT_STRONG_GAP_IN_RADII * float(np.max(radii)) if radii.size else 0.0
        self.gap, self.strong_gap = float(gap), float(strong_gap)
        self.num_blobs = arrays.num_blobs
        offsets = arrays.blob_offsets
        sizes = np.diff(offsets)
        candidates = candidate_pairs(r_vectors, offsets, radii, configuration.locations, self.gap,
                                     periodic_length, body_lengths)
        # the candidates' share of the blob pairs: the cost of the correction against one M f product
        candidate_blobs = np.sum(sizes[candidates[0][:, 0]] * sizes[candidates[0][:, 1]])
        self.cost_ratio = float(candidate_blobs) / max(self.num_blobs, 1) ** 2
        if max_cost_ratio is not None and self.cost_ratio > max_cost_ratio:
            candidates = _no_pairs()
        self.pairs, shifts, gaps = neighbour_pairs(r_vectors, arrays.blob_body_index, radii, configuration.locations,
                                                   self.gap, periodic_length, body_lengths, candidates=candidates)
        self.pair_gaps = gaps
        # every body's structure type and index within it; Q: the blob-blob blocks of the base inverse
        body_type, local = body_types(arrays)
        self.has_neighbours = bool(self.pairs.size)
        self.size = base.operator.shape[0]
        self.groups = []  # (first_i (P,), first_j (P,), O (P, 3 n_i, 3 n_j)): pairs of two structure types
        self.pair_groups = []  # (rows of pairs (P,), O): the same blocks, by the pairs they belong to
        self.second_order = []  # (blob rows (k, 3n), body rows (k, 6), blocks (k, 3n, 3n) and (k, 6, 3n))
        self.obstacles = None
        fixed = np.flatnonzero(getattr(base, 'fixed', np.zeros(0, dtype=bool)))
        if 2 <= fixed.size <= MAX_COARSE_OBSTACLES:
            self.obstacles = _ObstacleCoarseCorrection(base, fixed, r_vectors, radii, mobility, periodic_length)
        self.on_the_fly, self.stored_gap = False, self.gap
        if not self.has_neighbours:
            return  # every body alone: the base preconditioner (with the obstacles' coarse correction)
        Q = base.blob_blocks()
        W = [np.zeros_like(blocks) for blocks in Q]
        # the second-order terms are kept for the free bodies only: those of bodies of prescribed motion changed
        # no iteration count measured (16 pillars among 84 spheres: 14 either way) and cost most of the build
        second_order = ~np.asarray(getattr(base, 'fixed', np.zeros(arrays.num_bodies, dtype=bool)), dtype=bool)
        # the near field from the positions (compiled, one blob radius, a wall or free space), else from stored
        # pair blocks; on the fly, blocks are made only for the strongly coupled pairs (their W terms)
        self.on_the_fly = (near_field_domain in ('single_wall', 'no_wall') and _preconditioner_cpp is not None and
                           hasattr(_preconditioner_cpp, 'rigid_near_field') and bool(radii.size) and
                           np.ptp(radii) == 0 and not (near_field_domain == 'single_wall' and np.any(shifts[:, 2])))
        # pair_groups holds the blocks of every pair closer than stored_gap (noise_factor takes them from here)
        self.stored_gap = self.strong_gap if self.on_the_fly else self.gap
        stored = np.flatnonzero(gaps < self.strong_gap) if self.on_the_fly else np.arange(self.pairs.shape[0])
        if self.on_the_fly:
            # every pair once, under its first body (the pairs are sorted by it): the loop adds both directions
            self.near_field_arguments = (
                np.ascontiguousarray(r_vectors, dtype=float), float(radii[0]), float(eta),
                near_field_domain == 'single_wall', np.ascontiguousarray(offsets, dtype=np.int64),
                np.searchsorted(self.pairs[:, 0], np.arange(arrays.num_bodies + 1)).astype(np.int64),
                np.ascontiguousarray(self.pairs[:, 1], dtype=np.int64),
                np.ascontiguousarray(shifts, dtype=float).reshape(-1, 3))
        for chosen, t_i, t_j, O in pair_blocks(arrays, r_vectors, radii, self.pairs[stored], shifts[stored], mobility,
                                               body_type) if stored.size else ():
            chosen = stored[chosen]
            i, j = self.pairs[chosen, 0], self.pairs[chosen, 1]
            # the second-order terms W_i = sum_j O_ij Q_j O_ji of the strongly coupled pairs only
            strong = gaps[chosen] < self.strong_gap
            for first, second, side in ((i, j, False), (j, i, True)):  # W of the first body of the pair
                use = np.flatnonzero(strong & second_order[first])
                if use.size:
                    O_s = np.swapaxes(O[use], 1, 2) if side else O[use]
                    t_first, t_second = (t_j, t_i) if side else (t_i, t_j)
                    np.add.at(W[t_first], local[first[use]],
                              np.matmul(np.matmul(O_s, Q[t_second][local[second[use]]]), np.swapaxes(O_s, 1, 2)))
            if not self.on_the_fly:
                self.groups.append(((3 * offsets[i]).astype(np.int64), (3 * offsets[j]).astype(np.int64), O))
            self.pair_groups.append((chosen, O))
        # T_i^{-1} to first order in W_i: G_i = W_i (zero for a body without neighbours).  The exact
        # (I - W_i Q_i)^{-1} W_i costs a batched solve and gave the same GMRES iterations in every scene measured.
        G = W
        if exact_woodbury:
            G = [np.linalg.solve(np.eye(W_type.shape[1])[None, :, :] - np.matmul(W_type, Q_type), W_type)
                 if W_type.size else W_type for W_type, Q_type in zip(W, Q)]
        # the second-order term P_i^{-1} [G_i z_i; 0] of the bodies with a G_i: its blob rows (Q_i G_i) and body
        # rows (the base's response to a blob field, times G_i), applied to z_i in one product each
        n3 = 3 * self.num_blobs
        for (bodies, _), G_type, Q_type, V_type in zip(arrays.type_slices, G, Q, base.blob_body_blocks()):
            coupled = np.flatnonzero(np.any(G_type != 0.0, axis=(1, 2))) if G_type.size else np.zeros(0, int)
            if coupled.size == 0:
                continue
            body = bodies.start + coupled
            m = G_type.shape[1]
            blob_rows = (3 * offsets[body])[:, None] + np.arange(m)[None, :]
            body_rows = (n3 + 6 * body)[:, None] + np.arange(6)[None, :]
            self.second_order.append((blob_rows, body_rows, np.matmul(Q_type[coupled], G_type[coupled]),
                                      np.matmul(V_type[coupled], G_type[coupled])))

    # What it shares with its base, named (no attribute forwarding): where it was built, its bodies, and the
    # base's block-diagonal Cholesky factors, which Lanczos uses unless a noise factor of its own is given
    # (``lanczos_preconditioner incomplete_cholesky`` sets ``noise_factor``).
    noise_factor = None

    @property
    def body_arrays(self):
        return self.base.body_arrays

    @property
    def cholesky_factors(self):
        return self.base.cholesky_factors

    @property
    def inverse_cholesky_factors(self):
        return self.base.inverse_cholesky_factors

    def _blockwise(self, vector, factors, transpose=False, lower=False):
        return self.base._blockwise(vector, factors, transpose=transpose, lower=lower)

    def neighbour_product(self, blob_forces):
        """``O_near lambda``: blob velocities (3N,) of blob forces (3N,) through the neighbour blocks only."""
        if self.on_the_fly:
            return _preconditioner_cpp.rigid_near_field(
                *self.near_field_arguments, np.ascontiguousarray(blob_forces, dtype=float).reshape(-1, 3)).reshape(-1)
        return symmetric_pair_product(self.groups, blob_forces)

    def apply(self, x):
        """The preconditioner applied to ``x = [s (3N); f (6Nb) ...]`` (the base preconditioner's layout)."""
        x = np.asarray(x, dtype=float).reshape(-1)
        if not self.has_neighbours:
            z = self.base.apply(x)
        else:
            n3 = 3 * self.num_blobs
            y = self.base.apply(x)
            s = x.copy()
            s[:n3] -= self.neighbour_product(y[:n3])
            z = self.base.apply(s)
            for blob_rows, body_rows, blob_block, body_block in self.second_order:
                z_i = z[blob_rows][:, :, None]
                z[blob_rows] += np.matmul(blob_block, z_i)[:, :, 0]
                z[body_rows] += np.matmul(body_block, z_i)[:, :, 0]
        if self.obstacles is not None:
            self.obstacles.add_to(x, z)
        return z
