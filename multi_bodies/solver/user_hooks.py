"""Loading the user's override files and adapting their functions to the package's hooks (floor 4).

:mod:`multi_bodies.solver.physics` holds the default physics; this module reads
``user_defined_functions.py`` (this package's style or the published one,
see doc/overrides.md) and ``forces_pycuda_user_defined.py``, and builds a
:class:`PhysicsHooks` whose functions all follow the package's vectorised
conventions, whatever the signature of the user's function, with checks of
the shapes and finiteness of what they return.  The published override
module ``multi_bodies/multi_bodies_functions.py`` (on the scripts' floor)
re-exports the physics and these names; this module never imports it: it
copies that file for each user file and looks the package-style module up
in ``sys.modules`` only when the user's file imported it.
"""
import inspect
import os
import sys
import traceback
from collections import namedtuple
from functools import partial

import numpy as np

from mobility.periodic import minimum_image
from multi_bodies.solver import physics as mbf
from body.geometry import Quaternion
import utils
from utils import SimulationStopped, UserInputError
from multi_bodies.solver.user_files import (  # noqa: F401 (re-exported: the reading of user files lives there)
    FACE_ROOT, FOLDER_MODULE_COPY, JOINT_FACE_MODULES, PACKAGE_MODULE_NAME, PUBLISHED_EXTRA_HOOKS, PUBLISHED_FACES,
    PUBLISHED_MODULE_FILE, PUBLISHED_TREE_MODULES, _fresh_copy_of_this_module, _public_callables, import_failure,
    import_module_file, import_user_file, override_file, restore_modules)


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
        self.blob_external_forces = mbf.blob_external_forces
        self.blob_blob_force = mbf.blob_blob_force
        self.body_body_force_torque = mbf.body_body_force_torque
        self.blob_blob_forces_python = None
        self.body_body_forces_python = None
        self.bodies_external_force_torque = mbf.bodies_external_force_torque
        self.set_slip_by_ID = mbf.set_slip_by_ID
        self.preprocess = mbf.preprocess
        self.postprocess = mbf.postprocess
        self.calc_blob_blob_forces_pycuda = None
        self.body_body_of_bodies = None  # published calc_body_body_forces_torques_python (bodies, r_vectors)
        self.published_constraint_class = None  # the user's patched constraint.constraint.Constraint, or None
        self.published_articulated_class = None  # the user's articulated.articulated.Articulated, update_links patched
        self.published_joint_class = None  # with it: the constraint.constraint.Constraint class of the same import
        self.pycuda_file = None
        # A folder's own multi_bodies_functions.py (read_folder_module): its force_torque_calculator_sort_by_bodies
        # as (bodies, r_vectors (N, 3)) -> (2 Nb, 3), which replaces the whole force-torque assembly, and its path.
        self.force_torque_calculator = None
        self.folder_module = None
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
        one_blob = [name for name in mbf.ONE_BLOB_NAMES if name in found]
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

            def bodies_external(bodies, r_vectors, function=function, **kw):  # bound now: `function` is reused
                nb = len(bodies)
                value = call_user_function(function, 'bodies_external_force_torque', bodies, r_vectors, **kw)
                return checked_array(value, [(2 * nb, 3), (nb, 6), (6 * nb,)], function,
                                     'bodies_external_force_torque', 'the force and torque of every body')
            self.bodies_external_force_torque = bodies_external
            self._replaced('bodies_external_force_torque', function, '(bodies, r_vectors) -> (2 Nb, 3)')
        if 'set_slip_by_ID' in found:
            function = found['set_slip_by_ID']
            one_argument = positional_capacity(function) == 1

            def set_slip(body, slip, function=function, one_argument=one_argument):
                if one_argument:
                    call_user_function(function, 'set_slip_by_ID', body)
                else:
                    call_user_function(function, 'set_slip_by_ID', body, slip)
            self.set_slip_by_ID = set_slip
            self._replaced('set_slip_by_ID', function, '(body)' if one_argument else '(body, slip)')
        if 'calc_body_body_forces_torques_python' in found:
            function = found['calc_body_body_forces_torques_python']

            def body_body_of_bodies(bodies, r_vectors, function=function, **kw):
                nb = len(bodies)
                value = call_user_function(function, 'calc_body_body_forces_torques_python', bodies, r_vectors, **kw)
                return checked_array(value, [(2 * nb, 3), (nb, 6), (6 * nb,)], function,
                                     'calc_body_body_forces_torques_python', 'the force and torque of every body')
            self.body_body_of_bodies = body_body_of_bodies
            self._replaced('calc_body_body_forces_torques_python', function,
                           '(bodies, r_vectors) -> (2 Nb, 3), with body_body_force_torque_implementation python')
        if 'published Articulated' in found:
            self.published_articulated_class, self.published_joint_class = found['published Articulated']
            self.notes.append('%s patches the published Articulated.update_links: the joints are restored after every '
                              'move with the links it gives, as published (the velocity solve takes them from '
                              'Constraint.update_links)' % path)
        if 'published Constraint' in found:
            self.published_constraint_class = found['published Constraint']
            self.notes.append('%s patches the published Constraint class (%s): the joints take their links from '
                              'its update_links%s' % (path, ', '.join(sorted(
                                  name for name, value in vars(self.published_constraint_class).items()
                                  if callable(value) and getattr(value, '__module__', '') != 'constraint.constraint')),
                                  ' and every step calls its tumbling_event(t)' if hasattr(
                                      self.published_constraint_class, 'tumbling_event') else ''))
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
                rows = max(1, mbf.PAIR_CHUNK_ELEMENTS // max(n, 1))
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
            cutoff = getattr(function, 'cutoff', None)   # the law vanishes beyond it: the near pairs only
            if cutoff is not None and not callable(cutoff):
                mbf.cutoff_length(cutoff, {}, hook)       # refused at set-up
            return lambda locations, orientations=None, **kw: mbf.calc_body_body_forces_torques(
                locations, pair_force_torque=law, cutoff=mbf.cutoff_length(cutoff, kw, hook), **kw)

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



def folder_module_path(directory):
    """The path of a run directory's own ``multi_bodies_functions.py`` (not this package's), or None.

    Raises UserInputError when something other than a file has that name (a folder, a FIFO, a dangling link)."""
    path = override_file(directory, FOLDER_MODULE_COPY)
    if path is None or os.path.samefile(path, PUBLISHED_MODULE_FILE):
        return None
    return path


def check_folder_module_copy(directory):
    """Refuse a run directory that holds its own ``multi_bodies_functions.py`` (not this package's) where it is not
    read: anywhere but a dynamic run of rigid bodies whose input is in the published spectral form
    (:func:`read_folder_module`).

    Several published example folders ship a modified copy of the published ``multi_bodies_functions.py`` (and of
    ``multi_bodies.py``, which imports it instead of the defaults and may hard-code keywords, e.g. the ``f = 9.0``
    of ``Spectral_Multiblob_Roller``).  Ignoring such a copy would run other physics than the folder's: the run
    stops instead, naming the file, the hooks it defines and what to do.  Raises UserInputError.
    """
    path = folder_module_path(directory)
    if path is None:
        return
    import ast
    try:
        with open(path, encoding='utf-8', errors='replace') as f:
            tree = ast.parse(f.read())
        defined = [node.name for node in tree.body if isinstance(node, ast.FunctionDef)
                   and node.name in mbf.HOOK_NAMES + PUBLISHED_EXTRA_HOOKS]
    except (SyntaxError, ValueError, OSError):
        defined = []
    raise UserInputError(
        '%s: this folder has its own copy of the published multi_bodies_functions.py (the folder\'s copy of the '
        'published multi_bodies.py reads it in place of the defaults); this package reads such a copy only in a '
        'dynamic run of rigid bodies whose input is in the published spectral form (doc/periodic.md), which this is '
        'not; copy the functions you need%s into user_defined_functions.py (published style: '
        'multi_bodies_functions.<name> = <function>; a keyword that the folder\'s multi_bodies.py sets and the input '
        'file does not must get its value in the function), then rename or remove %s (doc/overrides.md)'
        % (path, ' (it defines %s)' % ', '.join(defined) if defined else '', FOLDER_MODULE_COPY))


FolderModuleCall = namedtuple('FolderModuleCall', ['keywords', 'blob_blob_implementation',
                                                   'body_body_implementation'])
FolderModuleCall.__doc__ = """How a folder's own script calls its ``multi_bodies_functions.py``: the ``keywords`` of its
``force_torque_calculator_sort_by_bodies`` (name -> value) and the input's ``blob_blob_force_implementation`` and
``body_body_force_torque_implementation``, which it passes to the module's ``set_blob_blob_forces`` and
``set_body_body_forces_torques``."""

# The functions of a folder module that its script calls (multi_bodies.solver.published_spectral).
FOLDER_MODULE_FUNCTIONS = ('force_torque_calculator_sort_by_bodies', 'set_blob_blob_forces',
                           'set_body_body_forces_torques')


def _imp_for_old_modules():
    """A stand-in for the ``imp`` module (removed in Python 3.12) with the one function published modules use,
    ``find_module(name)``: raises ImportError when ``name`` cannot be imported.  None where ``imp`` exists."""
    import importlib.util
    if importlib.util.find_spec('imp') is not None:
        return None
    import types
    stand_in = types.ModuleType('imp')

    def find_module(name, path=None):
        if importlib.util.find_spec(name) is None:
            raise ImportError('No module named %r' % name, name=name)
        return None, name, ('', '', 5)
    stand_in.find_module = find_module
    return stand_in


def import_folder_module(path):
    """Import a folder's ``multi_bodies_functions.py`` at ``path`` as the folder's own script imports it.

    Returns ``(module, user module or None)``: while the file runs it is the module ``multi_bodies_functions``, its
    folder is the first entry of the import path and the working directory, and the published faces are
    importable, so its ``import general_application_utils``, ``from quaternion_integrator.quaternion import
    Quaternion`` and its closing ``import user_defined_functions`` (which rebinds ``multi_bodies_functions.<name>``
    on this module, published style) work as in the published tree; the user module is the
    ``user_defined_functions`` it imported, if any.  ``imp`` (Python 3.12 has none) is given a stand-in.
    Everything is restored afterwards.  Any error is a UserInputError naming the file and line."""
    import importlib.util
    import warnings
    directory = os.path.dirname(os.path.abspath(path))
    names = ('multi_bodies_functions', 'user_defined_functions', 'imp')
    saved = {name: sys.modules.get(name) for name in names}
    spec = importlib.util.spec_from_file_location('multi_bodies_functions', path)
    module = importlib.util.module_from_spec(spec)
    sys.modules['multi_bodies_functions'] = module
    sys.modules.pop('user_defined_functions', None)
    stand_in = _imp_for_old_modules()
    if stand_in is not None:
        sys.modules['imp'] = stand_in
    added_root = FACE_ROOT not in sys.path and importlib.util.find_spec('general_application_utils') is None
    if added_root:
        sys.path.append(FACE_ROOT)
    sys.path.insert(0, directory)
    cwd = os.getcwd()
    user_module = None
    try:
        os.chdir(directory)  # the module looks for user_defined_functions.py in the working directory
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', DeprecationWarning)  # its import of imp, on Python 3.11
            spec.loader.exec_module(module)
        user_module = sys.modules.get('user_defined_functions')
    except Exception as err:
        raise import_failure(path, err, file_words='the folder\'s multi_bodies_functions.py',
                             content_words='the folder\'s multi_bodies_functions.py')
    finally:
        os.chdir(cwd)
        sys.path.remove(directory)
        restore_modules(saved, added_root)
    return module, user_module


def read_folder_module(path, call, hooks):
    """Read a folder's own ``multi_bodies_functions.py`` into ``hooks`` as the folder's published script does.

    ``call``: :class:`FolderModuleCall`.  As that script: ``calc_blob_blob_forces`` and
    ``calc_body_body_forces_torques`` of the module are set by its ``set_blob_blob_forces`` and
    ``set_body_body_forces_torques`` from the input's implementations, and its
    ``force_torque_calculator_sort_by_bodies(bodies, r_vectors, **call.keywords)`` gives the force and torque of
    every body (``hooks.force_torque_calculator``, checked: shape (2 Nb, 3), finite), in place of this package's
    assembly of blob, body and pair forces; its ``preprocess`` and ``postprocess`` are the run's.  A
    ``user_defined_functions.py`` beside it is imported by the module itself, as published (only its
    ``multi_bodies_functions.<name> = ...`` rebindings act on the module); one that defines hooks of its own, which
    the published script would not call, is refused.  Raises UserInputError naming the file."""
    module, user_module = import_folder_module(path)
    missing = [name for name in FOLDER_MODULE_FUNCTIONS if not callable(getattr(module, name, None))]
    if missing:
        raise UserInputError('%s: the folder\'s multi_bodies_functions.py has no %s, which the folder\'s published '
                             'multi_bodies.py calls; restore the function, or move the functions you need into '
                             'user_defined_functions.py and remove %s (doc/overrides.md)'
                             % (path, ', '.join(missing), FOLDER_MODULE_COPY))
    if user_module is not None:
        unused = [name for name in mbf.HOOK_NAMES + PUBLISHED_EXTRA_HOOKS + FOLDER_MODULE_FUNCTIONS
                  if callable(getattr(user_module, name, None)) and getattr(module, name, None)
                  is not getattr(user_module, name)]
        if unused:
            raise UserInputError(
                '%s defines %s, but beside the folder\'s own %s (which imports it, as the folder\'s published '
                'multi_bodies.py does) only rebinding on that module acts (multi_bodies_functions.<name> = '
                '<function>): rebind them, or move the file away' % (getattr(user_module, '__file__', mbf.USER_FILE),
                                                                      ', '.join(unused), path))
    for setter, target, implementation in (
            ('set_blob_blob_forces', 'calc_blob_blob_forces', call.blob_blob_implementation),
            ('set_body_body_forces_torques', 'calc_body_body_forces_torques', call.body_body_implementation)):
        try:
            setattr(module, target, call_user_function(getattr(module, setter), setter, implementation))
        except UserFunctionError as err:
            raise UserInputError(str(err))
    calculator = module.force_torque_calculator_sort_by_bodies
    keywords = dict(call.keywords)

    def force_torque_calculator(bodies, r_vectors):
        nb = len(bodies)
        value = call_user_function(calculator, 'force_torque_calculator_sort_by_bodies', bodies,
                                   np.asarray(r_vectors, dtype=float).reshape(-1, 3), **keywords)
        return checked_array(value, [(2 * nb, 3), (nb, 6), (6 * nb,)], calculator,
                             'force_torque_calculator_sort_by_bodies', 'the force and torque of every body')
    hooks.force_torque_calculator = force_torque_calculator
    hooks.folder_module = path
    hooks.sources.append(path)
    hooks.notes.append('%s: the folder\'s own module, read as its published multi_bodies.py reads it (doc/periodic.md): '
                       'force_torque_calculator_sort_by_bodies gives every body\'s force and torque (this package adds '
                       'no force of its own), with the keywords %s; calc_blob_blob_forces = set_blob_blob_forces(%r), '
                       'calc_body_body_forces_torques = set_body_body_forces_torques(%r)'
                       % (path, ', '.join('%s=%s' % (name, _keyword_text(value)) for name, value in keywords.items()),
                          call.blob_blob_implementation, call.body_body_implementation))
    found = {name: getattr(module, name) for name in ('preprocess', 'postprocess')
             if callable(getattr(module, name, None))}
    hooks.install(found, path)
    if user_module is not None:
        hooks.notes.append('%s imported %s itself, as published' % (path, getattr(user_module, '__file__', '')))


def _keyword_text(value):
    """A keyword's value for the log (arrays as their numbers)."""
    if isinstance(value, np.ndarray):
        return ' '.join('%g' % v for v in value.ravel())
    return '%g' % value if isinstance(value, float) else str(value)


def load_user_hooks(directory='.', load_pycuda=True, physics=None, folder_module=None):
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
    folder_module : FolderModuleCall or None
        Given (an input in the published spectral form, dynamics of rigid bodies), a ``multi_bodies_functions.py``
        of the run directory is read as its folder's published script reads it (:func:`read_folder_module`) and
        gives the forces; otherwise such a file is refused (:func:`check_folder_module_copy`).

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
    if folder_module is not None:
        path = folder_module_path(directory)
        if path is not None:  # the folder's own module gives the forces; it imports user_defined_functions.py itself
            hooks = PhysicsHooks(physics)
            read_folder_module(path, folder_module, hooks)
            pycuda_path = override_file(directory, mbf.USER_PYCUDA_FILE)
            if pycuda_path is not None:
                hooks.notes.append('%s is not used: the folder\'s module gives the forces' % pycuda_path)
            return hooks
    check_folder_module_copy(directory)
    hooks = PhysicsHooks(physics)
    path = override_file(directory, mbf.USER_FILE)
    if path is not None:
        found, notes = import_user_file(path)
        hooks.sources.append(path)
        hooks.install(found, path)
        hooks.notes.extend(notes)
        if not found:
            hooks.notes.append('%s defines no hook; the defaults are used (the hooks are %s)'
                               % (path, ', '.join(mbf.HOOK_NAMES)))
    path = override_file(directory, mbf.USER_PYCUDA_FILE)
    if path is not None:
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
        from multi_bodies.solver import forces_pycuda
        forces_pycuda.check_usable()
    except Exception as err:
        raise UserInputError('%s replaces the GPU blob-blob force kernel, but no GPU is usable here (%s: %s); run '
                             'on a machine with a CUDA GPU, or set blob_blob_force_implementation to python or '
                             'C++ (and move the file away)' % (path, type(err).__name__, err))
    module = import_module_file(path, 'forces_pycuda_user_defined')
    function = getattr(module, 'calc_blob_blob_forces_pycuda', None)
    if not callable(function):
        raise UserInputError('%s must define calc_blob_blob_forces_pycuda(r_vectors, **kwargs) -> (N, 3)' % path)

    def gpu_forces(r_vectors, **kw):
        n = np.asarray(r_vectors).size // 3
        return checked_array(call_user_function(function, 'calc_blob_blob_forces_pycuda', r_vectors, **kw),
                             [(n, 3), (3 * n,)], function, 'calc_blob_blob_forces_pycuda', 'the force on every blob')
    return gpu_forces
