"""Preconditioners applied away from where they were built: turned with the bodies, and kept between solves.

Laws: in free space a body's own saddle-point system turns with the body, so the block-diagonal preconditioner
built at one configuration and turned (``corotated_preconditioner``) is the one built at the turned and moved
configuration, to rounding (the unturned one is off by the turn: the negative control); the turned one changes no
Lanczos factor; the published solves (``block_diagonal``) are never turned; deterministic solves under ``auto``
keep their preconditioner (one build for several steps), reach the published trajectory within what the solver
tolerance allows, build a new one when a solve has taken ``KEPT_WEAR_ITERATIONS`` more iterations than the
fewest, and a restart from the saved history repeats the run bit for bit.
"""
from dataclasses import replace

import numpy as np
import pytest

from body.body import Configuration
from body.geometry import rotate_quaternions
from multi_bodies.run.record_checks import _Bad, _check_history
from multi_bodies.solver import corotated_preconditioner
from quaternion_integrator import scheme_base
from quaternion_integrator.scheme_state import RunState
from quaternion_integrator.schemes import make_scheme
from test_neighbour_preconditioner import boomerang_model, count_builds, grid


def _turned_and_moved(configuration, seed, angle=0.3, shift=0.2):
    rng = np.random.default_rng(seed)
    nb = configuration.locations.shape[0]
    axes = rng.normal(size=(nb, 3))
    axes *= angle / np.linalg.norm(axes, axis=1, keepdims=True)
    return Configuration(configuration.locations + shift * rng.normal(size=(nb, 3)),
                         rotate_quaternions(configuration.orientations, axes))


@pytest.mark.parametrize('backend', ['C++_no_wall', 'python_no_wall'])
def test_turned_preconditioner_is_the_one_built_at_the_turned_bodies_in_free_space(backend):
    """Four boomerangs, each turned by 0.3 rad about its own random axis and moved by ~0.2: the block-diagonal
    preconditioner of the start, turned, applies as the one built at the new configuration (rotation covariance
    of the RPY mobility, relative 1e-10; measured 1e-15); unturned it is off by the order of the turn (> 1e-2)."""
    model = boomerang_model(grid(4, 6.0), seed=4, preconditioner='block_diagonal').replace(
        vector_product_name=backend, blobs_name=backend)
    start = model.start_configuration
    moved = _turned_and_moved(start, seed=5)
    built_at_start = model.build_preconditioner(start)
    built_here = model.build_preconditioner(moved)
    problem = model.mobility_problem(moved)
    turned = corotated_preconditioner.following(problem, built_at_start, model.arrays)
    assert isinstance(turned, corotated_preconditioner.CorotatedPreconditioner)
    x = np.random.default_rng(6).normal(size=problem.size)
    exact = built_here.operator.matvec(x)
    scale = np.linalg.norm(exact)
    assert np.linalg.norm(turned.operator.matvec(x) - exact) < 1e-10 * scale
    assert np.linalg.norm(built_at_start.operator.matvec(x) - exact) > 1e-2 * scale
    # the Lanczos factors are the build's, not turned
    blobs = x[:3 * model.num_blobs]
    np.testing.assert_array_equal(turned.L_dot(blobs), built_at_start.L_dot(blobs))


def test_turns_about_the_wall_normal_are_exact_above_the_wall():
    """Above the wall a turn about z keeps each body's wall images where they were relative to its blobs: the turned
    preconditioner is the one built there (relative 1e-10)."""
    model = boomerang_model(grid(4, 6.0), seed=4, preconditioner='block_diagonal')
    start = model.start_configuration
    nb = start.locations.shape[0]
    turns = np.zeros((nb, 3))
    turns[:, 2] = np.linspace(0.2, 0.8, nb)
    moved = Configuration(start.locations + np.array([0.3, -0.2, 0.0]), rotate_quaternions(start.orientations, turns))
    problem = model.mobility_problem(moved)
    turned = corotated_preconditioner.following(problem, model.build_preconditioner(start),
                                                model.arrays)
    x = np.random.default_rng(7).normal(size=problem.size)
    exact = model.build_preconditioner(moved).operator.matvec(x)
    assert np.linalg.norm(turned.operator.matvec(x) - exact) < 1e-10 * np.linalg.norm(exact)


def test_published_solves_and_unturned_bodies_use_the_preconditioner_as_built(monkeypatch):
    """``block_diagonal`` never turns (the published iterates); a preconditioner at the orientations it was built at
    is returned as it is."""
    model = boomerang_model(grid(4, 6.0), seed=4, preconditioner='block_diagonal')
    start = model.start_configuration
    pc = model.build_preconditioner(start)
    seen = []
    from multi_bodies.solver import body_solver
    solve = body_solver.solve

    def spy(problem, rhs, preconditioner, **kwargs):
        seen.append(preconditioner)
        return solve(problem, rhs, preconditioner, **kwargs)
    monkeypatch.setattr(body_solver, 'solve', spy)
    moved = _turned_and_moved(start, seed=8, angle=0.05, shift=0.0)
    problem = model.mobility_problem(moved)
    model.solve(problem, problem.rhs(force_torque=np.ones((4, 6))), pc)
    assert seen[-1] is pc
    auto = model.replace(preconditioner='auto')
    auto.solve(problem, problem.rhs(force_torque=np.ones((4, 6))), pc)
    assert isinstance(seen[-1], corotated_preconditioner.CorotatedPreconditioner)
    same = auto.mobility_problem(Configuration(start.locations + 0.1, start.orientations))
    assert corotated_preconditioner.following(same, pc, model.arrays) is pc


def _run(model, scheme_name, steps, state=None, dt=0.01):
    scheme = make_scheme(scheme_name, dt)
    state = scheme.init(model, model.start_configuration) if state is None else state
    for _ in range(steps):
        state = scheme.step(model, state, None)
    return scheme, state


@pytest.mark.parametrize('scheme_name, solves_per_step', [('deterministic_adams_bashforth', 1),
                                                          ('deterministic_midpoint', 2)])
def test_deterministic_solves_keep_their_preconditioner_to_the_same_trajectory(scheme_name, solves_per_step,
                                                                               monkeypatch):
    """16 boomerangs, 6 steps of dt 0.01 under gravity: ``auto`` builds fewer preconditioners than it makes solves
    (``block_diagonal``, the negative control, builds one per solve), weighing the first against
    ``KEPT_SOLVES_WEIGHED`` solves, and ends where the published solves end within what solver_tolerance 1e-8
    allows (asserted 1e-6 of the distance travelled)."""
    asked = count_builds(monkeypatch)
    model = boomerang_model(grid(16, 4.0), seed=2, preconditioner='auto')
    _, kept = _run(model, scheme_name, 6)
    assert 1 <= len(asked) < 6 * solves_per_step and asked[0] == scheme_base.KEPT_SOLVES_WEIGHED, asked
    assert kept.preconditioner_configuration is not None or kept.preconditioner_lifetime is not None
    asked.clear()
    published = model.replace(preconditioner='block_diagonal')
    _, rebuilt = _run(published, scheme_name, 6)
    assert len(asked) == 6 * solves_per_step and set(asked) == {1}
    assert rebuilt.preconditioner_configuration is None and rebuilt.preconditioner_solves is None
    travelled = np.abs(rebuilt.configuration.locations - model.start_configuration.locations).max()
    assert travelled > 0
    assert np.abs(kept.configuration.locations - rebuilt.configuration.locations).max() < 1e-6 * travelled


def test_a_worn_preconditioner_is_built_anew(monkeypatch):
    """The served counts: the fewest iterations are remembered; a solve with KEPT_WEAR_ITERATIONS more ends the
    preconditioner (the next solve builds one, weighed against the solves it served before the worn one, at
    most KEPT_SOLVES_WEIGHED, averaged with the weight before); fewer more than the fewest does not."""
    state = RunState(None, preconditioner=object(), preconditioner_configuration=object(), preconditioner_solves=0)
    wear = scheme_base.KEPT_WEAR_ITERATIONS
    for iterations in (6, 4, 4 + wear - 1):
        state = scheme_base.Scheme.served(state, iterations)
    assert (state.preconditioner_solves, state.preconditioner_fewest) == (3, 4)
    assert state.preconditioner is not None
    state = scheme_base.Scheme.served(state, 4 + wear)
    assert state.preconditioner is None and state.preconditioner_configuration is None
    assert state.preconditioner_solves is None and state.preconditioner_lifetime == 3
    # the next one wears after serving one solve: the weight is the mean of 3 and 1, rounded up
    state = replace(state, preconditioner=object(), preconditioner_configuration=object(), preconditioner_solves=0)
    for iterations in (4, 4 + wear):
        state = scheme_base.Scheme.served(state, iterations)
    assert state.preconditioner is None and state.preconditioner_lifetime == 2
    # the next build is weighed against the solves this one served
    asked = count_builds(monkeypatch)
    model = boomerang_model(grid(4, 4.0), seed=1, preconditioner='auto')
    scheme = make_scheme('deterministic_adams_bashforth', 0.01)
    state = RunState(model.start_configuration, preconditioner_lifetime=2)
    scheme.step(model, state, None)
    assert asked == [2]
    asked.clear()
    scheme.step(model, RunState(model.start_configuration, preconditioner_lifetime=50), None)
    assert asked == [scheme_base.KEPT_SOLVES_WEIGHED]


def test_restart_with_a_kept_preconditioner_repeats_the_run_bit_for_bit(monkeypatch):
    """Steps with a kept preconditioner, the history saved (what a restart record holds) and a fresh state made
    from it: the restarted run builds the preconditioner again where the saved one was built, and ends where the
    uninterrupted run ends, to the bit.  A wear margin of 1 and dt 0.1 make builds happen inside the run too."""
    monkeypatch.setattr(scheme_base, 'KEPT_WEAR_ITERATIONS', 1)
    asked = count_builds(monkeypatch)
    model = boomerang_model(grid(9, 4.0), seed=3, preconditioner='auto')
    scheme, whole = _run(model, 'deterministic_adams_bashforth', 8, dt=0.1)
    assert len(asked) >= 2, asked  # worn and built anew within the run
    _, half = _run(model, 'deterministic_adams_bashforth', 4, dt=0.1)
    history = half.history()
    _check_history(history, 9)  # the record checks accept it
    assert history['preconditioner_configuration'] is not None and isinstance(history['preconditioner_solves'], int)
    restarted = scheme.init(model, half.configuration, half.step, history=history)
    assert restarted.preconditioner is None and restarted.preconditioner_solves == half.preconditioner_solves
    _, rest = _run(model, 'deterministic_adams_bashforth', 4, state=restarted, dt=0.1)
    np.testing.assert_array_equal(rest.configuration.locations, whole.configuration.locations)
    np.testing.assert_array_equal(rest.configuration.orientations, whole.configuration.orientations)
    assert rest.counters.gmres_iterations == whole.counters.gmres_iterations - half.counters.gmres_iterations
    for bad in (-1, 2.5, 'three'):
        with pytest.raises(_Bad):
            _check_history(dict(history, preconditioner_fewest=bad), 9)


def janus_model(tmp_path, preconditioner='neighbours'):
    """Four 42-blob Janus spheres (emitting caps, mobility 1, no background) 2.6 apart above the wall, read from
    input files as a run reads them; their solute moves them (phoretic slip)."""
    from multi_bodies.files.structure_generators import icosahedral_shell, janus_laplace_table
    from test_phoretic import _model_of, _shell_files
    _shell_files(tmp_path, 42, 0.0, 0.0, 1.0, (0, 0, 3.0), (0.0,), domain='single_wall')
    np.savetxt(tmp_path / 'shell.Laplace', janus_laplace_table(icosahedral_shell(42), (0, 1, 1), (0, 0, 1)))
    rng = np.random.default_rng(5)
    with open(tmp_path / 'shell.clones', 'w') as f:
        f.write('4\n')
        for k in range(4):
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            f.write('%r %r 3.0 %r %r %r %r\n' % ((2.6 * (k % 2), 2.6 * (k // 2)) + tuple(float(c) for c in q)))
    return _model_of(tmp_path, 'input.dat').replace(preconditioner=preconditioner)


def test_phoretic_runs_keep_the_concentration_preconditioner_and_restart_bit_for_bit(tmp_path, monkeypatch):
    """Four Janus spheres, forward Euler at dt 0.05: the concentration problem's preconditioner is kept between
    steps (fewer builds than solves; with a wear margin of 0, the control, one build per solve), the trajectory
    is the one of a fresh preconditioner at every solve within what solver_tolerance allows (1e-6 of the distance
    travelled), the record checks accept the saved history, and a restart from it repeats the run bit for bit."""
    from multi_bodies.solver.surface import Surface
    from quaternion_integrator import scheme_state
    builds = []
    original = Surface.concentration_preconditioner

    def spy(self, model, configuration, problem=None):
        builds.append(configuration)
        return original(self, model, configuration, problem)
    monkeypatch.setattr(Surface, 'concentration_preconditioner', spy)
    model = janus_model(tmp_path)
    steps = 6
    _, kept = _run(model, 'deterministic_forward_euler', steps, dt=0.05)
    assert kept.counters.laplace_iterations > 0
    assert 1 <= len(builds) < steps, len(builds)
    kept_builds = len(builds)
    monkeypatch.setattr(scheme_state, 'CONCENTRATION_WEAR_ITERATIONS', 0)  # every solve wears it: built anew
    builds.clear()
    _, fresh = _run(model, 'deterministic_forward_euler', steps, dt=0.05)
    assert len(builds) >= steps > kept_builds
    travelled = np.linalg.norm(fresh.configuration.locations - model.start_configuration.locations)
    assert travelled > 1e-3
    assert np.linalg.norm(kept.configuration.locations - fresh.configuration.locations) < 1e-6 * travelled
    monkeypatch.undo()
    # restart: half the run, its history through the record checks, the rest
    scheme, half = _run(model, 'deterministic_forward_euler', steps // 2, dt=0.05)
    history = half.history()
    _check_history(history, 4)
    assert history['concentration_preconditioner_configuration'] is not None
    restarted = scheme.init(model, half.configuration, half.step, history=history)
    assert restarted.concentration_preconditioner is None
    _, rest = _run(model, 'deterministic_forward_euler', steps - steps // 2, state=restarted, dt=0.05)
    np.testing.assert_array_equal(rest.configuration.locations, kept.configuration.locations)
    np.testing.assert_array_equal(rest.configuration.orientations, kept.configuration.orientations)
    # the published solves keep nothing
    _, published = _run(janus_model(tmp_path, 'block_diagonal'), 'deterministic_forward_euler', 2, dt=0.05)
    assert published.concentration_preconditioner_configuration is None


def test_record_checks_refuse_a_bad_kept_concentration_preconditioner():
    """A saved history whose concentration preconditioner counts or configuration are not this run's is refused."""
    good = RunState(Configuration(np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1))))
    history = good.history()
    _check_history(history, 2)
    for key, value in (('concentration_preconditioner_solves', -1), ('concentration_preconditioner_fewest', 'x'),
                       ('concentration_preconditioner_configuration', [np.zeros((3, 3)), np.zeros((3, 4))])):
        with pytest.raises(_Bad, match=key):
            _check_history(dict(history, **{key: value}), 2)
