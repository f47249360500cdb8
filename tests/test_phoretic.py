"""Phoretic bodies (multi_bodies/solver/phoretic.py, laplace_kernels.py): the published probes of Laplace_sphere and
chiral_phoretic_particle, the wall's images against the method of images, an inert sphere in a uniform background,
and Anderson's diffusiophoretic velocity with its discretisation error measured against resolution."""
import os

import numpy as np
import pytest

from multi_bodies.files.input_options import read_input_file
from multi_bodies.files.structure_generators import icosahedral_shell, smallest_distance
from multi_bodies.run.run_setup import prepare
from multi_bodies.solver import body_solver
from multi_bodies.solver.phoretic import LaplaceProblem

EXAMPLES = 'published_2025/phoretic/multi_bodies/examples'


def _model_of(directory, input_name):
    """The Model of an input file in ``directory`` (read from there, as the scripts do)."""
    here = os.getcwd()
    os.chdir(directory)
    try:
        options = read_input_file(input_name, 'dynamic')
        return prepare(options, 'dynamics', log=lambda line: None).system
    finally:
        os.chdir(here)


def _relative(ours, published, scale=None):
    scale = np.max(np.abs(published)) if scale is None else scale
    return np.max(np.abs(np.asarray(ours) - published)) / scale


@pytest.mark.parametrize('folder, input_name, probe, tolerance', [
    ('Laplace_sphere', 'inputfile.dat', 'run.probe.npz', 1e-8),
    ('chiral_phoretic_particle', 'inputfile_chiral_phoretic_particle.dat',
     'data/run_chiral_phoretic_particle.probe.npz', 1e-10)])
def test_published_probes(reference_dir, folder, input_name, probe, tolerance):
    """Concentrations, gradients, slip and body velocities of the published runs, through the input file."""
    directory = reference_dir / EXAMPLES / folder
    p = np.load(directory / probe)
    model = _model_of(directory, input_name)
    q = model.start_configuration
    problem, result = model.surface.solve_concentrations(model, q)
    np.testing.assert_array_equal(problem.r_vectors, p['step0_r_vectors'])
    assert _relative(problem.normals, p['step0_normals']) < 1e-15
    assert _relative(problem.rhs(), p['step0_RHS_Laplace']) < 1e-14
    c = result.constraint_force_torque
    # measured: 1e-14, 2e-15 (both unpreconditioned, as published: fewer than 400 blobs under preconditioner auto);
    # the chiral pair preconditioned (preconditioner neighbours) 5e-11, test_phoretic_examples.py
    assert _relative(c, p['step0_c']) < tolerance
    g = problem.surface_gradient(c)
    assert _relative(g, p['step0_grad_c']) < tolerance              # measured: 5e-15, 2e-15
    slip = model.slip(q)
    # the slip of the uniform sphere is zero by symmetry (1e-14): compared against the size of mu |grad c|
    scale = np.max(np.abs(p['step0_surface_mobility'][:, None] * p['step0_grad_c']))
    assert _relative(slip, p['step0_slip'], scale) < tolerance
    velocities = model.deterministic_velocities(q).velocities
    published = p['step0_velocities']
    speed_scale = max(np.max(np.abs(published)), 1e-3 * scale)  # a resting sphere: against the slip's size
    assert _relative(velocities, published, speed_scale) < max(tolerance, 1e-8), velocities


def _shell_files(directory, n, reaction, emitting, mobility_value, location, background, domain='no_wall',
                 extra=''):
    """Write a unit-shell body (Rg = 1, w = 4 pi / n, outward unit normals) and its input file; the Model."""
    reference = icosahedral_shell(n)
    a = 0.5 * smallest_distance(reference)
    np.savetxt(directory / 'shell.vertex', reference, header=str(n), comments='')
    with open(directory / 'shell.clones', 'w') as f:
        f.write('1\n%r %r %r 1 0 0 0\n' % tuple(location))
    normals = reference / np.linalg.norm(reference, axis=1)[:, None]
    table = np.column_stack((normals, np.full(n, reaction), np.full(n, emitting), np.full(n, mobility_value),
                             np.full(n, 4 * np.pi / n)))
    np.savetxt(directory / 'shell.Laplace', table, header='normals, reaction rate, emitting rate, mobility, weight')
    implementation = 'python_no_wall' if domain == 'no_wall' else 'python'
    with open(directory / 'input.dat', 'w') as f:
        f.write('scheme deterministic_forward_euler\ndt 0.01\nn_steps 1\nblob_radius %r\neta 1\ng 0\n'
                'mobility_vector_prod_implementation %s\nmobility_blobs_implementation %s\ndomain %s\n'
                'repulsion_strength_wall 0\nrepulsion_strength 0\nbackground_Laplace %s\n'
                'structure shell.vertex shell.clones shell.Laplace\noutput_name out/run\n%s'
                % (a, implementation, implementation, domain, ' '.join('%r' % float(b) for b in background), extra))
    return _model_of(directory, 'input.dat')


def test_wall_images_equal_the_mirror_pair(tmp_path):
    """Method of images: one emitting, reacting sphere above the no-flux wall has the concentrations of the sphere and
    its mirror image in free space (upper sphere's blobs), to the solver tolerance."""
    model = _shell_files(tmp_path, 42, 0.5, 1.0, 1.0, (0.3, -0.2, 1.6), (0.2, 0.1, 0.3, 0.0, 0.05),
                         domain='single_wall')
    q = model.start_configuration
    problem, result = model.surface.solve_concentrations(model, q)
    assert problem.wall
    x, n = problem.r_vectors, problem.normals
    mirror = np.array([1.0, 1.0, -1.0])
    # a background symmetric under z -> -z (no z in G or H) keeps the mirror pair an exact image system
    pair = LaplaceProblem(np.vstack((x, x * mirror)), np.vstack((n, n * mirror)), np.tile(problem.reaction, 2),
                          np.tile(problem.emitting, 2), np.tile(problem.weights, 2), 1.0, problem.background, False)
    free = body_solver.solve(pair, pair.rhs(), None, tolerance=1e-12, restart=200).constraint_force_torque
    c = result.constraint_force_torque
    assert _relative(c, free[:42]) < 1e-7
    g_pair = pair.surface_gradient(free)[:42]
    assert _relative(problem.surface_gradient(c), g_pair) < 1e-7
    # negative control: without the images the concentrations differ
    lone = LaplaceProblem(x, n, problem.reaction, problem.emitting, problem.weights, 1.0, problem.background, False)
    alone = body_solver.solve(lone, lone.rhs(), None, tolerance=1e-12, restart=200).constraint_force_torque
    assert _relative(alone, free[:42]) > 1e-2


def test_inert_sphere_in_uniform_background_does_not_move(tmp_path):
    model = _shell_files(tmp_path, 162, 0.0, 0.0, 3.0, (0, 0, 0), (2.0,))
    U = model.deterministic_velocities(model.start_configuration).velocities
    assert np.max(np.abs(U)) < 1e-10
    # negative control: the same sphere in a gradient moves at order mu |G|
    model = _shell_files(tmp_path, 162, 0.0, 0.0, 3.0, (0, 0, 0), (2.0, 0.0, 0.0, 0.1))
    U = model.deterministic_velocities(model.start_configuration).velocities
    assert abs(U[0, 2]) > 0.1


def test_anderson_diffusiophoresis():
    """Inert sphere, uniform surface mobility mu, background gradient G: U = -mu G (Anderson, Annu. Rev. Fluid
    Mech. 21, 61, 1989: surface concentration (3/2) G.x, slip mu (3/2) P G, body velocity minus the mean slip).
    The discretisation error is measured over 42, 162, 642 blobs."""
    import tempfile
    from pathlib import Path
    mu, G = 2.0, np.array([0.0, 0.1, 0.2])
    errors, speeds = [], []
    for n in (42, 162, 642):
        with tempfile.TemporaryDirectory() as directory:
            model = _shell_files(Path(directory), n, 0.0, 0.0, mu, (0, 0, 0), (0.0,) + tuple(G))
            U = model.deterministic_velocities(model.start_configuration).velocities[0]
        speeds.append(U[:3])
        errors.append(np.linalg.norm(U[:3] + mu * G) / np.linalg.norm(mu * G))
        assert np.linalg.norm(U[3:]) < 1e-8
    # measured: relative errors 0.516, 0.256, 0.127 (orders 1.01, 1.01 in the blob spacing); the mean slip is
    # within 5 %, 2.3 %, 1.1 % of mu G: most of the error is the multiblob slip-to-velocity map at these shells
    assert errors[0] > errors[1] > errors[2]
    assert min(np.log2(errors[i] / errors[i + 1]) for i in range(2)) > 0.8
    # first-order Richardson extrapolation of the two finest shells: within 2 % of Anderson (measured 0.2 %)
    extrapolated = 2.0 * speeds[2] - speeds[1]
    assert np.linalg.norm(extrapolated + mu * G) / np.linalg.norm(mu * G) < 0.02
    # negative control: the opposite sign (moving up the gradient) is far off
    assert np.linalg.norm(extrapolated - mu * G) / np.linalg.norm(mu * G) > 1.5


def test_concentrations_are_warm_started_from_the_previous_step(reference_dir):
    """The run state keeps the last normalised concentrations (saved in the restart history); the next step's solve
    starts there, in fewer GMRES iterations, to the same concentrations (chiral sprinklers, 3 steps)."""
    from quaternion_integrator.schemes import make_scheme
    from quaternion_integrator.scheme_state import RunState
    model = _model_of(reference_dir / EXAMPLES / 'chiral_phoretic_particle', 'inputfile_chiral_phoretic_particle.dat')
    scheme = make_scheme('deterministic_forward_euler', 0.5)
    state = scheme.init(model, model.start_configuration)
    assert state.concentration_guess is None
    for _ in range(3):
        state = scheme.step(model, state, None)
    assert state.concentration_guess.shape == (model.num_blobs,)
    _, warm = model.surface.solve_concentrations(model, state.configuration, x0=state.concentration_guess)
    _, cold = model.surface.solve_concentrations(model, state.configuration)
    assert warm.iterations < cold.iterations, (warm.iterations, cold.iterations)
    assert _relative(warm.constraint_force_torque, cold.constraint_force_torque) < 1e-9
    restored = RunState(state.configuration).with_history(state.history())
    np.testing.assert_array_equal(restored.concentration_guess, state.concentration_guess)


def test_concentration_iterations_are_counted_in_info(reference_dir, monkeypatch):
    """The run's counters add up the GMRES iterations of every concentration solve of the steps (counted here
    by wrapping the solve), ``.info`` writes them as laplace_iterations_count for phoretic runs only, and a
    restart record gives them back."""
    from multi_bodies.solver.counters import Counters
    from quaternion_integrator.schemes import make_scheme
    model = _model_of(reference_dir / EXAMPLES / 'chiral_phoretic_particle', 'inputfile_chiral_phoretic_particle.dat')
    seen = []
    solve = type(model.surface).solve_concentrations

    def counted(self, *args, **kwargs):
        problem, result = solve(self, *args, **kwargs)
        seen.append(result.iterations)
        return problem, result
    monkeypatch.setattr(type(model.surface), 'solve_concentrations', counted)
    scheme = make_scheme('deterministic_adams_bashforth', 0.5)
    state = scheme.init(model, model.start_configuration)
    for _ in range(3):
        state = scheme.step(model, state, None)
    assert len(seen) >= 3 and all(n > 0 for n in seen)
    assert state.counters.laplace_iterations == sum(seen)
    info = state.counters.info(phoretic=True)
    assert info['laplace_iterations_count'] == sum(seen)
    assert Counters.from_info(info) == state.counters
    assert 'laplace_iterations_count' not in state.counters.info()


@pytest.mark.parametrize('name', ['stochastic_EM', 'stochastic_first_order_RFD', 'stochastic_adams_bashforth'])
def test_stochastic_schemes_use_the_solute_slip(reference_dir, name):
    """At kT = 0 a first-order stochastic scheme moves the chiral sprinklers as deterministic forward Euler (the
    solute's slip enters through the same step; measured: equal to rounding), and they do move (1.7e-4)."""
    from multi_bodies.files.input_options import options_with
    from quaternion_integrator.schemes import make_scheme
    model = _model_of(reference_dir / EXAMPLES / 'chiral_phoretic_particle', 'inputfile_chiral_phoretic_particle.dat')
    rng = np.random.default_rng(0)
    start = model.start_configuration
    euler = make_scheme('deterministic_forward_euler', 0.01)
    expected = euler.step(model, euler.init(model, start), rng).configuration.locations
    scheme = make_scheme(name, 0.01, options_with(kT=0.0))
    moved = scheme.step(model, scheme.init(model, start), rng).configuration.locations
    assert np.max(np.abs(moved - expected)) < 1e-12
    assert np.max(np.abs(expected - start.locations)) > 1e-4


def test_janus_sphere_self_diffusiophoresis(tmp_path):
    """A sphere emitting on its z > 0 half (k = 0, uniform mu, D = 1) swims away from its cap at alpha mu / (4 D)
    (Golestanian, Liverpool and Ajdari, New J. Phys. 9, 126, 2007), up to a discretisation error measured at 42,
    162, 642 blobs; the generator's Janus table (doc/phoretic.md) gives the hemispheres."""
    from multi_bodies.files.structure_generators import janus_laplace_table
    speeds = []
    for n in (42, 162, 642):
        folder = tmp_path / str(n)
        folder.mkdir()
        _shell_files(folder, n, 0.0, 0.0, 1.0, (0, 0, 0), (0.0,))
        np.savetxt(folder / 'shell.Laplace', janus_laplace_table(icosahedral_shell(n), (0, 1, 1), (0, 0, 1)))
        model = _model_of(folder, 'input.dat')
        U = model.deterministic_velocities(model.start_configuration).velocities[0]
        assert np.max(np.abs(U[[0, 1, 3, 4, 5]])) < 1e-10
        speeds.append(-U[2])
    errors = [abs(s - 0.25) / 0.25 for s in speeds]
    # measured: speeds 0.2978, 0.2831, 0.2689; relative errors 0.19, 0.13, 0.076; Richardson (order 1) 1.9 %
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.1
    assert abs(2 * speeds[2] - speeds[1] - 0.25) / 0.25 < 0.03
    # negative control: the cap on the other half swims the other way
    folder = tmp_path / 'flipped'
    folder.mkdir()
    _shell_files(folder, 42, 0.0, 0.0, 1.0, (0, 0, 0), (0.0,))
    np.savetxt(folder / 'shell.Laplace', janus_laplace_table(icosahedral_shell(42), (0, 0, 1), (0, 1, 1)))
    model = _model_of(folder, 'input.dat')
    assert abs(model.deterministic_velocities(model.start_configuration).velocities[0, 2] - speeds[0]) < 1e-8


def test_bad_phoretic_input_names_file_line_and_fix(tmp_path):
    """Ten background numbers, a short .Laplace row, a wrong row count, a second structure line without a .Laplace
    file: each a UserInputError naming where and what to do."""
    from utils import UserInputError
    _shell_files(tmp_path, 42, 0.0, 1.0, 1.0, (0, 0, 5), (0.0,))
    good = (tmp_path / 'input.dat').read_text()

    def error_of(text):
        (tmp_path / 'bad.dat').write_text(text)
        with pytest.raises(UserInputError) as err:
            _model_of(tmp_path, 'bad.dat')
        return str(err.value)
    message = error_of(good.replace('background_Laplace 0.0', 'background_Laplace ' + ' 1' * 10))
    assert 'bad.dat, line' in message and 'one to nine numbers' in message
    rows = (tmp_path / 'shell.Laplace').read_text().splitlines()
    (tmp_path / 'short.Laplace').write_text('\n'.join(rows[:5] + [' '.join(rows[5].split()[:6])] + rows[6:]) + '\n')
    line = 'shell.vertex shell.clones shell.Laplace'
    message = error_of(good.replace(line, 'shell.vertex shell.clones short.Laplace'))
    assert 'short.Laplace, line 6' in message and '7 numbers' in message
    (tmp_path / 'few.Laplace').write_text('\n'.join(rows[:30]) + '\n')
    message = error_of(good.replace(line, 'shell.vertex shell.clones few.Laplace'))
    assert 'few.Laplace' in message and 'shell.vertex has 42 blobs' in message
    (tmp_path / 'other.clones').write_text('1\n5 0 5 1 0 0 0\n')
    message = error_of(good + 'structure shell.vertex other.clones\n')
    assert 'no .Laplace file' in message and 'bad.dat, line' in message
