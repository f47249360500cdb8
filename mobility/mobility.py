"""``from mobility import mobility``: the published module of blob mobilities, as a face for users' files.

Override files and drivers written for the published package call its functions by their published names;
this module gives them those names over the package's one mobility interface (:mod:`mobility.interface`: every
product is a method of a ``BlobMobility``), on the top floor of the mobility room (the package itself never
imports it):

* the public functions of :mod:`mobility` with their published signatures: the dense matrices
  ``rotne_prager_tensor``, ``single_wall_fluid_mobility``, ``free_surface_fluid_mobility`` (NumPy backend),
  ``{single_wall,no_wall}_mobility_{trans_times_force,trans_times_torque,rot_times_force,rot_times_torque}``
  and the source-target products (keyword ``implementation``: python, C++, numba or pycuda), the free-surface
  products, ``mobility_radii_trans_times_force``; the registry's look-ups (``mobility_vector_product``, ...)
  as :mod:`mobility` has them;
* the published backend-suffixed names ``..._numba`` (the registry's first usable CPU backend: the compiled C++
  backend where it is built, NumPy otherwise, the same numbers) and ``..._pycuda`` (CUDA, imported when first
  called), with the published argument order ``(r_vectors, vector, eta, a, L=(0, 0, 0))``;
* ``{single_wall,no_wall}_mobility_trans_times_force_source_target_numba(source, target, force,
  radius_source, radius_target, eta, L=(0, 0, 0))``.

Shapes as in :mod:`mobility`: ``r_vectors`` (N, 3), vectors flat (3N,); ``a`` one radius or per-blob radii (N,).
The mobility objects of one radius are kept (a few dozen, by backend, geometry, viscosity, radius and box), so a
call costs what the backend's product costs.
"""
import functools

import numpy as np

from mobility import *  # noqa: F401,F403  (the published names; the products are redefined below)
from mobility.interface import Geometry, implementation_geometry, make_mobility, preferred_backend
from mobility.product_names import DOMAINS as _DOMAINS, PRODUCT_KINDS as _KINDS

_GEOMETRY_OF_DOMAIN = {'single_wall': 'single_wall', 'no_wall': 'free_space', 'free_surface': 'free_surface'}


@functools.lru_cache(maxsize=64)
def _kept(backend, kind, eta, a, box):
    return make_mobility(backend, Geometry(kind, box), eta, a)


def _mobility(backend, kind, eta, a, periodic_length):
    """The ``BlobMobility`` of ``backend`` in geometry ``kind`` (one radius: kept for the next call)."""
    box = (0.0, 0.0, 0.0) if periodic_length is None else tuple(np.asarray(periodic_length, dtype=float).reshape(-1))
    if np.ndim(a) == 0:
        return _kept(backend, kind, float(eta), float(a), box)
    return make_mobility(backend, Geometry(kind, box), eta, a)


def _backend_of(implementation):
    """The registry backend of a published implementation name (its domain suffix is the function's, not its)."""
    return implementation_geometry(implementation)[0]


def _dense(domain):
    def matrix(r_vectors, eta, a, periodic_length=(0, 0, 0)):
        return _mobility('python', _GEOMETRY_OF_DOMAIN[domain], eta, a, periodic_length).dense_matrix(r_vectors)
    return matrix


rotne_prager_tensor = _dense('no_wall')
rotne_prager_tensor.__name__ = 'rotne_prager_tensor'
rotne_prager_tensor.__doc__ = 'Dense free-space RPY blob mobility (3N, 3N); r_vectors (N, 3) (or a stack of bodies).'
single_wall_fluid_mobility = _dense('single_wall')
single_wall_fluid_mobility.__name__ = 'single_wall_fluid_mobility'
single_wall_fluid_mobility.__doc__ = ('Dense Rotne-Prager-Blake blob mobility (3N, 3N) with the wall regularisation; '
                                      'r_vectors (N, 3).')
free_surface_fluid_mobility = _dense('free_surface')
free_surface_fluid_mobility.__name__ = 'free_surface_fluid_mobility'
free_surface_fluid_mobility.__doc__ = 'Dense blob mobility above a free-slip surface at z = 0 (3N, 3N).'


def _product(domain, kind):
    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0), implementation='python'):
        return _mobility(_backend_of(implementation), _GEOMETRY_OF_DOMAIN[domain], eta, a,
                         periodic_length).coupling(kind, r_vectors, vector)
    product.__name__ = '%s_mobility_%s' % (domain, kind)
    product.__doc__ = ('%s blob product %s: r_vectors (N, 3), vector (3N,) -> (3N,). implementation: python, C++ '
                       '(numba) or pycuda.' % (domain, kind))
    return product


def _source_target(domain):
    def product(source, target, force, radius_source, radius_target, eta, periodic_length=(0, 0, 0),
                implementation='python'):
        mobility = _mobility(_backend_of(implementation), _GEOMETRY_OF_DOMAIN[domain], eta, radius_source,
                             periodic_length)
        return mobility.source_target(source, target, force, radius_source, radius_target)
    product.__name__ = '%s_mobility_source_target' % domain
    product.__doc__ = ('Velocity (3Nt,) at targets (Nt, 3) of radius radius_target from forces (3Ns,) on sources '
                       '(Ns, 3) of radius radius_source (%s).' % domain)
    return product


for _domain in ('single_wall', 'no_wall'):
    for _kind in _KINDS:
        globals()['%s_mobility_%s' % (_domain, _kind)] = _product(_domain, _kind)
    globals()['%s_mobility_source_target' % _domain] = _source_target(_domain)
free_surface_mobility_trans_times_force = _product('free_surface', 'trans_times_force')
free_surface_mobility_source_target = _source_target('free_surface')


def _suffixed_backend(backend, kind):
    if backend == 'numba':  # the compiled backend where it is built, else NumPy: the registry's first CPU backend
        return preferred_backend(Geometry(kind), device='cpu')
    return backend


def _suffixed_product(domain, kind, backend):
    def product(r_vectors, vector, eta, a, L=(0.0, 0.0, 0.0)):
        geometry = _GEOMETRY_OF_DOMAIN[domain]
        return _mobility(_suffixed_backend(backend, geometry), geometry, eta, a, L).coupling(kind, r_vectors,
                                                                                              vector)
    return product


def _suffixed_source_target(domain, backend):
    def product(source, target, force, radius_source, radius_target, eta, L=(0.0, 0.0, 0.0)):
        geometry = _GEOMETRY_OF_DOMAIN[domain]
        mobility = _mobility(_suffixed_backend(backend, geometry), geometry, eta, radius_source, L)
        return mobility.source_target(source, target, force, radius_source, radius_target)
    return product


for _domain, _wall in _DOMAINS:
    for _backend in ('numba', 'pycuda'):
        for _kind in _KINDS:
            _name = '%s_mobility_%s_%s' % (_domain, _kind, _backend)
            globals()[_name] = _suffixed_product(_domain, _kind, _backend)
            globals()[_name].__name__ = _name
        _name = '%s_mobility_trans_times_force_source_target_%s' % (_domain, _backend)
        globals()[_name] = _suffixed_source_target(_domain, _backend)
        globals()[_name].__name__ = _name
