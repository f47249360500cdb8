"""Rigid-body kinematics: blob positions, K, K^T, body length, validity, slip."""
import numpy as np
import pytest

from body.body import (Body, BodyArrays, K_dense, K_dot, KT_dot, bodies_to_arrays,
                       reference_body_length)
from quaternion_integrator.quaternion import Quaternion, rotation_matrices

BOOMERANG = np.array([[0.3 * k, 0, 0] for k in range(7, 0, -1)] + [[0, 0, 0]]
                     + [[0, 0.3 * k, 0] for k in range(1, 8)])


def random_system(seed=0):
    """Three bodies of a 4-blob type then two of a 2-blob type."""
    rng = np.random.default_rng(seed)
    ref_a, ref_b = rng.normal(size=(4, 3)), rng.normal(size=(2, 3))
    locations = rng.normal(size=(5, 3)) + [0, 0, 5]
    q = rng.normal(size=(5, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    return BodyArrays(locations, q, [ref_a, ref_b], [3, 2], 0.3), [ref_a, ref_b]


def test_blob_positions_follow_location_and_rotation():
    body = Body([1.0, 2.0, 3.0], Quaternion.from_rotation([0, 0, np.pi / 2]), BOOMERANG, 0.25)
    r = body.get_r_vectors()
    # The x arm turns into the +y direction, the y arm into -x.
    np.testing.assert_allclose(r[0], [1.0, 2.0 + 2.1, 3.0], atol=1e-14)
    np.testing.assert_allclose(r[-1], [1.0 - 2.1, 2.0, 3.0], atol=1e-14)


def test_arrays_match_single_bodies():
    arrays, refs = random_system()
    r = arrays.blob_positions(arrays.configuration)
    for k in range(arrays.num_bodies):
        ref = refs[0] if k < 3 else refs[1]
        body = Body(arrays.locations[k], arrays.orientations[k], ref, 0.3)
        np.testing.assert_allclose(r[arrays.blob_offsets[k]:arrays.blob_offsets[k + 1]], body.get_r_vectors(),
                                   atol=1e-14)


def test_K_dot_is_rigid_motion_and_KT_is_its_adjoint():
    arrays, _ = random_system(1)
    r = arrays.blob_positions(arrays.configuration)
    rng = np.random.default_rng(7)
    U = rng.normal(size=(arrays.num_bodies, 6))
    lam = rng.normal(size=(arrays.num_blobs, 3))
    blob_velocity = arrays.K_dot(arrays.configuration, U, r)
    for i in range(arrays.num_blobs):
        k = arrays.blob_body_index[i]
        expected = U[k, :3] + np.cross(U[k, 3:], r[i] - arrays.locations[k])
        np.testing.assert_allclose(blob_velocity[i], expected, atol=1e-13)
    body_forces = arrays.KT_dot(arrays.configuration, lam, r)
    assert np.sum(blob_velocity * lam) == pytest.approx(np.sum(U * body_forces), rel=1e-12)
    K = K_dense(r, arrays.locations, arrays.blob_body_index)
    np.testing.assert_allclose(K @ U.ravel(), blob_velocity.ravel(), atol=1e-13)
    np.testing.assert_allclose(K.T @ lam.ravel(), body_forces.ravel(), atol=1e-13)


def test_KT_sums_forces_and_torques_about_location():
    body = Body([0, 0, 5], [1, 0, 0, 0], [[1, 0, 0], [-1, 0, 0]], 0.5)
    arrays = bodies_to_arrays([body])
    r = arrays.blob_positions(arrays.configuration)
    ft = KT_dot(r, arrays.locations, arrays.blob_offsets, arrays.blob_body_index, [[0, 1, 0], [0, -1, 0]])
    np.testing.assert_allclose(ft, [[0, 0, 0, 0, 0, 2]])
    v = K_dot(r, arrays.locations, arrays.blob_body_index, [[0, 0, 0, 0, 0, 1]])
    np.testing.assert_allclose(v, [[0, 1, 0], [0, -1, 0]], atol=1e-15)


def test_body_K_matrix_matches_global():
    body = Body([0.5, -1, 4], Quaternion.from_rotation([0.3, 0.2, -0.1]), BOOMERANG, 0.25)
    K = body.calc_K_matrix()
    arrays = bodies_to_arrays([body])
    np.testing.assert_allclose(K, K_dense(arrays.blob_positions(arrays.configuration), arrays.locations, arrays.blob_body_index),
                               atol=1e-15)


def test_body_length():
    assert reference_body_length(BOOMERANG, 0.25) == pytest.approx(2.1 * np.sqrt(2) + 0.5)
    assert reference_body_length([[0, 0, 0]], 0.3) == pytest.approx(0.6)
    body = Body([0, 0, 1], [1, 0, 0, 0], BOOMERANG, 0.25)
    assert body.calc_body_length() == pytest.approx(2.1 * np.sqrt(2) + 0.5)


def test_validity_check_is_blob_centre_below_wall():
    body = Body([0, 0, 0.1], Quaternion.from_rotation([np.pi / 2, 0, 0]), BOOMERANG, 0.25)
    assert body.check_function()                # the y arm points up (+z)
    body.orientation = Quaternion.from_rotation([-np.pi / 2, 0, 0])
    assert not body.check_function()            # the y arm points down, below z = 0
    arrays = bodies_to_arrays([body])
    np.testing.assert_array_equal(arrays.check_positions(arrays.blob_positions(arrays.configuration)), [0])


def test_slip_rotates_with_the_body():
    body = Body([0, 0, 3], Quaternion.from_rotation([0, 0, np.pi / 2]), [[0, 0, 0], [1, 0, 0]], 0.5)
    assert np.all(body.calc_slip() == 0)
    body.slip_reference = np.array([[1.0, 0, 0], [0, 0, 2.0]])
    np.testing.assert_allclose(body.calc_slip(), [[0, 1, 0], [0, 0, 2]], atol=1e-15)
    arrays = bodies_to_arrays([body])
    np.testing.assert_allclose(arrays.lab_frame_slip(arrays.configuration), body.calc_slip(), atol=1e-15)


def test_rotation_matrices_of_arrays():
    arrays, _ = random_system(2)
    np.testing.assert_array_equal(arrays.rotation_matrices(arrays.configuration), rotation_matrices(arrays.orientations))


def test_compiled_K_and_KT_equal_numpy_and_dense():
    """The compiled K U, K^T lambda and saddle-point product (body/cpp/rigid_module.cpp) equal the NumPy versions
    and the dense K to rounding, on bodies of two types; a blob index that names no body is refused."""
    from body import body as body_module
    if body_module._rigid_cpp is None:
        pytest.skip('body._rigid_cpp is not built (python3 setup.py build_ext --inplace)')
    from body.body import K_dot_numpy, KT_dot_numpy, saddle_point_product
    arrays, _ = random_system(3)
    r = arrays.blob_positions(arrays.configuration)
    rng = np.random.default_rng(4)
    U = rng.normal(size=(arrays.num_bodies, 6))
    lam = rng.normal(size=(arrays.num_blobs, 3))
    M_lam = rng.normal(size=3 * arrays.num_blobs)
    K = K_dense(r, arrays.locations, arrays.blob_body_index)
    args = (r, arrays.locations, arrays.blob_body_index)
    np.testing.assert_allclose(K_dot(*args, U), K_dot_numpy(*args, U), rtol=0, atol=1e-13)
    np.testing.assert_allclose(K_dot(*args, U).ravel(), K @ U.ravel(), rtol=0, atol=1e-13)
    kt = KT_dot(r, arrays.locations, arrays.blob_offsets, arrays.blob_body_index, lam)
    np.testing.assert_allclose(kt, KT_dot_numpy(r, arrays.locations, arrays.blob_offsets, arrays.blob_body_index,
                                                lam), rtol=0, atol=1e-13)
    np.testing.assert_allclose(kt.ravel(), K.T @ lam.ravel(), rtol=0, atol=1e-13)
    saddle = saddle_point_product(r, arrays.locations, arrays.blob_offsets, arrays.blob_body_index, M_lam,
                                  lam.ravel(), U.ravel())
    expected = np.concatenate((M_lam - K @ U.ravel(), -K.T @ lam.ravel()))
    np.testing.assert_allclose(saddle, expected, rtol=0, atol=1e-13)
    bad = arrays.blob_body_index.copy()
    bad[0] = arrays.num_bodies
    with pytest.raises(ValueError, match='blob_body_index'):
        K_dot(r, arrays.locations, bad, U)
