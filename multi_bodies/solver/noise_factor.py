"""The incomplete Cholesky factor of the blob mobility: a Lanczos preconditioner that sees the neighbours.

The Brownian slip of the iterative schemes is ``M^{1/2} z`` by Lanczos on ``L^{-1} M L^{-T}`` times ``L``
(SPEC decision 1): for any invertible ``L`` the result ``L (L^{-1} M L^{-T})^{1/2} z`` has covariance
``L L^{-1} M L^{-T} L^T = M`` exactly, and Lanczos needs fewer iterations the closer ``L L^T`` is to ``M``.
The published ``L`` is block diagonal: each body's own Cholesky factor ``L_k L_k^T = M_kk``.  This module
adds the couplings of neighbouring bodies (those whose blobs come within 2 blob radii: the closest of the
neighbour pairs of the GMRES preconditioner) by a block incomplete Cholesky factorisation with no fill
(IC(0)) over the bodies:

    L_kk L_kk^T = M_kk - sum_{l < k} L_kl L_kl^T,
    L_ik = (M_ik - sum_{l < k} L_il L_kl^T) L_kk^{-T}   (i > k a neighbour of k; the sums over neighbours),

so ``L L^T`` equals ``M`` on the diagonal blocks and on the neighbour blocks.  Where a Schur complement
``M_kk - sum L_kl L_kl^T`` is not positive definite (the factorisation can break down for matrices that are
not diagonally dominant), body ``k``'s row keeps its diagonal block alone (``L_kk L_kk^T = M_kk``); ``L``
stays invertible, so the covariance stays ``M``; ``breakdowns`` counts those rows.

It is an option (``lanczos_preconditioner incomplete_cholesky``), off by default: the noise of a given
``z`` is another sample of the same distribution, so a published ``.random_state`` no longer repeats the
published trajectory (doc/preconditioners.md has its measured effect on the iterations, the time and the
statistics).

The roller schemes' noise of single blobs (published: Lanczos without a preconditioner) takes the same
factorisation over 3 x 3 blocks under the option (:func:`single_blob_factor`).

Layout: body ``b``'s unknowns are ``x[3 o_b : 3 o_{b+1}]`` with ``o`` the bodies' blob offsets; every block is
dense.  The factorisation and the applications use the compiled ``_preconditioner_cpp``
(``incomplete_cholesky_blocks``, ``block_lower_apply``; NumPy loops of the same formulas otherwise).
"""
import numpy as np

from mobility.interface import BlobMobility, as_blob_mobility
from multi_bodies.solver.body_solver import blob_mobility, lower_triangular_inverse
from multi_bodies.solver.neighbour_preconditioner import blobs_of, cross_or_stacked_blocks, neighbour_pairs, pair_blocks

try:
    from multi_bodies.solver import _preconditioner_cpp
except ImportError:  # pragma: no cover - the compiled kernels are built by the install
    _preconditioner_cpp = None

LANCZOS_PRECONDITIONERS = ('block_diagonal', 'incomplete_cholesky')
# Bodies whose blobs come within this many (largest) blob radii of each other enter the factor.  Measured
# (doc/preconditioners.md), Lanczos iterations at 1e-8 and factor build against one M f product: 100 boomerangs
# 21 -> 13 (2 radii), 13 (4), 12 (6), 11 (8), builds 1.1, 1.4, 1.9, 3.6 products; packed at half the spacing
# 25 -> 20, 19, 20, 19, builds 1.8, 4.4, 6.0, 7.9 products.  2 radii saves the most time in both.
NOISE_GAP_IN_RADII = 2.0
# The same for single blobs (rollers), whose 3 x 3 blocks are cheap: measured on 4,000 rollers above the wall at
# area fraction 0.4 (stochastic_adams_bashforth_rollers, Lanczos iterations per step and s/step): none (published)
# 28, 0.60 s; 2 radii 22, 0.55 s; 4 radii 11, 0.43 s; 6 radii 9, 0.45 s; 8 radii 8, 0.44 s.
ROLLER_NOISE_GAP_IN_RADII = 4.0


def incomplete_cholesky(own_factors, own_inverses, pair_blocks_by_pair):
    """Block IC(0) of a symmetric positive definite matrix given by its blocks (module docstring).

    own_factors, own_inverses : lists (Nb) of the lower-triangular Cholesky factors ``C_b`` of the diagonal
        blocks (``C_b C_b^T = M_bb``) and of their inverses;
    pair_blocks_by_pair : dict ``(i, j) -> M_ij`` with ``i < j`` ((m_i, m_j) arrays), the blocks kept.
    Returns (diagonal factors: list of lower-triangular (m_b, m_b) ``L_bb``, their inverses, rows: list of
    dicts ``{k: L_ik}`` with ``k < i``, breakdowns: the number of rows that kept their diagonal block alone).
    A body with no neighbour before it keeps its own factor (``L_bb = C_b``).
    """
    num = len(own_factors)
    later = [[] for _ in range(num)]  # later[k]: the neighbours i > k of k, ascending
    for (i, j) in sorted(pair_blocks_by_pair):
        later[i].append(j)
    rows = [dict() for _ in range(num)]
    factors, inverses = list(own_factors), list(own_inverses)
    breakdowns = 0
    for k in range(num):
        row_k = rows[k]
        if row_k:  # the Schur complement M_kk - sum_l L_kl L_kl^T
            schur = own_factors[k] @ own_factors[k].T
            for block in row_k.values():
                schur -= block @ block.T
            try:
                factor = np.linalg.cholesky(schur)
            except np.linalg.LinAlgError:
                factor = None
            if factor is not None and np.all(np.diag(factor) > 0.0):
                factors[k] = factor
                inverses[k] = lower_triangular_inverse(factor[None])[0]
            else:
                row_k.clear()  # this row keeps its own block alone: L stays invertible
                breakdowns += 1
        inverse_T = inverses[k].T
        for i in later[k]:
            coupling = pair_blocks_by_pair[(k, i)].T.copy()  # M_ik
            row_i = rows[i]
            for l in row_k.keys() & row_i.keys():
                coupling -= row_i[l] @ row_k[l].T
            row_i[k] = coupling @ inverse_T  # L_ik = (M_ik - sum L_il L_kl^T) L_kk^{-T}
    return factors, inverses, rows, breakdowns


def _exclusive_cumsum(counts):
    """Offsets (k,) int64 of consecutive pieces of the given sizes (k,): 0, c0, c0 + c1, ..."""
    counts = np.asarray(counts, dtype=np.int64).reshape(-1)
    return np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64) if counts.size else np.zeros(0, np.int64)


class BlockLowerFactor:
    """A block lower-triangular ``L`` over the bodies, applied as ``L x``, ``L^{-1} x`` and ``L^{-T} x``.

    The flat layout of ``_preconditioner_cpp.block_lower_apply``: starts (Nb + 1,) every body's first unknown
    (3 times its first blob); diag and diag_inverse: the diagonal blocks ``L_bb`` and ``L_bb^{-1}`` (lower
    triangular, positive diagonal) one after another in body order; row_ptr (Nb + 1,), cols, block_offsets and
    blocks: the strictly lower blocks ``L_ik`` of every block row.  :meth:`from_blocks` builds it from lists of
    blocks.  Vectors are (3N,) (blob velocities or forces).
    """

    def __init__(self, starts, diag, diag_inverse, row_ptr, cols, block_offsets, blocks):
        self.starts = np.asarray(starts, dtype=np.int64)
        self.diag_offsets = _exclusive_cumsum(np.diff(self.starts) ** 2)
        self.diag, self.diag_inverse = np.asarray(diag, float), np.asarray(diag_inverse, float)
        self.row_ptr, self.cols = np.asarray(row_ptr, np.int64), np.asarray(cols, np.int64)
        self.block_offsets, self.blocks = np.asarray(block_offsets, np.int64), np.asarray(blocks, float)
        self.num_lower_blocks = self.cols.size

    @classmethod
    def from_blocks(cls, starts, factors, rows, inverses=None):
        """The factor of the diagonal blocks ``factors`` (Nb lower-triangular arrays), ``rows`` (list of dicts
        ``{k: L_ik}``, k < i) and ``inverses`` (the ``L_bb^{-1}``; None: computed here)."""
        if inverses is None:
            inverses = [lower_triangular_inverse(np.asarray(f, float)[None])[0] for f in factors]
        cols, flat, row_ptr = [], [], [0]
        for row in rows:
            for k in sorted(row):
                cols.append(k)
                flat.append(np.ascontiguousarray(row[k], dtype=float).reshape(-1))
            row_ptr.append(len(cols))

        def joined(pieces):
            return np.concatenate([np.asarray(p, float).reshape(-1) for p in pieces]) if len(pieces) else np.zeros(0)
        return cls(starts, joined(factors), joined(inverses), row_ptr, cols, _exclusive_cumsum([f.size for f in flat]),
                   joined(flat))

    def _apply(self, mode, x):
        x = np.ascontiguousarray(x, dtype=float).reshape(-1)
        if x.size != self.starts[-1]:
            raise ValueError('a vector of %d unknowns for a factor of %d' % (x.size, self.starts[-1]))
        out = np.zeros_like(x)
        if _preconditioner_cpp is not None and hasattr(_preconditioner_cpp, 'block_lower_apply'):
            _preconditioner_cpp.block_lower_apply(mode, self.starts, self.diag_offsets,
                                                  self.diag if mode == 0 else self.diag_inverse, self.row_ptr,
                                                  self.cols, self.block_offsets, self.blocks, x, out)
            return out
        return self._apply_numpy(mode, x, out)

    def _diagonal(self, b, inverse):
        m = self.starts[b + 1] - self.starts[b]
        source = self.diag_inverse if inverse else self.diag
        return source[self.diag_offsets[b]:self.diag_offsets[b] + m * m].reshape(m, m)

    def _lower(self, p, i):
        k = self.cols[p]
        m_i, m_k = self.starts[i + 1] - self.starts[i], self.starts[k + 1] - self.starts[k]
        return k, self.blocks[self.block_offsets[p]:self.block_offsets[p] + m_i * m_k].reshape(m_i, m_k)

    def _apply_numpy(self, mode, x, out):
        """The same three products as the compiled loop (for a build without the compiled module)."""
        s = self.starts
        num = s.size - 1
        if mode == 0:
            for i in range(num):
                out[s[i]:s[i + 1]] = self._diagonal(i, False) @ x[s[i]:s[i + 1]]
                for p in range(self.row_ptr[i], self.row_ptr[i + 1]):
                    k, block = self._lower(p, i)
                    out[s[i]:s[i + 1]] += block @ x[s[k]:s[k + 1]]
        elif mode == 1:
            for i in range(num):
                t = x[s[i]:s[i + 1]].copy()
                for p in range(self.row_ptr[i], self.row_ptr[i + 1]):
                    k, block = self._lower(p, i)
                    t -= block @ out[s[k]:s[k + 1]]
                out[s[i]:s[i + 1]] = self._diagonal(i, True) @ t
        else:
            out[:] = x
            for i in range(num - 1, -1, -1):
                out[s[i]:s[i + 1]] = self._diagonal(i, True).T @ out[s[i]:s[i + 1]]
                for p in range(self.row_ptr[i], self.row_ptr[i + 1]):
                    k, block = self._lower(p, i)
                    out[s[k]:s[k + 1]] -= block.T @ out[s[i]:s[i + 1]]
        return out

    def L_dot(self, vector):
        """``L x``: (3N,) -> (3N,)."""
        return self._apply(0, vector)

    def L_inv_dot(self, vector):
        """``L^{-1} x``: (3N,) -> (3N,)."""
        return self._apply(1, vector)

    def L_inv_T_dot(self, vector):
        """``L^{-T} x``: (3N,) -> (3N,)."""
        return self._apply(2, vector)


def _compiled():
    return _preconditioner_cpp is not None and hasattr(_preconditioner_cpp, 'incomplete_cholesky_blocks')


def _compiled_factor(starts, own, pairs, pair_offsets, pair_data):
    """(BlockLowerFactor, breakdowns) of ``_preconditioner_cpp.incomplete_cholesky_blocks`` (flat arguments)."""
    starts = np.asarray(starts, dtype=np.int64)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    *layout, breakdowns = _preconditioner_cpp.incomplete_cholesky_blocks(
        starts, _exclusive_cumsum(np.diff(starts) ** 2), np.ascontiguousarray(own, dtype=float).reshape(-1),
        np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1]), np.asarray(pair_offsets, np.int64),
        np.ascontiguousarray(pair_data, dtype=float).reshape(-1))
    return BlockLowerFactor(starts, *layout), int(breakdowns)


def incomplete_cholesky_factor(starts, own_factors, own_inverses, pair_blocks_by_pair, compiled=True):
    """(BlockLowerFactor, breakdowns): the block IC(0) of :func:`incomplete_cholesky`, by the compiled loop
    (``_preconditioner_cpp.incomplete_cholesky_blocks``, the same formulas) where it is built and ``compiled``.

    starts (Nb + 1,): every body's first unknown; own_factors, own_inverses, pair_blocks_by_pair as
    :func:`incomplete_cholesky` takes them.
    """
    if compiled and _compiled():
        keys = sorted(pair_blocks_by_pair)
        flat = [np.ascontiguousarray(pair_blocks_by_pair[key], dtype=float).reshape(-1) for key in keys]
        pair_offsets = _exclusive_cumsum([f.size for f in flat])
        own = np.concatenate([np.asarray(f, float).reshape(-1) for f in own_factors]) if len(own_factors) else \
            np.zeros(0)
        return _compiled_factor(starts, own, keys, pair_offsets, np.concatenate(flat) if flat else np.zeros(0))
    factors, inverses, rows, breakdowns = incomplete_cholesky(own_factors, own_inverses, pair_blocks_by_pair)
    return BlockLowerFactor.from_blocks(starts, factors, rows, inverses), breakdowns


def neighbour_noise_factor(base, mobility, eta=None, blob_radius=None, periodic_length=(0.0, 0.0, 0.0),
                           body_lengths=None, cross_blocks=None, gap=None, neighbours=None):
    """The block IC(0) factor of the blob mobility over neighbouring bodies (module docstring): a
    :class:`BlockLowerFactor` with ``pairs`` (P, 2), the neighbour pairs whose blocks enter, and ``breakdowns``,
    the rows that kept their diagonal block alone.

    Parameters
    ----------
    base : body_solver.BlockDiagonalPreconditioner (or a subclass), built at the configuration: its bodies'
        Cholesky factors give the diagonal blocks ``M_bb = L_b L_b^T``.
    mobility, eta, blob_radius, periodic_length, body_lengths, cross_blocks : as
        :class:`neighbour_preconditioner.NeighbourPreconditioner` takes them (the model passes its blobs
        mobility, a ``BlobMobility``, alone).
    gap : float or None, the neighbour gap (surface to surface, length; None: NOISE_GAP_IN_RADII blob radii).
    neighbours : a NeighbourPreconditioner built on ``base`` that stores the blocks of its pairs up to at least
        that gap (its ``stored_gap``), or None: its pairs closer than ``gap`` and their blocks are taken instead
        of computed again.
    """
    mobility = blob_mobility(base.body_arrays, mobility, eta, blob_radius, role='stacked_dense_matrix',
                             cross_blocks=cross_blocks)
    arrays, configuration, r_vectors, radii = blobs_of(base, mobility.blob_radius)
    if gap is None:
        gap = NOISE_GAP_IN_RADII * float(np.max(radii)) if radii.size else 0.0
    by_start = sorted(range(len(arrays.type_slices)), key=lambda t: arrays.type_slices[t][0].start)
    own_factors = [L for t in by_start for L in base.cholesky_factors[t]]  # in the order of the bodies
    own_inverses = [L for t in by_start for L in base.inverse_cholesky_factors[t]]
    if neighbours is not None and getattr(neighbours, 'stored_gap', neighbours.gap) >= float(gap) and \
            neighbours.pairs.size:
        # the neighbour pairs of the GMRES preconditioner that are close enough, with their blocks
        close = neighbours.pair_gaps < float(gap)
        pairs = neighbours.pairs[close]
        renumbered = np.cumsum(close) - 1
        groups = [(renumbered[chosen[close[chosen]]], O[close[chosen]]) for chosen, O in neighbours.pair_groups]
    else:
        pairs, shifts, _ = neighbour_pairs(r_vectors, arrays.blob_body_index, radii, configuration.locations,
                                           float(gap), periodic_length, body_lengths)
        groups = [(chosen, O) for chosen, _, _, O in pair_blocks(
            arrays, r_vectors, radii, pairs, shifts, mobility)] if pairs.size else []
    by_pair = {}
    for chosen, O in groups:
        for (i, j), block in zip(map(tuple, pairs[chosen]), O):
            # a pair that meets through two periodic images couples through both
            by_pair[(i, j)] = by_pair[(i, j)] + block if (i, j) in by_pair else block
    factor, breakdowns = incomplete_cholesky_factor(3 * np.asarray(arrays.blob_offsets), own_factors, own_inverses,
                                                    by_pair)
    factor.pairs, factor.breakdowns = pairs, breakdowns
    return factor


def single_blob_factor(r_vectors, mobility, blob_radius=None, stacked_mobility=None, cross_blocks=None, gap=None):
    """The block IC(0) factor of the mobility of single blobs (rollers): (BlockLowerFactor, pairs (P, 2)).

    r_vectors (N, 3); mobility : the BlobMobility of the blobs (one radius ``a``: its dense blocks and
    ``cross_blocks``), or the viscosity of the published-form call ``(r_vectors, eta, a, stacked_mobility,
    cross_blocks)`` with ``stacked_mobility`` ``f(r (P, n, 3), eta, a)``.  The 3 x 3 blocks of blobs whose
    surfaces come within ``gap`` (None: ROLLER_NOISE_GAP_IN_RADII a, centre distances below 2a + gap) and the
    blobs' own blocks.  No periodic images: a pair coupled only through one is left out (L stays invertible,
    the covariance M).
    """
    from scipy.spatial import cKDTree
    if not isinstance(mobility, BlobMobility):
        mobility = as_blob_mobility(stacked_mobility, mobility, float(blob_radius), role='stacked_dense_matrix',
                                    cross_blocks=cross_blocks)
    r = np.ascontiguousarray(r_vectors, dtype=float).reshape(-1, 3)
    a = float(mobility.blob_radius)
    gap = ROLLER_NOISE_GAP_IN_RADII * a if gap is None else float(gap)
    own = np.linalg.cholesky(mobility.dense_matrix(r[:, None, :]))
    pairs = cKDTree(r).query_pairs(2.0 * a + gap, output_type='ndarray') if r.shape[0] > 1 else np.zeros((0, 2))
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    blocks = np.zeros((0, 3, 3))
    if pairs.size:
        blocks = cross_or_stacked_blocks(mobility, r[pairs[:, 0]][:, None, :], r[pairs[:, 1]][:, None, :], a)
    starts = 3 * np.arange(r.shape[0] + 1)
    if _compiled():  # the blocks as they are: one (3, 3) block per pair, in the pairs' order
        factor, _ = _compiled_factor(starts, own, pairs, 9 * np.arange(pairs.shape[0]), blocks)
    else:
        factor, _ = incomplete_cholesky_factor(starts, own, lower_triangular_inverse(own),
                                               dict(zip(map(tuple, pairs.tolist()), blocks)))
    return factor, pairs

