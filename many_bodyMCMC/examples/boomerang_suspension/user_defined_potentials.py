"""Potentials of the boomerang suspension example (Sprinkle et al. 2017): replace two defaults.

Read by many_body_MCMC.py from the run directory; every function is vectorised
and receives the physics keywords of the input file (see doc/mcmc.md).
"""
import numpy as np


def blob_potential(r_vectors, g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, blob_radius=1.0,
                   blob_mass=1.0, **kwargs):
    """Gravity plus the Yukawa-like wall U = eps a exp(-(h - a)/b) / (h - a); r_vectors (N, 3) -> (N,).

    A blob whose centre is within a of the wall (h <= a) has infinite energy: the move is rejected.
    """
    eps, b, a = repulsion_strength_wall, debye_length_wall, blob_radius
    h = r_vectors[:, 2]
    gap = h - a
    with np.errstate(divide='ignore', invalid='ignore'):
        wall = np.where(gap > 0.0, eps * a * np.exp(-gap / b) / gap, np.inf)
    return g * blob_mass * h + wall


def blob_blob_potential(r, repulsion_strength=1.0, debye_length=1.0, blob_radius=1.0, **kwargs):
    """Yukawa repulsion U = eps 2a exp(-(|r| - 2a)/b) / |r| of blob pairs; r (..., 3) -> (...)."""
    eps, b, d = repulsion_strength, debye_length, 2.0 * blob_radius
    distance = np.sqrt(np.einsum('...k,...k->...', r, r))
    return eps * d * np.exp(-(distance - d) / b) / distance
