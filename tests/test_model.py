"""The centre of the house: a frozen model, a run state that is a value, and one solve for every problem.

* Nothing can be assigned to a model after its construction (a trap: assigning raises), for a model made
  by the programs' set-up from the manual's example input; ``Model.replace`` builds a variant.
* A scheme's step returns a new run state and leaves the one it was given as it was.
* The only call of GMRES in the package is in ``body_solver.gmres_solve``, and the only call of that is the
  one solve ``body_solver.solve`` (read from the source with ``ast``: a new path that calls GMRES on its own
  fails here).
"""
import ast
import os
from pathlib import Path

import numpy as np
import pytest

from multi_bodies.files.input_options import read_input_file
from multi_bodies.run.run_setup import prepare
from quaternion_integrator.schemes import make_scheme

REPO = Path(__file__).resolve().parents[1]
MULTI_BODIES = REPO / 'multi_bodies'


@pytest.fixture
def example_model(monkeypatch):
    monkeypatch.chdir(MULTI_BODIES)
    options = read_input_file('inputfile_dynamic.dat', 'dynamic')
    return options, prepare(options, 'dynamics', log=lambda *a: None).system


def test_a_model_cannot_be_changed_after_construction(example_model):
    _, model = example_model
    for name in ('physics', 'tolerance', 'eta', 'articulated', 'check_wall', 'mobility_product', 'configuration',
                 'gmres_iterations', 'anything_new'):
        with pytest.raises(AttributeError, match='frozen'):
            setattr(model, name, None)
    with pytest.raises(AttributeError, match='frozen'):
        del model.physics
    looser = model.replace(solver_tolerance=1e-3)
    assert looser.tolerance == 1e-3 and model.tolerance != 1e-3
    assert looser.num_blobs == model.num_blobs


def test_a_step_returns_a_new_state_and_keeps_the_old_one(example_model):
    options, model = example_model
    scheme = make_scheme('deterministic_adams_bashforth', options.dt, options)
    start = scheme.init(model, model.start_configuration)
    locations = start.configuration.locations.copy()
    bodies_before = np.array([b.location for b in model.bodies])
    first = scheme.step(model, start, None)
    second = scheme.step(model, first, None)
    np.testing.assert_array_equal(start.configuration.locations, locations)
    np.testing.assert_array_equal([b.location for b in model.bodies], bodies_before)  # the model's bodies: unmoved
    assert start.step == 0 and first.step == 1 and second.step == 2
    assert start.counters.gmres_iterations == 0 < first.counters.gmres_iterations < second.counters.gmres_iterations
    assert start.previous_velocities is None and first.previous_velocities is not None
    assert not np.array_equal(first.configuration.locations, locations)
    # the same state stepped again gives the same next state (no hidden state in the scheme or the model)
    again = scheme.step(model, first, None)
    np.testing.assert_array_equal(again.configuration.locations, second.configuration.locations)
    with pytest.raises(Exception):
        first.step = 5  # frozen dataclass


def calls_in(path):
    """(function name, called name) of every call in a file, by ``ast``."""
    tree = ast.parse(path.read_text(), str(path))
    found = []
    for function in ast.walk(tree):
        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(function):
                if isinstance(node, ast.Call):
                    target = node.func
                    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, 'id', None)
                    found.append((function.name, name))
    return found


def package_files():
    for package in ('body', 'mobility', 'multi_bodies', 'quaternion_integrator', 'stochastic_forcing',
                    'many_bodyMCMC', 'boomerang', 'sphere', 'lubrication'):
        for path in (REPO / package).rglob('*.py'):
            if 'examples' not in path.parts:
                yield path


def test_gmres_is_called_only_through_the_one_solve():
    """(``stochastic_forcing/compat.py`` is the SciPy version shim of ``scipy.sparse.linalg.gmres``, which the
    tests use as the reference GMRES; the package does not call it.)"""
    callers = {'gmres': set(), 'gmres_solve': set()}
    for path in package_files():
        if path == REPO / 'stochastic_forcing' / 'compat.py':
            continue
        for function, name in calls_in(path):
            if name in callers:
                callers[name].add('%s:%s' % (os.path.relpath(path, REPO), function))
    assert callers['gmres_solve'] == {'multi_bodies/solver/body_solver.py:solve'}, callers
    assert callers['gmres'] == {'multi_bodies/solver/body_solver.py:gmres_solve'}, callers


def test_the_checker_sees_a_planted_gmres_call(tmp_path):
    """Negative control of the test above: a function calling gmres_solve is found."""
    planted = tmp_path / 'planted.py'
    planted.write_text('def my_solve(a, b):\n    return body_solver.gmres_solve(a, b, 1e-8)\n')
    assert ('my_solve', 'gmres_solve') in calls_in(planted)


HOOK_WRITES_A_BODY = '''
import numpy as np


def bodies_external_force_torque(bodies, r_vectors, *args, **kwargs):
    bodies[0].location[2] += 1.0  # a force hook that moves a body: the run would ignore it
    return np.zeros((2 * len(bodies), 3))
'''

POSTPROCESS_LIFTS_THE_BODY = '''
def postprocess(bodies, *args, **kwargs):
    for b in bodies:
        b.location[2] += 0.5
'''


def test_hooks_see_read_only_bodies_and_postprocess_moves_copies(tmp_path, monkeypatch, capsys):
    """A published-style force hook that writes to a body is stopped with a message naming the hook (it got a
    read-only view at the configuration evaluated); ``postprocess`` gets writable copies, and what it does to
    them is the next configuration: each of 3 steps lifts the boomerang by 0.5 on top of its motion."""
    from test_dynamics import boomerang_scene, read_trajectory, run_script
    boomerang_scene(tmp_path, n_steps=3, extra={'g': 0.0, 'repulsion_strength_wall': 0.0})
    (tmp_path / 'user_defined_functions.py').write_text(HOOK_WRITES_A_BODY)
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 1
    error = capsys.readouterr().err
    assert 'bodies_external_force_torque' in error and 'read-only' in error, error
    (tmp_path / 'user_defined_functions.py').write_text(POSTPROCESS_LIFTS_THE_BODY)
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 0
    heights = read_trajectory(tmp_path, 'run', 'boomerang')[:, 0, 2]
    np.testing.assert_allclose(np.diff(heights), 0.5, rtol=0, atol=1e-12)  # force-free: only the lift moves it
