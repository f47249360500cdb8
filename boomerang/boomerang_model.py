"""The boomerang of Delong, Balboa Usabiaga and Donev, J. Chem. Phys. 143, 144107 (2015), section IV.

A rigid L-shaped colloid of 15 blobs above a no-slip wall at ``z = 0``:
the apex (cross point) at the body's location and two perpendicular arms of
7 blobs each along the body axes +x and +y, spacing 0.3 um (made by
``multi_bodies.files.structure_generators.boomerang``).  Units: um, s, mg.

Physical constants (as in the paper and the published code):

* blob radius ``A = 0.265 sqrt(3/2)`` um; viscosity ``ETA = 8.9e-4`` (water);
  ``KT = 300 * 1.3806488e-5`` (300 K);
* weight: the particle volume 1.1781 um^3 with an excess density 0.2 g/cm^3,
  ``TOTAL_WEIGHT = 1.1781 * 2e-10 * 9.8e6``, shared equally by the 15 blobs,
  times ``gfactor``;
* wall repulsion on every blob at height ``z``: the potential
  ``REPULSION_STRENGTH exp(-(z - A)/DEBYE_LENGTH) / (z - A)`` with
  ``REPULSION_STRENGTH = 7.5 KT`` and ``DEBYE_LENGTH = 0.5 A``, whose force is
  ``REPULSION_STRENGTH ((z - A)/b + 1) exp(-(z - A)/b) / (z - A)^2``.

So the potential energy of a configuration is
``U = sum_i [w z_i + REPULSION_STRENGTH exp(-(z_i - A)/b)/(z_i - A)]`` and a
configuration is valid only while every blob centre is above ``z = A``.

The body mobility is ``N = pinv(K^T M^-1 K)`` (6x6, tracking point the apex)
with the Rotne-Prager-Blake blob mobility ``M`` of the ``mobility`` package.

Every function takes a stack of independent boomerangs: ``locations``
shape (nb, 3), ``orientations`` shape (nb, 4) (scalar-first quaternions).
"""
import numpy as np

from body.body import BodyArrays, KT_dot, K_matrices, blob_positions
from mobility.interface import from_implementation_name
from multi_bodies.solver.body_solver import body_mobility_from_resistance, dense_body_mobility
from multi_bodies.files.structure_generators import boomerang as boomerang_blobs

A = 0.265 * np.sqrt(3.0 / 2.0)
ETA = 8.9e-4
KT = 300.0 * 1.3806488e-5
TOTAL_WEIGHT = 1.1781 * 2e-10 * (9.8 * 1e6)
NUM_BLOBS = 15
REPULSION_STRENGTH = 7.5 * KT
DEBYE_LENGTH = 0.5 * A
ARM_BLOBS = 7
SPACING = 0.3
INITIAL_LOCATION = (0.0, 0.0, 2.0)
INITIAL_ORIENTATION = (1.0, 0.0, 0.0, 0.0)


def reference_configuration():
    """Body-frame blob positions, shape (15, 3): x arm (tip first), apex at the origin, y arm."""
    return boomerang_blobs(ARM_BLOBS, SPACING)


def wall_potential(z):
    """Wall repulsion of one blob at height ``z`` (any shape; ``inf`` where ``z <= A``)."""
    z = np.asarray(z, dtype=float)
    gap = z - A
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        energy = REPULSION_STRENGTH * np.exp(-gap / DEBYE_LENGTH) / gap
    return np.where(gap > 0.0, energy, np.inf)


def wall_force(z):
    """z-force of the wall repulsion on one blob at height ``z > A`` (minus the derivative of ``wall_potential``)."""
    gap = np.asarray(z, dtype=float) - A
    return REPULSION_STRENGTH * (gap / DEBYE_LENGTH + 1.0) * np.exp(-gap / DEBYE_LENGTH) / gap ** 2


class BoomerangModel:
    """Forces, mobility and validity of independent boomerangs.

    Parameters
    ----------
    gfactor : float
        Multiplies the weight of every blob (``-gfactor`` of the script).
    implementation : str
        Dense blob mobility: ``python`` or ``C++`` (a ``mobility.interface.BlobMobility`` above the wall, the
        boomerang's blob radius and viscosity: ``blob_mobility``).

    Attributes
    ----------
    reference : ndarray, shape (15, 3)
    blob_weights : ndarray, shape (15,)
        Gravity force on each blob (``TOTAL_WEIGHT / 15 * gfactor``).
    """

    def __init__(self, gfactor=1.0, implementation='python'):
        self.gfactor = float(gfactor)
        self.implementation = implementation
        self.reference = reference_configuration()
        self.blob_weights = np.full(NUM_BLOBS, TOTAL_WEIGHT / NUM_BLOBS * self.gfactor)
        self.blob_mobility = from_implementation_name(implementation, ETA, A, dense_matrices=True)

    def _layout(self, nb):
        blob_body_index = np.repeat(np.arange(nb), NUM_BLOBS)
        blob_offsets = NUM_BLOBS * np.arange(nb + 1)
        return blob_body_index, blob_offsets

    def blob_positions(self, locations, orientations):
        """Lab-frame blob positions, shape (nb, 15, 3)."""
        locations = np.asarray(locations, dtype=float).reshape(-1, 3)
        nb = locations.shape[0]
        blob_body_index, _ = self._layout(nb)
        r = blob_positions(locations, np.asarray(orientations, dtype=float).reshape(-1, 4),
                           np.tile(self.reference, (nb, 1)), blob_body_index)
        return r.reshape(nb, NUM_BLOBS, 3)

    def potential(self, locations, orientations):
        """Potential energy ``U`` of each boomerang, shape (nb,) (``inf`` when a blob is below ``z = A``)."""
        z = self.blob_positions(locations, orientations)[:, :, 2]
        return np.sum(self.blob_weights * z + wall_potential(z), axis=1)

    def is_valid(self, locations, orientations):
        """True for the boomerangs whose blobs are all above ``z = A``, shape (nb,)."""
        return np.all(self.blob_positions(locations, orientations)[:, :, 2] > A, axis=1)

    def force_torque(self, locations, orientations):
        """Gravity and wall repulsion summed over the blobs: ``[F, T]`` per body, shape (nb, 6).

        Torques are about the apex (the body location).
        """
        locations = np.asarray(locations, dtype=float).reshape(-1, 3)
        nb = locations.shape[0]
        r = self.blob_positions(locations, orientations)
        forces = np.zeros_like(r)
        forces[:, :, 2] = wall_force(r[:, :, 2]) - self.blob_weights
        blob_body_index, blob_offsets = self._layout(nb)
        return KT_dot(r.reshape(-1, 3), locations, blob_offsets, blob_body_index, forces.reshape(-1, 3))

    def mobility(self, locations, orientations):
        """6x6 body mobility of each boomerang alone above the wall, shape (nb, 6, 6).

        Rows ``[v, w]``, columns ``[F, T]``, about the apex.  One body goes
        through ``multi_bodies.solver.body_solver.dense_body_mobility``; a stack is
        computed with the same formula, ``pinv(K^T M^-1 K)``, for all bodies at once.
        """
        locations = np.asarray(locations, dtype=float).reshape(-1, 3)
        orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
        r = self.blob_positions(locations, orientations)
        nb = locations.shape[0]
        if nb == 1:
            bodies = BodyArrays(locations, orientations, [self.reference], [1], A)
            N, _ = dense_body_mobility(bodies, bodies.configuration, self.blob_mobility)
            return N[None]
        M = self.blob_mobility.dense_matrix(r)
        K = K_matrices(r, locations)
        return body_mobility_from_resistance(np.matmul(np.swapaxes(K, 1, 2), np.linalg.solve(M, K)))


def transfer_mobility(body_mobility, point):
    """Mobility (6, 6) about another tracking point.

    ``point`` (3,) is the new tracking point minus the old one (lab frame).
    With ``v_P = v_O + w x d`` and ``T_O = T_P + d x F`` (``d = point``):
    ``N_P = J N_O J^T`` where ``J = [[I, -[d]_x], [0, I]]``.
    """
    d = np.asarray(point, dtype=float).reshape(3)
    cross = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
    J = np.eye(6)
    J[:3, 3:] = -cross
    return J @ np.asarray(body_mobility) @ J.T
