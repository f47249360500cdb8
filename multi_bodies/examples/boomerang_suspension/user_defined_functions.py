"""Physics of the boomerang suspension example: replaces three default hooks.

Every function is vectorised (see doc/dynamics.md, "Overriding the physics").
"""
import numpy as np

SPRING_STIFFNESS = 1e-3      # force per unit stretch of the body-body spring
SPRING_REST_LENGTH = 1.0


def blob_external_forces(r_vectors, g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, blob_radius=1.0,
                         blob_mass=1.0, **kwargs):
    """Gravity plus the wall potential U = eps a exp(-(h - a)/b) / (h - a), r_vectors (N, 3) -> (N, 3).

    The force -dU/dh = eps a exp(-(h - a)/b) (1/(b (h - a)) + 1/(h - a)^2) diverges at
    h = a; heights closer than 1e-3 a are treated as 1e-3 a above contact.
    """
    eps, b, a = repulsion_strength_wall, debye_length_wall, blob_radius
    gap = np.maximum(r_vectors[:, 2] - a, 1e-3 * a)
    forces = np.zeros_like(r_vectors)
    forces[:, 2] = -g * blob_mass + eps * a * np.exp(-gap / b) * (1.0 / (b * gap) + 1.0 / gap ** 2)
    return forces


def blob_blob_force(r, repulsion_strength=1.0, debye_length=1.0, blob_radius=1.0, **kwargs):
    """Yukawa repulsion U = eps 2a exp(-(|r| - 2a)/b) / |r| of blob pairs; r (..., 3) from i to j, force on i."""
    eps, b, d = repulsion_strength, debye_length, 2.0 * blob_radius
    distance = np.maximum(np.linalg.norm(r, axis=-1), 1e-12)
    dU_dr = -eps * d * np.exp(-(distance - d) / b) * (1.0 / (b * distance) + 1.0 / distance ** 2)
    return (dU_dr / distance)[..., None] * r


def body_body_force_torque(r, **kwargs):
    """Harmonic spring between tracking points; r (..., 3) from body i to body j.

    Returns (force on i, torque on i): k (|r| - l0) r/|r| (k = SPRING_STIFFNESS,
    l0 = SPRING_REST_LENGTH), no torque.
    """
    distance = np.maximum(np.linalg.norm(r, axis=-1), 1e-12)
    force = (SPRING_STIFFNESS * (distance - SPRING_REST_LENGTH) / distance)[..., None] * r
    return force, np.zeros_like(r)
