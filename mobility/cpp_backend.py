"""C++ backend: the pybind11 module ``mobility._mobility_cpp`` behind the public signatures.

Import fails with ImportError when the extension was not built; the
registry (``mobility.backends``) reports that as an unusable backend.
"""
import numpy as np

from . import _mobility_cpp as _ext

max_threads = _ext.max_threads


def _L(periodic_length):
    return np.asarray((0.0, 0.0, 0.0) if periodic_length is None else periodic_length, dtype=np.float64)


def _make_product(kind, wall):
    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0)):
        return _ext.product(kind, r_vectors, np.ravel(vector), float(eta), float(a), _L(periodic_length), wall)
    product.__name__ = '%s_mobility_%s' % ('single_wall' if wall else 'no_wall', kind)
    product.__doc__ = 'C++ %s product %s; r_vectors (N, 3), vector (3N,) -> (3N,).' % (
        'wall' if wall else 'free-space', kind)
    return product


single_wall_mobility_trans_times_force = _make_product('trans_times_force', True)
no_wall_mobility_trans_times_force = _make_product('trans_times_force', False)
single_wall_mobility_trans_times_torque = _make_product('trans_times_torque', True)
no_wall_mobility_trans_times_torque = _make_product('trans_times_torque', False)
single_wall_mobility_rot_times_force = _make_product('rot_times_force', True)
no_wall_mobility_rot_times_force = _make_product('rot_times_force', False)
single_wall_mobility_rot_times_torque = _make_product('rot_times_torque', True)
no_wall_mobility_rot_times_torque = _make_product('rot_times_torque', False)


def single_wall_mobility_source_target(source_r, target_r, force, radius_source, radius_target, eta,
                                       periodic_length=(0, 0, 0)):
    """Velocity (3Nt,) at targets from forces on sources of given radii, with the wall."""
    return _ext.source_target(source_r, target_r, np.ravel(force), np.ravel(radius_source),
                              np.ravel(radius_target), float(eta), _L(periodic_length), True)


def no_wall_mobility_source_target(source_r, target_r, force, radius_source, radius_target, eta,
                                   periodic_length=(0, 0, 0)):
    """Velocity (3Nt,) at targets from forces on sources of given radii, free space."""
    return _ext.source_target(source_r, target_r, np.ravel(force), np.ravel(radius_source),
                              np.ravel(radius_target), float(eta), _L(periodic_length), False)


def single_wall_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense (3N, 3N) Rotne-Prager-Blake mobility with the wall regularisation."""
    return _ext.dense_trans_trans(r_vectors, float(eta), float(a), _L(periodic_length), True)


def rotne_prager_tensor(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense (3N, 3N) free-space RPY mobility."""
    return _ext.dense_trans_trans(r_vectors, float(eta), float(a), _L(periodic_length), False)
