"""The minimum image (re-exported from the ground floor, ``body.geometry``) and the wall regularisation.

One Python source of each formula (the compiled backends use their twin in
``mobility/cpp/pair_laws.h``):

* :func:`minimum_image` (and its one-axis form :func:`wrap_axis`), defined in
  :mod:`body.geometry`; ``multi_bodies.solver.physics`` re-exports it too.
* :func:`wall_regularisation`: blobs closer to the wall than their radius
  are raised to ``z_eff = radius`` and damped by ``z / radius`` (Balboa,
  Delmotte and Donev 2017); works on NumPy or CuPy arrays (``xp``).
"""
import numpy as np

from body.geometry import minimum_image, wrap_axis  # noqa: F401  (their one source: the ground floor)


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
