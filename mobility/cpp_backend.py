"""C++ backend: the pybind11 module ``mobility._mobility_cpp`` behind the public signatures.

Import fails with ImportError when the extension was not built; the
registry (``mobility.backends``) reports that as an unusable backend.
"""
import numpy as np

from . import _mobility_cpp as _ext
from .product_names import product_functions, source_target_functions

max_threads = _ext.max_threads


def _L(periodic_length):
    return np.asarray((0.0, 0.0, 0.0) if periodic_length is None else periodic_length, dtype=np.float64)


def _make_product(kind, wall):
    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0), precision='double'):
        return _ext.product(kind, r_vectors, np.ravel(vector), float(eta), float(a), _L(periodic_length), wall,
                            precision)
    return product


def _source_target(source_r, target_r, force, radius_source, radius_target, eta, periodic_length, wall):
    return _ext.source_target(source_r, target_r, np.ravel(force), np.ravel(radius_source),
                              np.ravel(radius_target), float(eta), _L(periodic_length), wall)


globals().update(product_functions(_make_product, 'C++'))
globals().update(source_target_functions(_source_target, 'C++'))


def _dense(r_vectors, eta, a, periodic_length, wall):
    r = np.asarray(r_vectors, dtype=np.float64)
    if r.ndim == 3 and r.shape[2] == 3:  # a stack of bodies: one block each
        return np.stack([_ext.dense_trans_trans(body, float(eta), float(a), _L(periodic_length), wall) for body in r])
    return _ext.dense_trans_trans(r, float(eta), float(a), _L(periodic_length), wall)


def single_wall_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense Rotne-Prager-Blake mobility with the wall regularisation: (N, 3) -> (3N, 3N),
    or a stack of bodies (nb, n, 3) -> (nb, 3n, 3n)."""
    return _dense(r_vectors, eta, a, periodic_length, True)


def rotne_prager_tensor(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense free-space RPY mobility: (N, 3) -> (3N, 3N), or (nb, n, 3) -> (nb, 3n, 3n)."""
    return _dense(r_vectors, eta, a, periodic_length, False)
