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


# ------------------------------------------------------------------ cell lists (tree_numba, a law with a cutoff)
def pairs_within(r_vectors, periodic_length, cutoff, law):
    """Forces (N, 3) summed over the pairs with |r| <= cutoff (minimum image), by the all-pairs python sum."""
    def masked(r, **kw):
        return law(r, **kw) * (np.linalg.norm(r, axis=-1) <= cutoff)[..., None]
    return mbf.calc_blob_blob_forces(r_vectors, periodic_length=periodic_length, pair_force=masked, **PARAMS)


def spread_blobs(seed, n=400, box=(30.0, 30.0, 12.0)):
    """Blobs in a box much larger than the cutoff 2a + 30b = 9.5, with overlaps and a coincident pair."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0, 1, size=(n, 3)) * np.array(box)
    r[:5] = r[5:10] + rng.normal(scale=0.1, size=(5, 3))
    r[10] = r[11]
    return r


@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (30.0, 30.0, 0.0), (30.0, 13.0, 12.0), (8.0, 0.0, 0.0)])
def test_cell_list_equals_the_pairs_within_the_cutoff(periodic_length):
    """tree_numba = the all-pairs sum over pairs within 2a + 30b (round-off), also with (pseudo-)periodic
    boxes (one box side shorter than the cutoff included); the neglected remainder is below exp(-30) of the
    contact force eps/b per neglected pair."""
    L = np.array(periodic_length)
    r = spread_blobs(3)
    cutoff = 2 * PARAMS['blob_radius'] + 30 * PARAMS['debye_length']
    cell = calculator('tree_numba')(r, periodic_length=L, **PARAMS)
    within = pairs_within(r, L, cutoff, mbf.blob_blob_force)
    scale = np.max(np.abs(within))
    np.testing.assert_allclose(cell, within, rtol=0, atol=1e-13 * scale)
    everything = mbf.calc_blob_blob_forces(r, periodic_length=L, **PARAMS)
    contact = PARAMS['repulsion_strength'] / PARAMS['debye_length']
    assert np.max(np.abs(everything - cell)) <= len(r) * contact * np.exp(-30)


def test_cell_list_single_and_no_blobs():
    f = calculator('tree_numba')
    assert f(np.zeros((0, 3)), **PARAMS).shape == (0, 3)
    np.testing.assert_array_equal(f(np.array([[1.0, 2.0, 3.0]]), **PARAMS), np.zeros((1, 3)))


def test_python_law_with_a_cutoff_uses_only_the_pairs_within_it():
    """A user law with an attribute ``cutoff`` gives the sum over the pairs within it (periodic in x, y)."""
    def law(r, **kw):
        return mbf.blob_blob_force(r, **kw)
    law.cutoff = 3.0
    L = np.array([30.0, 30.0, 0.0])
    r = spread_blobs(5)
    forces = mbf.blob_blob_force_calculator('python', pair_force=law)(r, periodic_length=L, **PARAMS)
    np.testing.assert_allclose(forces, pairs_within(r, L, 3.0, mbf.blob_blob_force), rtol=0,
                               atol=1e-13 * np.max(np.abs(forces)))
    assert np.max(np.abs(forces.sum(axis=0))) < 1e-10 * np.max(np.abs(forces))  # Newton's third law


def test_law_with_a_bad_cutoff_is_refused():
    def law(r, **kw):
        return mbf.blob_blob_force(r, **kw)
    law.cutoff = -1.0
    with pytest.raises(UserInputError, match='cutoff'):
        mbf.blob_blob_force_calculator('python', pair_force=law)


# ------------------------------------------------------------------ body pairs with a cutoff
def rollers_law(r, repulsion_strength=1.0, debye_length=1.0, **kw):
    """The spectral roller example's body law: Yukawa-like push along the line of centres, none beyond 3.5 R
    (R = 1.0155), no torque."""
    R = 1.0155
    distance = np.maximum(np.linalg.norm(r, axis=-1), np.finfo(float).eps)
    magnitude = np.where(distance > 2 * R, (repulsion_strength / debye_length) * np.exp(-(distance - 2 * R) /
                                                                                         debye_length),
                         repulsion_strength / debye_length)
    magnitude = np.where(distance < 3.5 * R, magnitude, 0.0)
    force = -(magnitude / distance)[..., None] * r
    return force, np.zeros_like(force)


@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (40.0, 40.0, 0.0), (40.0, 9.0, 0.0)])
def test_body_pairs_with_a_cutoff_equal_every_pair(periodic_length):
    """A body law with an attribute ``cutoff`` (doc/overrides.md): the user hook visits only the pairs within it
    (every r the law receives is shorter), and the sum equals the all-pairs sum (the law is zero beyond; the
    pairs are taken in the all-pairs order, so to the last bit), also in periodic boxes with a side shorter
    than three cutoffs; Newton's third law holds."""
    from multi_bodies.solver.user_hooks import PhysicsHooks
    seen = []

    def law(r, **kw):
        seen.append(np.linalg.norm(r, axis=-1).max(initial=0.0))
        return rollers_law(r, **kw)
    law.cutoff = 3.5 * 1.0155
    rng = np.random.default_rng(7)
    locations = rng.uniform(0, 1, size=(300, 3)) * np.array([40.0, 40.0, 3.0])
    L = np.array(periodic_length)
    keywords = dict(repulsion_strength=0.3, debye_length=0.5, periodic_length=L)
    near = PhysicsHooks._body_pairs_adapter(law, False)(locations, None, **keywords)
    assert max(seen) <= law.cutoff
    every = mbf.calc_body_body_forces_torques(locations, pair_force_torque=rollers_law, **keywords)
    assert np.max(np.abs(every)) > 0.1            # pushes within the cutoff
    np.testing.assert_array_equal(near, every)
    assert np.max(np.abs(near[0::2].sum(axis=0))) < 1e-12 * np.max(np.abs(near))


def test_body_law_with_a_bad_cutoff_is_refused():
    from multi_bodies.solver.user_hooks import PhysicsHooks

    def law(r, **kw):
        return rollers_law(r, **kw)
    law.cutoff = 0.0
    with pytest.raises(UserInputError, match='cutoff'):
        PhysicsHooks._body_pairs_adapter(law, False)
    law.cutoff = lambda **kw: float('nan')
    hook = PhysicsHooks._body_pairs_adapter(law, False)
    with pytest.raises(UserInputError, match='cutoff'):
        hook(np.zeros((2, 3)), None, periodic_length=np.zeros(3))
