"""Articulated rigid bodies (doc/articulated.md): the published examples, the joints, and laws of the method.

Reference runs: ``../shared/reference/published_2025`` relative to the repository root (the published code,
July 2025, its README says how they were made); tests that need them skip with a reason when absent.
"""
import importlib.util
import os
import shutil

import numpy as np
import pytest

from body.body import Configuration
from multi_bodies.files.input_options import parse_input_text, read_input_file
from multi_bodies.run.dynamic_run import run_dynamics
from multi_bodies.run.run_setup import prepare
from multi_bodies.solver import articulated as art
from utils import UserInputError
from multi_bodies.files import snapshots

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PUBLISHED = os.path.join(REPO_ROOT, '..', 'shared', 'reference', 'published_2025', 'multi_bodies')
needs_published = pytest.mark.skipif(not os.path.isdir(PUBLISHED),
                                     reason='published reference runs not found at %s' % PUBLISHED)
# The published bacteria override file imports numexpr (it does not use it); it runs unchanged only with it.
needs_numexpr = pytest.mark.skipif(importlib.util.find_spec('numexpr') is None,
                                   reason="the published bacteria user_defined_functions.py imports numexpr, "
                                          "which is not installed (pip install numexpr)")


def read_frames(path):
    """Every snapshot of a ``save_clones one_file`` ``.config`` (n_frames, Nb, 7), by the package's reader."""
    return snapshots.read_config_frames(str(path))


def copy_example(tmp_path, name):
    shutil.copytree(os.path.join(PUBLISHED, 'examples', name), tmp_path / 'examples' / name)
    shutil.copytree(os.path.join(PUBLISHED, 'Structures'), tmp_path / 'Structures')
    folder = tmp_path / 'examples' / name
    for old in folder.glob('run_*'):  # the published outputs are read from the reference, not from the copy
        old.unlink()
    return folder


def run_example(folder, input_file, monkeypatch):
    monkeypatch.chdir(folder)
    options = read_input_file(input_file, 'dynamic')
    assert run_dynamics(options, log=lambda *a: None) == 0
    return options


def joint_residuals(options, frames, dt, n_save):
    """Max joint residual of every saved frame (length units), from the files the run copied."""
    spec = options.articulated[0]
    const = art.read_const_file('%s.%s' % (options.output_name, os.path.basename(spec.const_file)), 'test')
    joints = art.ArticulatedSet()
    joints.add(const, 0, frames.shape[1] // const.num_bodies)
    return np.array([np.max(np.abs(joints.violation(Configuration(f[:, :3], f[:, 3:]), k * n_save * dt)))
                     for k, f in enumerate(frames)])


# ------------------------------------------------------------------------------------------ published examples
@needs_published
def test_bacteria_constant_angular_velocity_equals_the_published_run(tmp_path, monkeypatch):
    """Active joint (prescribed relative rotation, 3 joints lock the relative motion): the solution of every step,
    nonlinear correction included, is unique, so the trajectory equals the published one to the solver tolerance
    (solver_tolerance 1e-10 and nonlinear_solver_tolerance 1e-10 on lengths of order 1: atol 1e-9).
    The example's override file runs unchanged when numexpr is installed; without numexpr it is removed, which
    changes nothing here: it only replaces the python body-body force-torque, which this input does not select
    (body_body_force_torque_implementation None)."""
    folder = copy_example(tmp_path, 'bacteria')
    if importlib.util.find_spec('numexpr') is None:
        (folder / 'user_defined_functions.py').unlink()
    options = run_example(folder, 'inputfile_bacteria_constant_angular_velocity.dat', monkeypatch)
    ours = read_frames('run_constant_angular_velocity.bacteria.config')
    published = read_frames(os.path.join(PUBLISHED, 'examples', 'bacteria',
                                         'run_constant_angular_velocity.bacteria.config'))
    assert ours.shape == published.shape == (9, 2, 7)
    assert np.max(np.abs(ours - published)) < 1e-9
    assert np.all(joint_residuals(options, ours, options.dt, options.n_save) < options.nonlinear_solver_tolerance)
    # the copies of the articulated files, as the published run writes them
    for name in ('bacteria.list_vertex', 'bacteria_active.const'):
        assert open('run_constant_angular_velocity.' + name).read() == \
            open(os.path.join(PUBLISHED, 'examples', 'bacteria', 'run_constant_angular_velocity.' + name)).read()
    info = open('run_constant_angular_velocity.info').read()
    assert 'nonlinear_iterations_count     = 64' in info  # the published count (same least-squares problems)


@needs_published
@needs_numexpr
def test_bacteria_constant_torque_follows_the_published_run(tmp_path, monkeypatch):
    """Constant torque between body and flagellum (the published override, unchanged) with two passive joints on
    the flagellum axis (a hinge).  The spin about the hinge axis is free in the nonlinear correction's
    least-squares problem, so the spin that the correction adds depends on its dogbox iterations, which the bounds
    of the unknowns steer: those bounds and the tolerance check use the published size of the residuals, the
    matrix infinity norm of the (nc, 3) joint residuals (articulated.joint_residual_norm).  Measured: 2.8e-14
    after 8 steps (3.4e-15 after one), the published nonlinear count (79); one step from each published frame
    gives the next to 4e-15.  (With the largest residual component instead: 9.5e-9 after one step, 2.6e-5 after
    8.)  The joints hold to nonlinear_solver_tolerance at every step."""
    folder = copy_example(tmp_path, 'bacteria')
    options = run_example(folder, 'inputfile_bacteria_constant_torque.dat', monkeypatch)
    ours = read_frames('run_constant_torque.bacteria_constant_torque.config')
    published = read_frames(os.path.join(PUBLISHED, 'examples', 'bacteria',
                                         'run_constant_torque.bacteria_constant_torque.config'))
    assert ours.shape == published.shape == (9, 2, 7)
    assert np.max(np.abs(ours - published)) < 1e-10
    # the torque turns the flagellum: a rotation much larger than the tolerance above
    assert abs(ours[-1, 1, 6]) > 0.5
    assert np.all(joint_residuals(options, ours, options.dt, options.n_save) < options.nonlinear_solver_tolerance)
    assert np.all(joint_residuals(options, published, options.dt, options.n_save) < 1e-9)
    assert 'nonlinear_iterations_count     = 79' in open('run_constant_torque.info').read()  # the published count


@needs_published
@needs_numexpr
def test_bacteria_constant_torque_runs_the_published_100_steps(tmp_path, monkeypatch):
    """The published input runs 100 steps (the reference cut it to 8).  The two joints on the hinge axis are
    redundant; where they are treated as independent the solve becomes near-singular as the axes drift apart by
    the nonlinear tolerance, and GMRES stagnates (at step 61 before the rank reduction of C).  The joints hold
    at every saved step."""
    folder = copy_example(tmp_path, 'bacteria')
    monkeypatch.chdir(folder)
    options = read_input_file('inputfile_bacteria_constant_torque.dat', 'dynamic')
    options.n_steps, options.n_save = 100, 10
    assert run_dynamics(options, log=lambda *a: None) == 0
    frames = read_frames('run_constant_torque.bacteria_constant_torque.config')
    assert frames.shape[0] == 11
    assert np.all(joint_residuals(options, frames, options.dt, options.n_save) < options.nonlinear_solver_tolerance)


@needs_published
def test_robot_arm_sedimentation_equals_the_published_run(tmp_path, monkeypatch):
    """100 chains of 15 single blobs sedimenting (rollers model: blob translation and rotation).  The published
    run used solver_tolerance 1e-8 (default); our run converged to 1e-12 differs from our default run by 4e-10
    and from the published run by 5e-7 of a 5.3 displacement (1e-7 relative), the published solve's own error:
    atol 2e-6 (4e-7 of the displacement).  Without the rotation-translation couplings the difference is 0.1."""
    folder = copy_example(tmp_path, 'robot_arm_sedimentation_example')
    options = run_example(folder, 'inputfile_robot_arm_N_15_Mx_10_Mz_10_single_blob.dat', monkeypatch)
    name = 'run_robot_arm_N_15_Mx_10_Mz_10_single_blob.robot_arm_N_15_Mx_10_Mz_10.config'
    ours = read_frames(name)
    published = read_frames(os.path.join(PUBLISHED, 'examples', 'robot_arm_sedimentation_example', name))
    assert ours.shape == published.shape == (3, 1500, 7)
    displacement = np.max(np.abs(published[-1, :, :3] - published[0, :, :3]))
    assert displacement > 5
    assert np.max(np.abs(ours - published)) < 2e-6
    assert np.all(joint_residuals(options, ours, options.dt, options.n_save) < options.nonlinear_solver_tolerance)
    assert 'nonlinear_iterations_count     = 0' in open(name.split('.')[0] + '.info').read()


# ------------------------------------------------------------------------------------------ laws of the method
def test_joint_residual_norm_is_the_published_one():
    """The nonlinear correction measures the joint residuals (nc, 3) as the published code: the matrix infinity
    norm (largest row sum of absolute values), not the largest component; it decides whether the correction runs
    and bounds its unknowns (see test_bacteria_constant_torque_follows_the_published_run)."""
    g = np.array([[1e-9, -2e-9, 3e-9], [-4e-9, 0.0, 0.0]])
    assert art.joint_residual_norm(g) == np.linalg.norm(g, ord=np.inf)
    assert art.joint_residual_norm(g) > np.max(np.abs(g))
    assert art.joint_residual_norm(np.zeros((0, 3))) == 0.0


SHELL = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-0.7, -0.3, 0.4],
                  [0.2, -0.8, -0.5]])  # no symmetry
OCTAHEDRON = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]])


def write_chain(folder, n_bodies, spacing, height, locked, lines=(), shape=SHELL):
    """A straight chain along x of ``n_bodies`` identical bodies (SHELL) joined at the midpoints; ``locked``: three
    non-collinear joints per pair (all 6 relative dof constrained), else one ball joint per pair."""
    np.savetxt(folder / 'shell.vertex', shape, header=str(len(shape)), comments='')
    (folder / 'chain.list_vertex').write_text('shell.vertex\n' * n_bodies)
    constraints = []
    for k in range(n_bodies - 1):
        offsets = [(0.0, 0.0, 0.0)] + ([(0.0, 1.0, 0.0), (0.0, 0.0, 1.0)] if locked else [])
        for dy, dz, dx in [(o[1], o[2], o[0]) for o in offsets]:
            constraints.append('%d %d  %g %g %g  %g %g %g' % (k, k + 1, spacing / 2, dy, dz, -spacing / 2, dy, dz))
    (folder / 'chain.const').write_text('%d\n%d\n%s\n' % (n_bodies, len(constraints), '\n'.join(constraints)))
    clones = ['%d' % n_bodies] + ['%g 0 %g 1 0 0 0' % (k * spacing, height) for k in range(n_bodies)]
    (folder / 'chain.clones').write_text('\n'.join(clones) + '\n')
    fused = np.concatenate([shape + [k * spacing, 0, 0] for k in range(n_bodies)])
    np.savetxt(folder / 'fused.vertex', fused, header=str(len(fused)), comments='')
    (folder / 'fused.clones').write_text('1\n0 0 %g 1 0 0 0\n' % height)
    common = ['eta 1.0', 'blob_radius 0.25', 'g 1.0', 'repulsion_strength_wall 0', 'solver_tolerance 1e-12',
              'mobility_blobs_implementation python', 'mobility_vector_prod_implementation python',
              'blob_blob_force_implementation None', 'dt 0.01', 'n_steps 1'] + list(lines)
    return common


def setup_system(folder, text, monkeypatch, script='static'):
    monkeypatch.chdir(folder)
    (folder / 'input.dat').write_text(text)
    options = parse_input_text(text, 'input.dat', 'static' if script == 'static' else 'dynamic')
    return options, prepare(options, script, log=lambda *a: None)


def fused_and_chain_velocities(tmp_path, common, monkeypatch):
    """(velocity (6,) of the blobs fused into one body, the chain's set-up, the chain's articulated velocities)
    of the mobility problem written by ``write_chain`` (both from GMRES at solver_tolerance 1e-12)."""
    from multi_bodies.solver import body_solver
    _, fused = setup_system(tmp_path, '\n'.join(['scheme mobility', 'structure fused.vertex fused.clones']
                                                + common), monkeypatch)
    _, chain = setup_system(tmp_path, '\n'.join(['scheme mobility', 'articulated chain.list_vertex chain.clones '
                                                 'chain.const'] + common), monkeypatch)
    system = fused.system
    problem = system.mobility_problem(system.start_configuration)
    reference = body_solver.solve(problem, problem.rhs(force_torque=system.forces_torques(system.start_configuration)),
                                  system.build_preconditioner(system.start_configuration), tolerance=1e-12).velocities[0]
    result = art.articulated_velocities(chain.system, chain.system.articulated, chain.system.start_configuration, 0.0)
    return reference, chain, result


def test_locked_chain_under_gravity_moves_as_the_fused_rigid_body(tmp_path, monkeypatch):
    """A chain whose joints constrain all 6 relative dof is one rigid body: each body's velocity is that rigid
    motion, ``v_k = V + W x (q_k - q_0)``, ``w_k = W``, with (V, W) of the same blobs fused into one body.  The
    chain sediments near the wall (gravity on every blob, one force per blob), so W is not zero.  Both come from
    GMRES at solver_tolerance 1e-12: agreement to 1e-9 of |V|."""
    common = write_chain(tmp_path, 3, 2.5, 3.0, locked=True)
    reference, chain, result = fused_and_chain_velocities(tmp_path, common, monkeypatch)
    assert result.converged
    V, W = reference[:3], reference[3:]
    q = chain.system.start_configuration.locations
    expected = np.concatenate((V + np.cross(W, q - q[0]), np.tile(W, (3, 1))), axis=1)
    assert np.linalg.norm(W) > 1e-3 * np.linalg.norm(V)  # the wall makes the fused body turn
    assert np.max(np.abs(result.velocities - expected)) < 1e-9 * np.linalg.norm(V)
    # and the joints move together: C U = 0
    a, _ = chain.system.articulated.lab_links(chain.system.start_configuration, 0.0)
    assert np.max(np.abs(chain.system.articulated.C_dot(a, result.velocities))) < 1e-9 * np.linalg.norm(V)


def test_locked_chain_far_from_the_wall_sediments_as_one_body(tmp_path, monkeypatch):
    """Far from the wall (free-space mobilities) a locked chain under gravity translates as one body: the chain of
    octahedra is symmetric under inversion through its middle, so by symmetry W = 0 and every body has the
    same velocity, and a step of the
    articulated scheme moves every body by the same displacement (to 1e-9 relative)."""
    common = write_chain(tmp_path, 3, 2.5, 3.0, locked=True, lines=['nonlinear_solver_tolerance 1e-12'],
                         shape=OCTAHEDRON)
    common = [line.replace('python', 'python_no_wall') if 'mobility' in line else line for line in common]
    text = '\n'.join(['scheme articulated_deterministic_forward_euler', 'output_name run', 'save_clones one_file',
                      'articulated chain.list_vertex chain.clones chain.const'] + common)
    options, setup = setup_system(tmp_path, text, monkeypatch, script='dynamics')
    result = art.articulated_velocities(setup.system, setup.system.articulated, setup.system.start_configuration, 0.0)
    U = result.velocities
    assert np.max(np.abs(U - U[1])) < 1e-9 * np.linalg.norm(U[1])
    assert np.linalg.norm(U[1, :3]) > 0 and U[1, 2] < 0
    assert run_dynamics(options, log=lambda *a: None) == 0
    frames = read_frames('run.chain.config')
    displacement = frames[-1, :, :3] - frames[0, :, :3]
    assert np.max(np.abs(displacement - displacement[1])) < 1e-9 * np.linalg.norm(displacement[1])


def test_the_velocities_follow_a_moving_joint_to_second_order(tmp_path, monkeypatch):
    """Two octahedra joined at a point that moves in body p's frame, ``l_p(t) = (1.25 + 0.5 sin 2t, 0, 0)`` (the
    .const line's expressions), under gravity.  The velocity solve at t = 0 must make the joint residual
    ``g = q_p + R_p l_p(t) - q_q - R_q l_q`` stationary along the motion, so moving the bodies with the solved
    velocities for h (no restoration) leaves ``|g(h)| = O(h^2)``: halving h divides it by 4.  With the wrong sign of
    the moving link's term (``B = +(R_p dl_p/dt - R_q dl_q/dt)``) the residual would be ``2 h |dl_p/dt| = 2 h``,
    first order; asserted below 1 % of ``h |dl_p/dt|`` (measured 4e-5 of it at h = 1e-3, ratio 4.0)."""
    from quaternion_integrator.scheme_base import moved
    np.savetxt(tmp_path / 'shell.vertex', OCTAHEDRON, header='6', comments='')
    (tmp_path / 'pair.list_vertex').write_text('shell.vertex\nshell.vertex\n')
    moving = '1.25+0.5*sin(2*t) 0 0 -1.25 0 0 cos(2*t) 0 0 0 0 0'
    (tmp_path / 'pair.const').write_text('2\n1\n0 1  1.25 0 0  -1.25 0 0  %s\n' % moving)
    (tmp_path / 'pair.clones').write_text('2\n0 0 3 1 0 0 0\n2.5 0 3 1 0 0 0\n')
    text = '\n'.join(['scheme articulated_deterministic_forward_euler', 'output_name run', 'eta 1.0',
                      'blob_radius 0.25', 'g 1.0', 'repulsion_strength_wall 0', 'solver_tolerance 1e-12',
                      'mobility_blobs_implementation python', 'mobility_vector_prod_implementation python',
                      'blob_blob_force_implementation None', 'dt 0.01', 'n_steps 1',
                      'articulated pair.list_vertex pair.clones pair.const'])
    _, setup = setup_system(tmp_path, text, monkeypatch, script='dynamics')
    system = setup.system
    joints, start = system.articulated, system.start_configuration
    assert np.max(np.abs(joints.violation(start, 0.0))) < 1e-14  # the joint holds at t = 0
    U = art.articulated_velocities(system, joints, start, 0.0).velocities
    assert np.linalg.norm(U[:, 3:]) > 1e-3  # the bodies turn: R_p l_p moves too
    residual = {h: np.max(np.abs(joints.violation(moved(start, U, h), h))) for h in (1e-3, 5e-4)}
    link_rate = 1.0  # |dl_p/dt| at t = 0
    assert residual[1e-3] < 0.01 * 1e-3 * link_rate, residual
    assert residual[1e-3] / residual[5e-4] > 3.0, residual  # second order in h


def joint_residuals_from_file(frames, const_path):
    """|q_p + R_p l_p - q_q - R_q l_q| (frames, joints) of saved frames (F, Nb, 7), from the .const file's links.

    Computed here from the file and the quaternions (R(q) = 2 [[p p^T + s^2 - 1/2] + s [p]_x], scalar first),
    not with the package's joint code, so a change of where the package puts a joint shows up.
    """
    lines = open(const_path).read().split('\n')
    rows = np.array([[float(x) for x in line.split()] for line in lines[2:2 + int(lines[1])]])
    p, q, lp, lq = rows[:, 0].astype(int), rows[:, 1].astype(int), rows[:, 2:5], rows[:, 5:8]
    s, v = frames[..., 3], frames[..., 4:7]
    R = 2 * (v[..., :, None] * v[..., None, :] + (s ** 2 - 0.5)[..., None, None] * np.eye(3))
    cross = np.zeros(v.shape + (3,))
    cross[..., 0, 1], cross[..., 0, 2], cross[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    R = R + 2 * s[..., None, None] * (cross - np.swapaxes(cross, -1, -2))
    ends_p = frames[:, p, :3] + np.einsum('fkij,kj->fki', R[:, p], lp)
    ends_q = frames[:, q, :3] + np.einsum('fkij,kj->fki', R[:, q], lq)
    return np.linalg.norm(ends_p - ends_q, axis=2)


@pytest.mark.parametrize('scheme', ['articulated_deterministic_forward_euler', 'articulated_deterministic_midpoint'])
def test_joints_hold_at_every_saved_step(tmp_path, monkeypatch, scheme):
    """A chain of four bodies with ball joints bends as it sediments near the wall; at every saved step the
    joints, measured from the .const file (not with the package's joint code), hold to
    nonlinear_solver_tolerance 1e-10 (and the bodies do move and turn: a scheme that stood still would pass the
    joint check).  Negative control: the same residual of a joint moved by 1e-3 in the .const file is 1e-3."""
    common = write_chain(tmp_path, 4, 2.5, 2.0, locked=False, lines=['nonlinear_solver_tolerance 1e-10'])
    common = [line for line in common if not line.startswith('n_steps')]
    text = '\n'.join(['scheme ' + scheme, 'output_name run', 'save_clones one_file', 'n_steps 12', 'n_save 1',
                      'articulated chain.list_vertex chain.clones chain.const'] + common)
    options, _ = setup_system(tmp_path, text, monkeypatch, script='dynamics')
    assert run_dynamics(options, log=lambda *a: None) == 0
    frames = read_frames('run.chain.config')
    assert frames.shape[:2] == (13, 4)
    residuals = joint_residuals_from_file(frames, tmp_path / 'chain.const')
    assert residuals.shape == (13, 3) and np.max(residuals) < 1e-9, np.max(residuals)
    assert np.max(frames[-1, :, 2] - frames[0, :, 2]) < -1e-3  # they fall ...
    assert np.max(np.abs(frames[-1, :, 4:] - frames[0, :, 4:])) > 1e-4  # ... and turn (the chain bends)
    moved = (tmp_path / 'chain.const').read_text().replace('1.25 0 0  -1.25 0 0', '1.251 0 0  -1.25 0 0', 1)
    (tmp_path / 'moved.const').write_text(moved)
    assert abs(np.max(joint_residuals_from_file(frames[:1], tmp_path / 'moved.const')) - 1e-3) < 1e-9


def test_chain_of_single_blobs_with_the_multiblob_schemes_is_the_pinv_answer(tmp_path, monkeypatch):
    """Single-blob bodies in the blob saddle-point problem have a rank-deficient K: they resist no rotation, so
    (as body_solver's pinv answer) they get no angular velocity and a torque on them is projected out.  Joined by
    ball joints at the midpoints they then move as the rod of the same blobs fused into one rigid body: in free
    space under gravity that rod only translates (its rotations about y and z change sign under the reflection
    x -> -x, which leaves the problem unchanged; about its axis it has no resistance, so pinv gives 0).
    GMRES at solver_tolerance 1e-12: agreement to 1e-9 of |V|."""
    common = write_chain(tmp_path, 5, 2.5, 3.0, locked=False, shape=np.zeros((1, 3)))
    common = [line.replace('python', 'python_no_wall') if 'mobility' in line else line for line in common]
    reference, chain, result = fused_and_chain_velocities(tmp_path, common, monkeypatch)
    assert result.converged
    V = reference[:3]
    assert np.linalg.norm(reference[3:]) < 1e-9 * np.linalg.norm(V) and V[2] < 0
    expected = np.concatenate((np.tile(V, (5, 1)), np.zeros((5, 3))), axis=1)
    assert np.max(np.abs(result.velocities - expected)) < 1e-9 * np.linalg.norm(V)


def test_several_articulated_lines_and_structures_in_one_run(tmp_path, monkeypatch):
    """A rigid body, one articulated line with two copies of a 3-body chain and a second articulated line, far
    apart (1e5, free space): each moves as it does alone, to their hydrodynamic coupling (blob size over distance,
    1e-5 relative; asserted 1e-3), which checks that bodies and joints of every line and copy are numbered right.
    """
    common = write_chain(tmp_path, 3, 2.5, 0.0, locked=False)
    common = [line.replace('python', 'python_no_wall') if 'mobility' in line else line for line in common]
    chain = np.loadtxt(tmp_path / 'chain.clones', skiprows=1)
    copies = np.concatenate((chain + [1e5, 0, 0, 0, 0, 0, 0], chain + [2e5, 0, 0, 0, 0, 0, 0]))
    copies[3:, 3:] = [0.9, 0.3, -0.2, np.sqrt(1 - 0.94)]  # the second copy turned: a different motion
    (tmp_path / 'copies.clones').write_text('6\n' + '\n'.join(' '.join(repr(float(v)) for v in row) for row in copies))
    (tmp_path / 'free.clones').write_text('1\n3e5 0 0 1 0 0 0\n')
    lines = ['scheme mobility', 'structure shell.vertex free.clones',
             'articulated chain.list_vertex copies.clones chain.const',
             'articulated chain.list_vertex chain.clones chain.const']
    _, together = setup_system(tmp_path, '\n'.join(lines + common), monkeypatch)
    assert together.system.articulated.num_constraints == 6
    both = art.articulated_velocities(together.system, together.system.articulated,
                                      together.system.start_configuration, 0.0).velocities
    alone = []
    for clones in ('free', 'copies_0', 'copies_1', 'chain'):
        if clones == 'free':
            text = lines[:2]
        else:
            rows = {'copies_0': copies[:3], 'copies_1': copies[3:], 'chain': chain}[clones]
            (tmp_path / (clones + '.clones')).write_text('3\n' + '\n'.join(' '.join(repr(float(v)) for v in row)
                                                                           for row in rows))
            text = ['scheme mobility', 'articulated chain.list_vertex %s.clones chain.const' % clones]
        _, setup = setup_system(tmp_path, '\n'.join(text + common), monkeypatch)
        if setup.system.articulated is None:
            from multi_bodies.solver import body_solver
            problem = setup.system.mobility_problem(setup.system.start_configuration)
            alone.append(body_solver.solve(problem, problem.rhs(force_torque=setup.system.forces_torques(
                setup.system.start_configuration)), setup.system.build_preconditioner(setup.system.start_configuration),
                tolerance=1e-12).velocities)
        else:
            alone.append(art.articulated_velocities(setup.system, setup.system.articulated,
                                                    setup.system.start_configuration, 0.0).velocities)
    alone = np.concatenate(alone)
    assert np.max(np.abs(both - alone)) < 1e-3 * np.max(np.abs(alone))
    assert np.max(np.abs(alone[4:7] - alone[1:4])) > 1e-2 * np.max(np.abs(alone))  # the copies differ


@needs_published
def test_active_swimmer_exerts_no_net_force_or_torque_on_the_fluid(tmp_path, monkeypatch):
    """The bacterium of the published example with its active joint and no external force (g = 0, the blob-blob
    repulsion is internal): the joint forces are internal too (C^T phi has zero sum and zero moment), so the
    blob forces on the fluid have zero sum and zero moment about the origin, to the solver tolerance times the
    size of the blob forces."""
    folder = copy_example(tmp_path, 'bacteria')
    (folder / 'user_defined_functions.py').unlink()  # not needed here (no torque), and it imports numexpr
    monkeypatch.chdir(folder)
    options = read_input_file('inputfile_bacteria_constant_angular_velocity.dat', 'dynamic')
    setup = prepare(options, 'dynamics', log=lambda *a: None)
    system = setup.system
    result = art.articulated_velocities(system, system.articulated, system.start_configuration, 0.0)
    lam = result.lambda_blobs
    r = system.blob_positions(system.start_configuration)
    scale = np.sum(np.linalg.norm(lam, axis=1)) * (1 + np.max(np.abs(r)))
    assert np.linalg.norm(result.velocities[1, 3:] - result.velocities[0, 3:]) > 50  # the motor turns (100 rad/s)
    assert np.linalg.norm(lam.sum(axis=0)) < 1e-8 * scale
    assert np.linalg.norm(np.cross(r, lam).sum(axis=0)) < 1e-8 * scale


@needs_published
def test_articulated_restart_continues_the_uninterrupted_run(tmp_path, monkeypatch):
    """initial_step 2 picks up the restart record of step 2 (configuration, warm start, counters) and the last
    step equals that of the uninterrupted 4-step run bit for bit (the same operations in the same order)."""
    folder = copy_example(tmp_path, 'bacteria')
    (folder / 'user_defined_functions.py').unlink()  # not needed without the torque (it imports numexpr)
    monkeypatch.chdir(folder)
    options = read_input_file('inputfile_bacteria_constant_angular_velocity.dat', 'dynamic')
    options.n_steps, options.output_name = 4, 'whole'
    assert run_dynamics(options, log=lambda *a: None) == 0
    options = read_input_file('inputfile_bacteria_constant_angular_velocity.dat', 'dynamic')
    options.n_steps, options.output_name = 2, 'pieces'
    assert run_dynamics(options, log=lambda *a: None) == 0
    options = read_input_file('inputfile_bacteria_constant_angular_velocity.dat', 'dynamic')
    options.n_steps, options.output_name, options.initial_step = 4, 'pieces', 2
    assert run_dynamics(options, log=lambda *a: None) == 0
    whole, pieces = read_frames('whole.bacteria.config'), read_frames('pieces.bacteria.config')
    assert whole.shape == pieces.shape == (5, 2, 7)
    assert np.array_equal(whole[-1], pieces[-1])
    assert open('whole.info').read().split('nonlinear')[1] == open('pieces.info').read().split('nonlinear')[1]


@needs_published
def test_vtk_output_shows_the_joints(tmp_path, monkeypatch):
    """save_vtk: output_name.joints.<step>.vtp holds every joint at q_p + R_p l_p; read back (pyvista) it is
    also at q_q + R_q l_q of the saved configuration, to the nonlinear tolerance (the joint holds)."""
    folder = copy_example(tmp_path, 'bacteria')
    (folder / 'user_defined_functions.py').unlink()  # not needed without the torque (it imports numexpr)
    monkeypatch.chdir(folder)
    options = read_input_file('inputfile_bacteria_constant_angular_velocity.dat', 'dynamic')
    options.n_steps, options.output_name, options.save_vtk = 2, 'vtk', True
    assert run_dynamics(options, log=lambda *a: None) == 0
    assert 'vtk.joints.00000002.vtp' in open('vtk.joints.pvd').read()
    pyvista = pytest.importorskip('pyvista', reason='pyvista is not installed: the VTK files cannot be read back')
    frame = read_frames('vtk.bacteria.config')[-1]
    const = art.read_const_file('vtk.bacteria_active.const', 'test')
    joints = art.ArticulatedSet()
    joints.add(const, 0, 1)
    a, _ = joints.lab_links(Configuration(frame[:, :3], frame[:, 3:]), 2 * options.dt)
    from_q = frame[joints.bodies[:, 1], :3] + a[:, 3:]
    points = np.asarray(pyvista.read('vtk.joints.00000002.vtp').points)
    assert points.shape == (3, 3)
    assert np.max(np.abs(points - from_q)) < 1e-9


# ------------------------------------------------------------------------------------------ input
def test_const_file_expressions_and_errors(tmp_path):
    """The 12 extra fields of a .const line are expressions of t (link and its rate); bad input names file/line."""
    path = tmp_path / 'a.const'
    path.write_text('2\n1\n0 1  0 0 1  0 0 -1   1 0 1  cos(-100*t) -sin(-100*t) -0.1  0 0 0  '
                    '100*sin(-100*t) 100*cos(-100*t) 0\n')
    const = art.read_const_file(str(path), 'here')
    values = [f(0.01) for f in const.expressions[0]]
    assert values[3] == pytest.approx(np.cos(-1.0)) and values[10] == pytest.approx(100 * np.cos(-1.0))
    path.write_text('2\n1\n0 1  0 0 1  0 0 -1   1 0 1  __import__("os") 0 0  0 0 0  0 0 0\n')
    with pytest.raises(UserInputError, match='a.const, line 3'):
        art.read_const_file(str(path), 'here')
    path.write_text('2\n2\n0 1  0 0 1  0 0 -1\n')
    with pytest.raises(UserInputError, match='announces 2 constraints'):
        art.read_const_file(str(path), 'here')


def test_other_schemes_refuse_articulated_bodies():
    text = 'scheme deterministic_forward_euler\ndt 0.1\narticulated a.list_vertex a.clones a.const\n'
    with pytest.raises(UserInputError, match="cannot move articulated bodies"):
        parse_input_text(text, 'in.dat', 'dynamic')
    # an articulated scheme moves plain bodies (no joint) as the published code does (tests/test_published_joints.py)
    assert parse_input_text('scheme articulated_deterministic_midpoint\ndt 0.1\n', 'in.dat', 'dynamic').articulated == []


def test_missing_import_in_a_user_file_names_the_package(tmp_path):
    from multi_bodies.solver.user_hooks import load_user_hooks
    (tmp_path / 'user_defined_functions.py').write_text('import not_a_package_here_xyz\n')
    with pytest.raises(UserInputError, match='the user file imports not_a_package_here_xyz, which is not '
                                             'installed; pip install not_a_package_here_xyz or remove the import'):
        load_user_hooks(str(tmp_path))


def test_rotated_vector_jacobian_is_the_derivative_of_the_rotation():
    """d(R(theta) a)/d theta of the joint restoration against central differences of R(theta) a, which are exact
    for its entries (quadratic in theta) up to round-off; at unit and at general quaternions (the least-squares
    iterates are not normalised).  Control: the same differences of another link differ."""
    from multi_bodies.solver.articulated import quaternion_rotation, rotated_vector_jacobian
    rng = np.random.default_rng(4)
    theta = rng.normal(size=(5, 4))
    theta[:2] /= np.linalg.norm(theta[:2], axis=1)[:, None]
    a = rng.normal(size=(5, 3))
    h = 1e-3
    numeric = np.empty((5, 3, 4))
    for j in range(4):
        step = np.zeros(4)
        step[j] = h
        numeric[:, :, j] = (np.einsum('kij,kj->ki', quaternion_rotation(theta + step), a)
                            - np.einsum('kij,kj->ki', quaternion_rotation(theta - step), a)) / (2 * h)
    J = rotated_vector_jacobian(theta, a)
    assert np.abs(J - numeric).max() < 1e-9 * np.abs(numeric).max()
    assert np.abs(rotated_vector_jacobian(theta, a[::-1]) - numeric).max() > 0.1
