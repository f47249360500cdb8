"""Default physics of the many-body problem: forces, torques and slip (SPEC section 7).

Each hook is a module-level function that receives the keyword arguments
``g, repulsion_strength_wall, debye_length_wall, repulsion_strength,
debye_length, periodic_length, blob_radius, blob_mass`` (extra keywords are
ignored).  A file ``user_defined_functions.py`` in the run directory replaces
hooks in either of two styles (see doc/overrides.md and
:func:`multi_bodies.solver.user_hooks.load_user_hooks`):

* this package's style: the file defines functions with the hook names;
* the published style, accepted for compatibility: the file starts with
  ``import multi_bodies_functions`` and ``from multi_bodies_functions import *``
  and rebinds ``multi_bodies_functions.X = X_new``.  The published helper
  names (``project_to_periodic_image``, ``default_zero_blobs``,
  ``default_zero_r_vectors``, ``default_zero_bodies``, ``active_body_slip``,
  the per-blob ``blob_external_force``) and the names such files take from a
  star import (``np``, ``partial``, ``Quaternion``) exist here.

Each default force law has its energy beside it (``blob_external_potential``,
``blob_blob_potential``, ``body_body_potential``; force = -grad U), which the
Monte Carlo sampler (``many_bodyMCMC.mcmc_energy``) uses; the compiled
backends use the same laws from ``mobility/cpp/pair_laws.h``.  The minimum
image is ``mobility.periodic.minimum_image``, re-exported here.

All defaults are vectorised over blobs and bodies (no Python loop over them);
the all-pairs sums are done in row chunks to bound memory.  Per-blob and
per-pair user functions (the published signatures) are called in a Python
loop, which the log says is slow.

Shapes: blob positions ``r_vectors`` (N, 3); blob forces (N, 3);
force-torque arrays (2 Nb, 3) with rows ``F_0, T_0, F_1, T_1, ...`` (the
published layout), equivalently (Nb, 6) after reshaping.
"""
from functools import partial  # noqa: F401  (published override files use it through a star import)

import numpy as np

from mobility.periodic import minimum_image  # noqa: F401  (published name of this module; one source in mobility)
from body.geometry import Quaternion  # noqa: F401  (star-imported by published override files)
from multi_bodies.files.input_options import DEFAULTS  # the laws' keyword defaults are the option table's
from utils import UserInputError

PAIR_CHUNK_ELEMENTS = 262144  # pairs per chunk in the all-pairs sums (bounded memory, cache friendly)


def blob_external_forces(r_vectors, g=DEFAULTS.g, repulsion_strength_wall=DEFAULTS.repulsion_strength_wall,
                         debye_length_wall=DEFAULTS.debye_length_wall, blob_radius=DEFAULTS.blob_radius, blob_mass=1.0,
                         top_wall=None, **kwargs):
    """Gravity and soft wall repulsion on every blob, shape (N, 3).

    Gravity ``(0, 0, -g blob_mass)``; the wall potential
    ``U = eps + eps (a - z)/b`` for ``z < a`` and ``eps exp(-(z - a)/b)``
    otherwise gives ``f_z = (eps/b) exp(-(z - a)/b)`` (``eps/b`` below ``a``),
    with ``eps = repulsion_strength_wall``, ``b = debye_length_wall``, ``a = blob_radius``.
    ``top_wall`` (the height of the top wall of a slit, doc/periodic.md; None without): the same repulsion
    from that wall, with ``top_wall - z`` in place of ``z``, pushing down.
    """
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    z = r_vectors[:, 2]
    eps, b, a = repulsion_strength_wall, debye_length_wall, blob_radius
    forces = np.zeros_like(r_vectors)
    forces[:, 2] = -g * blob_mass + np.where(z > a, (eps / b) * np.exp(-(z - a) / b), eps / b)
    if top_wall is not None:
        gap = top_wall - z
        forces[:, 2] -= np.where(gap > a, (eps / b) * np.exp(-(gap - a) / b), eps / b)
    return forces


def blob_external_potential(r_vectors, g=DEFAULTS.g, repulsion_strength_wall=DEFAULTS.repulsion_strength_wall,
                            debye_length_wall=DEFAULTS.debye_length_wall, blob_radius=DEFAULTS.blob_radius,
                            blob_mass=1.0, top_wall=None, **kwargs):
    """Energy of gravity and of the soft wall of every blob (the potential of ``blob_external_forces``).

    r_vectors (N, 3) -> energies (N,): ``g blob_mass z + eps exp(-(z - a)/b)``
    for ``z >= a`` and ``g blob_mass z + eps + eps (a - z)/b`` below; with ``top_wall`` the same wall energy of
    the gap ``top_wall - z`` added.
    """
    z = np.asarray(r_vectors, dtype=float).reshape(-1, 3)[:, 2]
    eps, b, a = repulsion_strength_wall, debye_length_wall, blob_radius

    def wall(gap):
        return eps * np.exp(-np.maximum(gap - a, 0.0) / b) + (eps / b) * np.maximum(a - gap, 0.0)
    energy = g * blob_mass * z + wall(z)
    return energy if top_wall is None else energy + wall(top_wall - z)


def blob_external_force(r_vectors, *args, **kwargs):
    """The default one-blob force of a single blob (published per-blob signature): r (3,) -> (3,)."""
    return blob_external_forces(np.asarray(r_vectors, dtype=float).reshape(1, 3), **kwargs)[0]


def calc_one_blob_forces(r_vectors, *args, **kwargs):
    """Sum of one-blob forces (the ``blob_external_forces`` hook), shape (N, 3)."""
    return blob_external_forces(r_vectors, **kwargs)


def blob_blob_force(r, *args, repulsion_strength=DEFAULTS.repulsion_strength, debye_length=DEFAULTS.debye_length,
                    blob_radius=DEFAULTS.blob_radius, **kwargs):
    """Soft repulsion of one blob pair, vectorised over pairs.

    ``r`` (shape (..., 3)) points from blob i to blob j; returns the force on
    blob i, shape (..., 3): ``-(eps/b) exp(-(|r| - 2a)/b) r/|r|`` for
    ``|r| > 2a`` and ``-(eps/b) r/|r|`` otherwise.
    """
    eps, b, d = repulsion_strength, debye_length, 2.0 * blob_radius
    distance = np.maximum(np.sqrt(np.einsum('...k,...k->...', r, r)), np.finfo(float).eps)
    # exp(-max(|r| - 2a, 0)/b) is 1 for overlapping blobs: one exponential for both branches.
    magnitude = (eps / b) * np.exp(-np.maximum(distance - d, 0.0) / b) / distance
    return -magnitude[..., None] * r


def blob_blob_potential(r, repulsion_strength=DEFAULTS.repulsion_strength, debye_length=DEFAULTS.debye_length,
                        blob_radius=DEFAULTS.blob_radius, **kwargs):
    """Energy of the soft repulsion of blob pairs (the potential of ``blob_blob_force``).

    r (..., 3) from blob i to blob j -> energies (...): ``eps exp(-(|r| - 2a)/b)``
    for ``|r| >= 2a`` and ``eps + eps (2a - |r|)/b`` below.
    """
    eps, b, d = repulsion_strength, debye_length, 2.0 * blob_radius
    distance = np.sqrt(np.einsum('...k,...k->...', r, r))
    return eps * np.exp(-np.maximum(distance - d, 0.0) / b) + (eps / b) * np.maximum(d - distance, 0.0)


def calc_blob_blob_forces(r_vectors, periodic_length=(0.0, 0.0, 0.0), pair_force=None, blob_radii=None, **kwargs):
    """Forces of all blob pairs (the ``blob_blob_force`` hook), shape (N, 3).

    Pairs use the minimum image on periodic axes; every pair is counted once
    per blob, so blob i receives ``sum_{j != i} f(r_j - r_i)``.  ``pair_force``
    (default: this module's ``blob_blob_force``) is the law of one pair,
    vectorised over pairs: ``pair_force(r (..., 3), **kwargs) -> (..., 3)``.
    ``blob_radii`` (N,), when the vertex files give radii: each pair gets
    ``blob_radius = (a_i + a_j)/2`` (shape (..., ) of the pairs), so that the
    default law's contact distance is ``a_i + a_j`` (the published rule of
    the radii forces).
    """
    pair_force = blob_blob_force if pair_force is None else pair_force
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    n = r_vectors.shape[0]
    forces = np.zeros_like(r_vectors)
    rows = max(1, PAIR_CHUNK_ELEMENTS // max(n, 1))
    radii = None if blob_radii is None else np.asarray(blob_radii, dtype=float).reshape(n)
    for start in range(0, n, rows):
        stop = min(n, start + rows)
        r = minimum_image(r_vectors[None, :, :] - r_vectors[start:stop, None, :], periodic_length)
        if radii is not None:
            kwargs['blob_radius'] = 0.5 * (radii[start:stop, None] + radii[None, :])
        pair = pair_force(r, periodic_length=periodic_length, **kwargs)
        pair[np.arange(stop - start), np.arange(start, stop)] = 0.0
        forces[start:stop] = np.einsum('ijk->ik', pair)
    return forces


def body_body_force_torque(r, quaternion_i=None, quaternion_j=None, *args,
                           repulsion_strength=DEFAULTS.repulsion_strength, debye_length=DEFAULTS.debye_length,
                           **kwargs):
    """Yukawa force of one body pair, vectorised over pairs.

    ``r`` (shape (..., 3)) points from body i to body j; the orientations
    (published signature) are not used by this law.  Returns an array of
    shape (2, ..., 3): ``[force on i, torque on i]`` (for one pair the
    published (2, 3) layout; ``force, torque = ...`` unpacks it).  Force
    ``-(eps/b + eps/|r|) exp(-|r|/b) r/|r|^2``, torque zero.
    """
    r = np.asarray(r, dtype=float)
    eps, b = repulsion_strength, debye_length
    distance = np.maximum(np.linalg.norm(r, axis=-1), np.finfo(float).eps)
    magnitude = (eps / b + eps / distance) * np.exp(-distance / b) / distance ** 2
    return np.stack((-magnitude[..., None] * r, np.zeros_like(r)))


def body_body_potential(r, quaternion_i=None, quaternion_j=None, repulsion_strength=DEFAULTS.repulsion_strength,
                        debye_length=DEFAULTS.debye_length, **kwargs):
    """Yukawa energy ``eps exp(-|r|/b)/|r|`` of body pairs (the potential of ``body_body_force_torque``).

    r (..., 3) from body i to body j -> energies (...); the orientations
    (quaternions (..., 4)) are not used by this law.
    """
    eps, b = repulsion_strength, debye_length
    distance = np.maximum(np.linalg.norm(r, axis=-1), np.finfo(float).eps)
    return eps * np.exp(-distance / b) / distance


def calc_body_body_forces_torques(locations, periodic_length=(0.0, 0.0, 0.0), pair_force_torque=None, cutoff=None,
                                  **kwargs):
    """Force and torque of all body pairs (the ``body_body_force_torque`` hook), shape (2 Nb, 3).

    Body j receives the opposite of the force and torque body i receives from
    the pair.  ``pair_force_torque`` (default: this module's
    ``body_body_force_torque``) is vectorised over pairs.  ``cutoff`` (a length,
    or None: every pair): the law vanishes beyond it (its ``cutoff`` attribute,
    doc/overrides.md), so only the pairs closer than it are visited
    (:func:`pairs_within`, O(Nb)); the sum is the all-pairs one over them.
    """
    pair_force_torque = body_body_force_torque if pair_force_torque is None else pair_force_torque
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    nb = locations.shape[0]
    if cutoff is not None:
        i_index, j_index = pairs_within(locations, cutoff, periodic_length)
        result = np.zeros((nb, 2, 3))
        if i_index.size == 0:
            return result.reshape(2 * nb, 3)
        r = minimum_image(locations[j_index] - locations[i_index], periodic_length)
        force, torque = pair_force_torque(r, periodic_length=periodic_length, **kwargs)
        np.add.at(result[:, 0], i_index, force)
        np.add.at(result[:, 0], j_index, -force)
        np.add.at(result[:, 1], i_index, torque)
        np.add.at(result[:, 1], j_index, -torque)
        return result.reshape(2 * nb, 3)
    r = minimum_image(locations[None, :, :] - locations[:, None, :], periodic_length)
    upper = np.triu(np.ones((nb, nb), dtype=bool), k=1)
    force, torque = pair_force_torque(r[upper], periodic_length=periodic_length, **kwargs)
    i_index, j_index = np.nonzero(upper)
    result = np.zeros((nb, 2, 3))
    np.add.at(result[:, 0], i_index, force)
    np.add.at(result[:, 0], j_index, -force)
    np.add.at(result[:, 1], i_index, torque)
    np.add.at(result[:, 1], j_index, -torque)
    return result.reshape(2 * nb, 3)


def bodies_external_force_torque(bodies, r_vectors, *args, **kwargs):
    """External force and torque on each body (default zero), shape (2 Nb, 3)."""
    return np.zeros((2 * len(bodies), 3))


def set_slip_by_ID(body, slip=None, *args, **kwargs):
    """Give ``body`` its reference-frame slip (shape (n, 3) or None for no slip).

    The slip turns with the body (``body.calc_slip()`` returns it in the lab
    frame), as the published ``active_body_slip`` does.
    """
    body.slip_reference = None if slip is None else np.asarray(slip, dtype=float).reshape(-1, 3)


def preprocess(bodies, *args, **kwargs):
    """Called at the start of every time step with the list of Body objects (default: nothing)."""


def postprocess(bodies, *args, **kwargs):
    """Called after every time step, before the validity check (default: nothing)."""


# ------------------------------------------------------------------ published helper names
def project_to_periodic_image(r, L):
    """Minimum image of one vector ``r`` (shape (3,), or (..., 3)) in the box ``L``, in place; returns ``r``.

    Axes with ``L <= 0`` (or ``L`` None) are not periodic.  Same rounding as
    :func:`minimum_image` (half away from zero).
    """
    if L is None:
        return r
    L = np.asarray(L, dtype=float).reshape(3)
    r[...] = minimum_image(r, L)
    return r


def default_zero_r_vectors(r_vectors, *args, **kwargs):
    """Zero force on every blob, shape (N, 3)."""
    return np.zeros((np.size(r_vectors) // 3, 3))


def default_zero_blobs(body, *args, **kwargs):
    """Zero slip (or force) on every blob of ``body``, shape (body.Nblobs, 3)."""
    return np.zeros((body.Nblobs, 3))


def default_zero_bodies(bodies, *args, **kwargs):
    """Zero force and torque on every body, shape (2 len(bodies), 3)."""
    return np.zeros((2 * len(bodies), 3))


def active_body_slip(body, slip):
    """Slip ``slip`` given in the body frame (shape (Nblobs, 3)), turned into the lab frame: ``R(q) slip_i``."""
    return np.asarray(slip, dtype=float).reshape(-1, 3) @ body.orientation.rotation_matrix().T


# Marks that let the set-up recognise these helpers in a user's slip functions (also in fresh module copies).
default_zero_blobs.published_helper = 'default_zero_blobs'
active_body_slip.published_helper = 'active_body_slip'


def default_blob_blob_cutoff(blob_radius=DEFAULTS.blob_radius, debye_length=DEFAULTS.debye_length, **kwargs):
    """``2 a + 30 b``: beyond it the default soft repulsion is below ``exp(-30)`` of its contact value
    (the cutoff of the published ``tree_numba``)."""
    return 2.0 * float(blob_radius) + 30.0 * float(debye_length)


def pairs_within(positions, cutoff, periodic_length=(0.0, 0.0, 0.0)):
    """``(i, j)``: the index pairs (i < j, each (P,) int) of the points ``positions`` (N, 3) closer than ``cutoff``
    (minimum image on the periodic axes), found in O(N) by ``scipy.spatial.cKDTree`` on a box that is periodic on
    the periodic axes and, on the others, wider than the points' extent plus the cutoff (so no pair wraps there)."""
    from scipy.spatial import cKDTree
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    shifted = positions.copy()
    box = np.empty(3)
    for d in range(3):
        if L[d] > 0:
            shifted[:, d] = np.mod(shifted[:, d], L[d])
            shifted[:, d][shifted[:, d] >= L[d]] = 0.0
            box[d] = L[d]
        else:
            shifted[:, d] -= shifted[:, d].min()
            box[d] = shifted[:, d].max() + 2.0 * cutoff + 1.0
    pairs = cKDTree(shifted, boxsize=box).query_pairs(float(cutoff), output_type='ndarray')
    if pairs.size == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]   # the all-pairs order (i, then j)
    return pairs[:, 0], pairs[:, 1]


def cutoff_length(cutoff, keywords, name):
    """The length of a pair law's ``cutoff`` attribute (a positive length, or a function of the physics keywords
    returning one); None for a law without one.  ``name``: the law, for the one-line error."""
    if cutoff is None:
        return None
    length = cutoff(**keywords) if callable(cutoff) else cutoff
    if isinstance(length, bool) or not isinstance(length, (int, float, np.floating, np.integer)) \
            or not (np.isfinite(length) and length > 0):
        raise UserInputError('%s.cutoff must be a positive length (or a function of the physics keywords returning '
                             'one), got %r' % (name, length))
    return float(length)


def calc_blob_blob_forces_cell_list(r_vectors, cutoff, pair_force, periodic_length=(0.0, 0.0, 0.0), **kwargs):
    """Forces (N, 3) of the pairs closer than ``cutoff`` (minimum image on periodic axes), O(N) neighbours.

    ``pair_force(r (P, 3), **kwargs) -> (P, 3)`` is the law of one pair (force on i, r from i to j),
    vectorised over pairs (a law of one pair only, r (3,) -> (3,), is called pair by pair).  The pairs come
    from :func:`pairs_within`.
    """
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    forces = np.zeros_like(r_vectors)
    if r_vectors.shape[0] < 2:
        return forces
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    i, j = pairs_within(r_vectors, cutoff, L)
    if i.size == 0:
        return forces
    r = minimum_image(r_vectors[j] - r_vectors[i], L)
    try:
        on_i = np.asarray(pair_force(r, periodic_length=periodic_length, **kwargs), dtype=float)
        vectorised = on_i.shape == r.shape
    except Exception:
        vectorised = False
    if not vectorised:
        on_i = np.array([pair_force(rk, periodic_length=periodic_length, **kwargs) for rk in r], dtype=float)
    # the law is that of a pair: the force on j (r_i - r_j) is minus that on i
    np.add.at(forces, i, on_i)
    np.add.at(forces, j, -on_i)
    return forces


def blob_blob_force_calculator(implementation, pair_force=None, pycuda_forces=None, python_forces=None,
                               radii_given=False):
    """The blob force function for ``blob_blob_force_implementation``.

    Returns None for 'None' (no blob-blob forces), else
    ``f(r_vectors (N, 3), **physics_keywords) -> (N, 3)``:

    * 'python': ``python_forces`` if given (the all-pairs function that
      :class:`PhysicsHooks` builds around a user's pair law), else
      ``calc_blob_blob_forces`` with the vectorised pair law ``pair_force``
      (default this module's ``blob_blob_force``).  A law with an attribute
      ``cutoff`` (a length, or a function of the physics keywords returning
      one) declares that it vanishes beyond it: then only the pairs within
      the cutoff are visited (``calc_blob_blob_forces_cell_list``, O(N));
    * 'C++' (alias 'numba', the later published name): the OpenMP kernel of
      ``multi_bodies.solver._forces_cpp`` (default law, all pairs);
    * 'tree_numba' (the later published name of the O(N) version): the C++
      cell list of the default law, which neglects pairs farther than
      ``2 blob_radius + 30 debye_length`` (their force is below ``exp(-30)``
      of the contact force);
    * 'pycuda': ``pycuda_forces`` if given (the function of a
      ``forces_pycuda_user_defined.py``), else the CuPy kernel of
      ``multi_bodies.solver.forces_pycuda`` (imported only here).
    * 'radii_numba' (the published name of the forces with per-blob radii):
      the C++ kernel; python and C++ use the radii as well when the vertex
      files give them (the function then takes ``blob_radii`` (N,)).

    ``radii_given``: the vertex files give per-blob radii; pycuda and
    tree_numba, which have one contact distance, are then refused.
    """
    if implementation == 'None':
        return None
    if implementation == 'radii_numba':
        implementation = 'C++'
    if radii_given and implementation in ('pycuda', 'tree_numba'):
        raise UserInputError("blob_blob_force_implementation %s uses one blob_radius, but the vertex files give "
                             "per-blob radii (fourth column); use python, C++ or radii_numba" % implementation)
    if implementation == 'python':
        cutoff = getattr(pair_force, 'cutoff', None)
        if cutoff is not None:
            if not callable(cutoff):
                cutoff_length(cutoff, {}, 'blob_blob_force')   # refused at set-up

            def cell_list_forces(r_vectors, **kw):
                length = cutoff_length(cutoff, kw, 'blob_blob_force')
                return calc_blob_blob_forces_cell_list(r_vectors, length, pair_force, **kw)
            return cell_list_forces
        if python_forces is not None:
            return python_forces
        return lambda r_vectors, **kw: calc_blob_blob_forces(r_vectors, pair_force=pair_force, **kw)
    if implementation in ('C++', 'numba', 'tree_numba'):
        try:
            from multi_bodies.solver import _forces_cpp
        except ImportError as err:
            raise UserInputError("blob_blob_force_implementation %s: the extension multi_bodies.solver._forces_cpp "
                                 "is not built (%s); run 'pip install -e .' or use python" % (implementation, err))

        if implementation == 'tree_numba':
            def cell_list_cpp_forces(r_vectors, periodic_length=(0.0, 0.0, 0.0),
                                     repulsion_strength=DEFAULTS.repulsion_strength, debye_length=DEFAULTS.debye_length,
                                     blob_radius=DEFAULTS.blob_radius, **kw):
                return _forces_cpp.blob_blob_forces_cell_list(
                    np.asarray(r_vectors, dtype=float).reshape(-1, 3), np.asarray(periodic_length, dtype=float).reshape(3),
                    float(repulsion_strength), float(debye_length), float(blob_radius),
                    default_blob_blob_cutoff(blob_radius, debye_length))
            return cell_list_cpp_forces

        def cpp_forces(r_vectors, periodic_length=(0.0, 0.0, 0.0), repulsion_strength=DEFAULTS.repulsion_strength,
                       debye_length=DEFAULTS.debye_length, blob_radius=DEFAULTS.blob_radius, blob_radii=None, **kw):
            if blob_radii is not None:
                return _forces_cpp.blob_blob_forces_radii(np.asarray(r_vectors, dtype=float).reshape(-1, 3),
                                                          np.asarray(periodic_length, dtype=float).reshape(3),
                                                          float(repulsion_strength), float(debye_length),
                                                          np.asarray(blob_radii, dtype=float).reshape(-1))
            return _forces_cpp.blob_blob_forces(np.asarray(r_vectors, dtype=float).reshape(-1, 3),
                                                np.asarray(periodic_length, dtype=float).reshape(3),
                                                float(repulsion_strength), float(debye_length), float(blob_radius))
        return cpp_forces
    if implementation == 'pycuda':
        try:
            from multi_bodies.solver import forces_pycuda
            forces_pycuda.check_usable()
        except Exception as err:  # no CuPy, no GPU, compiler failure
            raise UserInputError("blob_blob_force_implementation pycuda cannot run on this machine (%s: %s); "
                                 "use C++ or python" % (type(err).__name__, err))
        if pycuda_forces is not None:
            return pycuda_forces
        return forces_pycuda.calc_blob_blob_forces_pycuda
    raise UserInputError("blob_blob_force_implementation '%s' is unknown; use None, python, C++ (or numba, "
                         "radii_numba), tree_numba or pycuda" % implementation)


def body_body_force_calculator(implementation, pair_force_torque=None, python_forces_torques=None):
    """'None' -> None; 'python' -> ``f(locations (Nb, 3), orientations (Nb, 4) or None, **kw) -> (2 Nb, 3)``.

    ``python_forces_torques`` (built by :class:`PhysicsHooks` around a user's
    per-pair law) wins; otherwise ``calc_body_body_forces_torques`` with the
    vectorised pair law ``pair_force_torque``.
    """
    if implementation == 'None':
        return None
    if implementation == 'python':
        if python_forces_torques is not None:
            return python_forces_torques
        return lambda locations, orientations=None, **kw: calc_body_body_forces_torques(
            locations, pair_force_torque=pair_force_torque, **kw)
    raise UserInputError("body_body_force_torque_implementation '%s' is unknown; use None or python"
                         % implementation)


# Every keyword that the published code passes to one of its hooks (calc_one_blob_forces, calc_blob_blob_forces,
# bodies_external_force_torque, body_body_force_torque, force_torque_calculator_sort_by_bodies) in its main program
# or the main programs of its example folders; the lubrication-only keywords (mu, B0, omega, ...) are not here.
PUBLISHED_HOOK_KEYWORDS = ('g', 'repulsion_strength_wall', 'debye_length_wall', 'repulsion_strength', 'debye_length',
                           'periodic_length', 'blob_radius', 'blob_mass', 'eta', 'a', 'particle_radius',
                           'omega_one_roller', 'tilt_angle', 'kT')
# Keywords of this package's own physics that the published code never passes (its hooks take **kwargs).
PACKAGE_HOOK_KEYWORDS = ('top_wall',)


def physics_keywords(options):
    """Keyword arguments of every hook (SPEC section 7) from validated input options: ``PUBLISHED_HOOK_KEYWORDS``.

    ``blob_mass`` is 1; ``a`` is ``blob_radius`` (the published name); ``particle_radius`` (length) is the
    option of that name (default 1.0, the value the published Multi_Blob_Two_Rollers program sets);
    ``omega_one_roller`` (3,) in 1/time; ``tilt_angle`` in radians; ``periodic_length`` (3,); and
    ``PACKAGE_HOOK_KEYWORDS``: ``top_wall``, the height of the top wall of a spectral slit (None otherwise,
    doc/periodic.md).
    """
    top_wall = None
    if options.mobility_vector_prod_implementation == 'spectral':  # a slit (a top wall) only with the spectral product
        from multi_bodies.solver.periodic import top_wall_height
        top_wall = top_wall_height(options)
    return dict(g=options.g, repulsion_strength_wall=options.repulsion_strength_wall,
                debye_length_wall=options.debye_length_wall, repulsion_strength=options.repulsion_strength,
                debye_length=options.debye_length, periodic_length=np.array(options.periodic_length, dtype=float),
                blob_radius=options.blob_radius, blob_mass=1.0, eta=options.eta, a=options.blob_radius,
                particle_radius=options.particle_radius,
                omega_one_roller=np.array(options.omega_one_roller, dtype=float),
                tilt_angle=options.tilt_angle, kT=options.kT, top_wall=top_wall)


def force_torque_calculator_sort_by_bodies(bodies, body_arrays, r_vectors, blob_blob_forces=None,
                                           body_body_forces=None, **kwargs):
    """Total force and torque on every body with this module's default hooks, shape (2 Nb, 3) (SPEC section 7).

    Parameters
    ----------
    bodies : list of Body
        Passed to ``bodies_external_force_torque``.
    body_arrays : body.body.BodyArrays
        The same bodies as arrays; ``K^T`` and the body locations are those of its ``configuration``.
    r_vectors : ndarray, shape (N, 3)
        The blob positions of that configuration.
    blob_blob_forces, body_body_forces : callables or None
        From ``blob_blob_force_calculator`` and ``body_body_force_calculator``.
    **kwargs
        The physics keywords (g, repulsion_strength_wall, ..., blob_mass).

    The scripts use ``Model.forces_torques``, which calls the run's hooks
    (the user's overrides included); this function is the same sum over this
    module's attributes.
    """
    blob_forces = calc_one_blob_forces(r_vectors, **kwargs)
    if blob_blob_forces is not None:
        blob_forces = blob_forces + blob_blob_forces(r_vectors, **kwargs)
    configuration = body_arrays.configuration
    force_torque = body_arrays.KT_dot(configuration, blob_forces, r_vectors).reshape(-1, 3)
    force_torque = force_torque + bodies_external_force_torque(bodies, r_vectors, **kwargs)
    if body_body_forces is not None:
        force_torque = force_torque + body_body_forces(configuration.locations, configuration.orientations, **kwargs)
    return force_torque


# ---------------------------------------------------------------------------------------------- overrides
USER_FILE = 'user_defined_functions.py'
USER_PYCUDA_FILE = 'forces_pycuda_user_defined.py'
# Hooks a user file may replace, in both styles.  The one-blob force has three published names:
# per blob ``blob_external_force`` (2017 manual), vectorised ``blob_external_forces`` and
# ``calc_one_blob_forces`` (later published code); the first that is replaced, from the right, is used.
ONE_BLOB_NAMES = ('calc_one_blob_forces', 'blob_external_forces', 'blob_external_force')
HOOK_NAMES = ONE_BLOB_NAMES + ('blob_blob_force', 'body_body_force_torque', 'bodies_external_force_torque',
                               'set_slip_by_ID', 'preprocess', 'postprocess')
