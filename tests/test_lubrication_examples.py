"""The published lubrication examples run unchanged with their own drivers over the ``Lub_Solver`` face.

Each test copies a published example folder (``../shared/reference/lubrication/examples``) into a
temporary directory, shortens its input (``n_steps``; the copy only), and runs its ``main_*.py`` in a
subprocess with the repository on PYTHONPATH.  Test devices, not parts of the package:

* (no stub any more: the drivers' unused ``from sksparse.cholmod import cholesky`` finds the package's own
  ``sksparse`` face, as after the README's install);
* the two Python 3 fixes the reference README lists for Magnetic_Chain_With_Twist, applied to the copy:
  tabs expanded in ``main_chain.py``, ``r_vectors.size / 3`` -> ``// 3`` in its force file.

The deterministic chain run (``runs_Magnetic_Chain_With_Twist/input_det.dat``, kT = 0: Heun's method)
is compared frame by frame with the published run at the GMRES tolerance (1e-4 relative).
Force files that import numba (Colloidal_Quasicrystal) are skipped when numba is not installed.
"""
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
REFERENCE = REPO.parent / 'shared' / 'reference' / 'lubrication'
EXAMPLES = REFERENCE / 'examples'
CHAIN_RUNS = REFERENCE / 'runs_Magnetic_Chain_With_Twist'
HAS_NUMBA = importlib.util.find_spec('numba') is not None

pytestmark = pytest.mark.skipif(not EXAMPLES.is_dir(), reason='the published lubrication examples are not in '
                                                              '../shared/reference/lubrication/examples')


def set_option(text, name, value):
    """The input text with option ``name`` set to ``value`` (the line replaced)."""
    pattern = re.compile(r'^%s\s.*$' % re.escape(name), re.MULTILINE)
    assert pattern.search(text), name
    return pattern.sub('%s %s' % (name, value), text)


def run_driver(folder, driver, input_file, timeout=600):
    """Run ``python driver --input-file input_file`` in ``folder``; returns the CompletedProcess."""
    paths = [str(REPO)] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(paths), OMP_NUM_THREADS='2')
    result = subprocess.run([sys.executable, driver, '--input-file', input_file], cwd=folder, env=env,
                            capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


def read_config(path):
    """Frames (F, N, 7) of a published ``.config`` file (N [B_z], then x y z q0 q1 q2 q3 per sphere)."""
    lines = [line for line in Path(path).read_text().splitlines() if line.strip()]
    frames, i = [], 0
    while i < len(lines):
        n = int(lines[i].split()[0])  # the quasicrystal drivers add the field B_z after N
        frames.append(np.array([[float(x) for x in line.split()] for line in lines[i + 1:i + 1 + n]]))
        i += n + 1
    return np.array(frames)


def copy_example(tmp_path, name):
    target = tmp_path / 'work' / name
    shutil.copytree(EXAMPLES / name, target)
    return target


def python3_fixes_of_the_chain(folder):
    """The two Python 3 fixes of the reference README, on the copy."""
    driver = folder / 'main_chain.py'
    driver.write_text(driver.read_text().expandtabs(8))
    forces = folder / 'multi_bodies_functions.py'
    forces.write_text(forces.read_text().replace('r_vectors.size / 3', 'r_vectors.size // 3'))


def shorten(folder, input_name, n_steps, **options):
    path = folder / input_name
    text = set_option(path.read_text(), 'n_steps', n_steps)
    for name, value in options.items():
        text = set_option(text, name, value)
    path.write_text(text)


@pytest.mark.skipif(not CHAIN_RUNS.is_dir(), reason='runs_Magnetic_Chain_With_Twist is not in ../shared/reference')
def test_deterministic_chain_run_equals_the_published_run(tmp_path):
    folder = copy_example(tmp_path, 'Magnetic_Chain_With_Twist')
    python3_fixes_of_the_chain(folder)
    shutil.copy(CHAIN_RUNS / 'input_det.dat', folder / 'input_det.dat')
    (folder / 'data').mkdir(exist_ok=True)
    log = run_driver(folder, 'main_chain.py', 'input_det.dat').stdout
    assert 'Number of rejected timesteps wall: 0' in log
    ours = read_config(folder / 'data' / 'chain_det.chain_60.config')
    reference = read_config(CHAIN_RUNS / 'chain_det.chain_60.config')
    start = np.loadtxt(folder / 'chain_60.clones', skiprows=1)
    assert ours.shape == reference.shape == (6, 60, 7)
    for frame, (mine, theirs) in enumerate(zip(ours, reference)):
        moved = np.linalg.norm(theirs[:, :3] - start[:, :3])
        # GMRES tolerance 1e-4 of the run: the displacement since the start agrees to 1e-4 relative
        # (measured 4e-5 after one step, 9e-6 after six)
        assert np.linalg.norm(mine[:, :3] - theirs[:, :3]) <= 1e-4 * moved, frame
        np.testing.assert_allclose(mine[:, 3:], theirs[:, 3:], atol=1e-5)


def test_chain_example_with_its_own_input_runs_two_stochastic_steps(tmp_path):
    folder = copy_example(tmp_path, 'Magnetic_Chain_With_Twist')
    python3_fixes_of_the_chain(folder)
    shorten(folder, 'inputfile_chain.dat', 2)
    (folder / 'data').mkdir(exist_ok=True)
    run_driver(folder, 'main_chain.py', 'inputfile_chain.dat')
    frames = read_config(folder / 'data' / 'twist_helix.chain_60.config')
    start = np.loadtxt(folder / 'chain_60.clones', skiprows=1)
    assert frames.shape == (1, 60, 7)  # n_save 20: the first step is saved
    assert 0 < np.abs(frames[0, :, :3] - start[:, :3]).max() < 0.5


@pytest.mark.slow
def test_colloidal_sheets_runs_unchanged(tmp_path):
    """520 spheres; one step takes about 9 s here, 8.5 s of it in the example's pure-Python pair forces."""
    folder = copy_example(tmp_path, 'Colloidal_Sheets')
    shorten(folder, 'inputfile_suspension.dat', 1)
    run_driver(folder, 'main_chain.py', 'inputfile_suspension.dat')
    outputs = list((folder / 'data').glob('*.config'))
    assert len(outputs) == 1 and read_config(outputs[0]).shape[0] == 1


def corner_of_the_roller_suspension(folder, clones_name, count=256, a=1.0155, phi=0.4):
    """A smaller roller suspension at the same area fraction: the rollers of the published 2048 (wrapped into
    the driver's box ``sqrt(pi a^2 N / phi)``) that lie in a corner square holding about ``count``; written to
    ``corner.clones``.  (One step of the 2048 rollers takes about a minute here: far-field products of 1 s.)"""
    data = np.loadtxt(folder / clones_name, skiprows=1)
    box = np.sqrt(np.pi * a ** 2 * data.shape[0] / phi)
    side = np.sqrt(np.pi * a ** 2 * count / phi)
    wrapped = data[:, :2] % box
    kept = data[(wrapped[:, 0] < side) & (wrapped[:, 1] < side)]
    kept[:, :2] = wrapped[(wrapped[:, 0] < side) & (wrapped[:, 1] < side)]
    lines = ['%d' % kept.shape[0]] + [' '.join('%.16g' % x for x in row) for row in kept]
    (folder / 'corner.clones').write_text('\n'.join(lines) + '\n')
    return kept.shape[0]


def test_uniform_rollers_run_unchanged_and_write_their_torques(tmp_path):
    folder = copy_example(tmp_path, 'Uniform_Rollers')
    clones = 'big_a_8kt_experiment_hard_phi_0.4_n_2048_eq.clones'
    count = corner_of_the_roller_suspension(folder, clones)
    shorten(folder, 'inputfile_rollers_exp.dat', 2, structure='./blob.vertex ./corner.clones')
    (folder / 'data').mkdir(exist_ok=True)
    log = run_driver(folder, 'main_rollers.py', 'inputfile_rollers_exp.dat').stdout
    configs = list((folder / 'data').glob('*.config'))
    torques = list((folder / 'data').glob('*.Torque'))
    assert len(configs) == 1 and len(torques) == 1, log[-2000:]
    assert read_config(configs[0]).shape == (2, count, 7)  # n_save 1: both steps saved
    torque = np.loadtxt(torques[0], comments=None, skiprows=1, max_rows=count)
    assert torque.shape == (count, 3)
    magnitude = np.linalg.norm(torque, axis=1)
    assert np.all(magnitude <= 1.9904 * (1 + 1e-12))  # the driver's torque cap
    assert np.all(torque[:, 1] > 0)  # rollers driven about +y


@pytest.mark.skipif(not HAS_NUMBA, reason='the Colloidal_Quasicrystal force file imports numba, which is not '
                                          'installed (pip install numba; not a dependency of the package)')
@pytest.mark.parametrize('scene', ['Square_to_Diamond', 'Ladder_to_Ring', 'Rhombus_to_Sigma'])
def test_colloidal_quasicrystal_scenes_run_unchanged(tmp_path, scene):
    root = copy_example(tmp_path, 'Colloidal_Quasicrystal')
    folder = root / scene
    shorten(folder, 'inputfile_suspension.dat', 2)
    run_driver(folder, 'main_chain.py', 'inputfile_suspension.dat')
    outputs = list((root / 'data').glob('*.config'))
    assert len(outputs) == 1 and read_config(outputs[0]).shape[0] == 1


def spheres(locations, a=1.0):
    from body.body import Body
    return [Body(location, [1.0, 0.0, 0.0, 0.0], np.zeros((1, 3)), a) for location in locations]


THREE = np.array([[0.0, 0.0, 1.5], [2.3, 0.0, 1.4], [1.0, 2.2, 1.3]])


def test_lub_solver_face_solves_as_the_dense_corrected_mobility():
    from Lub_Solver import Lub_Solver
    from lubrication.problem import dense_lubricated_mobility
    import lubrication
    solver = Lub_Solver(spheres(THREE), 1.0, 1.0, 4.5, np.zeros(3), debye_length=1e-4)
    solver.tolerance = 1e-11
    solver.Set_R_Mats()
    assert solver.Delta_R.shape == solver.R_Sup.shape == solver.R_MB.shape == (18, 18)
    np.testing.assert_allclose((solver.R_Sup - solver.R_MB - solver.Delta_R).toarray(), 0, atol=1e-12)
    M_lub = dense_lubricated_mobility(lubrication.LubricationProblem(THREE, 1.0, 1.0))
    F = np.random.default_rng(4).standard_normal(18)
    X = np.random.default_rng(5).standard_normal(18)
    U, residuals = solver.Lubrucation_solve(X=None, Xm=F)
    np.testing.assert_allclose(U, M_lub @ F, rtol=1e-8, atol=1e-10)
    U, _ = solver.Lubrucation_solve(X=X, Xm=None)
    np.testing.assert_allclose(U, M_lub @ np.linalg.solve(dense_far_field(THREE), X), rtol=1e-7, atol=1e-9)
    torques = solver.Torque_from_Omega(3.0, F.reshape(6, 3))  # FT_calc layout (2N, 3): its forces are used
    ft = np.hstack((F.reshape(6, 3)[0::2], torques))
    np.testing.assert_allclose((M_lub @ ft.ravel()).reshape(3, 6)[:, 3:], np.tile([0, 3.0, 0], (3, 1)), atol=1e-8)


def dense_far_field(locations):
    import lubrication
    from lubrication.problem import dense_far_field_mobility
    return dense_far_field_mobility(lubrication.LubricationProblem(locations, 1.0, 1.0))


def test_lub_solver_face_steps_move_the_bodies_and_count_rejections():
    from Lub_Solver import Lub_Solver
    bodies = spheres(THREE)
    solver = Lub_Solver(bodies, 1.0, 1.0, 4.5, np.zeros(3))
    solver.dt, solver.kT, solver.tolerance = 1e-3, 0.01, 1e-8

    def FT_calc(bodies, r_vectors, push=-1.0):
        assert r_vectors.shape == (len(bodies), 3)
        force_torque = np.zeros((2 * len(bodies), 3))
        force_torque[0::2, 2] = push
        return force_torque
    np.random.seed(1)
    reject_wall, reject_jump, torques = solver.Update_Bodies_Trap(FT_calc, Omega=2.0, Out_Torque=True, Cut_Torque=1.0)
    assert (reject_wall, reject_jump) == (0, 0) and torques.shape == (9,)
    assert np.all(np.abs(torques) <= 1.0 + 1e-12)
    moved = np.array([b.location for b in bodies])
    assert 0 < np.abs(moved - THREE).max() < 0.1
    assert solver.Update_Bodies(FT_calc) == (0, 0)  # Euler-Maruyama (broken in the published code)
    assert solver.Update_Bodies_no_lub(FT_calc) == (0, 0)
    before = np.array([b.location for b in bodies])
    solver.dt = 1e4
    assert solver.Update_Bodies_Trap(lambda b, r: FT_calc(b, r, push=-1e3)) == (1, 0)
    np.testing.assert_array_equal(np.array([b.location for b in bodies]), before)
    assert (solver.num_rejections_wall, solver.num_rejections_jump) == (1, 0)


def test_quaternion_square_root_of_the_published_class():
    from quaternion_integrator.quaternion import Quaternion
    q = Quaternion.from_rotation([0.3, -1.2, 2.5])
    root = q.square_root()
    np.testing.assert_allclose((root * root).entries, q.entries, atol=1e-14)
    np.testing.assert_allclose(root.entries, Quaternion.from_rotation([0.15, -0.6, 1.25]).entries, atol=1e-14)


def test_forces_see_the_centres_in_the_periodic_box_as_published():
    """``Update_Bodies_Trap`` gives FT_calc the sphere centres put in the periodic box, as the published
    ``put_r_vecs_in_periodic_box`` loop does (written out here): whole periods added below 0, taken off above L,
    a coordinate on a box face kept; the non-periodic axis untouched."""
    import numpy as np
    from Lub_Solver import in_periodic_box

    def published_loop(r_vecs_np, L):
        r_vecs = np.copy(r_vecs_np)
        for r_vec in r_vecs:
            for i in range(3):
                if L[i] > 0:
                    while r_vec[i] < 0:
                        r_vec[i] += L[i]
                    while r_vec[i] > L[i]:
                        r_vec[i] -= L[i]
        return r_vecs
    L = np.array([3.0, 4.5, 0.0])
    r = np.random.default_rng(0).uniform(-20.0, 20.0, (500, 3))
    r[:6, 0] = [0.0, 3.0, 6.0, -3.0, -6.0, 7.5]
    np.testing.assert_array_equal(in_periodic_box(r, L), published_loop(r, L))
    assert in_periodic_box(r, L)[1, 0] == 3.0 and in_periodic_box(r, L)[2, 0] == 3.0  # faces kept as published
    np.testing.assert_array_equal(in_periodic_box(r, np.zeros(3)), r)
