"""Matrix-free Laplace layer potentials on the blobs: point quadrature, wall images (floor 3).

The boundary-integral operators of the solute field of phoretic bodies
(doc/phoretic.md), as the published code discretises them: a point rule at
the blob centres with weights ``w_j`` (area units), no regularisation, the
free-space self term (``j = i``) dropped, and with a wall (the plane
``z = 0``, fluid above) a Neumann image term for every pair, ``j = i``
included.  With ``r = x_i - x_j`` and the image vector
``R = x_i - x_j* = (r1, r2, z_i + z_j)``, ``n_j* = (n1, n2, -n3)``:

* single layer   ``S[f]_i  = 1/(4 pi) sum_j w_j f_j / r      (+ wall: / R)``
* double layer   ``D[f]_i  = 1/(4 pi) sum_j w_j f_j r.n_j / r^3   (+ R.n_j* / R^3)``
* its gradient   ``dD[f]_i = 1/(4 pi) sum_j w_j f_j (n_j - 3 r (r.n_j)/r^2) / r^3   (+ image)``
* "dipole"       ``Dip[f]_i = 1/(4 pi) sum_j w_j f_j r / r^3   (+ R / R^3) = -grad S[f]``

``D`` is ``n_y . grad_y`` of the Neumann Green function
``G(x, y) = 1/(4 pi |x - y|) + 1/(4 pi |x - y*|)`` (Pozrikidis, *Boundary
Integral and Singularity Methods*, 1992, ch. 6, for the free-space layers).

The NumPy version (:func:`layers_numpy`, the reference) is vectorised over
all pairs and chunked over targets, so memory is ``O(chunk N)``; the compiled
pair loop (``multi_bodies/solver/cpp/surface_module.cpp``, OpenMP over
targets) computes the same sums with O(N) memory and is used when built.  Shapes: positions and normals
(N, 3), densities and weights (N,); scalar results (N,), vector results
(N, 3).
"""
import numpy as np

PAIRS_PER_CHUNK = 1 << 20  # target-source pairs held at once (about 100 MB of float64 work arrays)
FOUR_PI = 4.0 * np.pi


def _chunks(num_targets, num_sources):
    step = max(1, PAIRS_PER_CHUNK // max(1, num_sources))
    for start in range(0, num_targets, step):
        yield slice(start, min(num_targets, start + step))


try:  # the compiled pair loop (multi_bodies/solver/cpp/surface_module.cpp, OpenMP); NumPy without it
    from multi_bodies.solver import _surface_cpp
except ImportError:  # pragma: no cover - a build without a C++ compiler
    _surface_cpp = None


def layers(x, normals, weights, wall, single=None, double=None, grad_double=None, dipole=None, backend=None):
    """The requested layer potentials of densities on the blobs (see :func:`layers_numpy`).

    backend : 'C++' (the compiled pair loop), 'python' (:func:`layers_numpy`) or None (C++ when built).
    """
    if backend is None:
        backend = 'python' if _surface_cpp is None else 'C++'
    if backend == 'python':
        return layers_numpy(x, normals, weights, wall, single, double, grad_double, dipole)
    if _surface_cpp is None:
        raise RuntimeError('the C++ Laplace kernels are not built (python3 -m pip install --no-build-isolation '
                           '--no-deps -e .)')
    w = np.asarray(weights, dtype=float).reshape(-1)
    empty = np.zeros(0)
    given = {'single': single, 'double': double, 'dipole': dipole, 'grad_double': grad_double}
    densities = [empty if given[k] is None else np.asarray(given[k], dtype=float).reshape(-1) * w
                 for k in ('single', 'double', 'dipole', 'grad_double')]
    results = _surface_cpp.layers(np.ascontiguousarray(x, dtype=float).reshape(-1, 3),
                                  np.ascontiguousarray(normals, dtype=float).reshape(-1, 3), *densities, bool(wall))
    return {k: v / FOUR_PI for k, v in zip(('single', 'double', 'dipole', 'grad_double'), results)
            if given[k] is not None}


def layers_numpy(x, normals, weights, wall, single=None, double=None, grad_double=None, dipole=None):
    """The requested layer potentials of densities on the blobs, in one pass over the pairs (NumPy reference).

    x : (N, 3) blob positions (lab frame); normals : (N, 3) lab-frame normals of the sources (used as
    given, not normalised); weights : (N,) quadrature weights; wall : bool, add the wall's images.
    single, double, grad_double, dipole : (N,) densities or None.
    Returns a dict with the keys given: 'single' (N,), 'double' (N,), 'grad_double' (N, 3),
    'dipole' (N, 3).
    """
    x = np.ascontiguousarray(x, dtype=float).reshape(-1, 3)
    n = np.ascontiguousarray(normals, dtype=float).reshape(-1, 3)
    w = np.asarray(weights, dtype=float).reshape(-1)
    N = x.shape[0]
    wanted = {'single': single, 'double': double, 'grad_double': grad_double, 'dipole': dipole}
    wanted = {k: np.asarray(v, dtype=float).reshape(-1) * w for k, v in wanted.items() if v is not None}
    out = {k: np.zeros((N, 3)) if k in ('grad_double', 'dipole') else np.zeros(N) for k in wanted}
    n_image = n * np.array([1.0, 1.0, -1.0])
    for rows in _chunks(N, N):
        targets = np.arange(N)[rows]
        r = x[rows, None, :] - x[None, :, :]
        d2 = np.einsum('ijk,ijk->ij', r, r)
        d2[np.arange(targets.size), targets] = np.inf  # the free-space self term is dropped
        _accumulate(out, wanted, r, d2, n, rows)
        if wall:
            R = r.copy()
            R[:, :, 2] = x[rows, None, 2] + x[None, :, 2]
            _accumulate(out, wanted, R, np.einsum('ijk,ijk->ij', R, R), n_image, rows)
    for k in out:
        out[k] /= FOUR_PI
    return out


def _accumulate(out, densities, r, d2, n, rows):
    """Add one family of pair terms (free space or images): r (c, N, 3), d2 = |r|^2 (c, N), n (N, 3) normals."""
    inv_r = 1.0 / np.sqrt(d2)
    inv_r3 = inv_r * inv_r * inv_r
    if 'single' in densities:
        out['single'][rows] += inv_r @ densities['single']
    if 'double' in densities or 'grad_double' in densities:
        r_dot_n = np.einsum('ijk,jk->ij', r, n)
    if 'double' in densities:
        out['double'][rows] += (r_dot_n * inv_r3) @ densities['double']
    if 'dipole' in densities:
        out['dipole'][rows] += np.einsum('ij,ijk->ik', inv_r3 * densities['dipole'][None, :], r)
    if 'grad_double' in densities:
        f = densities['grad_double'][None, :] * inv_r3  # (c, N)
        out['grad_double'][rows] += (f @ n) - 3.0 * np.einsum('ij,ijk->ik', f * r_dot_n * inv_r * inv_r, r)
