"""Blob-level hydrodynamics: dense mobilities, matrix-free products, roller couplings.

Public functions (names kept from the published code, so user scripts work):

* ``rotne_prager_tensor(r_vectors, eta, a)``, ``single_wall_fluid_mobility(r_vectors, eta, a)``:
  dense (3N, 3N) matrices (free space; single wall with the regularisation
  for blobs closer than ``a`` to the wall).
* ``{single_wall,no_wall}_mobility_{trans_times_force,trans_times_torque,
  rot_times_force,rot_times_torque}(r_vectors, vector, eta, a,
  periodic_length=(0, 0, 0), implementation='python')``: flat (3N,) products.
* ``{single_wall,no_wall}_mobility_source_target(source, target, force,
  radius_source, radius_target, eta, periodic_length=(0, 0, 0),
  implementation='python')``: velocity (3Nt,) at target points.
* ``free_surface_mobility_trans_times_force(r_vectors, vector, eta, a, periodic_length, implementation)``,
  ``free_surface_mobility_source_target(...)`` and the dense
  ``free_surface_fluid_mobility(r_vectors, eta, a)``: a free-slip surface at z = 0.
* ``mobility_radii_trans_times_force(r_vectors, force, eta, a, radius_blobs, function)``
  (published name): ``M f`` with per-blob radii through a source-target ``function``.
  Every product above also takes ``a`` as per-blob radii (N,).
* The registry: ``mobility_vector_product(name)``, ``blob_mobility_matrix(name)``,
  ``source_target_product(name)``, ``blob_product(name, kind)``,
  ``available_implementations()``; names as in the manual (python, C++,
  pycuda, each also with _no_wall).

The package itself reaches every blob mobility through :mod:`mobility.interface` (one ``BlobMobility`` per
backend and geometry, one registry with one preference order; floor 2, above these functions, which are the
backends' look-ups and the function forms scripts written against the published code call).

Shapes and units: ``r_vectors`` (N, 3) in length units, the wall at z = 0;
``eta`` viscosity; ``a`` blob radius; vectors flat (3N,) interleaved
(x0, y0, z0, x1, ...); results are velocities (or angular velocities) in the
same unit system.
"""
from . import threads as _threads

_threads.apply_wait_policy()  # before any OpenMP kernel loads (mobility.threads: passive waiting threads)
_threads.apply_blas_policy()  # one BLAS thread: its spinning workers slowed the kernels (mobility.threads)

from . import python_backend as _python  # noqa: E402
from .product_names import PRODUCT_KINDS  # noqa: E402
from .backends import (available_implementations, blob_cross_blocks, blob_mobility_matrix, blob_product,
                       compiled_near_field_domain, mobility_vector_product, source_target_product,
                       split_implementation_name, usable_names)

__all__ = ['rotne_prager_tensor', 'single_wall_fluid_mobility', 'free_surface_fluid_mobility',
           'free_surface_mobility_trans_times_force', 'free_surface_mobility_source_target',
           'mobility_radii_trans_times_force', 'available_implementations',
           'blob_cross_blocks', 'blob_mobility_matrix', 'blob_product', 'compiled_near_field_domain',
           'mobility_vector_product',
           'source_target_product',
           'usable_names']


def rotne_prager_tensor(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense free-space RPY blob mobility (3N, 3N); r_vectors (N, 3)."""
    return _python.rotne_prager_tensor(r_vectors, eta, a, periodic_length)


def single_wall_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense Rotne-Prager-Blake blob mobility (3N, 3N) with the wall regularisation; r_vectors (N, 3)."""
    return _python.single_wall_fluid_mobility(r_vectors, eta, a, periodic_length)


def free_surface_fluid_mobility(r_vectors, eta, a, periodic_length=(0, 0, 0)):
    """Dense blob mobility above a free-slip surface at z = 0 (3N, 3N); ``a`` a number or radii (N,)."""
    return _python.free_surface_fluid_mobility(r_vectors, eta, a, periodic_length)


def free_surface_mobility_trans_times_force(r_vectors, vector, eta, a, periodic_length=(0, 0, 0),
                                            implementation='python'):
    """``M f`` (3N,) above a free-slip surface at z = 0; implementation python, C++ (numba) or pycuda."""
    backend, _ = split_implementation_name(implementation)
    return mobility_vector_product(backend + '_free_surface')(r_vectors, vector, eta, a, periodic_length)


def free_surface_mobility_source_target(source, target, force, radius_source, radius_target, eta,
                                        periodic_length=(0, 0, 0), implementation='python'):
    """Velocity (3Nt,) at targets from forces (3Ns,) on sources above a free-slip surface at z = 0."""
    backend, _ = split_implementation_name(implementation)
    return source_target_product(backend + '_free_surface')(source, target, force, radius_source, radius_target,
                                                            eta, periodic_length)


def mobility_radii_trans_times_force(r_vectors, force, eta, a, radius_blobs, function, *args, **kwargs):
    """``M f`` (3N,) of blobs of radii ``radius_blobs`` (N,) through a source-target ``function`` (published name).

    ``function(source, target, force, radius_source, radius_target, eta, periodic_length)``, e.g.
    ``single_wall_mobility_source_target``; ``a`` is not used (the radii are); keyword
    ``periodic_length`` (3,) as the published code passes it.
    """
    periodic_length = kwargs.get('periodic_length', (0, 0, 0))
    return function(r_vectors, r_vectors, force, radius_blobs, radius_blobs, eta, periodic_length)


def _public_product(domain, kind):
    suffix = '' if domain == 'single_wall' else '_no_wall'

    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0), implementation='python'):
        backend, _ = split_implementation_name(implementation)
        return blob_product(backend + suffix, kind)(r_vectors, vector, eta, a, periodic_length)

    product.__name__ = '%s_mobility_%s' % (domain, kind)
    product.__doc__ = ('%s blob product %s: r_vectors (N, 3), vector (3N,) -> (3N,). '
                       'implementation: python, C++ or pycuda.' % (domain, kind))
    return product


def _public_source_target(domain):
    suffix = '' if domain == 'single_wall' else '_no_wall'

    def product(source, target, force, radius_source, radius_target, eta, periodic_length=(0, 0, 0),
                implementation='python'):
        backend, _ = split_implementation_name(implementation)
        return source_target_product(backend + suffix)(source, target, force, radius_source, radius_target, eta,
                                                       periodic_length)

    product.__name__ = '%s_mobility_source_target' % domain
    product.__doc__ = ('Velocity (3Nt,) at targets (Nt, 3) of radius radius_target from forces (3Ns,) on '
                       'sources (Ns, 3) of radius radius_source (%s).' % domain)
    return product


for _domain in ('single_wall', 'no_wall'):
    for _kind in PRODUCT_KINDS:
        _name = '%s_mobility_%s' % (_domain, _kind)
        globals()[_name] = _public_product(_domain, _kind)
        __all__.append(_name)
    globals()['%s_mobility_source_target' % _domain] = _public_source_target(_domain)
    __all__.append('%s_mobility_source_target' % _domain)
