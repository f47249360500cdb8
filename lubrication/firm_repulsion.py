"""The "firm" pair repulsion of the published lubrication examples (input options ``repulsion_strength_firm``
and ``firm_delta``): a stiff, short-ranged repulsion that keeps the gaps of spheres of radius ``a`` above
about ``firm_delta a``, where the lubrication clamp works.

Potential of a pair at centre distance r (the form of the published examples' force files):
``U(r) = S exp(-(r - d) / b)`` for ``r > d`` and ``U(r) = S + S (d - r) / b`` below, with
``d = 2a - 2 firm_delta a`` and ``b = 2 a firm_delta / ln 10`` (the examples' drivers: the force falls
tenfold over a gap of ``2 firm_delta a``); ``S = repulsion_strength_firm`` (energy).
"""
import numpy as np

from . import assembly


def firm_range(a, firm_delta):
    """``(d, b)``: the offset ``2a - 2 firm_delta a`` and the decay length ``2 a firm_delta / ln 10`` (length)."""
    return 2.0 * a - 2.0 * firm_delta * a, 2.0 * a * firm_delta / np.log(10.0)


def firm_repulsion_forces(locations, a, strength, firm_delta, periodic_length=(0.0, 0.0, 0.0), cutoff=None):
    """Forces (N, 3) of the firm repulsion on spheres at ``locations`` (N, 3).

    Pairs closer than ``cutoff`` radii (None: where the force has fallen below 1e-16 of its contact value,
    ``d + 37 b``) by the lubrication neighbour search (minimum image in periodic axes).
    """
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    forces = np.zeros_like(locations)
    if strength == 0 or locations.shape[0] < 2:
        return forces
    offset, decay = firm_range(a, firm_delta)
    if cutoff is None:
        cutoff = (offset + 37.0 * decay) / a
    neighbours = assembly.neighbour_pairs(locations, a, cutoff, periodic_length)
    distance = neighbours.r_over_a * a
    magnitude = strength / decay * np.exp(-np.maximum(distance - offset, 0.0) / decay)
    pair_force = magnitude[:, None] * neighbours.r_hat  # on sphere j, away from i (r_hat points from i to j)
    np.add.at(forces, neighbours.pairs[:, 1], pair_force)
    np.add.at(forces, neighbours.pairs[:, 0], -pair_force)
    return forces
