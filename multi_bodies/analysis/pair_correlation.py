"""Pair correlation g(r) in the plane (x, y) or in 3-d, with the minimum image on periodic axes.

g(r) is the number of pairs at distance r over the number an uncorrelated
system with the same one-particle density would have:

    g(r_k) = <pairs with r in bin k> / <ideal pairs in bin k>,

with ``M = N (N - 1) / 2`` pairs per frame.  Distances use the minimum image
on every periodic axis (``periodic_length > 0``), so ``r_max`` may be at most
half the shortest periodic length.  Pairs are counted with SciPy's compiled
k-d tree (``cKDTree(boxsize=L).count_neighbors``, dual-tree, O(N) per frame for
a fixed number of neighbours): memory O(N), no N x N matrix.

The ideal count of bin k is ``M * P_k``, with ``P_k`` the probability that the
separation of two independent particles falls in the bin:

* every axis periodic: ``P_k = (shell area or volume) / (box area or volume)``
  (exact: ``pi (r2^2 - r1^2) / (Lx Ly)`` in the plane, ``4/3 pi (r2^3 - r1^3) / V`` in 3-d);
* some axis not periodic (``periodic_length`` 0 there: a wall at z = 0, an open
  box): the particles are taken as uniform along the periodic axes and with the
  *observed* marginal density ``p_a(x)`` along each open axis a (histogram of
  every frame's coordinates, bin width ``r_max / n_bins``).  The separation of two
  independent particles along that axis then has the density
  ``w_a(d) = integral p_a(x) p_a(x + d) dx`` (the histogram's autocorrelation,
  linear between its nodes), along a periodic axis ``w = 1/L``, and
  ``P_k = integral over the shell of prod_a w_a(d_a)`` (Gauss-Legendre in r,
  a uniform grid in the angles).  So uniform points in an open square give
  g = 1 (no edge deficit), and in 3-d above a wall g(r) -> 1 at large r even
  though the height density is not uniform.

Error bars: the standard error of the block (or replica) means of g.
"""
import numpy as np
from scipy.spatial import cKDTree

from multi_bodies.analysis.trajectories import BlockSums
from utils import UserInputError, refuse_if_too_big


def _check_box(periodic_length, dimension, r_max):
    box = np.asarray(periodic_length, dtype=float).reshape(3)[:dimension]
    box = np.where(box > 0, box, 0.0)
    if dimension not in (2, 3):
        raise UserInputError('the dimension of g(r) must be 2 (in the plane x, y) or 3, got %r' % dimension)
    if not r_max > 0:
        raise UserInputError('r_max must be positive, got %g' % r_max)
    periodic = box > 0
    if np.any(periodic) and r_max > 0.5 * box[periodic].min() * (1 + 1e-12):
        raise UserInputError('r_max %g is more than half the shortest periodic length %g: the minimum image '
                             'cannot see such pairs; give --r-max at most %g' % (r_max, box[periodic].min(),
                                                                                0.5 * box[periodic].min()))
    return box


def pair_distance_histogram(positions, periodic_length, edges):
    """Number of unordered pairs with distance in each bin ``(edges[k], edges[k+1]]``, minimum image.

    positions : (N, d) lengths; periodic_length : (d,), 0 = open axis; edges : (n_bins + 1,) increasing from 0.
    Returns counts (n_bins,) of float.
    """
    box = np.asarray(periodic_length, dtype=float)
    points = np.array(positions, dtype=float)
    for axis in np.flatnonzero(box > 0):
        column = np.mod(points[:, axis], box[axis])
        column[column >= box[axis]] = 0.0  # np.mod may return L itself for a tiny negative value
        points[:, axis] = column
    tree = cKDTree(points, boxsize=box if np.any(box > 0) else None)
    ordered = tree.count_neighbors(tree, np.asarray(edges, dtype=float), cumulative=False)
    return ordered[1:].astype(float) / 2.0  # each unordered pair twice; bin 0 (r <= 0) holds the particles


class GrowingHistogram:
    """Histogram of coordinates on bins ``[j h, (j + 1) h)`` of fixed width h, grown as values arrive."""

    def __init__(self, width):
        self.width, self.first, self.counts = float(width), 0, np.zeros(0)

    def add(self, values):
        index = np.floor(np.asarray(values, dtype=float).ravel() / self.width).astype(np.int64)
        low, high = index.min(), index.max()
        if len(self.counts) == 0:
            self.first, self.counts = low, np.zeros(high - low + 1)
        if low < self.first or high >= self.first + len(self.counts):
            new_first = min(low, self.first)
            grown = np.zeros(max(high, self.first + len(self.counts) - 1) - new_first + 1)
            grown[self.first - new_first:self.first - new_first + len(self.counts)] = self.counts
            self.first, self.counts = new_first, grown
        self.counts += np.bincount(index - self.first, minlength=len(self.counts))

    def separation_density(self):
        """(lags d (m,) from 0 by h, density w(d) (m,)) of the separation of two independent draws."""
        p = self.counts / self.counts.sum()
        autocorrelation = np.correlate(p, p, mode='full')[len(p) - 1:]
        return np.arange(len(p)) * self.width, autocorrelation / self.width


def ideal_pair_fraction(edges, box, open_densities, angles=96, radial_nodes=4):
    """P_k: probability that two independent particles are at a distance in bin k (see module docstring).

    edges : (n_bins + 1,); box : (d,) periodic lengths, 0 = open; open_densities : {axis: (lags, w)} of
    the open axes.  Returns (n_bins,).
    """
    edges = np.asarray(edges, dtype=float)
    dimension = len(box)
    if np.all(box > 0):
        measure = np.pi * np.diff(edges ** 2) if dimension == 2 else 4.0 / 3.0 * np.pi * np.diff(edges ** 3)
        return measure / np.prod(box)

    def weight(axis, d):
        if box[axis] > 0:
            return np.full_like(d, 1.0 / box[axis])
        lags, density = open_densities[axis]
        return np.interp(np.abs(d), lags, density, right=0.0)

    nodes, node_weights = np.polynomial.legendre.leggauss(radial_nodes)
    half = 0.5 * np.diff(edges)
    radii = (edges[:-1, None] + half[:, None] * (nodes[None, :] + 1.0))  # (n_bins, radial_nodes)
    radial_weights = half[:, None] * node_weights[None, :]
    # the weights are even in every component: integrate one quadrant (octant) and multiply
    if dimension == 2:
        theta = (np.arange(angles) + 0.5) * (0.5 * np.pi / angles)
        directions = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        solid = np.full(angles, 0.5 * np.pi / angles) * 4.0
        jacobian = radii
    else:
        cos_nodes, cos_weights = np.polynomial.legendre.leggauss(angles // 2)
        cos_polar = 0.5 * (cos_nodes + 1.0)
        phi = (np.arange(angles) + 0.5) * (0.5 * np.pi / angles)
        sin_polar = np.sqrt(1.0 - cos_polar ** 2)
        directions = np.stack([np.outer(sin_polar, np.cos(phi)).ravel(), np.outer(sin_polar, np.sin(phi)).ravel(),
                               np.repeat(cos_polar, angles)], axis=1)
        solid = np.outer(0.5 * cos_weights, np.full(angles, 0.5 * np.pi / angles)).ravel() * 8.0
        jacobian = radii ** 2
    separations = radii[:, :, None, None] * directions[None, None, :, :]  # (bins, nodes, angles, d)
    integrand = np.ones(separations.shape[:3])
    for axis in range(dimension):
        integrand *= weight(axis, separations[..., axis])
    return np.einsum('bna,a,bn->b', integrand, solid, radial_weights * jacobian)


class PairCorrelation:
    """Accumulator of g(r) over frames (see module docstring).

    periodic_length : (3,) of the run; r_max : largest distance (lengths); n_bins : bins of width r_max / n_bins;
    dimension : 2 (in the plane x, y: distances of the x, y coordinates) or 3.
    """

    def __init__(self, periodic_length, r_max, n_bins=100, dimension=2, where='g(r)', blocks=10):
        self.box = _check_box(periodic_length, dimension, r_max)
        if int(n_bins) < 1:
            raise UserInputError('%s: g(r) needs at least one bin, got %d' % (where, n_bins))
        # per bin: its edge, the block sums and weights (twice while a block is added), a frame's histogram and
        # the work arrays of the pair histogram: refused before anything is allocated (``where``: the option)
        refuse_if_too_big(int(n_bins) * 8 * (6 + 4 * blocks), 'g(r) in %d bins' % int(n_bins), where,
                          'ask for fewer bins')
        self.dimension, self.r_max, self.n_bins = dimension, float(r_max), int(n_bins)
        self.edges = np.linspace(0.0, self.r_max, self.n_bins + 1)
        self.counts = BlockSums((self.n_bins,))
        self.open_histograms = {axis: GrowingHistogram(self.r_max / self.n_bins)
                                for axis in np.flatnonzero(self.box == 0)}
        self.n_particles = None

    def start_source(self):
        pass

    def add(self, positions, frames, blocks):
        points = np.asarray(positions, dtype=float)[:, :, :self.dimension]
        if self.n_particles is None:
            self.n_particles = points.shape[1]
        for frame_points, block in zip(points, blocks):
            self.counts.add(block, pair_distance_histogram(frame_points, self.box, self.edges))
            for axis, histogram in self.open_histograms.items():
                histogram.add(frame_points[:, axis])

    def result(self):
        """dict: r (n_bins,) bin centres, g (n_bins,), g_error (n_bins,), blocks, frames, particles, normalisation."""
        if self.n_particles is None:
            raise UserInputError('g(r): no frame was analysed')
        densities = {axis: h.separation_density() for axis, h in self.open_histograms.items()}
        ideal = 0.5 * self.n_particles * (self.n_particles - 1) * ideal_pair_fraction(self.edges, self.box, densities)
        frames = self.counts.weights[:, 0]
        used = frames > 0
        with np.errstate(invalid='ignore', divide='ignore'):
            g_blocks = self.counts.sums[used] / (frames[used, None] * ideal[None, :])
        mean = np.nan_to_num(self.counts.sums[used].sum(axis=0) / (frames[used].sum() * ideal))
        blocks = int(used.sum())
        error = g_blocks.std(axis=0, ddof=1) / np.sqrt(blocks) if blocks >= 2 else np.full(self.n_bins, np.nan)
        return {'r': 0.5 * (self.edges[1:] + self.edges[:-1]), 'g': mean, 'g_error': error,
                'pairs_per_frame_ideal': ideal, 'blocks': blocks, 'frames': int(frames.sum()),
                'particles': self.n_particles, 'dimension': self.dimension,
                'normalisation': 'box' if not densities else
                'observed marginal density along open axes %s' % ', '.join('xyz'[a] for a in densities)}
