"""Laws of the quaternion class (SPEC section 3): rotations, products, inverse."""
import numpy as np
import pytest

from quaternion_integrator.quaternion import Quaternion, rotation_matrices


def random_unit_quaternions(count, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(count, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def rodrigues(phi):
    """Rotation matrix of the rotation vector phi by Rodrigues' formula."""
    angle = np.linalg.norm(phi)
    if angle == 0:
        return np.eye(3)
    n = phi / angle
    cross = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def test_rotation_matrix_is_proper_orthogonal():
    for q in random_unit_quaternions(50):
        R = Quaternion(q).rotation_matrix()
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-13)


def test_identity_and_known_rotation():
    np.testing.assert_allclose(Quaternion([1, 0, 0, 0]).rotation_matrix(), np.eye(3))
    # 90 degrees about z sends x to y.
    R = Quaternion.from_rotation([0, 0, np.pi / 2]).rotation_matrix()
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_product_formula_and_composition():
    q1, q2 = (Quaternion(q) for q in random_unit_quaternions(2, seed=1))
    product = q1 * q2
    s, p, t, r = q1.s, q1.p, q2.s, q2.p
    np.testing.assert_allclose(product.entries,
                               np.concatenate(([s * t - p @ r], s * r + t * p + np.cross(p, r))))
    # Composition: R(q1 q2) = R(q1) R(q2).
    np.testing.assert_allclose(product.rotation_matrix(), q1.rotation_matrix() @ q2.rotation_matrix(),
                               atol=1e-14)


def test_from_rotation_components_and_rodrigues():
    rng = np.random.default_rng(2)
    for phi in rng.normal(size=(20, 3)):
        q = Quaternion.from_rotation(phi)
        angle = np.linalg.norm(phi)
        np.testing.assert_allclose(q.entries, np.concatenate(([np.cos(angle / 2)],
                                                              np.sin(angle / 2) * phi / angle)))
        np.testing.assert_allclose(q.rotation_matrix(), rodrigues(phi), atol=1e-14)
    np.testing.assert_array_equal(Quaternion.from_rotation([0, 0, 0]).entries, [1, 0, 0, 0])


def test_inverse():
    for q in random_unit_quaternions(10, seed=3):
        q = Quaternion(q)
        np.testing.assert_allclose((q * q.inverse()).entries, [1, 0, 0, 0], atol=1e-15)
        np.testing.assert_allclose(q.inverse().rotation_matrix(), q.rotation_matrix().T, atol=1e-14)
    # Non-unit quaternion: still the multiplicative inverse.
    q = Quaternion([2.0, 1.0, -1.0, 0.5])
    np.testing.assert_allclose((q.inverse() * q).entries, [1, 0, 0, 0], atol=1e-15)


def test_rotation_angle_round_trip():
    rng = np.random.default_rng(4)
    for phi in rng.uniform(-1, 1, size=(20, 3)):
        np.testing.assert_allclose(Quaternion.from_rotation(phi).rotation_angle(), phi, atol=1e-13)


def test_batched_rotation_matrices_match_single():
    qs = random_unit_quaternions(7, seed=5)
    batched = rotation_matrices(qs)
    for q, R in zip(qs, batched):
        np.testing.assert_array_equal(Quaternion(q).rotation_matrix(), R)


def test_repeated_small_rotations_stay_rotations():
    q = Quaternion([1, 0, 0, 0])
    step = Quaternion.from_rotation([1e-3, -2e-3, 5e-4])
    for _ in range(10000):
        q = step * q
    assert np.linalg.norm(q.entries) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(q.rotation_matrix(), rodrigues(10000 * np.array([1e-3, -2e-3, 5e-4])),
                               atol=1e-10)


def test_wrong_size_is_refused():
    with pytest.raises(ValueError):
        Quaternion([1, 0, 0])
