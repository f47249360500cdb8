"""Static structure factor S(k) on the periodic box's wavevectors, per species, radially binned.

    rho_a(k) = sum_{j in a} exp(-i k . r_j),   S_ab(k) = Re < rho_a(k) rho_b(k)^* > / sqrt(N_a N_b),

with ``k = 2 pi (n_x / L_x, n_y / L_y[, n_z / L_z])``, integers ``|n| <= n_max`` (the
wavevectors of the box, so the sum does not depend on which periodic image
of a particle is saved).  In the plane (``dimension 2``, quasi-2-d suspensions
above a wall) only x and y enter and only ``L_x, L_y`` must be periodic; in
3-d all three must be.  Species: ``all`` and, with ``green = (i0, i1)`` (the
published option ``green_particles``: particles ``i0 <= index < i1``), ``green``,
``red`` (the others) and the cross term ``green_red``.  S(k) = S(-k), so one
half of the wavevectors is kept (``n_y > 0``, or ``n_y = 0`` and ``n_x > 0``;
in 3-d the same with ``n_z`` first); k = 0 is left out.

Ideal gas (uniform independent points): S(k) = 1, with per-frame variance
``1 - 1/N`` at every k; a perfect lattice of N points: S = N at its reciprocal
lattice vectors and 0 at every other box wavevector.

Computation: the phases factorise, ``exp(-i k.r) = e_x(n_x) e_y(n_y) [e_z(n_z)]``,
each ``e_a(n)`` the n-th power of one exponential (:func:`phase_powers`),
so the grid of rho(k) of one frame is a product of small matrices
(``(2 n_max + 1) x N`` times ``N x (n_max + 1)``, one BLAS call) instead of
N x n_k exponentials; particles are taken in chunks so memory stays
O(chunk x n_max^2).
"""
import numpy as np

from multi_bodies.analysis.trajectories import BlockSums, block_mean_and_error
from utils import UserInputError, refuse_if_too_big

PARTICLE_CHUNK = 4096


def species_masks(n_particles, green=None):
    """{species name: boolean mask (N,)}: ``all``, and ``green``/``red`` for green = (i0, i1)."""
    masks = {'all': np.ones(n_particles, dtype=bool)}
    if green is not None and green[1] > green[0]:
        i0, i1 = int(green[0]), int(green[1])
        if i0 < 0 or i1 > n_particles:
            raise UserInputError('green particles %d to %d: there are only %d particles' % (i0, i1, n_particles))
        masks['green'] = np.zeros(n_particles, dtype=bool)
        masks['green'][i0:i1] = True
        masks['red'] = ~masks['green']
    return masks


def species_pairs(masks):
    """The (a, b) pairs of S_ab: (all, all) and, with green particles, (green, green), (red, red), (green, red)."""
    pairs = [('all', 'all')]
    if 'green' in masks:
        pairs += [('green', 'green'), ('red', 'red'), ('green', 'red')]
    return pairs


def box_wavevectors(periodic_length, n_max, dimension=2):
    """Indices (n_k, d) and wavevectors (n_k, d) of the half space, |n_a| <= n_max[a], k = 0 left out.

    periodic_length : (3,); n_max : int or (d,) ints.  Order: the flattened grid of :func:`phase_grid`.
    """
    box = check_periodic(periodic_length, dimension)
    n_max = np.broadcast_to(np.asarray(n_max, dtype=int), (dimension,))
    ranges = [np.arange(-m, m + 1) for m in n_max[:-1]] + [np.arange(0, n_max[-1] + 1)]
    grid = np.stack(np.meshgrid(*ranges, indexing='ij'), axis=-1).reshape(-1, dimension)
    keep = half_space(grid)
    return grid, keep, 2.0 * np.pi * grid / box[None, :]


def half_space(indices):
    """Mask of one of each pair (n, -n), n != 0: the last nonzero component is positive."""
    indices = np.asarray(indices)
    keep = np.zeros(len(indices), dtype=bool)
    decided = np.zeros(len(indices), dtype=bool)
    for axis in range(indices.shape[1] - 1, -1, -1):
        component = indices[:, axis]
        keep |= ~decided & (component > 0)
        decided |= component != 0
    return keep


def check_periodic(periodic_length, dimension):
    box = np.asarray(periodic_length, dtype=float).reshape(3)[:dimension]
    if dimension not in (2, 3):
        raise UserInputError('the dimension of S(k) must be 2 (in the plane) or 3, got %r' % dimension)
    if np.any(box <= 0):
        raise UserInputError('S(k) on the box wavevectors needs periodic_length > 0 along %s (got %s); give the '
                             'box with --periodic-length' % ('x and y' if dimension == 2 else 'x, y and z',
                                                              ' '.join('%g' % v for v in box)))
    return box


def phase_powers(coordinates, length, m, both_signs=True):
    """exp(-2 pi i n x / L) for n = -m..m (both_signs) or 0..m: array (N, 2m+1) or (N, m+1).

    One exponential per particle, then its powers by a cumulative product
    (rounding grows like n * 1e-16: 5e-14 at n = 32, measured), four times
    faster than N x n exponentials.
    """
    powers = np.empty((len(coordinates), m + 1), dtype=complex)
    powers[:, 0] = 1.0
    powers[:, 1:] = np.exp(-2j * np.pi * np.asarray(coordinates, dtype=float) / length)[:, None]
    np.cumprod(powers, axis=1, out=powers)
    if not both_signs:
        return powers
    return np.concatenate([np.conj(powers[:, :0:-1]), powers], axis=1)


def density_modes(positions, box, n_max):
    """rho(k) = sum_j exp(-i k . r_j) on the grid of :func:`box_wavevectors` (flattened), one frame.

    positions : (N, d) lengths; box : (d,); n_max : (d,) ints.  Returns complex (n_grid,).
    """
    dimension = len(box)
    total = None
    for start in range(0, len(positions), PARTICLE_CHUNK):
        chunk = positions[start:start + PARTICLE_CHUNK]
        factors = [phase_powers(chunk[:, axis], box[axis], n_max[axis], both_signs=axis < dimension - 1)
                   for axis in range(dimension)]
        if dimension == 2:
            part = factors[0].T @ factors[1]
        else:
            xy = (factors[0][:, :, None] * factors[1][:, None, :]).reshape(len(chunk), -1)
            part = xy.T @ factors[2]
        part = part.ravel()
        total = part if total is None else total + part
    if total is None:
        total = np.zeros(np.prod([2 * m + 1 for m in n_max[:-1]]) * (n_max[-1] + 1), dtype=complex)
    return total


def structure_factor_memory(n_max, blocks=10, pairs=4):
    """Bytes the S(k) accumulator of the index box ``n_max`` (d,) needs at most: per wavevector of the box grid
    its indices, wavevector and |k| (3 d + 2 doubles), the density modes of a frame (complex, three species, the
    sum and its copy), and the block sums of ``pairs`` species pairs over ``blocks`` blocks (sums and weights,
    twice while a block is added)."""
    n_max = [int(m) for m in np.atleast_1d(n_max)]
    grid = 1
    for m in n_max[:-1]:
        grid *= 2 * m + 1
    grid *= n_max[-1] + 1
    return grid * (8 * (3 * len(n_max) + 2) + 16 * 3 * 3 + 8 * pairs * (1 + 4 * blocks))


class StructureFactor:
    """Accumulator of S_ab(k) over frames on the half-space box wavevectors (see module docstring).

    periodic_length : (3,); n_max : largest |index| per axis (int or (d,)); dimension : 2 or 3;
    green : (i0, i1) or None; radial_width : bin width of |k| (default 2 pi / largest box length);
    where : the option that sets ``n_max`` (its file and line, or the command-line flag), for the refusal of a
    box of wavevectors that does not fit in memory (:func:`structure_factor_memory`, checked before anything is
    allocated); blocks : blocks of frames of the error bars.
    """

    def __init__(self, periodic_length, n_max=16, dimension=2, green=None, radial_width=None, where='S(k)',
                 blocks=10):
        self.box = check_periodic(periodic_length, dimension)
        self.dimension = dimension
        self.n_max = np.broadcast_to(np.asarray(n_max, dtype=np.int64), (dimension,)).copy()
        if np.any(self.n_max < 1):
            raise UserInputError('%s: the largest wavevector index must be at least 1, got %s' % (where, self.n_max))
        refuse_if_too_big(structure_factor_memory(self.n_max, blocks), 'S(k) on the wavevectors of |n| <= %s'
                          % ' x '.join(str(int(m)) for m in self.n_max), where,
                          'ask for fewer wavevectors (the largest index of every axis)')
        grid, keep, _ = box_wavevectors(periodic_length, self.n_max, dimension)
        self.keep = keep
        self.indices = grid[keep]
        self.wavevectors = 2.0 * np.pi * self.indices / self.box[None, :]
        self.k = np.linalg.norm(self.wavevectors, axis=1)
        self.radial_width = float(radial_width) if radial_width else 2.0 * np.pi / self.box.max()
        self.green, self.masks, self.pairs, self.sums, self.n_particles = green, None, None, None, None

    def start_source(self):
        pass

    def _prepare(self, n_particles):
        self.n_particles = n_particles
        self.masks = species_masks(n_particles, self.green)
        self.pairs = species_pairs(self.masks)
        self.sums = BlockSums((len(self.pairs), len(self.k)))

    def add(self, positions, frames, blocks):
        points = np.asarray(positions, dtype=float)[:, :, :self.dimension]
        if self.masks is None:
            self._prepare(points.shape[1])
        for frame_points, block in zip(points, blocks):
            self.sums.add(block, self.frame_values(frame_points))

    def frame_values(self, frame_points):
        """S_ab(k) of one frame: (n_pairs, n_k)."""
        modes = {name: density_modes(frame_points[mask], self.box, self.n_max)[self.keep]
                 for name, mask in self.masks.items() if name in {p for pair in self.pairs for p in pair}}
        counts = {name: mask.sum() for name, mask in self.masks.items()}
        values = np.empty((len(self.pairs), len(self.k)))
        for row, (a, b) in enumerate(self.pairs):
            values[row] = (modes[a] * np.conj(modes[b])).real / np.sqrt(max(counts[a] * counts[b], 1))
        return values

    def reset(self):
        """Start the averages afresh (the published ``save_HydroGrid``: the average restarts after a save)."""
        if self.sums is not None:
            self.sums = BlockSums(self.sums.shape)

    def result(self):
        """dict: indices (n_k, d), wavevectors (n_k, d), k (n_k,), pairs, S and S_error (n_pairs, n_k),
        radial: k (n_r,), S and S_error (n_pairs, n_r), count (n_r,) wavevectors per bin; blocks, frames."""
        if self.sums is None or self.sums.weights.sum() == 0:
            raise UserInputError('S(k): no frame was analysed')
        weights = self.sums.weights[:, 0, 0]
        mean, error = block_mean_and_error(self.sums.sums, weights)
        bins = np.floor(self.k / self.radial_width + 0.5).astype(int)  # bin j holds |k| in ((j - 1/2) w, (j + 1/2) w]
        labels, inverse, count = np.unique(bins, return_inverse=True, return_counts=True)
        radial_blocks = np.stack([np.stack([np.bincount(inverse, weights=row, minlength=len(labels)) / count
                                            for row in block]) for block in self.sums.sums])
        radial_mean, radial_error = block_mean_and_error(radial_blocks, weights)
        radial_k = np.bincount(inverse, weights=self.k) / count
        return {'indices': self.indices, 'wavevectors': self.wavevectors, 'k': self.k, 'pairs': self.pairs,
                'S': mean, 'S_error': error,
                'radial': {'k': radial_k, 'S': radial_mean, 'S_error': radial_error, 'count': count},
                'blocks': int((weights > 0).sum()), 'frames': int(weights.sum()), 'particles': self.n_particles,
                'dimension': self.dimension, 'box': self.box}
