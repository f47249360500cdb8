"""Which grid nodes each blob touches and with which weights (the node, clamping, ghost-folding and wall-node
rules of the DoublyPeriodicStokes discretisation), vectorised over blobs.

A blob's 3-D kernel weight at a node is the product of three 1-D factors, so a blob's stencil is stored as
per-direction node indices and 1-D weights (one source of truth for the NumPy and the compiled product):

* x and y (and z on the triply periodic grid): ``w`` consecutive nodes from the first node ``i0``
  (``c = floor(X/h)``, for odd ``w`` rounded to the nearest node; ``i0 = c - w/2 + 1`` for even ``w``,
  ``c - (w-1)/2`` for odd ``w``), offsets ``(i0 + j) h - X``, an offset beyond the threshold replaced by
  ``+threshold`` (DoublyPeriodicStokes' clamping rule), indices wrapped periodically.
* z on a Chebyshev grid: every interior node within the threshold of the blob, plus the mirror images
  (ghost nodes) of interior nodes across an end of the grid, folded back onto the node they mirror with a
  sign: dropped at an open end, ``s`` at a wall, where ``s = -1`` for the force density, the x- and
  y-derivative torque spreads and the velocity, ``s = +1`` for the z-derivative spread (and the velocity
  it is tested against).  The node on a wall is multiplied by ``1 + s``.  Folding per blob and folding the
  spread grid give the same sums.

Arrays (n blobs): ``ix`` (n, wx), ``iy`` (n, wy), ``iz`` (n, nz) int64 node indices; ``phi_x``, ``phi_y``
(n, w) and ``phi_z`` (n, nz) 1-D weights (1/length each); for a dipole kernel also ``dphi_x``, ``dphi_y``
(derivative factors) and ``dphi_z`` (the z derivative folded with s = +1), 1/length^2.  Unused z slots
(blobs with fewer z nodes than the widest) carry weight 0 and a valid index.
"""
from dataclasses import dataclass

import numpy as np

# How ghost nodes fold at each end of the Chebyshev grid: (top, bottom) for the fields folded with s = -1
# (force density, x/y-derivative spreads, velocity) and s = +1 (z-derivative spread); 0 = dropped (open end).
# The wall-node factor 1 + s applies only at walls.
END_SIGNS = {'DP': ((0, 0), (0, 0)), 'DPBW': ((0, -1), (0, +1)), 'DPSC': ((-1, -1), (+1, +1))}
WALL_ENDS = {'DP': (False, False), 'DPBW': (False, True), 'DPSC': (True, True)}


@dataclass
class Stencil:
    """Per-blob nodes and 1-D weights of one kernel (see the module docstring for the arrays)."""
    ix: np.ndarray
    iy: np.ndarray
    iz: np.ndarray
    phi_x: np.ndarray
    phi_y: np.ndarray
    phi_z: np.ndarray
    dphi_x: np.ndarray = None
    dphi_y: np.ndarray = None
    dphi_z: np.ndarray = None

    @property
    def n(self):
        return self.ix.shape[0]

    def take(self, rows):
        """The stencil of the blobs ``rows`` (a slice or index array)."""
        def pick(a):
            return None if a is None else a[rows]
        return Stencil(*(pick(getattr(self, name)) for name in ('ix', 'iy', 'iz', 'phi_x', 'phi_y', 'phi_z',
                                                                 'dphi_x', 'dphi_y', 'dphi_z')))


def _es(d, beta, alpha):
    return np.exp(beta * (np.sqrt(1.0 - d * d / (alpha * alpha)) - 1.0))


def _es_derivative_factor(d, beta, alpha):
    """phi'(d) / phi(d) for the ES kernel: -beta d / (alpha^2 sqrt(1 - d^2/alpha^2))."""
    return -beta * d / (alpha * alpha * np.sqrt(1.0 - d * d / (alpha * alpha)))


def _two_product(a, b):
    """``(p, e)`` with ``p = fl(a b)`` and ``a b = p + e`` exactly (Dekker's splitting; no overflow assumed)."""
    p = a * b
    split = 134217729.0  # 2^27 + 1
    t = split * a
    a_hi = t - (t - a)
    a_lo = a - a_hi
    t = split * b
    b_hi = t - (t - b)
    b_lo = b - b_hi
    e = ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo
    return p, e


def _two_sum(a, b):
    """``(s, e)`` with ``s = fl(a + b)`` and ``a + b = s + e`` exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def fused_multiply_add(a, b, c):
    """``a b + c`` rounded once (what a fused multiply-add instruction gives), elementwise, in NumPy.

    DoublyPeriodicStokes is built with ``-O3 -march=native``, so the compiler fuses its node offsets
    ``index * h - X`` into one instruction; near the kernel's edge the ES weight ``sqrt(1 - d^2/alpha^2)``
    magnifies a one-ulp difference in ``d`` to 1e-7 of that weight, so the offsets are computed the same way
    here.  The exact value ``s + t + e`` (error-free product and sum) is rounded once: the small part
    ``t + e`` is first rounded to odd, which makes the final rounding correct (Boldo and Melquiond, IEEE
    Trans. Computers 57, 462, 2008).
    """
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (a, b, c)))
    p, e = _two_product(a, b)
    s, t = _two_sum(p, c)
    u, v = _two_sum(t, e)
    even = (u.view(np.int64) & 1) == 0
    u = np.where((v != 0) & even, np.nextafter(u, np.where(v > 0, np.inf, -np.inf)), u)
    return s + u


def uniform_nodes(X, h, n_nodes, width, threshold):
    """Nodes and clamped offsets on a uniform periodic grid.

    X : (n,) coordinates relative to the grid origin, in [0, n_nodes h]; h : spacing; width : nodes under the
    kernel; threshold : support half-width.  Returns ``(index (n, width) wrapped, offsets (n, width))``.
    """
    ratio = X / h
    c = np.floor(ratio).astype(np.int64)
    if width % 2:
        c += (ratio - c > 0.5)
        first = c - (width - 1) // 2
    else:
        first = c - width // 2 + 1
    index = first[:, None] + np.arange(width)
    offsets = fused_multiply_add(index.astype(float), h, -X[:, None])
    offsets = np.where(np.abs(offsets) > threshold, threshold, offsets)
    return np.mod(index, n_nodes), offsets


def _uniform_factors(X, h, n_nodes, width, beta, alpha, norm, threshold, derivative):
    index, d = uniform_nodes(X, h, n_nodes, width, threshold)
    phi = _es(d, beta, alpha)
    dphi = phi * _es_derivative_factor(d, beta, alpha) / norm if derivative else None
    return index, phi / norm, dphi


class ChebyshevNodes:
    """The Chebyshev z grid of a discretisation with its ghost images, for the z stencils."""

    def __init__(self, parameters):
        p = parameters
        self.Nz = p.Nz
        self.z = p.z_nodes()                     # interior nodes, top first: z[0] = Lz, z[Nz-1] = 0
        self.top = 2.0 * self.z[0] - self.z      # ghost above the top mirroring node k (k >= 1)
        self.bottom = -self.z                    # ghost below the bottom mirroring node k (k <= Nz-2)
        self.ascending = self.z[::-1]
        self.geometry = p.geometry

    def stencil(self, Z, beta, alpha, norm, threshold, derivative):
        """z indices and folded weights for blobs at heights Z (n,) relative to z0.

        Returns ``(iz (n, nz), phi_z (n, nz), dphi_z (n, nz) or None)``: phi_z folded with s = -1 at walls,
        dphi_z (the derivative factor) with s = +1; wall nodes multiplied by 1 + s; open ends dropped.
        """
        Nz = self.Nz
        lo, hi = Z - threshold, Z + threshold
        # interior nodes with lo <= z <= hi: ascending positions [a, b) -> descending indices
        a = np.searchsorted(self.ascending, lo, side='left')
        b = np.searchsorted(self.ascending, hi, side='right')
        count = b - a
        k_first = Nz - b                          # smallest interior index touched
        width = max(int(count.max()) if count.size else 1, 1)
        slots = np.arange(width)
        k = k_first[:, None] + slots
        used = slots < count[:, None]
        k = np.where(used, k, np.minimum(k_first[:, None], Nz - 1))
        (top_m, bottom_m), (top_p, bottom_p) = END_SIGNS[self.geometry]
        wall_top, wall_bottom = WALL_ENDS[self.geometry]
        Zc = Z[:, None]

        def folded(sign_top, sign_bottom, kernel):
            total = np.where(used, kernel(np.where(used, self.z[k] - Zc, 0.0)), 0.0)
            if sign_top:
                zg = self.top[k]
                inside = used & (k >= 1) & (zg >= lo[:, None]) & (zg <= hi[:, None])
                total = total + sign_top * np.where(inside, kernel(np.where(inside, zg - Zc, 0.0)), 0.0)
            if sign_bottom:
                zg = self.bottom[k]
                inside = used & (k <= Nz - 2) & (zg >= lo[:, None]) & (zg <= hi[:, None])
                total = total + sign_bottom * np.where(inside, kernel(np.where(inside, zg - Zc, 0.0)), 0.0)
            if wall_top:
                total = np.where(k == 0, (1 + sign_top) * total, total)
            if wall_bottom:
                total = np.where(k == Nz - 1, (1 + sign_bottom) * total, total)
            return np.where(used, total, 0.0)

        def phi(d):
            return _es(d, beta, alpha) / norm

        def dphi(d):
            return _es(d, beta, alpha) * _es_derivative_factor(d, beta, alpha) / norm

        phi_z = folded(top_m, bottom_m, phi)
        dphi_z = folded(top_p, bottom_p, dphi) if derivative else None
        return k, phi_z, dphi_z


def wrap_positions(parameters, r):
    """Blob coordinates relative to the grid origin, x and y (TP: also z) wrapped into [0, L]; (n, 3).

    Coordinates already in [0, L] are not touched (no round-off); others move by whole periods.
    """
    p = parameters
    rel = np.array(r, dtype=float)
    rel[:, 0] -= p.x0
    rel[:, 1] -= p.y0
    rel[:, 2] -= p.z0
    periods = [p.Lx, p.Ly] + ([p.Lz] if p.geometry == 'TP' else [])
    for axis, L in enumerate(periods):
        c = rel[:, axis]
        out = (c < 0) | (c > L)
        if np.any(out):
            c[out] = c[out] - np.floor(c[out] / L) * L
    return rel


STENCIL_CHUNK = 1 << 16  # blobs per block while stencils are made (bounds the temporaries)


def make_stencil(parameters, kernel, rel, derivative=False):
    """The :class:`Stencil` of ``kernel`` (a KernelParameters) for blobs at ``rel`` (n, 3), coordinates
    relative to the grid origin (:func:`wrap_positions`); ``derivative``: also the derivative factors.
    Made in blocks of :data:`STENCIL_CHUNK` blobs, the z slots padded to the widest block."""
    n = rel.shape[0]
    if n <= STENCIL_CHUNK:
        return _make_stencil(parameters, kernel, rel, derivative)
    parts = [_make_stencil(parameters, kernel, rel[start:start + STENCIL_CHUNK], derivative)
             for start in range(0, n, STENCIL_CHUNK)]
    width = max(part.iz.shape[1] for part in parts)
    names = ('ix', 'iy', 'iz', 'phi_x', 'phi_y', 'phi_z', 'dphi_x', 'dphi_y', 'dphi_z')
    out = {}
    for name in names:
        first = getattr(parts[0], name)
        if first is None:
            out[name] = None
            continue
        columns = width if name in ('iz', 'phi_z', 'dphi_z') else first.shape[1]
        array = np.zeros((n, columns), dtype=first.dtype)
        start = 0
        for part in parts:
            block = getattr(part, name)
            array[start:start + block.shape[0], :block.shape[1]] = block
            if name == 'iz' and block.shape[1] < columns:   # padded slots: a valid index, weight 0
                array[start:start + block.shape[0], block.shape[1]:] = block[:, :1]
            start += block.shape[0]
        out[name] = array
    return Stencil(**out)


def _make_stencil(parameters, kernel, rel, derivative=False):
    p = parameters
    k = kernel
    ix, phi_x, dphi_x = _uniform_factors(rel[:, 0], p.hx, p.Nx, k.width[0], k.beta[0], k.alpha[0], k.norm[0],
                                         k.threshold[0], derivative)
    iy, phi_y, dphi_y = _uniform_factors(rel[:, 1], p.hy, p.Ny, k.width[1], k.beta[1], k.alpha[1], k.norm[1],
                                         k.threshold[1], derivative)
    if p.geometry == 'TP':
        iz, phi_z, dphi_z = _uniform_factors(rel[:, 2], p.hz, p.Nz, k.width[2], k.beta[2], k.alpha[2], k.norm[2],
                                             k.threshold[2], derivative)
    else:
        iz, phi_z, dphi_z = ChebyshevNodes(p).stencil(rel[:, 2], k.beta[2], k.alpha[2], k.norm[2], k.threshold[2],
                                                      derivative)
    return Stencil(ix, iy, iz, phi_x, phi_y, phi_z, dphi_x, dphi_y, dphi_z)
