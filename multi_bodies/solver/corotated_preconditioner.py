"""A preconditioner built at one configuration, applied at another with every body turned as it has turned.

A preconditioner is often applied at a configuration other than the one it was built at: the corrector solve of
``stochastic_Slip_Trapz`` reuses the one built at the start of the step, the stochastic schemes keep theirs for
``update_PC`` steps, and the deterministic schemes under ``preconditioner auto`` keep theirs while it serves
(``quaternion_integrator.scheme_base``).  Each body has turned since the build by
``D_k = R(q_k) R(q_k^build)^T``.  A body's own saddle-point system turns with it: in free space the RPY blob
mobility is rotation covariant, ``M_k(q) = D_k M_k(q^build) D_k^T`` blob by blob, and ``K_k(q) = D_k K_k(q^build)
diag(D_k, D_k)^T``, so the exact inverse of body ``k`` alone at ``q`` is

    P_k(q)^{-1} = D_k P_k(q^build)^{-1} D_k^T,

with ``D_k`` acting on each of its blob vectors and on both halves of its body vector (velocities or forces and
torques).  Above a wall this is exact for turns about the wall's normal and a first-order approximation for the
others; the couplings between bodies (the neighbour correction) are not turned.  Applying the turned preconditioner
costs two rotations of the vector.

Measured (doc/preconditioners.md): the corrector solve of ``stochastic_Slip_Trapz`` on 100 boomerangs takes 8
GMRES iterations with the unturned preconditioner of the step's start, 6 turned, and 5.6 with one built at the
predictor (which costs more than the iterations it saves).

The turned preconditioner changes GMRES iterates only within ``solver_tolerance``; the Lanczos factors
(``L_dot``, ``L_inv_dot``, ``L_inv_T_dot``) stay those of the build, so the noise is unchanged.
"""
import numpy as np

from body.geometry import rotation_matrices
from multi_bodies.solver.body_solver import MobilityProblem
from multi_bodies.solver.linear_map import WrapsPreconditioner


def body_turns(built_at, configuration):
    """``D_k = R(q_k) R(q_k^build)^T`` (Nb, 3, 3) from the orientations (Nb, 4) of two configurations."""
    before = rotation_matrices(np.asarray(built_at.orientations, dtype=float))
    after = rotation_matrices(np.asarray(configuration.orientations, dtype=float))
    return np.matmul(after, np.swapaxes(before, 1, 2))


class CorotatedPreconditioner(WrapsPreconditioner):
    """``D P(q^build) D^T``: the preconditioner ``base`` built at ``q^build``, turned to a problem's orientations.

    Parameters
    ----------
    base : a preconditioner of the rigid problems' layout ``[blob vectors (3N); body vectors (6 Nb)]`` (an object
        with ``operator``, or a LinearOperator).
    turns : (Nb, 3, 3) rotations ``D_k`` (:func:`body_turns`).
    blob_body_index : (N,) int, the body of every blob.

    ``operator`` is the turned application; ``configuration``, ``noise_factor`` and the Lanczos factors
    ``L_dot``, ``L_inv_dot``, ``L_inv_T_dot`` are the base's (the build's, not turned).
    """

    def __init__(self, base, turns, blob_body_index):
        self.base = base
        self._base_apply = getattr(base, 'operator', base).matvec
        self.turns = np.ascontiguousarray(turns, dtype=float)
        self.blob_turns = self.turns[np.asarray(blob_body_index)]
        self.num_blob_unknowns = 3 * self.blob_turns.shape[0]
        self.size = self.num_blob_unknowns + 6 * self.turns.shape[0]

    # The factor of its noise is the base's (D L D^T is not what Lanczos needs; the solves apply the base's factor
    # to the turned problem only through ``operator``).
    @property
    def noise_factor(self):
        return getattr(self.base, 'noise_factor', None) or self.base

    def _turn(self, x, inverse):
        """``D x`` (``inverse``: ``D^T x``) of ``x = [blob vectors (3N); body vectors (6 Nb)]``."""
        n3 = self.num_blob_unknowns
        blob_turns, turns = self.blob_turns, self.turns
        if inverse:
            blob_turns, turns = np.swapaxes(blob_turns, 1, 2), np.swapaxes(turns, 1, 2)
        out = np.empty_like(x)
        out[:n3] = np.matmul(blob_turns, x[:n3].reshape(-1, 3, 1)).reshape(-1)
        # both halves of every body's vector (velocity and angular velocity, or force and torque) turn alike
        out[n3:] = np.matmul(turns[:, None], x[n3:].reshape(-1, 2, 3, 1)).reshape(-1)
        return out

    def apply(self, x):
        """The turned preconditioner applied to ``x`` (3N + 6Nb,)."""
        x = np.asarray(x, dtype=float).reshape(-1)
        return self._turn(np.asarray(self._base_apply(self._turn(x, True)), dtype=float).reshape(-1), False)


def following(problem, preconditioner, body_arrays):
    """``preconditioner`` as it applies at ``problem``'s configuration: turned with the bodies
    (:class:`CorotatedPreconditioner`) when it was built where the bodies were oriented otherwise.

    Returned unchanged when the problem is not of the rigid layout (rigid and mixed problems; the articulated,
    slip-length and roller problems have others), when the preconditioner does not say where it was built
    (``configuration``), or when no body has turned since.  body_arrays : body.body.BodyArrays (its
    ``blob_body_index``).
    """
    built_at = getattr(preconditioner, 'configuration', None)
    if built_at is None or not isinstance(problem, MobilityProblem) or isinstance(preconditioner,
                                                                                    CorotatedPreconditioner):
        return preconditioner
    before, after = np.asarray(built_at.orientations), np.asarray(problem.orientations)
    if before.shape != after.shape or np.array_equal(before, after):
        return preconditioner
    return CorotatedPreconditioner(preconditioner, body_turns(built_at, problem.configuration),
                                   body_arrays.blob_body_index)
