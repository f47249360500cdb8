"""Reading the user's Python files: the override file, the published module's copy and a folder's modules as
the published scripts import them, with one-line errors naming the file and line (floor 4).

:mod:`multi_bodies.solver.user_hooks` adapts the functions read here to the package's hooks and re-exports
these names.
"""
import os
import sys
import traceback

import utils
from multi_bodies.solver import physics as mbf
from utils import UserInputError


def import_module_file(path, module_name):
    """Import the Python file ``path`` as a module; a UserInputError naming the file when it fails."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as err:
        raise UserInputError('%s: could not be imported (%s: %s); fix the file or remove it from the run directory'
                             % (path, type(err).__name__, err))
    return module


# The published override module, a file beside this package's folder (read as a file, never imported here).
PUBLISHED_MODULE_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                     'multi_bodies_functions.py')
PACKAGE_MODULE_NAME = 'multi_bodies.multi_bodies_functions'
# Published hooks with no default here: ``calc_body_body_forces_torques_python(bodies, r_vectors, **kw) ->
# (2 Nb, 3)``, the python body-body force-torque of later published versions (the bacteria example), used with
# ``body_body_force_torque_implementation python``.
PUBLISHED_EXTRA_HOOKS = ('calc_body_body_forces_torques_python',)


def _fresh_copy_of_this_module():
    """A new module object with this file's defaults, importable as ``multi_bodies_functions``.

    Published override files rebind its attributes; each run gets its own
    copy, so one run's overrides never leak into another run in the same
    process, and the user's functions that look names up through
    ``multi_bodies_functions.X`` at run time see their own replacements.
    """
    import importlib.util
    spec = importlib.util.spec_from_file_location('multi_bodies_functions', PUBLISHED_MODULE_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _public_callables(module):
    return {name: value for name, value in vars(module).items() if not name.startswith('_') and callable(value)}


# Top-level modules and folders of the published code's tree: an import of one of them that fails is a published
# module path, not a missing package (pip would install unrelated software of the same name).
PUBLISHED_TREE_MODULES = ('mobility', 'articulated', 'constraint', 'general_application_utils', 'read_input', 'body',
                          'quaternion_integrator', 'multi_bodies', 'multi_bodies_functions', 'stochastic_forcing',
                          'utils', 'Lubrication', 'many_bodyMCMC', 'boomerang', 'sphere', 'forces_numba',
                          'forces_pycuda', 'forces_cpp', 'HydroGrid', 'calculateConcentration', 'visit',
                          'plot_velocity_field', 'multi_bodies_utilities', 'periodic_mobility', 'stkfmm')
# The published faces of the joints (constraint/, articulated/ at the repository root) and where they live.
JOINT_FACE_MODULES = ('constraint', 'constraint.constraint', 'articulated', 'articulated.articulated')
FACE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# The published module paths this package provides for override files and drivers (tests/test_layout.py).
PUBLISHED_FACES = ('mobility.mobility', 'general_application_utils', 'read_input', 'quaternion_integrator.quaternion',
                   'multi_bodies_functions', 'articulated.articulated', 'constraint.constraint')


def import_failure(path, err, file_words='the user file', content_words='the user-defined functions'):
    """The UserInputError (one line naming the file and line) for ``err`` raised while importing the Python file
    ``path``: a syntax error, an import of a published module this package has no face for, a package that is not
    installed, any other exception.  ``file_words``, ``content_words``: what the file is called in the message."""
    if isinstance(err, SyntaxError):
        return UserInputError('%s, line %s: syntax error in %s: %s (%s); fix the file or remove it from the run '
                              'directory' % (path, err.lineno, content_words, err.msg, (err.text or '').strip()))
    frames = [f for f in traceback.extract_tb(err.__traceback__)
              if os.path.abspath(f.filename) == os.path.abspath(path)]
    line = (', line %d' % frames[-1].lineno) if frames else ''
    if isinstance(err, ImportError) and getattr(err, 'name', None):
        missing = err.name.split('.')[0]
        if missing in PUBLISHED_TREE_MODULES:
            return UserInputError('%s%s: %s imports %s, a module of the published code\'s own tree (not a package '
                                  'to install); this package offers the published faces %s and not this one '
                                  '(doc/overrides.md); remove the import or use the package\'s equivalent'
                                  % (path, line, file_words, err.name, ', '.join(PUBLISHED_FACES)))
        return UserInputError('%s%s: %s imports %s, which is not installed; pip install %s or remove the import'
                              % (path, line, file_words, missing, missing))
    return UserInputError('%s%s: importing %s raised %s: %s; fix the file or remove it from the run directory'
                          % (path, line, content_words, type(err).__name__, err))


def restore_modules(saved, added_root):
    """Undo what reading a user's file changed: ``FACE_ROOT`` off ``sys.path`` when the reading added it
    (``added_root``), and each entry of ``saved`` (module name -> the module before, or None) back in
    ``sys.modules`` (None: removed)."""
    if added_root:
        sys.path.remove(FACE_ROOT)
    for name, value in saved.items():
        if value is None:
            sys.modules.pop(name, None)
        else:
            sys.modules[name] = value


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
    copy = _fresh_copy_of_this_module()
    # The package-style module ``multi_bodies.multi_bodies_functions`` has the same defaults as the copy; it is
    # checked for rebindings only when it was imported (by the user's file or before).
    before_copy = _public_callables(copy)
    this_before = sys.modules.get(PACKAGE_MODULE_NAME)
    before_this = _public_callables(this_before) if this_before is not None else dict(before_copy)
    # the published faces of the joints are imported afresh for each file, so one run's patches of their classes
    # never reach another run in the same process
    saved = {name: sys.modules.get(name) for name in ('multi_bodies_functions', 'user_defined_functions')
             + JOINT_FACE_MODULES}
    for name in JOINT_FACE_MODULES:
        sys.modules.pop(name, None)
    added_root = FACE_ROOT not in sys.path and importlib.util.find_spec('constraint') is None
    if added_root:  # an editable install made before the faces existed does not map them
        sys.path.append(FACE_ROOT)
    module_name = os.path.splitext(os.path.basename(path))[0]
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules['multi_bodies_functions'] = copy
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as err:
        raise import_failure(path, err)
    finally:
        published_constraint = getattr(sys.modules.get('constraint.constraint'), 'Constraint', None)
        published_articulated = getattr(sys.modules.get('articulated.articulated'), 'Articulated', None)
        restore_modules(saved, added_root)
        this = sys.modules.get(PACKAGE_MODULE_NAME)
        rebound_here = {} if this is None else {name: value for name, value in _public_callables(this).items()
                                                if before_this.get(name) is not value}
        for name in rebound_here:  # keep the package module clean for other runs
            if name in before_this:
                setattr(this, name, before_this[name])
            else:
                delattr(this, name)
    rebound_copy = {name: value for name, value in _public_callables(copy).items()
                    if before_copy.get(name) is not value}
    defaults = set(map(id, before_copy.values())) | set(map(id, before_this.values())) | \
        set(map(id, _public_callables(mbf).values()))
    found, notes = {}, []
    if published_constraint is not None and any(getattr(value, '__module__', 'constraint.constraint') !=
                                                 'constraint.constraint' for value in vars(published_constraint).values()
                                                 if callable(value)):
        found['published Constraint'] = published_constraint  # patched by the file: the joints use it
    if published_articulated is not None and getattr(published_articulated.update_links, '__module__',
                                                     'articulated.articulated') != 'articulated.articulated':
        # its update_links restores the joints; the joint objects it reads are of the (maybe unpatched) class
        found['published Articulated'] = (published_articulated, published_constraint)
    for name in mbf.HOOK_NAMES + PUBLISHED_EXTRA_HOOKS:
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
        for name in sorted(set(table) - set(mbf.HOOK_NAMES + PUBLISHED_EXTRA_HOOKS)):
            if isinstance(table[name], type) or name in ('np', 'partial', 'Quaternion'):
                continue
            notes.append('%s: rebinds multi_bodies_functions.%s, which this package does not call, so it has no '
                         'effect; the hooks that can be replaced are %s' % (path, name, ', '.join(mbf.HOOK_NAMES)))
    return found, notes


def override_file(directory, name):
    """The path of the override source ``name`` in ``directory`` when it is a file, None when nothing is there.

    Raises UserInputError when something else is there (a folder, a FIFO, a dangling link): the run would
    otherwise use the default physics without a word."""
    path = os.path.join(directory, name)
    kind = utils.special_file_kind(path)
    if kind is not None:
        raise UserInputError('%s is %s, not a Python file, so its overrides cannot be read; make it the file you '
                             'meant, or remove it to run with the default physics' % (path, kind))
    return path if os.path.isfile(path) else None


FOLDER_MODULE_COPY = 'multi_bodies_functions.py'
