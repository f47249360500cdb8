"""Blob-blob forces on every backend: agreement with python, Newton's third law, force = -grad U.

The pair energy is SPEC section 9's: U = eps + eps (2a - r)/b for r < 2a,
eps exp(-(r - 2a)/b) otherwise; the wall energy U = eps_w + eps_w (a - z)/b_w
for z < a, eps_w exp(-(z - a)/b_w) otherwise.
"""
import numpy as np
import pytest

from multi_bodies import multi_bodies_functions as mbf
from utils import UserInputError

PARAMS = dict(repulsion_strength=1.7, debye_length=0.3, blob_radius=0.25)


def calculator(name):
    try:
        return mbf.blob_blob_force_calculator(name)
    except UserInputError as err:
        pytest.skip('%s blob forces cannot run here: %s' % (name, err))


def random_blobs(seed, n=120, box=4.0):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0, box, size=(n, 3))
    r[:5] = r[5:10] + rng.normal(scale=0.1, size=(5, 3))   # overlapping pairs
    r[10] = r[11]                                          # two blobs at the same point
    return r


def pair_energy(r, eps, b, a):
    return np.where(r < 2 * a, eps + eps * (2 * a - r) / b, eps * np.exp(-(r - 2 * a) / b))


def total_energy(r_vectors, periodic_length):
    d = mbf.minimum_image(r_vectors[None, :, :] - r_vectors[:, None, :], periodic_length)
    dist = np.linalg.norm(d, axis=-1)
    iu = np.triu_indices(len(r_vectors), k=1)
    return pair_energy(dist[iu], PARAMS['repulsion_strength'], PARAMS['debye_length'], PARAMS['blob_radius']).sum()


@pytest.mark.parametrize('backend', ['C++', 'pycuda'])
@pytest.mark.parametrize('periodic_length', [(0, 0, 0), (4.0, 3.5, 0), (4.0, 4.0, 4.0)])
def test_compiled_backends_equal_python(backend, periodic_length):
    compiled = calculator(backend)
    for seed in range(3):
        r = random_blobs(seed)
        reference = mbf.calc_blob_blob_forces(r, periodic_length=np.array(periodic_length, float), **PARAMS)
        ours = compiled(r, periodic_length=np.array(periodic_length, float), **PARAMS)
        np.testing.assert_allclose(ours, reference, rtol=1e-12, atol=1e-12 * np.abs(reference).max())


@pytest.mark.parametrize('backend', ['python', 'C++', 'pycuda'])
@pytest.mark.parametrize('periodic_length', [(0, 0, 0), (4.0, 3.5, 0)])
def test_newtons_third_law(backend, periodic_length):
    forces = calculator(backend)(random_blobs(4), periodic_length=np.array(periodic_length, float), **PARAMS)
    assert np.abs(forces.sum(axis=0)).max() < 1e-12 * np.abs(forces).max()


@pytest.mark.parametrize('backend', ['python', 'C++', 'pycuda'])
@pytest.mark.parametrize('periodic_length', [(0, 0, 0), (4.0, 3.5, 0)])
def test_force_is_minus_gradient_of_pair_energy(backend, periodic_length):
    L = np.array(periodic_length, float)
    r = random_blobs(5, n=30)
    r[10] += 0.05           # no coincident blobs: the gradient is defined everywhere
    forces = calculator(backend)(r, periodic_length=L, **PARAMS)
    h = 1e-6
    for blob in (0, 7, 10, 29):
        for axis in range(3):
            plus, minus = r.copy(), r.copy()
            plus[blob, axis] += h
            minus[blob, axis] -= h
            gradient = (total_energy(plus, L) - total_energy(minus, L)) / (2 * h)
            assert forces[blob, axis] == pytest.approx(-gradient, rel=1e-6, abs=1e-7)


def test_wall_force_is_minus_gradient_of_wall_energy():
    eps, b, a, g = 2.0, 0.4, 0.25, 0.7
    z = np.array([0.05, 0.2, 0.26, 0.5, 1.3])
    r = np.column_stack((np.zeros_like(z), np.zeros_like(z), z))
    forces = mbf.blob_external_forces(r, g=g, repulsion_strength_wall=eps, debye_length_wall=b, blob_radius=a)

    def energy(z):
        return g * z + np.where(z < a, eps + eps * (a - z) / b, eps * np.exp(-(z - a) / b))
    h = 1e-7
    np.testing.assert_allclose(forces[:, 2], -(energy(z + h) - energy(z - h)) / (2 * h), rtol=1e-6)
