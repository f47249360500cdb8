"""Lubrication corrections for dense suspensions of spheres near each other and near the wall (issue 28).

Spheres of one radius ``a``, one blob each, above a no-slip wall at z = 0 (or in free space, or in a
pseudo-periodic box).  Far field: the package's single-blob RPB / RPY translational and rotational
mobility ``M``.  Near field: the sparse correction ``Delta_R = R_sup - R_MB`` from the published tables
and asymptotic forms (Sprinkle, van der Wee, Luo, Driscoll and Donev, Soft Matter 16, 7982, 2020).
Corrected mobility ``M_lub = (M^-1 + Delta_R)^-1``, applied by the package's one solve.

Modules (floor of ``multi_bodies.solver``):

* :mod:`lubrication.tables` - the five published tables (package data) and their interpolation;
* :mod:`lubrication.resistance` - pair (12 x 12) and wall (6 x 6) resistance blocks, vectorised;
* :mod:`lubrication.assembly` - neighbour search and the sparse R_sup, R_MB, Delta_R (6N x 6N);
* :mod:`lubrication.problem` - ``(I + M Delta_R) U = X + M F`` as a problem of ``body_solver.solve``;
* :mod:`lubrication.sparse_factor` - the preconditioners' sparse factorisations (the compiled block LDL^T,
  SuperLU where it is not built);
* :mod:`lubrication.brownian` - increments with covariance (2kT/dt) M_lub, the near-field root, the drift;
* :mod:`lubrication.integrators` - trapezoidal, Euler-Maruyama and RPB steps, ``torque_from_omega``, and
  ``KeptSolves`` (preconditioners kept between solves and steps, first guesses).

See ``doc/lubrication.md``.
"""
from .assembly import DEFAULT_CUTOFF, LubricationMatrices, delta_R, neighbour_pairs, resistance_matrices
from .problem import (LubricationPreconditioner, LubricationProblem, dense_lubricated_mobility, far_field_mobility,
                      far_field_product, lubricated_velocities)
from .resistance import DEFAULT_FIRM_DELTA

__all__ = ['DEFAULT_CUTOFF', 'DEFAULT_FIRM_DELTA', 'LubricationMatrices', 'LubricationPreconditioner',
           'LubricationProblem', 'delta_R', 'dense_lubricated_mobility', 'far_field_mobility', 'far_field_product',
           'lubricated_velocities', 'neighbour_pairs', 'resistance_matrices']
