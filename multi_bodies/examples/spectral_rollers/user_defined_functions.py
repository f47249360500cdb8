"""The forces of the published Spectral_Multiblob_Roller folder, in this package's style (doc/periodic.md).

That folder's own multi_bodies_functions.py (which this package reads only for the folder's own inputs, in the
published spectral form; doc/periodic.md) puts every force on the bodies, none on the blobs:

* gravity ``-g`` on each body (the input's ``g``);
* the roller's torque ``8 pi eta R^3 omega`` about y, ``omega = 2 pi f`` with the frequency ``f = 9`` (Hz) that the
  folder's multi_bodies.py passes, R the particle radius (1.0155);
* the wall's repulsion on the body's centre at height h: ``(eps_w / b_w) exp(-(h - R) / b_w)`` up (``eps_w / b_w``
  below R), with ``repulsion_strength_wall`` and ``debye_length_wall``;
* between bodies closer than ``3.5 R``, the repulsion ``(eps / b) exp(-(r - 2R) / b)`` along the line of centres
  (``eps / b`` below 2R), with ``repulsion_strength`` and ``debye_length``; none farther;
* no force on the blobs (``blob_external_forces`` below replaces this package's default gravity and wall
  repulsion on every blob).
"""
import numpy as np

FREQUENCY = 9.0           # Hz: the keyword f of the published folder's multi_bodies.py
PARTICLE_RADIUS = 1.0155  # the published input's blob_radius, the folder's particle radius


def bodies_external_force_torque(bodies, r_vectors, g=1.0, eta=1.0, repulsion_strength_wall=1.0,
                                 debye_length_wall=1.0, **kwargs):
    """Gravity, the roller torque and the wall repulsion of every body: (2 Nb, 3), rows F_0, T_0, F_1, ..."""
    R = PARTICLE_RADIUS
    h = np.array([body.location[2] for body in bodies])
    push = np.where(h > R, (repulsion_strength_wall / debye_length_wall) * np.exp(-(h - R) / debye_length_wall),
                    repulsion_strength_wall / debye_length_wall)
    force_torque = np.zeros((len(bodies), 2, 3))
    force_torque[:, 0, 2] = -g + push
    force_torque[:, 1, 1] = 2.0 * np.pi * FREQUENCY * 8.0 * np.pi * eta * R ** 3
    return force_torque.reshape(-1, 3)


def body_body_force_torque(r, repulsion_strength=1.0, debye_length=1.0, **kwargs):
    """Force on the first body of each pair (r from it to the second, nearest image), none beyond 3.5 R; no torque."""
    R = PARTICLE_RADIUS
    distance = np.maximum(np.linalg.norm(r, axis=-1), np.finfo(float).eps)
    magnitude = np.where(distance > 2 * R,
                         (repulsion_strength / debye_length) * np.exp(-(distance - 2 * R) / debye_length),
                         repulsion_strength / debye_length)
    magnitude = np.where(distance < 3.5 * R, magnitude, 0.0)
    force = -(magnitude / distance)[..., None] * r
    return force, np.zeros_like(force)


body_body_force_torque.cutoff = 3.5 * PARTICLE_RADIUS


def blob_external_forces(r_vectors, **kwargs):
    """No force on any blob, shape (N, 3): the folder's force module computes none (its one-blob forces are zero)."""
    return np.zeros_like(np.asarray(r_vectors, dtype=float).reshape(-1, 3))
