"""NumPy backend: matrix-free blob mobility products with bounded memory.

Pairs are processed in chunks of targets so that no array larger than about
``PAIRS_PER_CHUNK`` pairs is ever built, at any number of blobs.  Chunks are
independent and NumPy releases the GIL inside its loops, so two chunks run
at once on two threads.

All public functions take ``r_vectors: (N, 3)`` (or a flat (3N,) array),
vectors flat (3N,) or (N, 3), and return flat (3N,) arrays, in the units of
the caller (velocity = mobility x force).
"""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from body.geometry import wrap_axis

from . import pair_formulas as pf
from .pair_formulas import wall_regularisation
from .product_names import product_functions, source_target_functions

PAIRS_PER_CHUNK = 1 << 17
_THREADS = max(1, min(2, os.cpu_count() or 1))


def as_positions(r_vectors, name='r_vectors'):
    """Return ``r_vectors`` as a C-contiguous float64 (N, 3) array."""
    r = np.ascontiguousarray(r_vectors, dtype=np.float64)
    if r.ndim == 1:
        if r.size % 3:
            raise ValueError('%s has %d entries; expected 3 per blob' % (name, r.size))
        r = r.reshape(-1, 3)
    if r.ndim != 2 or r.shape[1] != 3:
        raise ValueError('%s must have shape (N, 3), got %s' % (name, r.shape))
    return r


def as_blob_vectors(vector, n_blobs, name='vector'):
    """Return a per-blob vector as a float64 (N, 3) array, checking its size."""
    v = np.ascontiguousarray(vector, dtype=np.float64).reshape(-1)
    if v.size != 3 * n_blobs:
        raise ValueError('%s has %d entries; expected 3 per blob (%d)' % (name, v.size, 3 * n_blobs))
    return v.reshape(n_blobs, 3)


def as_periodic_length(periodic_length):
    """Return the periodic box lengths (3,) as floats (0 = not periodic)."""
    if periodic_length is None:
        return np.zeros(3)
    L = np.asarray(periodic_length, dtype=np.float64).reshape(-1)
    if L.size != 3:
        raise ValueError('periodic_length needs three numbers (Lx, Ly, Lz), got %d' % L.size)
    if np.any(L < 0):
        raise ValueError('periodic_length entries must be >= 0, got %s' % (L,))
    return L


def image_shifts(periodic_length):
    """Shifts (K, 3) of the neighbour boxes -L, 0, +L along each periodic axis."""
    axes = [(-1.0, 0.0, 1.0) if L > 0 else (0.0,) for L in periodic_length]
    grid = np.array(np.meshgrid(*axes, indexing='ij')).reshape(3, -1).T
    return grid * periodic_length


def _chunks(n_targets, n_sources):
    rows = max(1, PAIRS_PER_CHUNK // max(1, n_sources))
    return [(i, min(i + rows, n_targets)) for i in range(0, n_targets, rows)]


def pair_sum(targets, sources, vectors, periodic_length, pair_function, extra_target=None, extra_source=None):
    """Sum ``pair_function`` over all source images for every target.

    targets: (Nt, 3), sources: (Ns, 3), vectors: (Ns, 3), all in the units the
    pair function expects.  ``pair_function(rx, ry, rz, zt, zs, [bt, bs,] vx, vy, vz)``
    receives arrays of shape (targets in chunk, Ns) and returns three (chunk,)
    sums.  Optional per-target and per-source scalars (radii) are passed as
    ``extra_target`` (Nt,) and ``extra_source`` (Ns,).  Returns (Nt, 3).
    """
    L = periodic_length
    shifts = image_shifts(L)
    result = np.zeros((targets.shape[0], 3))
    sx, sy, sz = (sources[:, k][None, :] for k in range(3))
    vx, vy, vz = (vectors[:, k][None, :] for k in range(3))
    es = None if extra_source is None else extra_source[None, :]

    def work(bounds):
        lo, hi = bounds
        t = targets[lo:hi]
        dx = wrap_axis(t[:, 0:1] - sx, L[0])
        dy = wrap_axis(t[:, 1:2] - sy, L[1])
        dz = wrap_axis(t[:, 2:3] - sz, L[2])
        zt = t[:, 2:3]
        extra = () if extra_target is None else (extra_target[lo:hi, None], es)
        for shift in shifts:
            ux, uy, uz = pair_function(dx + shift[0], dy + shift[1], dz + shift[2], zt, sz, *extra, vx, vy, vz)
            result[lo:hi, 0] += ux
            result[lo:hi, 1] += uy
            result[lo:hi, 2] += uz

    chunks = _chunks(targets.shape[0], sources.shape[0])
    if len(chunks) > 1 and _THREADS > 1:
        with ThreadPoolExecutor(_THREADS) as pool:
            list(pool.map(work, chunks))
    else:
        for bounds in chunks:
            work(bounds)
    return result


def _blob_product(pair_function, r_vectors, vector, eta, a, periodic_length, wall, radius_power):
    """Shared driver of the four equal-radius products (see the public functions)."""
    r = as_positions(r_vectors)
    v = as_blob_vectors(vector, r.shape[0])
    L = as_periodic_length(periodic_length)
    if wall and L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a wall at z = 0')
    if wall:
        r_eff, damping = _regularise(r, a)
        v = v * damping[:, None]
    else:
        r_eff, damping = r, None
    scaled = r_eff / a
    u = pair_sum(scaled, scaled, v, L / a, lambda *args: pair_function(*args, wall=wall))
    if damping is not None:
        u *= damping[:, None]
    return (u / (8.0 * np.pi * eta * a ** radius_power)).reshape(-1)


_PAIR_FUNCTIONS = {'trans_times_force': (pf.trans_times_force_pairs, 1),
                   'trans_times_torque': (pf.trans_times_torque_pairs, 2),
                   'rot_times_force': (pf.rot_times_force_pairs, 2),
                   'rot_times_torque': (pf.rot_times_torque_pairs, 3)}


def _make_product(kind, wall):
    pair_function, radius_power = _PAIR_FUNCTIONS[kind]

    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0)):
        radius = blob_radii(a, r_vectors, kind)
        if radius.ndim:
            return _source_target(r_vectors, r_vectors, vector, radius, radius, eta, periodic_length,
                                  'single_wall' if wall else 'no_wall')
        return _blob_product(pair_function, r_vectors, vector, eta, float(radius), periodic_length, wall,
                             radius_power)
    return product


def blob_radii(a, r_vectors, kind='trans_times_force'):
    """The blob radius argument ``a`` of a product: a number, or one radius per blob (N,).

    Returns a 0-d array (one radius: the equal-radius formulas) or an (N,)
    array of radii that are not all equal (the formulas for different radii).
    Per-blob radii that are all equal collapse to one number, so equal radii
    give exactly the single-radius numbers.  Only ``trans_times_force`` has
    a form for different radii; the roller couplings refuse them
    (``utils.UserInputError``).
    """
    radius = np.asarray(a, dtype=np.float64)
    if radius.ndim == 0 or radius.size == 1:
        return radius.reshape(())
    n = np.size(r_vectors) // 3
    radius = radius.reshape(-1)
    if radius.size != n:
        raise ValueError('blob radii: %d values for %d blobs' % (radius.size, n))
    if np.all(radius == radius[0]):
        return radius[0].reshape(())
    if not np.all(np.isfinite(radius)) or np.any(radius <= 0):
        raise ValueError('blob radii must be positive and finite')
    if kind != 'trans_times_force':
        from utils import UserInputError
        raise UserInputError('the %s product has no form for blobs of different radii (only M f does); give every '
                             'blob the same radius (remove the 4th column of the vertex files)' % kind)
    return radius


globals().update(product_functions(_make_product, 'NumPy'))


def _source_target(source_r, target_r, force, radius_source, radius_target, eta, periodic_length, wall):
    """Velocity (3Nt,) at targets; ``wall`` True/False or a domain name (single_wall, no_wall, free_surface)."""
    domain = wall if isinstance(wall, str) else ('single_wall' if wall else 'no_wall')
    wall = domain == 'single_wall'
    source = as_positions(source_r, 'source positions')
    target = as_positions(target_r, 'target positions')
    f = as_blob_vectors(force, source.shape[0], 'force')
    a_s = np.broadcast_to(np.asarray(radius_source, dtype=np.float64), (source.shape[0],)).copy()
    b_t = np.broadcast_to(np.asarray(radius_target, dtype=np.float64), (target.shape[0],)).copy()
    L = as_periodic_length(periodic_length)
    if domain != 'no_wall' and L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a wall or free surface at z = 0')
    damping_t = None
    if wall:
        source, damping_s = _regularise(source, a_s)
        target, damping_t = _regularise(target, b_t)
        f = f * damping_s[:, None]

    def pairs(rx, ry, rz, zt, zs, bt, as_, fx, fy, fz):
        if domain == 'free_surface':
            return pf.free_surface_unequal_radii_pairs(rx, ry, rz, zt, zs, bt, as_, fx, fy, fz)
        return pf.trans_times_force_unequal_radii_pairs(rx, ry, rz, zt, zs, bt, as_, fx, fy, fz, wall)

    u = pair_sum(target, source, f, L, pairs, extra_target=b_t, extra_source=a_s)
    if damping_t is not None:
        u *= damping_t[:, None]
    return (u / (8.0 * np.pi * eta)).reshape(-1)


def _regularise(r, radius):
    """Positions (N, 3) with z raised to max(z, radius) and the damping (N,) (see periodic.wall_regularisation)."""
    r_eff = r.copy()
    r_eff[:, 2], damping = wall_regularisation(r[:, 2], radius)
    return r_eff, damping


globals().update(source_target_functions(_source_target, 'NumPy'))


# ---------------------------------------------------------------------------
# Dense matrices (small systems, dense-algebra schemes, preconditioner blocks)

def _dense_trans_trans(r_vectors, eta, a, wall, periodic_length):
    """Dense mobility of one body (N, 3) -> (3N, 3N), or of a stack of bodies
    (nb, n, 3) -> (nb, 3n, 3n) built in one vectorised pass (preconditioner blocks)."""
    r = np.asarray(r_vectors, dtype=np.float64)
    stacked = r.ndim == 3 and r.shape[2] == 3
    if not stacked:
        r = as_positions(r)[None]
    nb, n, _ = r.shape
    L = as_periodic_length(periodic_length)
    if wall and L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a wall at z = 0')
    if wall:
        z_eff, damping = wall_regularisation(r[..., 2], a)
        s = np.concatenate((r[..., :2], z_eff[..., None]), axis=-1) / a
    else:
        damping = np.ones((nb, n))
        s = r / a
    La = L / a
    dx = wrap_axis(s[:, :, None, 0] - s[:, None, :, 0], La[0])
    dy = wrap_axis(s[:, :, None, 1] - s[:, None, :, 1], La[1])
    dz = wrap_axis(s[:, :, None, 2] - s[:, None, :, 2], La[2])
    zt, zs = s[:, :, None, 2], s[:, None, :, 2]
    # the nine entries M[a][b] of every 3x3 pair block, each a contiguous (nb, n, n) array, then one
    # transposed copy into (nb, n, 3, n, 3): fewer and smaller temporaries than outer products of stacked vectors
    entries = np.zeros((3, 3, nb, n, n))
    for shift in image_shifts(La):
        rx, ry, rz = dx + shift[0], dy + shift[1], dz + shift[2]
        c_iso, c_rr = pf.rpy_trans_trans(rx, ry, rz)
        r = (rx, ry, rz)
        if wall:
            ex, ey, ez, f1, f2, f3, f4, f5 = pf.wall_trans_trans(rx, ry, zt, zs)
            e = (ex, ey, ez)
            c_iso = c_iso + f1
        for row in range(3):
            c_rr_r = c_rr * r[row]
            if wall:
                f2_e = f2 * e[row]
            for col in range(3):
                entry = entries[row, col]
                entry += c_rr_r * r[col]
                if row == col:
                    entry += c_iso
                if wall:
                    entry += f2_e * e[col]
                    if col == 2:
                        entry += f3 * e[row]
                    if row == 2:
                        entry += f4 * e[col]
                    if row == 2 and col == 2:
                        entry += f5
    M = np.ascontiguousarray(entries.transpose(2, 3, 0, 4, 1))
    M *= (damping[:, :, None, None, None] * damping[:, None, None, :, None]) / (8.0 * np.pi * eta * a)
    M = M.reshape(nb, 3 * n, 3 * n)
    return M if stacked else M[0]


def rotne_prager_tensor(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense free-space RPY blob mobility: (N, 3) -> (3N, 3N), or (nb, n, 3) -> (nb, 3n, 3n).

    ``a``: one radius, or per-blob radii (N,) (for a stack (nb, n) or (n,)): Zuk et al. (2014)."""
    return _dense_or_radii(r_vectors, eta, a, periodic_length, 'no_wall')


def single_wall_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense Rotne-Prager-Blake blob mobility with the wall regularisation:
    (N, 3) -> (3N, 3N), or a stack of bodies (nb, n, 3) -> (nb, 3n, 3n).

    ``a``: one radius, or per-blob radii (N,) (for a stack (nb, n) or (n,))."""
    return _dense_or_radii(r_vectors, eta, a, periodic_length, 'single_wall')


def rotne_prager_tensor_radii(r_vectors, eta, radius, periodic_length=(0, 0, 0)):
    """Dense free-space mobility of blobs of radii ``radius`` (N,): (N, 3) -> (3N, 3N) (Zuk et al. 2014)."""
    return _dense_radii(r_vectors, eta, radius, periodic_length, 'no_wall')


def single_wall_fluid_mobility_radii(r_vectors, eta, radius, periodic_length=(0, 0, 0)):
    """Dense wall mobility of blobs of radii ``radius`` (N,), regularised below each blob's radius."""
    return _dense_radii(r_vectors, eta, radius, periodic_length, 'single_wall')


def _dense_radii(r_vectors, eta, radius, periodic_length, domain):
    """Dense (3N, 3N) matrix of the per-blob-radius product: the pair formulas of
    ``_source_target`` applied to unit vectors (one formula for product and matrix);
    a stack (nb, n, 3) with radii (nb, n) or (n,) gives (nb, 3n, 3n)."""
    r = np.asarray(r_vectors, dtype=np.float64)
    if r.ndim == 3 and r.shape[2] == 3:
        radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), r.shape[:2])
        return np.stack([_dense_or_radii(body, eta, rad, periodic_length, domain) for body, rad in zip(r, radii)])
    r = as_positions(r)
    n = r.shape[0]
    a = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)).copy()
    L = as_periodic_length(periodic_length)
    if domain != 'no_wall' and L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a wall or free surface at z = 0')
    damping = np.ones(n)
    if domain == 'single_wall':
        r, damping = _regularise(r, a)
    shifts = image_shifts(L)
    dx = wrap_axis(r[:, None, 0] - r[None, :, 0], L[0])[..., None]
    dy = wrap_axis(r[:, None, 1] - r[None, :, 1], L[1])[..., None]
    dz = wrap_axis(r[:, None, 2] - r[None, :, 2], L[2])[..., None]
    zt, zs = r[:, None, 2, None], r[None, :, 2, None]
    bt, as_ = a[:, None, None], a[None, :, None]
    M = np.zeros((n, 3, n, 3))
    for q in range(3):
        e = [np.zeros((1, 1, 1)) for _ in range(3)]
        e[q] = np.ones((1, 1, 1))
        for shift in shifts:
            if domain == 'free_surface':
                u = pf.free_surface_unequal_radii_pairs(dx + shift[0], dy + shift[1], dz + shift[2], zt, zs, bt, as_,
                                                        *e)
            else:
                u = pf.trans_times_force_unequal_radii_pairs(dx + shift[0], dy + shift[1], dz + shift[2], zt, zs,
                                                             bt, as_, *e, domain == 'single_wall')
            for p in range(3):
                M[:, p, :, q] += u[p]
    M *= damping[:, None, None, None] * damping[None, None, :, None] / (8.0 * np.pi * eta)
    return M.reshape(3 * n, 3 * n)


def _dense_or_radii(r_vectors, eta, a, periodic_length, domain):
    """Dense matrix with one radius (the equal-radius formulas) or per-blob radii (N,) or (nb, n)."""
    radius = np.asarray(a, dtype=np.float64)
    if radius.size > 1 and not np.all(radius == radius.reshape(-1)[0]):
        return _dense_radii(r_vectors, eta, radius, periodic_length, domain)
    a = float(radius.reshape(-1)[0])
    if domain == 'free_surface':
        return _dense_free_surface(r_vectors, eta, a, periodic_length)
    return _dense_trans_trans(r_vectors, eta, a, domain == 'single_wall', periodic_length)


# ---------------------------------------------------------------------------
# Free-slip surface at z = 0 (blobs in z > 0): the RPY tensor of the blobs plus
# that of their mirror images (pair_formulas.free_surface_trans_times_force_pairs).

def free_surface_mobility_trans_times_force(r_vectors, vector, eta, a, periodic_length=(0, 0, 0)):
    """``M f`` (3N,) above a free-slip surface at z = 0; ``a`` a number or per-blob radii (N,)."""
    radius = blob_radii(a, r_vectors)
    if radius.ndim:
        return _source_target(r_vectors, r_vectors, vector, radius, radius, eta, periodic_length, 'free_surface')
    a = float(radius)
    r = as_positions(r_vectors)
    v = as_blob_vectors(vector, r.shape[0])
    L = as_periodic_length(periodic_length)
    if L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a free surface at z = 0')
    scaled = r / a
    u = pair_sum(scaled, scaled, v, L / a, lambda rx, ry, rz, zt, zs, fx, fy, fz:
                 pf.free_surface_trans_times_force_pairs(rx, ry, rz, zt, zs, fx, fy, fz))
    return (u / (8.0 * np.pi * eta * a)).reshape(-1)


def free_surface_mobility_source_target(source, target, force, radius_source, radius_target, eta,
                                        periodic_length=(0, 0, 0)):
    """Velocity (3Nt,) at targets from forces on sources, above a free-slip surface, per-blob radii."""
    return _source_target(source, target, force, radius_source, radius_target, eta, periodic_length, 'free_surface')


def _dense_free_surface(r_vectors, eta, a, periodic_length):
    r = np.asarray(r_vectors, dtype=np.float64)
    if r.ndim == 3 and r.shape[2] == 3:
        return np.stack([_dense_free_surface(body, eta, a, periodic_length) for body in r])
    n = as_positions(r).shape[0]
    return _dense_radii(r, eta, np.full(n, float(a)), periodic_length, 'free_surface')


def free_surface_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense free-surface blob mobility (3N, 3N) (or a stack); ``a`` a number or per-blob radii."""
    return _dense_or_radii(r_vectors, eta, a, periodic_length, 'free_surface')
