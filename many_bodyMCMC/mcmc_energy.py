"""Energies of the Monte Carlo sampler: potentials, their user overrides and three backends.

The energy of a configuration (SPEC section 9) is

    U = sum_blobs u_1(r_i) + sum_{i<j} u_2(r_j - r_i) + sum_{k<l} u_b(x_l - x_k, q_k, q_l)

* one-blob ``u_1(z) = g z + eps_w exp(-(z - a)/b_w)`` for ``z >= a`` and
  ``g z + eps_w + eps_w (a - z)/b_w`` below (gravity of a blob of mass 1 and
  the soft wall of the dynamic code, whose forces are ``-du_1/dz``);
* blob-blob ``u_2(r) = eps exp(-(r - 2a)/b)`` for ``r >= 2a`` and
  ``eps + eps (2a - r)/b`` below, displacements by the minimum image on
  periodic axes; included always, as in the published sampler;
* body-body ``u_b = eps exp(-r/b)/r`` between body locations (the potential
  of the dynamic code's default body-body force) when
  ``body_body_force_torque_implementation python``; zero otherwise.

A configuration with a blob centre at or below the wall (``z <= 0``) has
infinite energy, so a proposal that puts one there is rejected.  (The
published sampler adds ``1e5 (1 - z)`` per such blob instead; for any kT
below about 1e3 that is a rejection too.)

Overrides: a file ``user_defined_potentials.py`` in the run directory may
define any of ``blob_potential``, ``blob_blob_potential`` and
``body_body_potential`` (signatures in ``load_user_potentials``); they
replace the defaults.  ``potential_pycuda_user_defined.py`` is the GPU
counterpart (see ``many_bodyMCMC.mcmc_cuda``).

Backends of the blob-blob sums (the only O(N^2) part): ``python``
(NumPy, vectorised in chunks of rows, any pair law), ``C++``
(``many_bodyMCMC._energy_cpp``, OpenMP, each pair once, default law) and
``pycuda`` (CuPy, imported only when asked for).  All give the same numbers
to round-off.  A one-body change costs O(blobs of the body x N) on each.

Shapes: blob positions (N, 3); locations (Nb, 3); quaternions (Nb, 4), scalar first.
"""
import math
import os

import numpy as np

from body.body import blob_positions
from body import geometry as _quaternion
from mobility.periodic import minimum_image
from multi_bodies.solver.physics import blob_blob_potential, blob_external_potential, body_body_potential
from multi_bodies.solver.user_hooks import import_module_file, override_file
from utils import UserInputError

PAIR_CHUNK_ELEMENTS = 65536  # pairs per chunk of the NumPy sums (bounded memory)
USER_POTENTIAL_FILE = 'user_defined_potentials.py'
GPU_POTENTIAL_FILE = 'potential_pycuda_user_defined.py'
POTENTIAL_HOOKS = ('blob_potential', 'blob_blob_potential', 'body_body_potential')
IMPLEMENTATIONS = ('auto', 'python', 'C++', 'pycuda')


# ---------------------------------------------------------------------------------------------- default laws
# The energies of the dynamic code's default forces, defined beside them in multi_bodies.solver.physics:
# blob_potential(r_vectors (N, 3), **kw) -> (N,), blob_blob_potential(r (..., 3), **kw) -> (...),
# body_body_potential(r (..., 3), quaternion_i, quaternion_j, **kw) -> (...).
blob_potential = blob_external_potential


# ---------------------------------------------------------------------------------------------- overrides
class PotentialHooks:
    """The three potentials of a run; ``overridden`` names those a user file replaced, ``sources`` the files.

    ``blob_blob_cuda_source`` is the CUDA text of ``potential_pycuda_user_defined.py`` (or None).
    """

    def __init__(self):
        self.blob_potential = blob_potential
        self.blob_blob_potential = blob_blob_potential
        self.body_body_potential = None
        self.overridden, self.sources = [], []
        self.gpu_file = None
        self.blob_blob_cuda_source = None


def _take_hooks(module, hooks):
    for name in POTENTIAL_HOOKS:
        function = getattr(module, name, None)
        if callable(function):
            setattr(hooks, name, function)
            hooks.overridden.append(name)


def load_user_potentials(directory='.', default_body_body=False):
    """Potentials for a run in ``directory``, with the user's overrides.

    ``user_defined_potentials.py`` may define, all vectorised (keywords: ``g,
    repulsion_strength_wall, debye_length_wall, repulsion_strength,
    debye_length, periodic_length, blob_radius, blob_mass``; accept ``**kwargs``):

    * ``blob_potential(r_vectors (N, 3), **kw) -> (N,)`` energy of each blob
      (gravity included: it replaces the default one-blob energy);
    * ``blob_blob_potential(r (..., 3), **kw) -> (...)`` energy of blob pairs,
      ``r`` from blob i to blob j after the minimum image;
    * ``body_body_potential(r (..., 3), quaternion_i (..., 4), quaternion_j (..., 4), **kw) -> (...)``
      energy of body pairs, ``r`` from the location of body i to that of body j.
      When given it is always included.

    ``default_body_body`` switches the default Yukawa body-body energy on
    (``body_body_force_torque_implementation python``).
    ``potential_pycuda_user_defined.py`` is read by the same rules (its python
    functions apply on the host) and may also hold ``BLOB_BLOB_POTENTIAL_SOURCE``,
    CUDA text of ``__device__ double blob_blob_potential(double rx, double ry,
    double rz, double eps, double b, double a)`` for the GPU pair sums.
    """
    hooks = PotentialHooks()
    if default_body_body:
        hooks.body_body_potential = body_body_potential
    path = override_file(directory, USER_POTENTIAL_FILE)  # a folder, FIFO or dangling link there is refused
    if path is not None:
        _take_hooks(import_module_file(path, 'user_defined_potentials'), hooks)
        hooks.sources.append(path)
    path = override_file(directory, GPU_POTENTIAL_FILE)
    if path is not None:
        hooks.gpu_file = path
    return hooks


def load_gpu_potentials(hooks):
    """Read ``hooks.gpu_file`` (``potential_pycuda_user_defined.py``) into ``hooks``; for the pycuda backend only."""
    module = import_module_file(hooks.gpu_file, 'potential_pycuda_user_defined')
    _take_hooks(module, hooks)
    source = getattr(module, 'BLOB_BLOB_POTENTIAL_SOURCE', None)
    if source is not None:
        if not isinstance(source, str) or 'blob_blob_potential' not in source:
            raise UserInputError('%s: BLOB_BLOB_POTENTIAL_SOURCE must be CUDA text defining __device__ double '
                                 'blob_blob_potential(double rx, double ry, double rz, double eps, double b, '
                                 'double a)' % hooks.gpu_file)
        hooks.blob_blob_cuda_source = source
        hooks.overridden.append('blob_blob_potential (CUDA)')
    elif not any(callable(getattr(module, n, None)) for n in POTENTIAL_HOOKS):
        raise UserInputError('%s defines none of BLOB_BLOB_POTENTIAL_SOURCE, %s: nothing to override (a file '
                             'written for the published pycuda code must be rewritten, see doc/mcmc.md)'
                             % (hooks.gpu_file, ', '.join(POTENTIAL_HOOKS)))
    hooks.sources.append(hooks.gpu_file)


# ---------------------------------------------------------------------------------------------- pair sums
class PythonPairSums:
    """Blob-blob sums with NumPy, for any vectorised pair law ``potential(r (P, 3), **kw) -> (P,)``."""

    name = 'python'

    def __init__(self, keywords, potential=blob_blob_potential):
        self.keywords, self.potential = dict(keywords), potential
        self.periodic_length = np.asarray(keywords.get('periodic_length', (0.0, 0.0, 0.0)), dtype=float)

    def _sum(self, r):
        return float(np.sum(self.potential(minimum_image(r, self.periodic_length), **self.keywords)))

    def total(self, r_vectors):
        """Sum over blob pairs i < j; r_vectors (N, 3).

        Rows are taken in blocks: each block against the blobs after it (a full
        rectangle of pairs) plus the pairs inside the block (its upper triangle).
        """
        n = r_vectors.shape[0]
        total = 0.0
        rows = max(1, min(n, PAIR_CHUNK_ELEMENTS // max(n, 1)))
        for start in range(0, n, rows):
            stop = min(n, start + rows)
            block = r_vectors[start:stop]
            if stop < n:
                total += self._sum(r_vectors[None, stop:, :] - block[:, None, :])
            if stop - start > 1:
                i, j = np.triu_indices(stop - start, k=1)
                total += self._sum(block[j] - block[i])
        return total

    def cross(self, targets, sources, exclude_start, exclude_stop):
        """Sum over targets (m, 3) and the sources (N, 3) outside rows [exclude_start, exclude_stop)."""
        others = np.concatenate((sources[:exclude_start], sources[exclude_stop:]))
        total = 0.0
        rows = max(1, PAIR_CHUNK_ELEMENTS // max(others.shape[0], 1))
        for start in range(0, targets.shape[0], rows):
            d = others[None, :, :] - targets[start:start + rows, None, :]
            total += self._sum(d.reshape(-1, 3))
        return total


class CppPairSums:
    """Blob-blob sums of the default law with the OpenMP extension ``many_bodyMCMC._energy_cpp``."""

    name = 'C++'

    def __init__(self, keywords):
        from many_bodyMCMC import _energy_cpp
        self._cpp = _energy_cpp
        self.law = (np.asarray(keywords.get('periodic_length', (0.0, 0.0, 0.0)), dtype=float).reshape(3),
                    float(keywords['repulsion_strength']), float(keywords['debye_length']),
                    float(keywords['blob_radius']))

    def total(self, r_vectors):
        return self._cpp.pair_energy_total(r_vectors, *self.law)

    def cross(self, targets, sources, exclude_start, exclude_stop):
        return self._cpp.pair_energy_cross(targets, sources, int(exclude_start), int(exclude_stop), *self.law)


def cpp_available():
    """(True, '') when the C++ extension imports, else (False, reason)."""
    try:
        from many_bodyMCMC import _energy_cpp  # noqa: F401
    except ImportError as err:
        return False, str(err)
    return True, ''


# ---------------------------------------------------------------------------------------------- quaternions
# The quaternion step and rotation matrix are the package's one copy (body.geometry);
# the names stay here for the sampler and for published Monte Carlo override files.
quaternions_from_rotations = _quaternion.quaternions_from_rotations
quaternion_products = _quaternion.quaternion_products


def quaternion_product_scalars(p, q):
    """``p * q`` of two quaternions given as 4 numbers each (one-body moves); returns a tuple of 4 floats."""
    return tuple(quaternion_products(p, q)[0].tolist())


def rotation_matrix_scalars(q):
    """``R(q)`` (3, 3) of one quaternion given as 4 numbers (SPEC section 3)."""
    return _quaternion.rotation_matrices(q)[0]


# ---------------------------------------------------------------------------------------------- energy
class MCMCEnergy:
    """Energy of configurations of the bodies of ``arrays``, and of one-body changes.

    Parameters
    ----------
    arrays : body.body.BodyArrays (reference blobs, offsets; its locations are not read)
    keywords : dict of physics keywords (g, blob_radius, ...)
    hooks : PotentialHooks
    pair_sums : PythonPairSums, CppPairSums or a CUDA equivalent
    """

    def __init__(self, arrays, keywords, hooks, pair_sums):
        self.arrays, self.keywords, self.hooks, self.pair_sums = arrays, dict(keywords), hooks, pair_sums
        self.periodic_length = np.asarray(self.keywords.get('periodic_length', (0.0, 0.0, 0.0)), dtype=float)
        self.offsets = np.asarray(arrays.blob_offsets)
        self.references = [arrays.reference_blobs[self.offsets[k]:self.offsets[k + 1]]
                           for k in range(arrays.num_bodies)]

    # ----------------------------------------------------------------------------- positions
    def blob_positions(self, locations, orientations):
        """Blob positions (N, 3) of the configuration (locations (Nb, 3), orientations (Nb, 4))."""
        return blob_positions(locations, orientations, self.arrays.reference_blobs, self.arrays.blob_body_index)

    def body_blob_positions(self, k, location, orientation):
        """Blob positions (n_k, 3) of body ``k`` at ``location`` (3,) and ``orientation`` (4,)."""
        return location + self.references[k] @ rotation_matrix_scalars(orientation).T

    # ----------------------------------------------------------------------------- energies
    def one_blob(self, r_vectors):
        return float(np.sum(self.hooks.blob_potential(r_vectors, **self.keywords)))

    def body_pairs(self, locations, orientations):
        """Sum over body pairs k < l of the body-body energy (0 without a body-body term)."""
        if self.hooks.body_body_potential is None or locations.shape[0] < 2:
            return 0.0
        i, j = np.triu_indices(locations.shape[0], k=1)
        r = minimum_image(locations[j] - locations[i], self.periodic_length)
        return float(np.sum(self.hooks.body_body_potential(r, orientations[i], orientations[j], **self.keywords)))

    def total(self, locations, orientations, r_vectors=None):
        """Energy of a configuration (inf when a blob centre is at or below the wall)."""
        r_vectors = self.blob_positions(locations, orientations) if r_vectors is None else r_vectors
        if np.any(r_vectors[:, 2] <= 0.0):
            return math.inf
        return (self.one_blob(r_vectors) + self.pair_sums.total(r_vectors)
                + self.body_pairs(locations, orientations))

    def body_terms(self, k, body_r, location, orientation, r_vectors, locations, orientations):
        """Energy terms that involve body ``k`` placed at ``body_r`` (n_k, 3) / ``location`` / ``orientation``.

        One-blob energies of its blobs, its blob pairs with every blob of the
        other bodies (``r_vectors`` (N, 3), its own rows ignored) and its body
        pairs with the other bodies (``locations``, ``orientations``, its own row
        ignored).  Pairs inside the body are left out (a rigid move keeps them).
        """
        start, stop = self.offsets[k], self.offsets[k + 1]
        energy = self.one_blob(body_r) + self.pair_sums.cross(body_r, r_vectors, start, stop)
        if self.hooks.body_body_potential is not None and locations.shape[0] > 1:
            others = np.arange(locations.shape[0]) != k
            after = np.arange(locations.shape[0])[others] > k
            r = minimum_image(locations[others] - location, self.periodic_length)
            # each pair keeps the orientation of (lower index, higher index): r from the lower to the higher
            r = np.where(after[:, None], r, -r)
            q_k = np.broadcast_to(orientation, (after.size, 4))
            q_i = np.where(after[:, None], q_k, orientations[others])
            q_j = np.where(after[:, None], orientations[others], q_k)
            energy += float(np.sum(self.hooks.body_body_potential(r, q_i, q_j, **self.keywords)))
        return energy

    def body_change(self, k, location, orientation, r_vectors, locations, orientations):
        """(Energy change of moving body ``k`` to ``location``/``orientation``, its new blobs (n_k, 3)).

        The change is inf when a new blob centre is at or below the wall.
        Costs O(n_k N) pair terms.
        """
        new_r = self.body_blob_positions(k, location, orientation)
        if np.any(new_r[:, 2] <= 0.0):
            return math.inf, new_r
        start, stop = self.offsets[k], self.offsets[k + 1]
        new = self.body_terms(k, new_r, location, orientation, r_vectors, locations, orientations)
        old = self.body_terms(k, r_vectors[start:stop], locations[k], orientations[k], r_vectors, locations,
                              orientations)
        return new - old, new_r


def physics_keywords(options):
    """The keywords every potential receives (the dynamic code's names; blob mass 1)."""
    return {'g': options.g, 'repulsion_strength_wall': options.repulsion_strength_wall,
            'debye_length_wall': options.debye_length_wall, 'repulsion_strength': options.repulsion_strength,
            'debye_length': options.debye_length, 'periodic_length': tuple(options.periodic_length),
            'blob_radius': options.blob_radius, 'blob_mass': 1.0}


def make_pair_sums(implementation, keywords, hooks, where='mcmc_energy_implementation'):
    """The blob-blob backend for ``implementation`` (auto, python, C++, pycuda); returns (pair_sums, notes).

    ``auto``: pycuda when ``potential_pycuda_user_defined.py`` is present, else
    python when ``blob_blob_potential`` is overridden, else C++ when built, else python.
    """
    notes = []
    if implementation not in IMPLEMENTATIONS:
        raise UserInputError("%s: mcmc_energy_implementation '%s' is unknown; use %s"
                             % (where, implementation, ', '.join(IMPLEMENTATIONS)))
    custom_law = 'blob_blob_potential' in hooks.overridden
    if implementation == 'auto':
        if hooks.gpu_file is not None:
            implementation = 'pycuda'
        elif custom_law:
            implementation = 'python'
        else:
            implementation = 'C++' if cpp_available()[0] else 'python'
    elif hooks.gpu_file is not None and implementation != 'pycuda':
        notes.append('%s is ignored: it is read only by mcmc_energy_implementation pycuda' % hooks.gpu_file)
    if implementation == 'python':
        return PythonPairSums(keywords, hooks.blob_blob_potential), notes
    if implementation == 'C++':
        if custom_law:
            raise UserInputError("%s: the C++ energy has the default blob-blob law, but %s overrides "
                                 "blob_blob_potential; use mcmc_energy_implementation python (or auto)"
                                 % (where, ', '.join(hooks.sources)))
        ok, reason = cpp_available()
        if not ok:
            raise UserInputError("%s: the extension many_bodyMCMC._energy_cpp is not built (%s); run "
                                 "'python3 setup.py build_ext --inplace' or use python" % (where, reason))
        return CppPairSums(keywords), notes
    # pycuda
    try:
        from many_bodyMCMC import mcmc_cuda
        mcmc_cuda.check_usable()
    except Exception as err:  # no CuPy, no device, compiler failure
        reason = '%s: %s' % (type(err).__name__, err)
        if hooks.gpu_file is not None:
            raise UserInputError('%s is for the GPU energy (mcmc_energy_implementation pycuda), which cannot run on '
                                 'this machine (%s); on a CPU write the potentials in %s and remove or rename %s'
                                 % (hooks.gpu_file, reason, USER_POTENTIAL_FILE, GPU_POTENTIAL_FILE))
        raise UserInputError('%s: mcmc_energy_implementation pycuda cannot run on this machine (%s); choose auto, '
                             'C++ or python' % (where, reason))
    if hooks.gpu_file is not None:
        load_gpu_potentials(hooks)
    if 'blob_blob_potential' in hooks.overridden and hooks.blob_blob_cuda_source is None:
        raise UserInputError("%s: blob_blob_potential is overridden in python, which the GPU cannot run; give "
                             "BLOB_BLOB_POTENTIAL_SOURCE in %s or use mcmc_energy_implementation python"
                             % (where, GPU_POTENTIAL_FILE))
    return mcmc_cuda.CudaPairSums(keywords, hooks.blob_blob_cuda_source), notes
