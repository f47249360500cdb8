"""Defaults only in the option table (issue 43): no source of the package writes an option's default again.

Every option is declared once, with its default, in ``multi_bodies.files.input_options.OPTION_TABLE``; code that
takes an option as a keyword reads the default from there (``DEFAULTS.solver_tolerance``).  The package's sources
are read with ``ast`` (the modules on the table's floor and above, the published faces included: below the table,
``mobility/`` and ``body/`` cannot import it) and these are refused:

* a keyword default that is a literal equal to the table's default of the option the parameter is named after
  (its name, or one of ``ALIASES``: ``tolerance`` is ``solver_tolerance``, ...);
* ``getattr(x, 'option', literal)`` with the option's default as the fallback, and any literal fallback of
  ``published_solves`` (the model always has it; a fallback once stood for the wrong behaviour);
* a module constant named ``*DEFAULT*`` whose literal value is an option's default, and a dict literal that maps
  option names to their defaults.

``periodic_length`` is exempt outside the model: a zero box is the geometry's "no periodic direction", the
value every kernel below the table takes too, not a choice of the input file's default.
"""
import ast
from pathlib import Path

from multi_bodies.files.input_options import DEFAULTS, OPTION_TABLE
from test_layout import floor, package_modules

TABLE_MODULE = 'multi_bodies.files.input_options'
# parameter names that stand for an option
ALIASES = {'tolerance': 'solver_tolerance', 'nonlinear_tolerance': 'nonlinear_solver_tolerance',
           'vector_product_name': 'mobility_vector_prod_implementation', 'blobs_name': 'mobility_blobs_implementation',
           'blob_blob_name': 'blob_blob_force_implementation',
           'body_body_name': 'body_body_force_torque_implementation', 'cutoff': 'Lub_Cut',
           'handover': 'lubrication_handover', 'move': 'mcmc_move', 'rfd_delta': 'rf_delta'}
EXEMPT_PARAMETERS = {'periodic_length'}  # outside the model (module note)
MODEL_MODULE = 'multi_bodies.solver.model'


def _literal(node):
    try:
        return True, ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return False, None


def _is_default(value, option):
    default = OPTION_TABLE[option].default
    if default is None or isinstance(value, bool) != isinstance(default, bool):
        return False
    if isinstance(default, (tuple, list)):
        return isinstance(value, (tuple, list)) and len(value) == len(default) and \
            all(_is_default_value(v, d) for v, d in zip(value, default))
    return _is_default_value(value, default)


def _is_default_value(value, default):
    if isinstance(value, (int, float)) and not isinstance(value, bool) and isinstance(default, (int, float)):
        return float(value) == float(default)
    return type(value) is type(default) and value == default


def written_defaults(source, module):
    """Lines of ``source`` (module ``module``) that write an option's default (see the module note)."""
    tree = ast.parse(source)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            arguments = node.args
            positional = arguments.posonlyargs + arguments.args
            pairs = list(zip(positional[len(positional) - len(arguments.defaults):], arguments.defaults))
            pairs += [(a, d) for a, d in zip(arguments.kwonlyargs, arguments.kw_defaults) if d is not None]
            for argument, default in pairs:
                option = argument.arg if argument.arg in OPTION_TABLE else ALIASES.get(argument.arg)
                if option is None or (argument.arg in EXEMPT_PARAMETERS and module != MODEL_MODULE):
                    continue
                ok, value = _literal(default)
                if ok and _is_default(value, option):
                    found.append('%s:%d %s(%s=%r): the default of %s' % (module, default.lineno, node.name,
                                                                        argument.arg, value, option))
        elif isinstance(node, ast.Call) and getattr(node.func, 'id', None) == 'getattr' and len(node.args) == 3:
            ok, name = _literal(node.args[1])
            fallback_ok, fallback = _literal(node.args[2])
            if not (ok and fallback_ok and isinstance(name, str)):
                continue
            if name == 'published_solves' or (name in OPTION_TABLE and _is_default(fallback, name)):
                found.append('%s:%d getattr(..., %r, %r)' % (module, node.lineno, name, fallback))
        elif isinstance(node, ast.Dict):
            keys = [(_literal(k), v) for k, v in zip(node.keys, node.values) if k is not None]
            options = [(k, v) for (ok, k), v in keys if ok and isinstance(k, str) and k in OPTION_TABLE]
            if len(options) >= 2 and all(_literal(v)[0] and _is_default(_literal(v)[1], k) for k, v in options):
                found.append('%s:%d a dict of the defaults of %s'
                             % (module, node.lineno, ', '.join(k for k, _ in options)))
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name) \
                and 'DEFAULT' in node.targets[0].id:
            ok, value = _literal(node.value)
            if ok and any(_is_default(value, option) for option in OPTION_TABLE):
                found.append('%s:%d %s = %r' % (module, node.lineno, node.targets[0].id, value))
    return found


def test_no_option_default_is_written_outside_the_table():
    found = []
    for module, path in sorted(package_modules().items()):
        if module == TABLE_MODULE or floor(module) < floor(TABLE_MODULE):
            continue
        found += written_defaults(Path(path).read_text(), module)
    assert not found, 'option defaults written outside OPTION_TABLE (read them from DEFAULTS):\n' + '\n'.join(found)


def test_the_check_catches_each_kind_of_written_default():
    """Negative control: a planted source with each kind of written default is caught, and the same source reading
    the table passes."""
    planted = ("DEFAULT_CUTOFF = 4.5\n"
               "OPTIONS = {'Lub_Cut': 4.5, 'firm_delta': 1e-4}\n"
               "def solve(problem, tolerance=1e-8, kT=1, handover='published', periodic_length=(0.0, 0.0, 0.0)):\n"
               "    return getattr(problem, 'published_solves', True), getattr(problem, 'preconditioner', 'auto')\n")
    found = written_defaults(planted, 'multi_bodies.solver.planted')
    assert len(found) == 7, found  # periodic_length exempt outside the model
    assert len(written_defaults(planted, MODEL_MODULE)) == 8
    reading = ("from multi_bodies.files.input_options import DEFAULTS\n"
               "DEFAULT_CUTOFF = DEFAULTS.Lub_Cut\n"
               "def solve(problem, tolerance=DEFAULTS.solver_tolerance, kT=DEFAULTS.kT, handover=None):\n"
               "    return problem.published_solves, getattr(problem, 'preconditioner', None)\n")
    assert written_defaults(reading, 'multi_bodies.solver.planted') == []


def test_the_aliases_and_the_defaults_are_the_table_s():
    assert set(ALIASES.values()) <= set(OPTION_TABLE)
    for name, option in OPTION_TABLE.items():
        assert getattr(DEFAULTS, name) == option.default or (getattr(DEFAULTS, name) is None and option.default is None)
