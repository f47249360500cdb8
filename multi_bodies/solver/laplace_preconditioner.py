"""A two-level preconditioner of the phoretic bodies' concentration problem (doc/preconditioners.md).

The concentration problem (:class:`phoretic.LaplaceProblem`) is ``A c = b`` with

    A_ij = delta_ij / 2 + K_ij / (4 pi),   K_ij = ws_j / r - wd_j (r.n_j) / r^3  (+ the wall's images),

``ws = w k / D`` and ``wd = w`` (the published point quadrature, ``laplace_kernels``).  Its single layer
couples bodies at ``1/r``: a body whose blobs react (``k != 0``) is a net sink whose strength every other
body feels, so a preconditioner that inverts every body alone (the blocks ``A_bb``) leaves the long-range
part to GMRES.  This one adds a coarse space of four modes per body (the constant and the three linear
functions ``x - x_b`` on its blobs, orthonormalised body by body: the monopole and dipole of its reaction),
corrected first (the multiplicative two-level form, Tang, Nabben, Vuik and Erlangga, J. Sci. Comput. 39,
340, 2009):

    y = E^{-1} Z^T r,   z = Z y + B^{-1} (r - (A Z) y),   E = Z^T A Z,   B = diag(A_bb).

``A Z`` (N, 4 B) and the blocks ``A_bb`` come from one pass over the blob pairs (a compiled kernel,
``_surface_cpp.laplace_blocks_and_moments``; :func:`blocks_and_moments_numpy` is its NumPy reference), about
the work of one product with ``A``.  Measured on Janus spheres above a wall (doc/preconditioners.md): GMRES
iterations from zero 15 -> 5 (30 spheres of 162 blobs, 2.6 radii apart), against 10 with the blocks alone.

With one body the blocks are ``A`` itself and GMRES converges in one iteration.  Under ``preconditioner auto``
the problem is preconditioned from ``AUTO_MIN_BLOBS`` blobs on (below, the build costs more than it saves).  When ``A Z`` would hold more
than ``MAX_COARSE_ENTRIES`` numbers the linear modes are dropped, and beyond that the coarse space (the blocks
stay).  Shapes: N blobs, B bodies; vectors (N,).
"""
import numpy as np
import scipy.linalg

from multi_bodies.solver.linear_map import LinearMap

try:
    from multi_bodies.solver import _surface_cpp
except ImportError:  # pragma: no cover - a build without a C++ compiler
    _surface_cpp = None

FOUR_PI = 4.0 * np.pi
MAX_COARSE_ENTRIES = 10_000_000  # numbers of A Z (80 MB): 4 modes for N B <= 2.5e6 (e.g. 100 bodies of 25,000 blobs)
MODE_CUTOFF = 1e-8  # a body's mode is kept when its singular value is above this fraction of the largest
# preconditioner auto: the concentration problem is preconditioned from this many blobs on.  Measured (42-blob
# shells, one solve from zero, build included, benchmarks/bench_phoretic.py): 210 blobs 2.1 ms unpreconditioned
# against 2.4 ms, 420 blobs 4.1 against 3.6-4.1 ms, 840 blobs 12.5 against 9.5 ms, 4,200 blobs 0.34 against 0.19 s.
AUTO_MIN_BLOBS = 400


def coarse_modes(x, offsets, modes_per_body):
    """Orthonormal coarse modes on every blob, Z (N, m), and which are used, active (B, m) bool.

    Body by body: the constant and (``modes_per_body`` 4) the linear functions ``x - centre`` on its blobs,
    orthonormalised (SVD); a mode of a body that has none of its own (a body of one blob has only the constant,
    one of collinear blobs two) is not active.
    """
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    num_bodies = len(offsets) - 1
    Z = np.zeros((x.shape[0], modes_per_body))
    active = np.zeros((num_bodies, modes_per_body), dtype=bool)
    if modes_per_body == 0:
        return Z, active
    for b in range(num_bodies):
        rows = slice(offsets[b], offsets[b + 1])
        xb = x[rows]
        basis = np.ones((xb.shape[0], 1))
        if modes_per_body == 4:
            basis = np.column_stack((basis, xb - xb.mean(axis=0)))
        U, s, _ = np.linalg.svd(basis, full_matrices=False)
        keep = s > MODE_CUTOFF * s[0]
        Z[rows, :int(keep.sum())] = U[:, keep]
        active[b, :int(keep.sum())] = True
    return Z, active


def blocks_and_moments_numpy(x, normals, ws, wd, offsets, modes, wall):
    """The NumPy reference of ``_surface_cpp.laplace_blocks_and_moments``: (blocks, moments).

    blocks : (sum n_b^2,) every body's own ``K_ij`` (row-major, body after body);
    moments : (N, B, m) ``sum over j of body b of K_ij Z_jm``.  ``K`` as in the module docstring, without 1/(4 pi).
    """
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    N, num_bodies, m = x.shape[0], len(offsets) - 1, modes.shape[1]
    blocks, moments = [], np.zeros((N, num_bodies, m))
    image = np.array([1.0, 1.0, -1.0])
    for b in range(num_bodies):
        sources = slice(offsets[b], offsets[b + 1])
        r = x[:, None, :] - x[None, sources, :]
        d = np.sqrt(np.einsum('ijk,ijk->ij', r, r))
        own = np.arange(offsets[b], offsets[b + 1])
        d[own, np.arange(own.size)] = np.inf  # the free-space self term is dropped
        kernel = ws[None, sources] / d - wd[None, sources] * np.einsum('ijk,jk->ij', r, normals[sources]) / d ** 3
        if wall:
            R = r.copy()
            R[:, :, 2] = x[:, None, 2] + x[None, sources, 2]
            dR = np.sqrt(np.einsum('ijk,ijk->ij', R, R))
            kernel += (ws[None, sources] / dR
                       - wd[None, sources] * np.einsum('ijk,jk->ij', R, normals[sources] * image) / dR ** 3)
        moments[:, b, :] = kernel @ modes[sources]
        blocks.append(kernel[sources].reshape(-1))
    return np.concatenate(blocks) if blocks else np.zeros(0), moments


class LaplacePreconditioner(LinearMap):
    """``P ~ A^{-1}`` of a :class:`phoretic.LaplaceProblem` (two-level: coarse modes, then every body alone).

    Parameters
    ----------
    problem : phoretic.LaplaceProblem (its blobs, normals, weights, reaction rates, diffusion coefficient, wall)
    blob_offsets : (B + 1,) ints, the blobs of body b are ``blob_offsets[b]:blob_offsets[b + 1]``
    modes_per_body : 4 (constant and linear, the default), 1 (constant) or 0 (the blocks alone)
    backend : 'C++', 'python' or None (C++ when built)

    ``apply(r)`` (N,) -> (N,); ``operator`` is it as a LinearOperator (``body_solver.solve`` takes either).
    ``modes_per_body`` says what was built (fewer than asked when ``A Z`` would be too large).
    """

    def __init__(self, problem, blob_offsets, modes_per_body=4, backend=None, max_coarse_entries=MAX_COARSE_ENTRIES):
        offsets = np.asarray(blob_offsets, dtype=np.int64).reshape(-1)
        x, normals = problem.r_vectors, problem.normals
        N, num_bodies = x.shape[0], offsets.size - 1
        if offsets[0] != 0 or offsets[-1] != N:
            raise ValueError('blob_offsets must run from 0 to the %d blobs of the problem' % N)
        if num_bodies < 2:
            modes_per_body = 0  # one body: its block is A
        while modes_per_body and N * num_bodies * modes_per_body > max_coarse_entries:
            modes_per_body = 1 if modes_per_body == 4 else 0
        self.modes_per_body = modes_per_body
        self.offsets, self.size, self.num_bodies = offsets, N, num_bodies
        Z, active = coarse_modes(x, offsets, modes_per_body)
        ws = problem.weights * problem.reaction / problem.diffusion_coefficient
        wd = np.array(problem.weights, dtype=float)
        if backend is None:
            backend = 'python' if _surface_cpp is None else 'C++'
        if backend == 'C++':
            blocks, moments = _surface_cpp.laplace_blocks_and_moments(
                np.ascontiguousarray(x), np.ascontiguousarray(normals), ws, wd, offsets, np.ascontiguousarray(Z),
                problem.wall)
        else:
            blocks, moments = blocks_and_moments_numpy(x, normals, ws, wd, offsets, Z, problem.wall)
        self._invert_blocks(blocks)
        self.coarse = None
        if modes_per_body:
            body_of_blob = np.repeat(np.arange(num_bodies), np.diff(offsets))
            AZ = moments / FOUR_PI
            AZ[np.arange(N), body_of_blob, :] += 0.5 * Z
            AZ = AZ.reshape(N, num_bodies * modes_per_body)[:, active.reshape(-1)]
            E = np.concatenate([Z[offsets[b]:offsets[b + 1], active[b]].T @ AZ[offsets[b]:offsets[b + 1]]
                                for b in range(num_bodies)])  # Z^T A Z over the active modes
            self.coarse = (Z, active, AZ, body_of_blob, scipy.linalg.lu_factor(E))
        self.size = N

    def _invert_blocks(self, blocks):
        sizes = np.diff(self.offsets)
        starts = np.concatenate(([0], np.cumsum(sizes ** 2)))
        self.inverses = []  # (bodies (k,), inverses (k, n, n)) for every body size n
        for n in np.unique(sizes):
            bodies = np.flatnonzero(sizes == n)
            K = np.stack([blocks[starts[b]:starts[b + 1]].reshape(n, n) for b in bodies])
            self.inverses.append((bodies, np.linalg.inv(0.5 * np.eye(n)[None] + K / FOUR_PI)))

    def block_solve(self, r):
        """``B^{-1} r`` (N,): every body's own block inverted."""
        out = np.empty(self.size)
        for bodies, inverses in self.inverses:
            n = inverses.shape[1]
            rows = self.offsets[bodies][:, None] + np.arange(n)[None, :]
            out[rows] = np.matmul(inverses, r[rows][:, :, None])[:, :, 0]
        return out

    def apply(self, r):
        """The preconditioner applied to a residual r (N,)."""
        r = np.asarray(r, dtype=float).reshape(-1)
        if self.coarse is None:
            return self.block_solve(r)
        Z, active, AZ, body_of_blob, E = self.coarse
        projected = np.add.reduceat(Z * r[:, None], self.offsets[:-1], axis=0)[active]  # Z^T r
        y = scipy.linalg.lu_solve(E, projected)
        per_body = np.zeros(active.shape)
        per_body[active] = y
        coarse = np.einsum('ik,ik->i', Z, per_body[body_of_blob])
        return coarse + self.block_solve(r - AZ @ y)
