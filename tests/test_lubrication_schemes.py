"""Lubrication schemes of multi_bodies.py (quaternion_integrator.lubrication_schemes) and the firm repulsion.

Checked against numbers from outside the code under test: Heun's method written here with the dense
M_lub = (M^-1 + Delta_R)^-1 (a deterministic run, kT = 0), the run split by a restart against the run
in one go (the package's restart law), the firm repulsion against the derivative of its potential.
"""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lubrication
from lubrication.firm_repulsion import firm_range, firm_repulsion_forces
from lubrication.problem import dense_lubricated_mobility

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / 'multi_bodies' / 'multi_bodies.py'
START = np.array([[0.0, 0.0, 1.5], [2.3, 0.0, 1.4], [1.0, 2.2, 1.3]])


def write_scene(folder, scheme='lubrication_trapezoidal', n_steps=5, vertex='1\n0 0 0\n', **extra):
    options = {'scheme': scheme, 'dt': 0.01, 'n_steps': n_steps, 'n_save': 1, 'eta': 1.0, 'g': 1.0,
               'blob_radius': 1.0, 'kT': 0.0, 'solver_tolerance': 1e-10, 'repulsion_strength_wall': 0.0,
               'mobility_vector_prod_implementation': 'C++', 'blob_blob_force_implementation': 'None',
               'Lub_Cut': 4.5, 'firm_delta': 1e-4, 'output_name': 'run', 'save_clones': 'one_file'}
    options.update(extra)
    (folder / 'sphere.vertex').write_text(vertex)
    (folder / 'three.clones').write_text('3\n' + ''.join('%.17g %.17g %.17g 1 0 0 0\n' % tuple(x) for x in START))
    text = ''.join('%s %s\n' % item for item in options.items()) + 'structure sphere.vertex three.clones\n'
    (folder / 'input.dat').write_text(text)


def run(folder):
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS='1')
    return subprocess.run([sys.executable, str(SCRIPT), '--input-file', 'input.dat'], cwd=folder, env=env,
                          capture_output=True, text=True, timeout=600)


def frames(folder):
    lines = [line for line in (folder / 'run.three.config').read_text().splitlines() if line.strip()]
    values = [np.array([[float(x) for x in line.split()] for line in lines[i + 1:i + 4]])
              for i in range(0, len(lines), 4)]
    return np.array(values)


def dense_heun(locations, dt, steps):
    """Heun's method with the dense lubrication-corrected mobility, weight 1 down per sphere (eta = a = 1)."""
    weight = np.zeros((3, 6))
    weight[:, 2] = -1.0

    def velocity(q):
        return (dense_lubricated_mobility(lubrication.LubricationProblem(q, 1.0, 1.0)) @ weight.ravel()).reshape(3, 6)
    for _ in range(steps):
        first = velocity(locations)
        locations = locations + 0.5 * dt * (first + velocity(locations + dt * first[:, :3]))[:, :3]
    return locations


def test_deterministic_lubrication_run_is_heun_with_the_dense_corrected_mobility(tmp_path):
    write_scene(tmp_path)
    result = run(tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    trajectory = frames(tmp_path)
    assert trajectory.shape == (6, 3, 7)
    np.testing.assert_allclose(trajectory[-1, :, :3], dense_heun(START, 0.01, 5), rtol=0, atol=1e-9)
    info = (tmp_path / 'run.info').read_text().splitlines()
    assert info[0].split() == ['invalid_configuration_count', '=', '0']


def test_stochastic_lubrication_run_restarts_exactly(tmp_path):
    whole, split = tmp_path / 'whole', tmp_path / 'split'
    whole.mkdir(), split.mkdir()
    common = dict(kT=0.05, seed=3, firm_delta=1e-2, repulsion_strength_firm=0.1)
    write_scene(whole, n_steps=6, **common)
    write_scene(split, n_steps=3, **common)
    assert run(whole).returncode == 0
    assert run(split).returncode == 0
    write_scene(split, n_steps=6, initial_step=3, **common)
    result = run(split)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    a, b = frames(whole), frames(split)
    assert a.shape == (7, 3, 7) and np.abs(a[-1] - a[0]).max() > 1e-4
    np.testing.assert_allclose(b[-1], a[-1], rtol=0, atol=1e-12)


def test_euler_maruyama_lubrication_run_moves_the_spheres(tmp_path):
    write_scene(tmp_path, scheme='lubrication_EM', kT=0.05, seed=1)
    result = run(tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    trajectory = frames(tmp_path)
    assert 0 < np.abs(trajectory[-1, :, :3] - START).max() < 0.5


def test_multiblob_bodies_are_refused_by_the_lubrication_schemes(tmp_path):
    write_scene(tmp_path, vertex='2\n0 0 0\n0.5 0 0\n')
    result = run(tmp_path)
    assert result.returncode != 0
    assert 'lubrication_trapezoidal: every body must be a single blob' in result.stdout + result.stderr


def test_lubrication_options_are_read_and_unused_elsewhere(tmp_path):
    from multi_bodies.files.input_options import parse_input_text
    options = parse_input_text('scheme lubrication_trapezoidal\ndt 0.01\nLub_Cut 3.5\nfirm_delta 1e-2\n'
                               'repulsion_strength_firm 0.0163\n', 'in.dat', 'dynamic')
    assert (options.Lub_Cut, options.firm_delta, options.repulsion_strength_firm) == (3.5, 1e-2, 0.0163)
    assert not options.warnings
    options = parse_input_text('scheme stochastic_first_order_RFD\ndt 0.01\nLub_Cut 3.5\n', 'in.dat', 'dynamic')
    assert any('Lub_Cut' in warning for warning in options.warnings)
    from utils import UserInputError
    with pytest.raises(UserInputError, match='in.dat, line 1.*Lub_Cut'):
        parse_input_text('Lub_Cut 1.5\n', 'in.dat')


def test_firm_repulsion_is_minus_the_gradient_of_its_potential():
    a, strength, firm_delta = 0.5, 0.0163, 1e-2
    offset, decay = firm_range(a, firm_delta)
    assert decay == pytest.approx(2 * a * firm_delta / np.log(10.0))
    locations = np.array([[0.0, 0.0, 1.5], [1.01, 0.2, 1.5], [0.1, 1.0, 1.6]])

    def energy(q):
        total = 0.0
        for i in range(3):
            for j in range(i + 1, 3):
                r = np.linalg.norm(q[j] - q[i])
                total += strength * (np.exp(-(r - offset) / decay) if r > offset else 1 + (offset - r) / decay)
        return total
    expected = np.zeros((3, 3))
    h = 1e-7
    for i in range(3):
        for k in range(3):
            step = np.zeros((3, 3))
            step[i, k] = h
            expected[i, k] = -(energy(locations + step) - energy(locations - step)) / (2 * h)
    forces = firm_repulsion_forces(locations, a, strength, firm_delta)
    np.testing.assert_allclose(forces, expected, rtol=1e-6, atol=1e-9)
    assert np.all(firm_repulsion_forces(locations, a, 0.0, firm_delta) == 0)


def test_lubrication_rollers_spin_at_the_prescribed_rate(tmp_path):
    """free_kinematics False: every sphere turns at omega_one_roller (torques solved for), so after n steps of
    Heun (kT = 0) each orientation is the rotation by n dt omega about y (to the solver tolerance)."""
    write_scene(tmp_path, scheme='lubrication_trapezoidal_rollers', omega_one_roller='0 3.0 0',
                free_kinematics='False', domain='single_wall')
    result = run(tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert 'warning' not in result.stdout + result.stderr
    trajectory = frames(tmp_path)
    angle = 5 * 0.01 * 3.0
    expected = np.array([np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0])
    np.testing.assert_allclose(trajectory[-1, :, 3:], np.tile(expected, (3, 1)), atol=1e-8)
    # rolling near the wall: the spheres move along +x
    assert np.all(trajectory[-1, :, 0] - START[:, 0] > 0)


def test_lubrication_rollers_with_a_constant_torque(tmp_path):
    """free_kinematics True: the torque 8 pi eta a^3 omega per sphere; Heun with the dense M_lub."""
    write_scene(tmp_path, scheme='lubrication_trapezoidal_rollers', omega_one_roller='0 3.0 0',
                free_kinematics='True', g=0.0, n_steps=2)
    result = run(tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    torque = np.zeros((3, 6))
    torque[:, 4] = 8.0 * np.pi * 3.0

    def velocity(q):
        return (dense_lubricated_mobility(lubrication.LubricationProblem(q, 1.0, 1.0)) @ torque.ravel()).reshape(3, 6)
    q = START.copy()
    for _ in range(2):
        first = velocity(q)
        q = q + 0.5 * 0.01 * (first + velocity(q + 0.01 * first[:, :3]))[:, :3]
    np.testing.assert_allclose(frames(tmp_path)[-1, :, :3], q, rtol=0, atol=1e-9)
