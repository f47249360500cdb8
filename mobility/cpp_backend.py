"""C++ backend: the pybind11 module ``mobility._mobility_cpp`` behind the public signatures.

Import fails with ImportError when the extension was not built; the
registry (``mobility.backends``) reports that as an unusable backend.
"""
import numpy as np

from . import _mobility_cpp as _ext
from .product_names import product_functions, source_target_functions
from .python_backend import blob_radii

max_threads = _ext.max_threads


def _L(periodic_length):
    return np.asarray((0.0, 0.0, 0.0) if periodic_length is None else periodic_length, dtype=np.float64)


def _make_product(kind, wall):
    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0), precision='double'):
        # one radius (a Python or NumPy number: the usual case) goes straight to the kernel; arrays of radii are
        # checked and collapsed by blob_radii
        radius = a if isinstance(a, (float, np.floating)) else blob_radii(a, r_vectors, kind)
        if np.ndim(radius):  # different radii: the source-target formulas, each pair once
            return _ext.radii_product(r_vectors, np.ravel(vector), radius, float(eta), _L(periodic_length), wall)
        return _ext.product(kind, r_vectors, np.ravel(vector), float(eta), float(radius), _L(periodic_length), wall,
                            precision)
    return product


def has_product_two():
    """True when the built extension has the two-vector product (rebuild with setup.py build_ext otherwise)."""
    return hasattr(_ext, 'product_two')


def trans_times_force_two(r_vectors, v1, v2, eta, a, wall=True):
    """``(M v1, M v2)`` (3N,) each, in one pass over the pairs (pair coefficients computed once).

    One radius ``a`` (a number), no periodic images; ``wall``: the single-wall mobility, else free space.
    The same numbers as two calls of the trans_times_force product, to rounding.
    """
    return _ext.product_two(r_vectors, np.ravel(v1), np.ravel(v2), float(eta), float(a), bool(wall))


def has_grand_product():
    """True when the built extension has the one-pass grand product (rebuild with setup.py build_ext otherwise)."""
    return hasattr(_ext, 'grand_product')


def grand_product(r_vectors, forces, torques, eta, a, periodic_length=(0, 0, 0), wall=True):
    """``(U, W)`` (3N,) each: the grand mobility times ``[forces; torques]`` in one pass over the pairs.

    ``U = M_UF F + M_UT T``, ``W = M_WF F + M_WT T`` of blobs of one radius ``a`` (a number), above the wall
    (``wall``: Rotne-Prager-Blake with the Swan-Brady rotation couplings) or in free space (RPY), with the
    periodic images of ``periodic_length`` as the other products take them.  The same numbers as the four
    coupling products summed, to rounding.
    """
    # asarray(..).ravel(): np.ravel's result without its two Python-level calls (a product of a small system)
    return _ext.grand_product(r_vectors, np.asarray(forces).ravel(), np.asarray(torques).ravel(), float(eta),
                              float(a), _L(periodic_length), bool(wall))


def _source_target(source_r, target_r, force, radius_source, radius_target, eta, periodic_length, wall):
    return _ext.source_target(source_r, target_r, np.ravel(force), np.ravel(radius_source),
                              np.ravel(radius_target), float(eta), _L(periodic_length), wall)


globals().update(product_functions(_make_product, 'C++'))
globals().update(source_target_functions(_source_target, 'C++'))


def _dense(r_vectors, eta, a, periodic_length, wall):
    """Dense matrix; ``wall`` True/False or the domain name; ``a`` one radius or per-blob radii."""
    domain = wall if isinstance(wall, str) else ('single_wall' if wall else 'no_wall')
    r = np.asarray(r_vectors, dtype=np.float64)
    radius = np.asarray(a, dtype=np.float64)
    if r.ndim == 3 and r.shape[2] == 3:  # a stack of bodies: one block each
        if radius.size == 1 and domain in ('single_wall', 'no_wall') and hasattr(_ext, 'dense_trans_trans_stack'):
            return _ext.dense_trans_trans_stack(r.reshape(-1, 3), r.shape[0], float(eta), float(radius.reshape(-1)[0]),
                                                _L(periodic_length), domain == 'single_wall')
        radii = np.broadcast_to(radius, r.shape[:2]) if radius.size > 1 else [radius] * r.shape[0]
        return np.stack([_dense(body, eta, rad, periodic_length, domain) for body, rad in zip(r, radii)])
    if radius.size > 1 and not np.all(radius == radius.reshape(-1)[0]):
        return _ext.dense_radii(r, radius.reshape(-1), float(eta), _L(periodic_length), domain)
    a = float(radius.reshape(-1)[0])
    if domain == 'free_surface':
        return _ext.dense_free_surface(r, float(eta), a, _L(periodic_length))
    return _ext.dense_trans_trans(r, float(eta), a, _L(periodic_length), domain == 'single_wall')


def cross_blocks(r_i, r_j, eta, a, domain):
    """Cross blocks of the blob mobility of pairs of bodies: r_i (P, ni, 3), r_j (P, nj, 3) -> (P, 3ni, 3nj).

    Block p couples the blobs of r_i[p] (rows) with those of r_j[p] (columns), one radius ``a``, no periodic
    images; domain 'single_wall' or 'no_wall'.  None when the compiled kernel cannot build them (another
    domain, per-blob radii): the caller then takes them from the stacked dense matrices.
    """
    radius = np.asarray(a, dtype=np.float64)
    if domain not in ('single_wall', 'no_wall') or radius.size != 1 or not hasattr(_ext, 'dense_trans_trans_cross'):
        return None
    r_i, r_j = np.asarray(r_i, dtype=np.float64), np.asarray(r_j, dtype=np.float64)
    return _ext.dense_trans_trans_cross(np.ascontiguousarray(r_i.reshape(-1, 3)),
                                        np.ascontiguousarray(r_j.reshape(-1, 3)), r_i.shape[0], float(eta),
                                        float(radius.reshape(-1)[0]), domain == 'single_wall')


def single_wall_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense Rotne-Prager-Blake mobility with the wall regularisation: (N, 3) -> (3N, 3N),
    or a stack of bodies (nb, n, 3) -> (nb, 3n, 3n)."""
    return _dense(r_vectors, eta, a, periodic_length, True)


def rotne_prager_tensor(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense free-space RPY mobility: (N, 3) -> (3N, 3N), or (nb, n, 3) -> (nb, 3n, 3n)."""
    return _dense(r_vectors, eta, a, periodic_length, False)


def free_surface_mobility_trans_times_force(r_vectors, vector, eta, a, periodic_length=(0, 0, 0)):
    """``M f`` (3N,) above a free-slip surface at z = 0; ``a`` a number or per-blob radii (N,)."""
    radius = blob_radii(a, r_vectors)
    if radius.ndim:
        return _ext.source_target_domain(r_vectors, r_vectors, np.ravel(vector), radius, radius, float(eta),
                                         _L(periodic_length), 'free_surface')
    return _ext.free_surface_product(r_vectors, np.ravel(vector), float(eta), float(radius), _L(periodic_length))


def free_surface_mobility_source_target(source, target, force, radius_source, radius_target, eta,
                                        periodic_length=(0, 0, 0)):
    """Velocity (3Nt,) at targets from forces on sources above a free-slip surface, per-blob radii."""
    return _ext.source_target_domain(source, target, np.ravel(force), np.ravel(radius_source),
                                     np.ravel(radius_target), float(eta), _L(periodic_length), 'free_surface')


def free_surface_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense free-surface blob mobility (3N, 3N) (or a stack of bodies)."""
    return _dense(r_vectors, eta, a, periodic_length, 'free_surface')
