"""The sparse near-field correction Delta_R = R_sup - R_MB of N spheres of one radius (6N x 6N, CSR).

``R_x = sum over pairs closer than cutoff a of R_x^pair(r_ij) + sum over spheres of R_x^wall(h_i)`` with
``x`` = sup (resolved two-sphere and sphere-wall resistances) or MB (the same systems modelled by single
RPY / RPB blobs, the far-field model itself, so the correction does not count it twice); blocks from
:mod:`lubrication.resistance`.  Vector layout ``[F1 T1 F2 T2 ...]`` (force units) against
``[U1 W1 U2 W2 ...]`` (velocity, angular velocity).

Pairs are found by a k-d tree (scipy ``cKDTree``; periodic axes by its toroidal box) within ``cutoff * a``;
the pair vector is the minimum image of ``r_j - r_i`` (``body.geometry.minimum_image``) divided by ``a`` in
EVERY direction.  (The published ``ResistCOO`` divides by ``a`` only along periodic axes, so with
``a != 1`` its pair lubrication is wrong: at ``a = 0.5`` every neighbour counts as touching.)  A pair is
kept when ``r_ij / a < cutoff`` (strict, as published).  With a wall every sphere gets its wall term (the
published ``cutoff_wall = 1e10`` puts it on everywhere); in free space there is none.

Entries are kept as computed (the published code drops entries below 1e-12 in absolute value, whatever
the units; here only exact zeros are left out), and the matrices are exactly symmetric.  They are put
together as 6 x 6 blocks (a diagonal block per sphere, two per pair) and handed to SciPy as CSR.
"""
from collections import namedtuple

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from body.geometry import minimum_image
from multi_bodies.files.input_options import DEFAULTS
from utils import UserInputError

from . import compiled, resistance

DEFAULT_CUTOFF = DEFAULTS.Lub_Cut  # centre distance in units of a (the option table's Lub_Cut)

NeighbourPairs = namedtuple('NeighbourPairs', ['pairs', 'r_over_a', 'r_hat'])
NeighbourPairs.__doc__ = """Pairs of spheres closer than the cutoff.

pairs : (P, 2) int, indices (i, j) with i < j.
r_over_a : (P,) centre distance over the radius.
r_hat : (P, 3) unit vectors from sphere i to sphere j (minimum image)."""

LubricationMatrices = namedtuple('LubricationMatrices', ['R_sup', 'R_MB', 'Delta_R', 'neighbours', 'isolated'])
LubricationMatrices.__doc__ = """The near-field matrices of N spheres at one configuration.

R_sup, R_MB, Delta_R : scipy.sparse.csr_matrix (6N, 6N), force units per velocity (Delta_R = R_sup - R_MB).
neighbours : :data:`NeighbourPairs` (the pairs within the cutoff).
isolated : (N,) bool, spheres with no neighbour within the cutoff and (with a wall) higher than
    ``cutoff * a``: the preconditioner leaves them alone (as published)."""


def check_geometry(locations, a, eta, cutoff, periodic_length):
    """Validated (locations (N, 3), a, eta, cutoff, periodic_length (3,)); UserInputError names the bad one."""
    try:
        locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    except ValueError:
        raise UserInputError('lubrication: the sphere locations must be an array of shape (N, 3); got shape %s'
                             % (np.shape(locations),)) from None
    if not np.all(np.isfinite(locations)):
        raise UserInputError('lubrication: the sphere locations hold NaN or inf; check the configuration')
    for name, value in (('blob_radius a', a), ('eta', eta), ('Lub_Cut (cutoff)', cutoff)):
        if not np.isfinite(value) or not float(value) > 0:
            raise UserInputError('lubrication: %s = %r must be a positive number' % (name, value))
    L = np.asarray(periodic_length, dtype=float).reshape(-1)
    if L.shape != (3,) or not np.all(np.isfinite(L)) or np.any(L < 0):
        raise UserInputError('lubrication: periodic_length %r must be three lengths >= 0 (0: not periodic)'
                             % (periodic_length,))
    return locations, float(a), float(eta), float(cutoff), L


def neighbour_pairs(locations, a, cutoff=DEFAULT_CUTOFF, periodic_length=(0.0, 0.0, 0.0)):
    """Pairs of spheres closer than ``cutoff * a`` (centre distance), as :data:`NeighbourPairs`.

    locations : (N, 3) sphere centres (length units); a : radius; cutoff : in units of a;
    periodic_length : (3,) box lengths, 0 for a non-periodic axis (minimum image on the others).
    """
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    periodic = L > 0
    if locations.shape[0] < 2:
        empty = np.zeros((0, 2), dtype=np.intp)
        return NeighbourPairs(empty, np.zeros(0), np.zeros((0, 3)))
    points = locations.copy()
    if np.any(periodic):
        # the toroidal tree wants periodic coordinates in [0, L)
        wrapped = np.mod(points[:, periodic], L[periodic])
        points[:, periodic] = np.where(wrapped >= L[periodic], 0.0, wrapped)
        if np.any(cutoff * a > 0.5 * L[periodic]):
            raise UserInputError('lubrication: the pair cutoff Lub_Cut * a = %g is more than half a periodic box '
                                 'length %s; make the box larger or the cutoff smaller'
                                 % (cutoff * a, L[periodic]))
    tree = cKDTree(points, boxsize=np.where(periodic, L, 0.0) if np.any(periodic) else None)
    pairs = tree.query_pairs(r=cutoff * a, output_type='ndarray')
    pairs = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    # sorted by i, then j: one key i N + j per pair (the pairs are distinct, so the order is lexsort's)
    pairs = pairs[np.argsort(pairs[:, 0] * locations.shape[0] + pairs[:, 1], kind='stable')]
    displacement = minimum_image(locations[pairs[:, 1]] - locations[pairs[:, 0]], L) / a
    r_over_a = np.sqrt(np.add.reduce(displacement * displacement, axis=1))  # np.linalg.norm(axis=1)'s own formula
    keep = r_over_a < cutoff
    if not keep.all():
        pairs, displacement, r_over_a = pairs[keep], displacement[keep], r_over_a[keep]
    if np.any(r_over_a == 0):
        i, j = pairs[np.argmax(r_over_a == 0)]
        raise UserInputError('lubrication: spheres %d and %d are at the same place; check the configuration' % (i, j))
    return NeighbourPairs(pairs, r_over_a, displacement / r_over_a[:, None])


class _BlockPattern:
    """Where the 6 x 6 blocks of N spheres and P pairs go: a diagonal block per sphere, an (i, j) and a (j, i)
    block per pair (each pair once, i < j), in the row-major order of a block-sparse (BSR) matrix."""

    def __init__(self, n, pairs):
        self.n, self.pairs = n, pairs
        block_rows = np.concatenate((np.arange(n), pairs[:, 0], pairs[:, 1]))
        block_cols = np.concatenate((np.arange(n), pairs[:, 1], pairs[:, 0]))
        self.order = np.lexsort((block_cols, block_rows))
        self.indices = block_cols[self.order]
        self.indptr = np.concatenate(([0], np.cumsum(np.bincount(block_rows, minlength=n))))

    def blocks(self, pair_blocks, wall_blocks):
        """The blocks (N + 2P, 6, 6) in BSR order from pair blocks (P, 12, 12) and wall blocks (N, 6, 6) or None.

        A sphere's diagonal block sums, in one fixed order, its wall block and the self blocks of its pairs,
        so the (p, q) and (q, p) entries are sums of the same numbers in the same order: exactly symmetric.
        """
        diagonal = np.zeros((self.n, 6, 6)) if wall_blocks is None else np.array(wall_blocks, dtype=float)
        np.add.at(diagonal, self.pairs[:, 0], pair_blocks[:, :6, :6])
        np.add.at(diagonal, self.pairs[:, 1], pair_blocks[:, 6:, 6:])
        every = np.concatenate((diagonal, pair_blocks[:, :6, 6:], pair_blocks[:, 6:, :6]))
        return every[self.order]

    def csr(self, blocks):
        """CSR (6N, 6N) of blocks in BSR order, exact zeros left out."""
        size = 6 * self.n
        matrix = sp.bsr_matrix((blocks, self.indices, self.indptr), shape=(size, size)).tocsr()
        matrix.eliminate_zeros()
        return matrix


def _numpy_matrices(n, neighbours, locations, a, wall, factors, firm_delta, handover, cutoff):
    """(R_sup, R_MB, Delta_R) CSR by NumPy: the reference of the compiled assembly and its fallback."""
    pattern = _BlockPattern(n, neighbours.pairs)
    pair_sup = resistance.pair_resistance_sup(neighbours.r_over_a, neighbours.r_hat, factors, firm_delta, handover)
    pair_mb = resistance.pair_resistance_blob_model(neighbours.r_over_a, neighbours.r_hat, factors, firm_delta)
    if handover != 'published':  # the pair terms tapered to zero at the cutoff
        taper = resistance.cutoff_taper(neighbours.r_over_a, cutoff, handover)[:, None, None]
        pair_sup, pair_mb = taper * pair_sup, taper * pair_mb
    wall_sup = wall_mb = None
    if wall and n:
        h = locations[:, 2] / a
        wall_sup = resistance.wall_resistance_sup(h, factors, firm_delta, handover)
        wall_mb = resistance.wall_resistance_blob_model(h, factors, firm_delta)
    blocks_sup = pattern.blocks(pair_sup, wall_sup)
    blocks_mb = pattern.blocks(pair_mb, wall_mb)
    return pattern.csr(blocks_sup), pattern.csr(blocks_mb), pattern.csr(blocks_sup - blocks_mb)


def resistance_matrices(locations, a, eta, cutoff=DEFAULT_CUTOFF, periodic_length=(0.0, 0.0, 0.0), wall=True,
                        firm_delta=resistance.DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover):
    """R_sup, R_MB and Delta_R = R_sup - R_MB of spheres at ``locations``: a :data:`LubricationMatrices`.

    locations : (N, 3) sphere centres (length units; the wall, if any, is the plane z = 0);
    a : sphere radius; eta : viscosity; cutoff : pair cutoff in units of a (``Lub_Cut``, default 4.5);
    periodic_length : (3,) box (0: not periodic); wall : True above a no-slip wall at z = 0, False in free
    space (no wall term); firm_delta : gap clamp in units of a (``firm_delta``, the published
    ``debye_cut``; default 1e-4); handover : ``'published'`` or ``'smooth'`` (the input option
    ``lubrication_handover``; see :mod:`lubrication.resistance`).  Built by the compiled kernels
    (:mod:`lubrication.compiled`) when the extension is built, else by NumPy (:func:`_numpy_matrices`).
    """
    locations, a, eta, cutoff, L = check_geometry(locations, a, eta, cutoff, periodic_length)
    firm_delta = resistance.check_firm_delta(firm_delta)
    resistance.check_handover(handover)
    n = locations.shape[0]
    factors = resistance.resistance_factors(eta, a)
    neighbours = neighbour_pairs(locations, a, cutoff, L)
    if compiled.in_use():
        R_sup, R_MB, Delta_R = compiled.matrices(n, neighbours.pairs, neighbours.r_over_a, neighbours.r_hat,
                                                 locations[:, 2] / a if wall and n else None, factors, firm_delta,
                                                 handover, cutoff)
    else:
        R_sup, R_MB, Delta_R = _numpy_matrices(n, neighbours, locations, a, wall, factors, firm_delta, handover,
                                               cutoff)
    has_neighbour = np.zeros(n, dtype=bool)
    has_neighbour[neighbours.pairs.reshape(-1)] = True
    isolated = ~has_neighbour
    if wall:
        isolated &= locations[:, 2] >= cutoff * a
    return LubricationMatrices(R_sup, R_MB, Delta_R, neighbours, isolated)


def delta_R(locations, a, eta, cutoff=DEFAULT_CUTOFF, periodic_length=(0.0, 0.0, 0.0), wall=True,
            firm_delta=resistance.DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover):
    """Only Delta_R (6N, 6N) CSR of :func:`resistance_matrices` (same arguments)."""
    return resistance_matrices(locations, a, eta, cutoff, periodic_length, wall, firm_delta, handover).Delta_R
