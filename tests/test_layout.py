"""The house plan, measured from the imports between files (ARCHITECTURE: floors, no loops).

Every ``import`` and ``from ... import`` of the package's Python files is
read with ``ast`` (also those inside functions, which run later but still tie
the files together), resolved to a file of the repository, and checked:

* no import loop between files (strongly connected components of size 1);
* no import from a higher floor (floors below, lowest first);
* ``stochastic_forcing`` imports nothing of the package but ``utils``;
* ``multi_bodies/`` top level holds only the scripts, ``__init__`` and the
  published override module; the library sits in subpackages.

The floors are a law of the design, not of the code under test: a new
import that runs back up fails here.
"""
import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ('body', 'mobility', 'multi_bodies', 'quaternion_integrator', 'stochastic_forcing', 'many_bodyMCMC',
            'boomerang', 'sphere', 'lubrication', 'read_input')

# The scripts (floor 9) and the published override module (floor 8, re-exports the physics for user files).
SCRIPTS = {'multi_bodies.multi_bodies', 'multi_bodies.multi_bodies_utilities', 'multi_bodies.advise',
           'multi_bodies.clones_to_vtk', 'multi_bodies.ensemble', 'multi_bodies.render',
           'many_bodyMCMC.many_body_MCMC', 'boomerang.boomerang', 'boomerang.calculate_boomerang_msd_from_trajectories',
           'boomerang.plot_boomerang_msd', 'boomerang.plot_boomerang_trajectory', 'sphere.sphere_rotational_msd',
           'sphere.make_mobility_table', 'multi_bodies.analyse'}
# The published import paths that users' files and drivers import: thin faces over the package, on the top
# floor of their room (floor 8), never imported by the package itself.
PUBLISHED_FACES = {'quaternion_integrator.quaternion', 'mobility.mobility', 'general_application_utils',
                   'read_input', 'read_input.read_input', 'read_input.read_vertex_file', 'read_input.read_clones_file',
                   'read_input.read_slip_file', 'Lub_Solver', 'constraint', 'constraint.constraint', 'articulated',
                   'articulated.articulated',
                   # scikit-sparse's import name, for the published lubrication drivers' unused cholmod import
                   'sksparse', 'sksparse.cholmod',
                   # libMobility's classes (SelfMobility, NBody, DPStokes) over the mobility interface: a face too
                   'mobility.libmobility'}
TOP_LEVEL_ALLOWED = {'__init__', 'multi_bodies_functions'} | {s.split('.', 1)[1] for s in SCRIPTS
                                                               if s.startswith('multi_bodies.')}


def floor(module):
    """Floor of a dotted module name (lower floors are imported by higher ones, never the reverse)."""
    if module in SCRIPTS:
        return 9
    if module == 'multi_bodies.multi_bodies_functions' or module in PUBLISHED_FACES:
        return 8
    if re.fullmatch(r'mobility\.\w+_mobility', module):  # a backend's adapter beside the interface
        return 2                                           # (doc/adding_a_backend.md)
    rules = [('utils', 1), ('body.geometry', 1), ('mobility.interface', 2), ('mobility.choose', 2),
             ('mobility.spectral_mobility', 2), ('mobility', 1),
             ('body', 2), ('stochastic_forcing', 2),
             ('multi_bodies.files', 3), ('multi_bodies.solver', 4), ('lubrication', 4),
             ('quaternion_integrator', 5), ('sphere', 5),
             ('multi_bodies.run', 6), ('multi_bodies.analysis', 6), ('many_bodyMCMC', 6), ('boomerang', 6),
             ('multi_bodies.advice', 7), ('multi_bodies.ensembles', 7), ('multi_bodies', 7)]
    for prefix, level in rules:
        if module == prefix or module.startswith(prefix + '.'):
            return level
    raise AssertionError('no floor for %s: add it to the plan' % module)


def package_modules():
    """Dotted name -> path of every Python file of the package (tests, benchmarks and doc charts excluded)."""
    modules = {'utils': REPO / 'utils.py', 'general_application_utils': REPO / 'general_application_utils.py',
               'Lub_Solver': REPO / 'Lub_Solver.py'}
    for package in PACKAGES:
        for path in (REPO / package).rglob('*.py'):
            if 'examples' in path.parts or 'Structures' in path.parts:
                continue
            parts = list(path.relative_to(REPO).with_suffix('').parts)
            if parts[-1] == '__init__':
                parts = parts[:-1]
            modules['.'.join(parts)] = path
    return modules


def imports_of(path, name, modules):
    """The package modules that file ``path`` (module ``name``) imports."""
    tree = ast.parse(path.read_text(), str(path))
    is_package = path.name == '__init__.py'
    found = set()

    def resolve(dotted):
        while dotted:
            if dotted in modules:
                return dotted
            dotted = dotted.rpartition('.')[0]
        return None

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = resolve(alias.name)
                if target:
                    found.add(target)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split('.') if is_package else name.split('.')[:-1]
                base = base[:len(base) - (node.level - 1)]
                prefix = '.'.join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module
            for alias in node.names:
                target = resolve(prefix + '.' + alias.name) or resolve(prefix)
                if target:
                    found.add(target)
    found.discard(name)
    return found


@pytest.fixture(scope='module')
def graph():
    modules = package_modules()
    return {name: imports_of(path, name, modules) for name, path in modules.items()}


def strongly_connected(graph):
    """Tarjan's components of the import graph (lists of module names)."""
    index, low, stack, on_stack, components, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            components.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return components


def test_no_import_loops(graph):
    loops = [sorted(c) for c in strongly_connected(graph) if len(c) > 1]
    assert not loops, 'import loops between files: %s' % loops


def test_no_import_runs_back_up(graph):
    upward = ['%s (floor %d) imports %s (floor %d)' % (a, floor(a), b, floor(b))
              for a, targets in sorted(graph.items()) for b in sorted(targets) if floor(b) > floor(a)]
    assert not upward, '\n'.join(upward)


def test_published_faces_are_not_imported_by_the_package(graph):
    """The published module paths are for users' files: the package imports the modules behind them."""
    users = ['%s imports %s' % (a, b) for a, targets in sorted(graph.items()) for b in sorted(targets)
             if b in PUBLISHED_FACES and a not in PUBLISHED_FACES]
    assert not users, '\n'.join(users)


def test_stochastic_forcing_imports_nothing_above_it(graph):
    above = sorted(b for a, targets in graph.items() if a.startswith('stochastic_forcing')
                   for b in targets if not (b == 'utils' or b.startswith('stochastic_forcing')))
    assert not above, above


def test_multi_bodies_top_level_holds_scripts_and_override_module():
    names = {p.stem for p in (REPO / 'multi_bodies').glob('*.py')}
    assert names - TOP_LEVEL_ALLOWED == set(), 'library modules at the top of multi_bodies/: %s' % sorted(
        names - TOP_LEVEL_ALLOWED)


def test_floor_checker_catches_an_upward_import(tmp_path):
    """Negative control: a planted import of a script from the solver is reported."""
    modules = dict(package_modules())
    planted = tmp_path / 'planted.py'
    planted.write_text('def f():\n    from multi_bodies.run import dynamic_run\n')
    modules['multi_bodies.solver.planted'] = planted
    targets = imports_of(planted, 'multi_bodies.solver.planted', modules)
    assert 'multi_bodies.run.dynamic_run' in targets
    assert floor('multi_bodies.run.dynamic_run') > floor('multi_bodies.solver.planted')
    loop = {'a': {'b'}, 'b': {'a'}, 'c': set()}
    assert sorted(map(sorted, strongly_connected(loop))) == [['a', 'b'], ['c']]


# ------------------------------------------------------------------ one way into the solve, one base of operators
SOLVE_ENTRY = 'multi_bodies.solver.solves'  # Solver.solve: the only caller of body_solver.solve (issue 43)


def solve_calls_and_operators(path):
    """(lines calling the package's one solve ``body_solver.solve`` or importing it by name, lines constructing a
    SciPy ``LinearOperator``) of one file, read with ``ast``."""
    tree = ast.parse(path.read_text(), str(path))
    solve_lines, operator_lines = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or '').endswith('body_solver') and \
                any(alias.name == 'solve' for alias in node.names):
            solve_lines.append(node.lineno)
        elif isinstance(node, ast.Call):
            function = node.func
            name = function.attr if isinstance(function, ast.Attribute) else getattr(function, 'id', None)
            owner = function.value if isinstance(function, ast.Attribute) else None
            if name == 'solve' and isinstance(owner, ast.Name) and owner.id == 'body_solver':
                solve_lines.append(node.lineno)
            if name == 'LinearOperator':
                operator_lines.append(node.lineno)
    return solve_lines, operator_lines


def test_the_solve_has_one_way_in():
    """Nothing of the package calls ``body_solver.solve`` but ``solves.Solver.solve`` (which counts by kind and stops
    or flags a solve that did not converge), and nothing builds a ``LinearOperator`` but the one base of the
    problems and preconditioners (``multi_bodies.solver.linear_map``); the published faces keep their own."""
    bypass, operators = [], []
    for name, path in sorted(package_modules().items()):
        if name in PUBLISHED_FACES:
            continue
        solve_lines, operator_lines = solve_calls_and_operators(path)
        if name != SOLVE_ENTRY:
            bypass += ['%s:%d' % (name, line) for line in solve_lines]
        if name != 'multi_bodies.solver.linear_map':
            operators += ['%s:%d' % (name, line) for line in operator_lines]
    assert not bypass, 'calls of body_solver.solve outside %s: %s' % (SOLVE_ENTRY, ', '.join(bypass))
    assert not operators, 'LinearOperators built outside linear_map: %s' % ', '.join(operators)


def test_the_one_way_check_catches_a_bypass(tmp_path):
    """Negative control: a planted direct solve and a planted hand-built operator are found."""
    planted = tmp_path / 'planted.py'
    planted.write_text('import scipy.sparse.linalg as spla\nfrom multi_bodies.solver import body_solver\n'
                       'from multi_bodies.solver.body_solver import solve\n'
                       'def f(p, b):\n    op = spla.LinearOperator((2, 2), matvec=abs)\n'
                       '    return body_solver.solve(p, b, None)\n')
    solve_lines, operator_lines = solve_calls_and_operators(planted)
    assert solve_lines == [3, 6] and operator_lines == [5]


STEP_PACKAGES = ('body', 'mobility', 'multi_bodies.solver', 'quaternion_integrator', 'stochastic_forcing')


def attribute_forwarders(path):
    """Lines of the classes of one file that define ``__getattr__`` (attribute forwarding), read with ``ast``."""
    tree = ast.parse(path.read_text(), str(path))
    return [item.lineno for node in ast.walk(tree) if isinstance(node, ast.ClassDef)
            for item in node.body if isinstance(item, ast.FunctionDef) and item.name == '__getattr__']


def test_no_attribute_forwarding_on_the_step_path():
    """No class of the packages a step runs through (the files ``benchmarks/trace_step.py`` finds a Slip_Trapz step
    entering) forwards unknown attributes with ``__getattr__``: what a wrapper shares with what it wraps is named
    (issue 43: the old step context forwarded everything to the model)."""
    found = []
    for name, path in sorted(package_modules().items()):
        if name in PUBLISHED_FACES or not any(name == p or name.startswith(p + '.') for p in STEP_PACKAGES):
            continue
        found += ['%s:%d' % (name, line) for line in attribute_forwarders(path)]
    assert not found, 'classes forwarding attributes with __getattr__: %s' % ', '.join(found)


def test_the_forwarding_check_catches_a_forwarder(tmp_path):
    """Negative control: a planted forwarding wrapper is found (and a module-level __getattr__ is not a class's)."""
    planted = tmp_path / 'planted.py'
    planted.write_text('def __getattr__(name):\n    raise AttributeError(name)\n\n'
                       'class Wrapper:\n    def __init__(self, base):\n        self.base = base\n\n'
                       '    def __getattr__(self, name):\n        return getattr(self.base, name)\n')
    assert attribute_forwarders(planted) == [8]
