"""The one way into the solve (multi_bodies.solver.solves.Solver): counts by kind, and a solve that does not
converge is refused (the schemes of every family: rigid, rollers, articulated, lubrication) or flagged (the static
script, the published Lub_Solver face) - never used as if it had converged (issue 43).

A solve is made not to converge by a GMRES limit of one iteration (``Solver.max_iterations``) on scenes whose
solves take more (a control run of each scene, without the limit, records the iterations of every solve and
completes).  What is asserted comes from outside the code under test: the exit status and the one line the
manual promises, the counts against the iterations each solve returned (spied on ``body_solver.solve``, the GMRES
under the solver), and the residual the flagged solve reports against the tolerance.
"""
import contextlib
import io
import os

import numpy as np
import pytest

from multi_bodies.files.input_options import read_input_file
from multi_bodies.files.structure_generators import boomerang
from multi_bodies.run.dynamic_run import run_dynamics
from multi_bodies.solver import body_solver
from multi_bodies.solver.counters import Counters, Tally
from multi_bodies.solver.linear_map import LinearProblem
from multi_bodies.solver.solves import Solver
from utils import SimulationStopped


def clones(rows):
    return '%d\n' % len(rows) + ''.join(' '.join('%.17g' % v for v in row) + '\n' for row in rows)


def rigid_scene(scheme):
    rng = np.random.default_rng(4)
    q = rng.normal(size=(4, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    files = {'b.vertex': '15\n' + ''.join('%.17g %.17g %.17g\n' % tuple(r) for r in boomerang()),
             'b.clones': clones([[2.2 * k, 0.3 * k, 2.0, *q[k]] for k in range(4)])}
    return files, ['scheme %s' % scheme, 'dt 0.02', 'kT 1.0', 'seed 7', 'blob_radius 0.25', 'g 1.0',
                   'mobility_blobs_implementation python', 'mobility_vector_prod_implementation python',
                   'blob_blob_force_implementation None', 'repulsion_strength_wall 1.0', 'debye_length_wall 0.3',
                   'structure b.vertex b.clones']


def roller_scene(scheme):
    files = {'s.vertex': '1\n0 0 0\n', 's.clones': clones([[1.5 * k, 0.7 * (k % 2), 1.1 + 0.1 * k, 1, 0, 0, 0]
                                                          for k in range(6)])}
    return files, ['scheme %s' % scheme, 'dt 0.02', 'kT 1.0', 'seed 7', 'blob_radius 0.5', 'g 1.0',
                   'free_kinematics False', 'omega_one_roller 0 1 0', 'domain single_wall',
                   'mobility_vector_prod_implementation python', 'blob_blob_force_implementation None',
                   'repulsion_strength_wall 1.0', 'debye_length_wall 0.1', 'structure s.vertex s.clones']


def articulated_scene(scheme):
    octahedron = [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]]
    joints = ['%d %d  1.25 0 0  -1.25 0 0' % (k, k + 1) for k in range(2)]
    files = {'shell.vertex': '6\n' + ''.join('%g %g %g\n' % tuple(r) for r in octahedron),
             'chain.list_vertex': 'shell.vertex\n' * 3, 'chain.const': '3\n2\n%s\n' % '\n'.join(joints),
             'chain.clones': clones([[2.5 * k, 0, 3.0, 1, 0, 0, 0] for k in range(3)])}
    # block_diagonal: the published Schur preconditioner, which leaves GMRES more than one iteration
    return files, ['scheme %s' % scheme, 'preconditioner block_diagonal', 'dt 0.01', 'blob_radius 0.25', 'g 1.0',
                   'repulsion_strength_wall 0', 'mobility_blobs_implementation python',
                   'mobility_vector_prod_implementation python', 'blob_blob_force_implementation None',
                   'articulated chain.list_vertex chain.clones chain.const']


def lubrication_scene(scheme):
    spheres = [[0.0, 0.0, 1.5, 1, 0, 0, 0], [2.3, 0.0, 1.4, 1, 0, 0, 0], [1.0, 2.2, 1.3, 1, 0, 0, 0]]
    files = {'s.vertex': '1\n0 0 0\n', 's.clones': clones(spheres)}
    return files, ['scheme %s' % scheme, 'dt 0.01', 'blob_radius 1.0', 'g 1.0', 'kT 0.3', 'seed 5',
                   'repulsion_strength_wall 0.0', 'mobility_vector_prod_implementation python',
                   'blob_blob_force_implementation None', 'structure s.vertex s.clones']


FAMILIES = [('rigid', 'deterministic_adams_bashforth', rigid_scene),
            ('rigid', 'stochastic_Slip_Trapz', rigid_scene),
            ('rollers', 'deterministic_forward_euler_rollers', roller_scene),
            ('rollers', 'stochastic_adams_bashforth_rollers', roller_scene),
            ('articulated', 'articulated_deterministic_forward_euler', articulated_scene),
            ('lubrication', 'lubrication_trapezoidal', lubrication_scene),
            ('lubrication', 'lubrication_EM', lubrication_scene)]


def run_scene(folder, scene, scheme, monkeypatch):
    """Run 2 steps of ``scene(scheme)`` in ``folder``: (exit status, stderr, the .info counts, the iterations of every
    solve GMRES made)."""
    files, lines = scene(scheme)
    folder.mkdir()
    for name, text in files.items():
        (folder / name).write_text(text)
    lines = lines + ['n_steps 2', 'n_save 1', 'eta 1.0', 'solver_tolerance 1e-8', 'output_name run']
    (folder / 'input.dat').write_text('\n'.join(lines) + '\n')
    monkeypatch.chdir(folder)
    iterations = []
    original = body_solver.solve

    def spy(*args, **kwargs):
        result = original(*args, **kwargs)
        iterations.append(result.iterations)
        return result
    monkeypatch.setattr(body_solver, 'solve', spy)
    errors = io.StringIO()
    with contextlib.redirect_stderr(errors), contextlib.redirect_stdout(io.StringIO()):
        status = run_dynamics(read_input_file('input.dat', 'dynamic'), log=lambda *a: None)
    info = {}
    if os.path.exists('run.info'):
        for line in open('run.info'):
            if '=' in line:
                key, value = (part.strip() for part in line.split('=', 1))
                info[key] = value
    return status, errors.getvalue(), info, iterations


@pytest.mark.parametrize('family, scheme, scene', FAMILIES, ids=['%s-%s' % (f, s) for f, s, _ in FAMILIES])
def test_a_solve_that_does_not_converge_stops_the_run_in_every_family(family, scheme, scene, tmp_path, monkeypatch):
    """With GMRES limited to one iteration, the run stops at the first solve (exit status 1) with one line that names
    the solve, the tolerance and the residual reached, and .info counts the iteration it made; the control (no
    limit) completes, and its solves took more than one iteration each at least once."""
    status, errors, _, iterations = run_scene(tmp_path / 'control', scene, scheme, monkeypatch)
    assert status == 0, errors
    assert max(iterations) > 1, iterations  # the limit below binds
    monkeypatch.setattr(Solver, 'max_iterations', 1)
    status, errors, info, iterations = run_scene(tmp_path / 'limited', scene, scheme, monkeypatch)
    assert status == 1
    stopped = [line for line in errors.splitlines() if 'did not converge' in line]
    assert len(stopped) == 1 and 'solver_tolerance 1e-08 in 1 iterations (relative residual' in stopped[0], errors
    residual = float(stopped[0].split('relative residual ')[1].split(')')[0])
    assert residual > 1e-8
    assert iterations and max(iterations) == 1
    # the solves made before the stop (the one that failed included) are counted
    assert int(info['deterministic_iterations_count']) == sum(iterations)


def test_the_static_script_flags_a_solve_that_does_not_converge(tmp_path, monkeypatch, capsys):
    """scheme mobility with GMRES limited to one iteration: the velocities are written, the script says they are not
    converged (tolerance, iterations, residual above the tolerance) and exits 1; without the limit it exits 0."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        'static_script_under_test', os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                                 'multi_bodies', 'multi_bodies_utilities.py'))
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    files, lines = rigid_scene('mobility')
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    lines = [line for line in lines if not line.startswith(('dt', 'kT', 'seed'))]
    (tmp_path / 'input.dat').write_text('\n'.join(lines + ['eta 1.0', 'solver_tolerance 1e-8',
                                                           'output_name run']) + '\n')
    monkeypatch.chdir(tmp_path)
    assert script.main(['--input-file', 'input.dat']) == 0
    converged = np.loadtxt('run.velocities.dat')
    monkeypatch.setattr(Solver, 'max_iterations', 1)
    capsys.readouterr()
    assert script.main(['--input-file', 'input.dat']) == 1
    err = capsys.readouterr().err
    assert 'GMRES did not converge to solver_tolerance 1e-08 in 1 iterations' in err
    residual = float(err.split('relative residual ')[1].split(')')[0])
    assert residual > 1e-8
    flagged = np.loadtxt('run.velocities.dat')
    assert flagged.shape == converged.shape and not np.allclose(flagged, converged, rtol=1e-6, atol=0)


def test_the_published_lubrication_face_flags_its_solve():
    """``Lub_Solver.Lubrucation_solve`` stopped at ``its_out`` iterations returns its velocities and the residual
    reached, above the tolerance (the published behaviour), instead of raising; with room it meets the tolerance."""
    import Lub_Solver
    from body.body import Body
    bodies = []
    for location in ([0.0, 0.0, 1.5], [2.3, 0.0, 1.4], [1.0, 2.2, 1.3]):
        body = Body(np.array(location), np.array([1.0, 0, 0, 0]), np.zeros((1, 3)), 1.0)
        bodies.append(body)
    solver = Lub_Solver.Lub_Solver(bodies, 1.0, 1.0, 4.5, np.zeros(3))
    solver.Set_R_Mats()
    force = np.tile([0.0, 0.0, -1.0, 0.0, 0.0, 0.0], 3)
    _, (residual,) = solver.Lubrucation_solve(None, force, its_out=1)
    assert residual > solver.tolerance
    _, (residual,) = solver.Lubrucation_solve(None, force)
    assert residual <= solver.tolerance


def test_the_tally_counts_each_solve_by_its_kind():
    """The counts a Solver adds are the iterations its solves returned, in the fields of their kind (.info's split
    of the GMRES iterations), and a solve that stops is counted before the stop."""
    A = np.diag(np.linspace(1.0, 50.0, 40)) + 0.01

    class Problem(LinearProblem):  # a plain linear problem of the protocol
        size = 40

        @staticmethod
        def matvec(x):
            return A @ x

        @staticmethod
        def prepare_rhs(rhs):
            return rhs

        @staticmethod
        def solution(x):
            return body_solver.SolutionParts(None, x.reshape(-1, 4), None)
    tally = Tally()
    solver = Solver(1e-10, tally=tally)
    b = np.linspace(1.0, 2.0, 40)
    problem = Problem()
    first = solver.solve(problem, b, None, kind='deterministic')
    second = solver.solve(problem, b, None, kind='stochastic')
    third = solver.solve(problem, b, None, kind='concentration')
    assert np.allclose(A @ first.velocities.reshape(-1), b, rtol=0, atol=1e-8)
    counters = tally.after(Counters())
    assert counters.gmres_iterations == first.iterations + second.iterations
    assert counters.gmres_stochastic_iterations == second.iterations and counters.stochastic_solves == 1
    assert counters.deterministic_solves == 1 and counters.laplace_iterations == third.iterations
    assert tally.last_iterations == first.iterations  # the progress line's: the last deterministic solve
    with pytest.raises(SimulationStopped, match='GMRES of the test problem did not converge') as stop:
        solver.solve(problem, b, None, maxiter=2, what='the test problem')
    assert '\n' not in str(stop.value)
    assert tally.after(Counters()).gmres_iterations == counters.gmres_iterations + 2
    flagged = solver.replace(not_converged='flag').solve(problem, b, None, maxiter=2)
    assert not flagged.converged and flagged.residual > 1e-10
