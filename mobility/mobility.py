"""``from mobility import mobility``: the published module of blob mobilities, as a face for users' files.

Override files and drivers written for the published package call its functions by their published names;
this module gives them those names over the package's backends (top floor of the mobility room: the package
itself never imports it):

* every public function of :mod:`mobility` (``rotne_prager_tensor``, ``single_wall_fluid_mobility``,
  ``{single_wall,no_wall}_mobility_{trans_times_force,trans_times_torque,rot_times_force,rot_times_torque}``,
  the source-target products, ``mobility_radii_trans_times_force``, the free-surface products);
* the published backend-suffixed names ``..._numba`` (the compiled C++ backend where it is built, NumPy
  otherwise: the same numbers) and ``..._pycuda`` (CUDA, imported when first called), with the published
  argument order ``(r_vectors, vector, eta, a, L=(0, 0, 0))``;
* ``{single_wall,no_wall}_mobility_trans_times_force_source_target_numba(source, target, force,
  radius_source, radius_target, eta, L=(0, 0, 0))``.

Shapes as in :mod:`mobility`: ``r_vectors`` (N, 3), vectors flat (3N,).
"""
import mobility as _mobility
from mobility import *  # noqa: F401,F403  (the published names of the package's functions)
from mobility import backends as _backends
from mobility.product_names import DOMAINS as _DOMAINS, PRODUCT_KINDS as _KINDS


def _compiled_or_python():
    return 'C++' if _backends.is_usable('C++') else 'python'


def _suffixed_product(domain_suffix, kind, backend):
    def product(r_vectors, vector, eta, a, L=(0.0, 0.0, 0.0)):
        name = (_compiled_or_python() if backend == 'numba' else backend) + domain_suffix
        return _mobility.blob_product(name, kind)(r_vectors, vector, eta, a, L)
    return product


def _suffixed_source_target(domain_suffix, backend):
    def product(source, target, force, radius_source, radius_target, eta, L=(0.0, 0.0, 0.0)):
        name = (_compiled_or_python() if backend == 'numba' else backend) + domain_suffix
        return _mobility.source_target_product(name)(source, target, force, radius_source, radius_target, eta, L)
    return product


for _domain, _wall in _DOMAINS:
    _suffix = '' if _wall else '_no_wall'
    for _backend in ('numba', 'pycuda'):
        for _kind in _KINDS:
            _name = '%s_mobility_%s_%s' % (_domain, _kind, _backend)
            globals()[_name] = _suffixed_product(_suffix, _kind, _backend)
            globals()[_name].__name__ = _name
        _name = '%s_mobility_trans_times_force_source_target_%s' % (_domain, _backend)
        globals()[_name] = _suffixed_source_target(_suffix, _backend)
        globals()[_name].__name__ = _name
