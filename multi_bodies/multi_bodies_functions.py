"""Default physics of the many-body problem: forces, torques and slip (SPEC section 7), and the loader of overrides.

Each hook is a module-level function that receives the keyword arguments
``g, repulsion_strength_wall, debye_length_wall, repulsion_strength,
debye_length, periodic_length, blob_radius, blob_mass`` (extra keywords are
ignored).  A file ``user_defined_functions.py`` in the run directory replaces
hooks in either of two styles (see doc/overrides.md and
:func:`load_user_hooks`):

* this package's style: the file defines functions with the hook names;
* the published style, accepted for compatibility: the file starts with
  ``import multi_bodies_functions`` and ``from multi_bodies_functions import *``
  and rebinds ``multi_bodies_functions.X = X_new``.  The published helper
  names (``project_to_periodic_image``, ``default_zero_blobs``,
  ``default_zero_r_vectors``, ``default_zero_bodies``, ``active_body_slip``,
  the per-blob ``blob_external_force``) and the names such files take from a
  star import (``np``, ``partial``, ``Quaternion``) exist here.

All defaults are vectorised over blobs and bodies (no Python loop over them);
the all-pairs sums are done in row chunks to bound memory.  Per-blob and
per-pair user functions (the published signatures) are called in a Python
loop, which the log says is slow.

Shapes: blob positions ``r_vectors`` (N, 3); blob forces (N, 3);
force-torque arrays (2 Nb, 3) with rows ``F_0, T_0, F_1, T_1, ...`` (the
published layout), equivalently (Nb, 6) after reshaping.
"""
import inspect
import os
import sys
import traceback
from functools import partial  # noqa: F401  (published override files use it through a star import)

import numpy as np

from quaternion_integrator.quaternion import Quaternion  # noqa: F401  (star-imported by published override files)
from utils import SimulationStopped, UserInputError

PAIR_CHUNK_ELEMENTS = 262144  # pairs per chunk in the all-pairs sums (bounded memory, cache friendly)


def minimum_image(displacements, periodic_length):
    """Minimum-image convention on periodic axes (SPEC section 8).

    ``displacements`` has shape (..., 3); for each axis with ``L > 0``,
    ``r -= trunc(r/L + 0.5 sign(r)) L`` (round half away from zero).
    """
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    if not np.any(L > 0):
        return displacements
    r = np.array(displacements, dtype=float, copy=True)
    for axis in np.nonzero(L > 0)[0]:
        r[..., axis] -= np.trunc(r[..., axis] / L[axis] + 0.5 * np.sign(r[..., axis])) * L[axis]
    return r


def blob_external_forces(r_vectors, g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0,
                         blob_radius=1.0, blob_mass=1.0, **kwargs):
    """Gravity and soft wall repulsion on every blob, shape (N, 3).

    Gravity ``(0, 0, -g blob_mass)``; the wall potential
    ``U = eps + eps (a - z)/b`` for ``z < a`` and ``eps exp(-(z - a)/b)``
    otherwise gives ``f_z = (eps/b) exp(-(z - a)/b)`` (``eps/b`` below ``a``),
    with ``eps = repulsion_strength_wall``, ``b = debye_length_wall``, ``a = blob_radius``.
    """
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    z = r_vectors[:, 2]
    eps, b, a = repulsion_strength_wall, debye_length_wall, blob_radius
    forces = np.zeros_like(r_vectors)
    forces[:, 2] = -g * blob_mass + np.where(z > a, (eps / b) * np.exp(-(z - a) / b), eps / b)
    return forces


def blob_external_force(r_vectors, *args, **kwargs):
    """The default one-blob force of a single blob (published per-blob signature): r (3,) -> (3,)."""
    return blob_external_forces(np.asarray(r_vectors, dtype=float).reshape(1, 3), **kwargs)[0]


def calc_one_blob_forces(r_vectors, *args, **kwargs):
    """Sum of one-blob forces (the ``blob_external_forces`` hook), shape (N, 3)."""
    return blob_external_forces(r_vectors, **kwargs)


def blob_blob_force(r, *args, repulsion_strength=1.0, debye_length=1.0, blob_radius=1.0, **kwargs):
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


def calc_blob_blob_forces(r_vectors, periodic_length=(0.0, 0.0, 0.0), pair_force=None, **kwargs):
    """Forces of all blob pairs (the ``blob_blob_force`` hook), shape (N, 3).

    Pairs use the minimum image on periodic axes; every pair is counted once
    per blob, so blob i receives ``sum_{j != i} f(r_j - r_i)``.  ``pair_force``
    (default: this module's ``blob_blob_force``) is the law of one pair,
    vectorised over pairs: ``pair_force(r (..., 3), **kwargs) -> (..., 3)``.
    """
    pair_force = blob_blob_force if pair_force is None else pair_force
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    n = r_vectors.shape[0]
    forces = np.zeros_like(r_vectors)
    rows = max(1, PAIR_CHUNK_ELEMENTS // max(n, 1))
    for start in range(0, n, rows):
        stop = min(n, start + rows)
        r = minimum_image(r_vectors[None, :, :] - r_vectors[start:stop, None, :], periodic_length)
        pair = pair_force(r, periodic_length=periodic_length, **kwargs)
        pair[np.arange(stop - start), np.arange(start, stop)] = 0.0
        forces[start:stop] = np.einsum('ijk->ik', pair)
    return forces


def body_body_force_torque(r, quaternion_i=None, quaternion_j=None, *args, repulsion_strength=1.0,
                           debye_length=1.0, **kwargs):
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


def calc_body_body_forces_torques(locations, periodic_length=(0.0, 0.0, 0.0), pair_force_torque=None, **kwargs):
    """Force and torque of all body pairs (the ``body_body_force_torque`` hook), shape (2 Nb, 3).

    Body j receives the opposite of the force and torque body i receives from
    the pair.  ``pair_force_torque`` (default: this module's
    ``body_body_force_torque``) is vectorised over pairs.
    """
    pair_force_torque = body_body_force_torque if pair_force_torque is None else pair_force_torque
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    nb = locations.shape[0]
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


def blob_blob_force_calculator(implementation, pair_force=None, pycuda_forces=None, python_forces=None):
    """The all-pairs blob force function for ``blob_blob_force_implementation``.

    Returns None for 'None' (no blob-blob forces), else
    ``f(r_vectors (N, 3), **physics_keywords) -> (N, 3)``:

    * 'python': ``python_forces`` if given (the all-pairs function that
      :class:`PhysicsHooks` builds around a user's pair law), else
      ``calc_blob_blob_forces`` with the vectorised pair law ``pair_force``
      (default this module's ``blob_blob_force``);
    * 'C++': the OpenMP kernel of ``multi_bodies._forces_cpp`` (default law);
    * 'pycuda': ``pycuda_forces`` if given (the function of a
      ``forces_pycuda_user_defined.py``), else the CuPy kernel of
      ``multi_bodies.forces_pycuda`` (imported only here).
    """
    if implementation == 'None':
        return None
    if implementation == 'python':
        if python_forces is not None:
            return python_forces
        return lambda r_vectors, **kw: calc_blob_blob_forces(r_vectors, pair_force=pair_force, **kw)
    if implementation == 'C++':
        try:
            from multi_bodies import _forces_cpp
        except ImportError as err:
            raise UserInputError("blob_blob_force_implementation C++: the extension multi_bodies._forces_cpp "
                                 "is not built (%s); run 'pip install -e .' or use python" % err)

        def cpp_forces(r_vectors, periodic_length=(0.0, 0.0, 0.0), repulsion_strength=1.0, debye_length=1.0,
                       blob_radius=1.0, **kw):
            return _forces_cpp.blob_blob_forces(np.asarray(r_vectors, dtype=float).reshape(-1, 3),
                                                np.asarray(periodic_length, dtype=float).reshape(3),
                                                float(repulsion_strength), float(debye_length), float(blob_radius))
        return cpp_forces
    if implementation == 'pycuda':
        try:
            from multi_bodies import forces_pycuda
            forces_pycuda.check_usable()
        except Exception as err:  # no CuPy, no GPU, compiler failure
            raise UserInputError("blob_blob_force_implementation pycuda cannot run on this machine (%s: %s); "
                                 "use C++ or python" % (type(err).__name__, err))
        if pycuda_forces is not None:
            return pycuda_forces
        return forces_pycuda.calc_blob_blob_forces_pycuda
    raise UserInputError("blob_blob_force_implementation '%s' is unknown; use None, python, C++ or pycuda"
                         % implementation)


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


def physics_keywords(options):
    """Keyword arguments of every hook (SPEC section 7) from validated input options; ``blob_mass`` is 1."""
    return dict(g=options.g, repulsion_strength_wall=options.repulsion_strength_wall,
                debye_length_wall=options.debye_length_wall, repulsion_strength=options.repulsion_strength,
                debye_length=options.debye_length, periodic_length=np.array(options.periodic_length, dtype=float),
                blob_radius=options.blob_radius, blob_mass=1.0)


def force_torque_calculator_sort_by_bodies(bodies, body_arrays, r_vectors, blob_blob_forces=None,
                                           body_body_forces=None, **kwargs):
    """Total force and torque on every body with this module's default hooks, shape (2 Nb, 3) (SPEC section 7).

    Parameters
    ----------
    bodies : list of Body
        Passed to ``bodies_external_force_torque``.
    body_arrays : body.body.BodyArrays
        The same bodies as arrays (for ``K^T`` and the body locations).
    r_vectors : ndarray, shape (N, 3)
    blob_blob_forces, body_body_forces : callables or None
        From ``blob_blob_force_calculator`` and ``body_body_force_calculator``.
    **kwargs
        The physics keywords (g, repulsion_strength_wall, ..., blob_mass).

    The scripts use ``System.forces_torques``, which calls the run's hooks
    (the user's overrides included); this function is the same sum over this
    module's attributes.
    """
    blob_forces = calc_one_blob_forces(r_vectors, **kwargs)
    if blob_blob_forces is not None:
        blob_forces = blob_forces + blob_blob_forces(r_vectors, **kwargs)
    force_torque = body_arrays.KT_dot(r_vectors, blob_forces).reshape(-1, 3)
    force_torque = force_torque + bodies_external_force_torque(bodies, r_vectors, **kwargs)
    if body_body_forces is not None:
        force_torque = force_torque + body_body_forces(body_arrays.locations, body_arrays.orientations, **kwargs)
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


class UserFunctionError(SimulationStopped):
    """A function of the user's override file raised, or returned the wrong shape or non-finite values.

    The message names the function, the hook it replaces and the file (with
    the line, when the function raised).  A subclass of SimulationStopped: a
    dynamic run stops after its files are complete (exit status 1).
    """


def function_name(function):
    """Readable name of a user function (partials show the wrapped function)."""
    if isinstance(function, partial):
        return 'partial(%s)' % function_name(function.func)
    return getattr(function, '__qualname__', getattr(function, '__name__', repr(function)))


def function_file(function):
    """File where ``function`` was defined, or None."""
    while isinstance(function, partial):
        function = function.func
    code = getattr(inspect.unwrap(function), '__code__', None) if callable(function) else None
    return None if code is None else code.co_filename


def describe_user_function(function, hook=None):
    """``'name (replacing hook) in file'`` for messages."""
    text = function_name(function)
    if hook is not None and hook != getattr(function, '__name__', None):
        text += ' (replacing %s)' % hook
    path = function_file(function)
    return text + (' in %s' % path if path else '')


def call_user_function(function, hook, *args, **kwargs):
    """Call a user's hook; any exception becomes a UserFunctionError naming function, file and line."""
    try:
        return function(*args, **kwargs)
    except SimulationStopped:
        raise
    except Exception as err:
        path = function_file(function)
        line = ''
        frames = traceback.extract_tb(err.__traceback__)
        inside = [f for f in frames if path is not None and os.path.abspath(f.filename) == os.path.abspath(path)]
        if inside:
            line = ', line %d (%s)' % (inside[-1].lineno, (inside[-1].line or '').strip())
        elif frames:
            line = ', in %s line %d' % (frames[-1].filename, frames[-1].lineno)
        raise UserFunctionError('the user-defined function %s raised %s: %s%s; fix the function or remove it '
                                'from the file' % (describe_user_function(function, hook), type(err).__name__,
                                                   err, line)) from None


def checked_array(value, shapes, function, hook, what):
    """``value`` as a float array of one of the accepted ``shapes`` (first is the result shape), finite.

    Raises UserFunctionError naming the function, the hook and the file when
    the value is not numbers, has another shape or holds NaN or inf.
    """
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise UserFunctionError('the user-defined function %s returned %r, not an array of numbers; it must return '
                                '%s, shape %s' % (describe_user_function(function, hook), type(value).__name__, what,
                                                  shapes[0])) from None
    if array.shape not in [tuple(s) for s in shapes]:
        raise UserFunctionError('the user-defined function %s returned an array of shape %s; it must return %s, '
                                'shape %s' % (describe_user_function(function, hook), array.shape, what,
                                              ' or '.join(str(tuple(s)) for s in shapes)))
    if not np.all(np.isfinite(array)):
        raise UserFunctionError('the user-defined function %s returned values that are not finite (NaN or inf) '
                                'for %s' % (describe_user_function(function, hook), what))
    return array.reshape(shapes[0])


def positional_arity(function):
    """(required positional parameters, accepts *args) of ``function``; (None, True) when unknown."""
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):
        return None, True
    required, var = 0, False
    for parameter in signature.parameters.values():
        if parameter.kind == parameter.VAR_POSITIONAL:
            var = True
        elif parameter.kind in (parameter.POSITIONAL_ONLY, parameter.POSITIONAL_OR_KEYWORD) \
                and parameter.default is parameter.empty:
            required += 1
    return required, var


def positional_capacity(function):
    """How many positional arguments ``function`` accepts (a large number for ``*args``; 2 when unknown)."""
    try:
        parameters = inspect.signature(function).parameters.values()
    except (TypeError, ValueError):
        return 2
    if any(p.kind == p.VAR_POSITIONAL for p in parameters):
        return 1 << 20
    return sum(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in parameters)


def _vectorises(function, samples, physics):
    """True when ``function`` applied to the rows ``samples`` (k, 3) at once equals its row-by-row results.

    Decides which published convention a ``blob_external_force`` or
    ``blob_blob_force`` follows: vectorised over rows, or one row (3,) at a
    time.  A function that fails on the stack but not on rows is per row.
    """
    with np.errstate(all='ignore'):
        try:
            stacked = np.asarray(function(samples.copy(), **physics), dtype=float)
        except Exception:
            return False
        if stacked.shape != samples.shape:
            return False
        try:
            rows = np.array([np.asarray(function(row.copy(), **physics), dtype=float).reshape(3) for row in samples])
        except Exception:
            return True  # works on the stack only
    return bool(np.allclose(stacked, rows, rtol=1e-10, atol=1e-300, equal_nan=True))


class PhysicsHooks:
    """The physics hooks of one run: this module's defaults, some replaced by the user's files.

    Every attribute follows this package's conventions, whatever the style
    and signature of the user's function (the adapters loop over blobs or
    pairs where the user's function takes one at a time, and check shapes and
    finiteness of what it returns):

    * ``blob_external_forces(r_vectors (N, 3), **kw) -> (N, 3)``;
    * ``blob_blob_forces_python(r_vectors (N, 3), **kw) -> (N, 3)``, the all-pairs
      sum for ``blob_blob_force_implementation python`` (None: the default sum
      with the vectorised law ``blob_blob_force``);
    * ``body_body_forces_python(locations (Nb, 3), orientations (Nb, 4), **kw) -> (2 Nb, 3)``
      (None: the default sum with the vectorised law ``body_body_force_torque``);
    * ``bodies_external_force_torque(bodies, r_vectors, **kw) -> (2 Nb, 3)``;
    * ``set_slip_by_ID(body, slip)``; ``preprocess(bodies)``; ``postprocess(bodies)``;
    * ``calc_blob_blob_forces_pycuda`` (None unless a ``forces_pycuda_user_defined.py`` supplied it).

    ``overridden`` lists the hooks the user's files replaced, ``sources`` the
    files read, ``notes`` the lines the log should show (what was replaced,
    with which convention, and what has no effect).
    """

    def __init__(self, physics=None):
        self.physics = {} if physics is None else dict(physics)
        self.blob_external_forces = blob_external_forces
        self.blob_blob_force = blob_blob_force
        self.body_body_force_torque = body_body_force_torque
        self.blob_blob_forces_python = None
        self.body_body_forces_python = None
        self.bodies_external_force_torque = bodies_external_force_torque
        self.set_slip_by_ID = set_slip_by_ID
        self.preprocess = preprocess
        self.postprocess = postprocess
        self.calc_blob_blob_forces_pycuda = None
        self.pycuda_file = None
        self.overridden = []
        self.sources = []
        self.notes = []
        self.user_functions = {}

    def is_default(self, name):
        return name not in self.overridden

    # -------------------------------------------------------------- installing user functions
    def install(self, found, path):
        """Install the user functions ``found`` (hook name -> function) read from ``path``."""
        physics = self.physics
        a = float(physics.get('blob_radius', 1.0))
        one_blob = [name for name in ONE_BLOB_NAMES if name in found]
        if one_blob:
            name = one_blob[0]
            function = found[name]
            for ignored in one_blob[1:]:
                self.notes.append('%s: %s is also replaced but not used: %s wins (the order is calc_one_blob_forces, '
                                  'blob_external_forces, blob_external_force)' % (path, ignored, name))
            samples = np.array([[0.1, -0.2, 1.7 * a], [0.4, 0.3, 2.6 * a], [-0.3, 0.5, 4.1 * a]])
            per_blob = name == 'blob_external_force' and not _vectorises(function, samples, physics)
            self.blob_external_forces = self._one_blob_adapter(function, name, per_blob)
            self._replaced(name, function, 'per blob, r (3,) -> (3,): a Python loop over blobs, slow' if per_blob
                           else 'vectorised, r_vectors (N, 3) -> (N, 3)')
        if 'blob_blob_force' in found:
            function = found['blob_blob_force']
            samples = 2.0 * a * np.array([[1.3, 0.2, -0.1], [-0.4, 1.6, 0.3], [0.9, -1.1, 1.7]])
            per_pair = not _vectorises(function, samples, physics)
            self.blob_blob_force = function
            self.blob_blob_forces_python = self._blob_pairs_adapter(function, per_pair)
            self._replaced('blob_blob_force', function, 'per pair, r (3,) -> (3,): a Python loop over blob pairs, '
                           'slow' if per_pair else 'vectorised over pairs, r (..., 3) -> (..., 3)')
        if 'body_body_force_torque' in found:
            function = found['body_body_force_torque']
            required, _ = positional_arity(function)
            per_pair = required is not None and required >= 3
            self.body_body_force_torque = function
            self.body_body_forces_python = self._body_pairs_adapter(function, per_pair)
            self._replaced('body_body_force_torque', function,
                           'per pair, (r, quaternion_i, quaternion_j) -> (2, 3): a Python loop over body pairs, slow'
                           if per_pair else 'vectorised over pairs, r (..., 3) -> (force, torque)')
        if 'bodies_external_force_torque' in found:
            function = found['bodies_external_force_torque']

            def bodies_external(bodies, r_vectors, **kw):
                nb = len(bodies)
                value = call_user_function(function, 'bodies_external_force_torque', bodies, r_vectors, **kw)
                return checked_array(value, [(2 * nb, 3), (nb, 6), (6 * nb,)], function,
                                     'bodies_external_force_torque', 'the force and torque of every body')
            self.bodies_external_force_torque = bodies_external
            self._replaced('bodies_external_force_torque', function, '(bodies, r_vectors) -> (2 Nb, 3)')
        if 'set_slip_by_ID' in found:
            function = found['set_slip_by_ID']
            one_argument = positional_capacity(function) == 1

            def set_slip(body, slip):
                if one_argument:
                    call_user_function(function, 'set_slip_by_ID', body)
                else:
                    call_user_function(function, 'set_slip_by_ID', body, slip)
            self.set_slip_by_ID = set_slip
            self._replaced('set_slip_by_ID', function, '(body)' if one_argument else '(body, slip)')
        for name in ('preprocess', 'postprocess'):
            if name in found:
                function = found[name]
                setattr(self, name, partial(call_user_function, function, name))
                self._replaced(name, function, '(bodies)')

    def _replaced(self, hook, function, convention):
        self.overridden.append(hook)
        self.user_functions[hook] = function
        self.notes.append('%s replaced by %s [%s]' % (hook, describe_user_function(function, hook), convention))

    @staticmethod
    def _one_blob_adapter(function, hook, per_blob):
        if per_blob:
            def one_blob_forces(r_vectors, **kw):
                r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
                forces = np.empty_like(r_vectors)
                for i, r in enumerate(r_vectors):
                    forces[i] = checked_array(call_user_function(function, hook, r.copy(), **kw), [(3,)], function,
                                              hook, 'the force on one blob')
                return forces
        else:
            def one_blob_forces(r_vectors, **kw):
                r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
                n = r_vectors.shape[0]
                return checked_array(call_user_function(function, hook, r_vectors, **kw), [(n, 3), (3 * n,)],
                                     function, hook, 'the force on every blob')
        return one_blob_forces

    @staticmethod
    def _blob_pairs_adapter(function, per_pair):
        hook = 'blob_blob_force'
        if not per_pair:
            def vectorised_pairs(r_vectors, periodic_length=(0.0, 0.0, 0.0), **kw):
                # As calc_blob_blob_forces, but the user's law never sees a blob paired with itself (r = 0).
                r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
                n = r_vectors.shape[0]
                forces = np.zeros_like(r_vectors)
                rows = max(1, PAIR_CHUNK_ELEMENTS // max(n, 1))
                for start in range(0, n, rows):
                    stop = min(n, start + rows)
                    others = np.ones((stop - start, n), dtype=bool)
                    others[np.arange(stop - start), np.arange(start, stop)] = False
                    r = minimum_image(r_vectors[None, :, :] - r_vectors[start:stop, None, :], periodic_length)[others]
                    pair = checked_array(call_user_function(function, hook, r, periodic_length=periodic_length, **kw),
                                         [r.shape], function, hook, 'the force on blob i of every pair')
                    # Each row has exactly n - 1 other blobs, in order: sum them per row.
                    forces[start:stop] = pair.reshape(stop - start, n - 1, 3).sum(axis=1)
                return forces
            return vectorised_pairs

        def blob_pairs(r_vectors, periodic_length=(0.0, 0.0, 0.0), **kw):
            r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
            n = r_vectors.shape[0]
            forces = np.zeros_like(r_vectors)
            for i in range(n - 1):
                separations = minimum_image(r_vectors[i + 1:] - r_vectors[i], periodic_length)
                for k, r in enumerate(separations):
                    force = checked_array(call_user_function(function, hook, r.copy(), periodic_length=periodic_length,
                                                             **kw), [(3,)], function, hook,
                                          'the force on blob i of one pair')
                    forces[i] += force
                    forces[i + 1 + k] -= force
            return forces
        return blob_pairs

    @staticmethod
    def _body_pairs_adapter(function, per_pair):
        hook = 'body_body_force_torque'
        if not per_pair:
            def law(r, **kw):
                value = call_user_function(function, hook, r, **kw)
                if isinstance(value, tuple) and len(value) == 2:
                    value = np.stack([np.asarray(v, dtype=float) for v in value])
                return checked_array(value, [(2,) + r.shape], function, hook,
                                     '(force on i, torque on i) of every pair')
            return lambda locations, orientations=None, **kw: calc_body_body_forces_torques(
                locations, pair_force_torque=law, **kw)

        def body_pairs(locations, orientations=None, periodic_length=(0.0, 0.0, 0.0), **kw):
            locations = np.asarray(locations, dtype=float).reshape(-1, 3)
            nb = locations.shape[0]
            if orientations is None:
                orientations = np.tile([1.0, 0.0, 0.0, 0.0], (nb, 1))
            quaternions = [Quaternion(q) for q in np.asarray(orientations, dtype=float).reshape(-1, 4)]
            result = np.zeros((nb, 2, 3))
            for i in range(nb - 1):
                separations = minimum_image(locations[i + 1:] - locations[i], periodic_length)
                for k, r in enumerate(separations):
                    j = i + 1 + k
                    value = call_user_function(function, hook, r.copy(), quaternions[i], quaternions[j],
                                               periodic_length=periodic_length, **kw)
                    if isinstance(value, tuple) and len(value) == 2:
                        value = np.stack([np.asarray(v, dtype=float) for v in value])
                    force_torque = checked_array(value, [(2, 3), (6,)], function, hook,
                                                 '(force on i, torque on i) of one pair')
                    result[i] += force_torque
                    result[j] -= force_torque
            return result.reshape(2 * nb, 3)
        return body_pairs


def _fresh_copy_of_this_module():
    """A new module object with this file's defaults, importable as ``multi_bodies_functions``.

    Published override files rebind its attributes; each run gets its own
    copy, so one run's overrides never leak into another run in the same
    process, and the user's functions that look names up through
    ``multi_bodies_functions.X`` at run time see their own replacements.
    """
    import importlib.util
    spec = importlib.util.spec_from_file_location('multi_bodies_functions', os.path.abspath(__file__))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _public_callables(module):
    return {name: value for name, value in vars(module).items() if not name.startswith('_') and callable(value)}


def import_user_file(path):
    """Import the user's override file; returns (hook name -> function, notes for the log).

    While the file runs, ``import multi_bodies_functions`` gives a fresh copy
    of this module (published style).  A hook counts as replaced when the file
    rebinds it on that copy, or on ``multi_bodies.multi_bodies_functions``
    (restored afterwards), or defines a function of that name that is not
    one of this module's (package style).  Rebinding a function that no run
    calls is reported in the notes.  A syntax error or an exception while
    importing is a UserInputError naming the file and line.
    """
    import importlib.util
    this = sys.modules[__name__]
    copy = _fresh_copy_of_this_module()
    before_copy, before_this = _public_callables(copy), _public_callables(this)
    saved = {name: sys.modules.get(name) for name in ('multi_bodies_functions', 'user_defined_functions')}
    module_name = os.path.splitext(os.path.basename(path))[0]
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules['multi_bodies_functions'] = copy
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except SyntaxError as err:
        raise UserInputError('%s, line %s: syntax error in the user-defined functions: %s (%s); fix the file or '
                             'remove it from the run directory' % (path, err.lineno, err.msg, (err.text or '').strip()))
    except Exception as err:
        frames = [f for f in traceback.extract_tb(err.__traceback__)
                  if os.path.abspath(f.filename) == os.path.abspath(path)]
        line = (', line %d' % frames[-1].lineno) if frames else ''
        raise UserInputError('%s%s: importing the user-defined functions raised %s: %s; fix the file or remove it '
                             'from the run directory' % (path, line, type(err).__name__, err))
    finally:
        for name, value in saved.items():
            if value is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = value
        rebound_here = {name: value for name, value in _public_callables(this).items()
                        if before_this.get(name) is not value}
        for name in rebound_here:  # keep the package module clean for other runs
            if name in before_this:
                setattr(this, name, before_this[name])
            else:
                delattr(this, name)
    rebound_copy = {name: value for name, value in _public_callables(copy).items()
                    if before_copy.get(name) is not value}
    defaults = set(map(id, before_copy.values())) | set(map(id, before_this.values()))
    found, notes = {}, []
    for name in HOOK_NAMES:
        candidates = []
        for where, table in (('multi_bodies_functions.%s = ...' % name, rebound_copy),
                             ('multi_bodies.multi_bodies_functions.%s = ...' % name, rebound_here)):
            if name in table:
                candidates.append((where, table[name]))
        defined = getattr(module, name, None)
        if callable(defined) and id(defined) not in defaults and not isinstance(defined, type):
            candidates.append(('def %s' % name, defined))
        if candidates:
            found[name] = candidates[0][1]
            others = [w for w, f in candidates[1:] if f is not candidates[0][1]]
            if others:
                notes.append('%s: %s is given twice (%s and %s); %s is used'
                             % (path, name, candidates[0][0], ', '.join(others), candidates[0][0]))
    for table in (rebound_copy, rebound_here):
        for name in sorted(set(table) - set(HOOK_NAMES)):
            if isinstance(table[name], type) or name in ('np', 'partial', 'Quaternion'):
                continue
            notes.append('%s: rebinds multi_bodies_functions.%s, which this package does not call, so it has no '
                         'effect; the hooks that can be replaced are %s' % (path, name, ', '.join(HOOK_NAMES)))
    return found, notes


def load_user_hooks(directory='.', load_pycuda=True, physics=None):
    """Physics hooks for a run in ``directory``, with the user's overrides (see doc/overrides.md).

    Parameters
    ----------
    directory : str
        The run directory; ``user_defined_functions.py`` there is imported
        (either style, :func:`import_user_file`).
    load_pycuda : bool
        Also read ``forces_pycuda_user_defined.py`` (when the run may use the
        pycuda blob-blob forces); it must define
        ``calc_blob_blob_forces_pycuda(r_vectors, **kw) -> (N, 3)``.
    physics : dict
        The run's hook keywords; the adapters are probed with them to tell a
        per-blob (per-pair) published function from a vectorised one.

    Conventions of the replaced functions (either is accepted where two are listed):
    ``blob_external_force(r (3,), **kw) -> (3,)`` (per blob, slow) or vectorised;
    ``blob_external_forces`` / ``calc_one_blob_forces(r_vectors (N,3), **kw) -> (N,3)``;
    ``blob_blob_force(r (3,) or (...,3), **kw)``, r from blob i to blob j, force on i;
    ``body_body_force_torque(r, quaternion_i, quaternion_j, **kw) -> (2,3)`` per pair, or
    ``body_body_force_torque(r (...,3), **kw) -> (force, torque)`` vectorised;
    ``bodies_external_force_torque(bodies, r_vectors, **kw) -> (2Nb, 3)``;
    ``set_slip_by_ID(body, slip)`` or ``set_slip_by_ID(body)``; ``preprocess(bodies)``;
    ``postprocess(bodies)``.
    """
    hooks = PhysicsHooks(physics)
    path = os.path.join(directory, USER_FILE)
    if os.path.isfile(path):
        found, notes = import_user_file(path)
        hooks.sources.append(path)
        hooks.install(found, path)
        hooks.notes.extend(notes)
        if not found:
            hooks.notes.append('%s defines no hook; the defaults are used (the hooks are %s)'
                               % (path, ', '.join(HOOK_NAMES)))
    path = os.path.join(directory, USER_PYCUDA_FILE)
    if os.path.isfile(path):
        hooks.sources.append(path)
        if load_pycuda:
            hooks.pycuda_file = path
        else:
            hooks.notes.append('%s is not used: blob_blob_force_implementation is not pycuda' % path)
    return hooks


def load_user_pycuda_forces(path):
    """``calc_blob_blob_forces_pycuda`` of a ``forces_pycuda_user_defined.py``, after checking that a GPU is usable.

    Raises UserInputError naming the file when no GPU can run it, when it
    does not import, or when it lacks the function.
    """
    try:
        from multi_bodies import forces_pycuda
        forces_pycuda.check_usable()
    except Exception as err:
        raise UserInputError('%s replaces the GPU blob-blob force kernel, but no GPU is usable here (%s: %s); run '
                             'on a machine with a CUDA GPU, or set blob_blob_force_implementation to python or '
                             'C++ (and move the file away)' % (path, type(err).__name__, err))
    import importlib.util
    spec = importlib.util.spec_from_file_location('forces_pycuda_user_defined', path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as err:
        raise UserInputError('%s: could not be imported (%s: %s); fix the file or remove it from the run directory'
                             % (path, type(err).__name__, err))
    function = getattr(module, 'calc_blob_blob_forces_pycuda', None)
    if not callable(function):
        raise UserInputError('%s must define calc_blob_blob_forces_pycuda(r_vectors, **kwargs) -> (N, 3)' % path)

    def gpu_forces(r_vectors, **kw):
        n = np.asarray(r_vectors).size // 3
        return checked_array(call_user_function(function, 'calc_blob_blob_forces_pycuda', r_vectors, **kw),
                             [(n, 3), (3 * n,)], function, 'calc_blob_blob_forces_pycuda', 'the force on every blob')
    return gpu_forces
