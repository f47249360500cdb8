"""Geometry on the ground floor: orientations of rigid bodies and the minimum image of periodic boxes.

Quaternions (as jax-md's ``space`` module holds its displacement functions,
this module holds the package's geometry, importing only numpy; every floor
may import it).  ``quaternion_integrator/quaternion.py`` re-exports the
quaternion part under the published import path, for users' files.

Convention (SPEC section 3): scalar first, ``q = (s, p1, p2, p3)``.  The
rotation matrix ``R(q)`` maps a vector of the body's reference frame to the
lab frame, and ``from_rotation(phi) * q`` rotates an orientation ``q`` by the
lab-frame rotation vector ``phi`` (angle ``|phi|`` in radians about
``phi/|phi|``).

The minimum image of pseudo-periodic boxes (:func:`minimum_image`,
:func:`wrap_axis`): ``d -= trunc(d/L + sign(d)/2) L`` (round half away from
zero) on every axis with ``L > 0``; ``L <= 0`` is not periodic (SPEC
section 8).  The compiled backends use their twin in
``mobility/cpp/pair_laws.h``.

And :func:`smallest_distance` of a set of points (the blob spacing of a body).
"""
import numpy as np


class Quaternion:
    """A quaternion ``s + p1 i + p2 j + p3 k`` stored scalar first.

    Attributes
    ----------
    entries : ndarray, shape (4,)
        ``[s, p1, p2, p3]``.  Orientation quaternions have unit norm, but the
        class does not renormalise (the time steppers of the published code
        never did).
    s : float
        Scalar part.
    p : ndarray, shape (3,)
        Vector part.
    """

    def __init__(self, entries):
        entries = np.asarray(entries, dtype=float).reshape(-1)
        if entries.shape != (4,):
            raise ValueError('a quaternion needs 4 numbers (s, p1, p2, p3), got %d' % entries.size)
        self.entries = entries.copy()

    @property
    def s(self):
        return self.entries[0]

    @property
    def p(self):
        return self.entries[1:4]

    def __mul__(self, other):
        """Hamilton product ``(s,p)*(t,q) = (s t - p.q, s q + t p + p x q)`` (:func:`quaternion_products`)."""
        return Quaternion(quaternion_products(self.entries, other.entries)[0])

    def __repr__(self):
        return 'Quaternion(%r)' % (self.entries.tolist(),)

    def __str__(self):
        return '[ %f, %f, %f, %f ]' % tuple(self.entries)

    @staticmethod
    def from_rotation(phi):
        """Quaternion of the rotation by the vector ``phi`` (shape (3,), radians).

        Returns ``(cos(|phi|/2), sin(|phi|/2) phi/|phi|)``, the identity when
        ``|phi| == 0``.
        """
        return Quaternion(quaternions_from_rotations(np.asarray(phi, dtype=float).reshape(1, 3))[0])

    def rotation_matrix(self):
        """Rotation matrix ``R(q)``, shape (3, 3) (SPEC section 3)."""
        return rotation_matrices(self.entries[None, :])[0]

    def inverse(self):
        """Multiplicative inverse ``conj(q) / |q|^2`` (the conjugate for unit quaternions)."""
        norm2 = np.dot(self.entries, self.entries)
        return Quaternion(np.concatenate(([self.s], -self.p)) / norm2)

    def rotation_angle(self):
        """Rotation vector ``phi`` with ``from_rotation(phi) == q`` (up to sign), shape (3,)."""
        s = np.clip(self.s, -1.0, 1.0)
        sin_half = np.linalg.norm(self.p)
        if sin_half == 0.0:
            return np.zeros(3)
        angle = 2.0 * np.arctan2(sin_half, s)
        return angle * self.p / sin_half

    def square_root(self):
        """The principal square root ``r`` with ``r * r == q`` (published method, used by the chain examples'
        force files): for a unit ``q`` the rotation about the same axis by half the angle,
        ``(q + 1) / |q + 1|`` (scalar part >= 0); scaled by ``sqrt(|q|)`` otherwise.  ``q = -1`` (a turn
        by 2 pi) has no principal root: the identity is returned, as for ``q = 1``."""
        norm = float(np.linalg.norm(self.entries))
        shifted = self.entries / norm + np.array([1.0, 0.0, 0.0, 0.0])
        size = float(np.linalg.norm(shifted))
        root = shifted / size if size > 0 else np.array([1.0, 0.0, 0.0, 0.0])
        return Quaternion(np.sqrt(norm) * root)

    def normalized(self):
        """The same orientation with unit norm."""
        return Quaternion(self.entries / np.linalg.norm(self.entries))


def rotation_matrices(quaternions):
    """Rotation matrices of many quaternions at once.

    Parameters
    ----------
    quaternions : array_like, shape (Nb, 4) (or (..., 4): any leading axes)
        Scalar-first quaternions (not renormalised here: the published
        formula, which for an unnormalised q is not a rotation).

    Returns
    -------
    ndarray, shape (Nb, 3, 3) (or (..., 3, 3))
        ``R(q_k)`` for every row ``k``.
    """
    q = np.asarray(quaternions, dtype=float)
    leading = q.shape[:-1] if q.ndim > 1 else (1,)
    q = q.reshape(-1, 4)
    s, p1, p2, p3 = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    rot = np.empty((q.shape[0], 3, 3))
    rot[:, 0, 0] = p1 * p1 + s * s - 0.5
    rot[:, 0, 1] = p1 * p2 - s * p3
    rot[:, 0, 2] = p1 * p3 + s * p2
    rot[:, 1, 0] = p2 * p1 + s * p3
    rot[:, 1, 1] = p2 * p2 + s * s - 0.5
    rot[:, 1, 2] = p2 * p3 - s * p1
    rot[:, 2, 0] = p3 * p1 - s * p2
    rot[:, 2, 1] = p3 * p2 + s * p1
    rot[:, 2, 2] = p3 * p3 + s * s - 0.5
    return (2.0 * rot).reshape(leading + (3, 3))


def quaternions_from_rotations(rotation_vectors):
    """``from_rotation(phi_k)`` of many rotation vectors (Nb, 3) (radians): unit quaternions (Nb, 4).

    ``(cos(|phi|/2), sin(|phi|/2) phi/|phi|)``, the identity where ``phi = 0``.
    """
    phi = np.asarray(rotation_vectors, dtype=float).reshape(-1, 3)
    angle = np.sqrt(np.einsum('ij,ij->i', phi, phi))
    safe = np.where(angle > 0, angle, 1.0)
    out = np.empty((phi.shape[0], 4))
    out[:, 0] = np.cos(0.5 * angle)
    out[:, 1:] = phi * np.where(angle > 0, np.sin(0.5 * angle) / safe, 0.0)[:, None]
    return out


def quaternion_products(left, right):
    """Hamilton products ``left_k * right_k`` of stacks of scalar-first quaternions (Nb, 4) -> (Nb, 4)."""
    left = np.asarray(left, dtype=float).reshape(-1, 4)
    right = np.asarray(right, dtype=float).reshape(-1, 4)
    s, p = left[:, 0], left[:, 1:]
    t, v = right[:, 0], right[:, 1:]
    out = np.empty((left.shape[0], 4))
    out[:, 0] = s * t - np.einsum('ij,ij->i', p, v)
    out[:, 1:] = s[:, None] * v + t[:, None] * p + _cross(p, v)
    return out


def _cross(a, b):
    """``np.cross`` of (n, 3) stacks, by its own formulas (each component a product less a product, rounded as it
    rounds them) without its general-purpose argument handling (a step of small systems turns every body)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def rotate_quaternions(orientations, rotation_vectors):
    """``from_rotation(phi_k) * q_k`` for every body at once: the quaternion step of every scheme.

    orientations: (Nb, 4) scalar-first; rotation_vectors: (Nb, 3) lab-frame
    rotation vectors (radians).  Returns (Nb, 4); not renormalised.
    """
    return quaternion_products(quaternions_from_rotations(rotation_vectors), orientations)


def wrap_axis(d, L):
    """Minimum image of displacement components ``d`` (array, any shape) on one axis of length ``L``.

    In place when ``d`` is an array of floats and ``L > 0``; returns ``d``.
    ``L <= 0``: not periodic, ``d`` unchanged.
    """
    if L > 0:
        d -= np.trunc(d / L + 0.5 * np.sign(d)) * L
    return d


def minimum_image(displacements, periodic_length):
    """Minimum-image convention on periodic axes: displacements (..., 3), box (3,) -> (..., 3).

    Returns a new array when some axis is periodic (``displacements`` unchanged),
    else ``displacements`` itself.
    """
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    if not np.any(L > 0):
        return displacements
    r = np.array(displacements, dtype=float, copy=True)
    for axis in np.nonzero(L > 0)[0]:
        wrap_axis(r[..., axis], L[axis])
    return r


def smallest_distance(points):
    """The smallest distance between two of ``points`` (n, 3); inf for fewer than two points.  A k-d tree
    (``scipy.spatial.cKDTree``, imported here only), so any n fits in memory."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if points.shape[0] < 2:
        return float('inf')
    from scipy.spatial import cKDTree
    distances, _ = cKDTree(points).query(points, k=2)
    return float(np.min(distances[:, 1]))
