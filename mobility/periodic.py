"""Geometry shared by every Python room: the minimum image and the wall regularisation.

One Python source of each formula (the compiled backends use their twin in
``mobility/cpp/pair_laws.h``):

* :func:`minimum_image` (and its one-axis form :func:`wrap_axis`): pseudo-periodic
  boxes, ``d -= trunc(d/L + sign(d)/2) L`` (round half away from zero) on
  every axis with ``L > 0``; ``L <= 0`` is not periodic (SPEC section 8).
  ``multi_bodies.solver.physics`` re-exports it under the same name.
* :func:`wall_regularisation`: blobs closer to the wall than their radius
  are raised to ``z_eff = radius`` and damped by ``z / radius`` (Balboa,
  Delmotte and Donev 2017); works on NumPy or CuPy arrays (``xp``).
"""
import numpy as np


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


def wall_regularisation(z, radius, xp=np):
    """Raised heights and damping factors of blobs near the wall.

    ``z`` (...,) heights, ``radius`` (scalar or (...,)) blob radii, same length
    unit; ``xp`` the array module (numpy or cupy).  Returns ``(z_eff, damping)``
    of the shape of ``z``: ``z_eff = max(z, radius)``, ``damping = 1`` for
    ``z >= radius``, else ``z / radius`` (0 for a point blob, radius 0).
    """
    z = xp.asarray(z, dtype=xp.float64)
    radius = xp.asarray(radius, dtype=xp.float64)
    safe_radius = xp.where(radius > 0, radius, 1.0)
    damping = xp.where(z >= radius, 1.0, xp.where(radius > 0, z / safe_radius, 0.0))
    return xp.maximum(z, radius), damping
