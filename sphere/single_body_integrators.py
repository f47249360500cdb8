"""Brownian integrators for rigid bodies that move alone (no hydrodynamic coupling between bodies).

The overdamped Langevin equation of one rigid body (Delong, Balboa Usabiaga
and Donev, J. Chem. Phys. 143, 144107 (2015), eq. 9), in the lab frame with
the configuration ``x = (location, orientation)``::

    dx = N F dt + kT (div_x N) dt + sqrt(2 kT) N^{1/2} dW

with ``N`` the 6x6 body mobility (rows ``v, w``; columns ``F, T``; torques and
angular velocities about the body's location) and ``F`` the force and torque.
Its invariant measure is the Gibbs-Boltzmann density ``exp(-U/kT)`` (uniform
over orientations).  Three schemes of that paper are offered:

* ``RFD`` (random finite difference, their eq. 41): with independent
  ``W, W~ ~ N(0, I_6)``::

      x^{n+1} = x^n + dt [N F + sqrt(2 kT/dt) L W + (kT/delta) (N(x^n + delta W~) - N(x^n)) W~]

  ``L`` is the lower Cholesky factor of ``N(x^n)``; ``x + delta W~`` moves
  the location by ``delta W~[:3]`` and rotates the orientation by the
  rotation vector ``delta W~[3:]``.
* ``FIXMAN`` (midpoint, their eq. 36)::

      x*      = x^n + (dt/2) N F + sqrt(kT dt) L W1
      x^{n+1} = x^n + dt N* F* + sqrt(kT dt) N* L^{-T} (W1 + W2)

  where ``*`` means evaluated at ``x*``.
* ``EM`` (Euler-Maruyama without the drift ``kT div N``)::

      x^{n+1} = x^n + dt N F + sqrt(2 kT dt) L W

  It samples the wrong distribution where ``N`` depends on the
  configuration (near a wall); it is kept as the negative control.

Every update moves the location by ``dt v`` and the orientation by
``q <- from_rotation(dt w) q`` (SPEC section 3; quaternions are not
renormalised).  A trial configuration that the model calls invalid (a blob
below the wall, or the midpoint of ``FIXMAN``) is rejected and the step is
repeated with new noise (the rejections are counted).

All arrays carry a leading axis of independent bodies, ``nb``: the same
code advances one body (``nb = 1``) or an ensemble of bodies that do not
interact (used by the statistical tests).  The model is given as three
functions of ``locations (nb, 3)`` and ``orientations (nb, 4)``:
``mobility -> (nb, 6, 6)``, ``force_torque -> (nb, 6)`` and
``is_valid -> (nb,) bool``.
"""
import numpy as np

from body.geometry import quaternion_products, quaternions_from_rotations  # noqa: F401
from stochastic_forcing import rfd
from utils import SimulationStopped

SCHEMES = ('RFD', 'FIXMAN', 'EM')


def move(locations, orientations, displacement):
    """Apply body displacements ``[dx (3), dphi (3)]`` (shape (nb, 6)) to a configuration.

    Returns ``(locations + dx, from_rotation(dphi) * orientations)``.
    """
    displacement = np.asarray(displacement, dtype=float).reshape(-1, 6)
    return (np.asarray(locations, dtype=float) + displacement[:, :3],
            quaternion_products(quaternions_from_rotations(displacement[:, 3:]), orientations))


def _matvec(matrices, vectors):
    """Stacked ``A_k x_k``: (nb, 6, 6) x (nb, 6) -> (nb, 6)."""
    return np.einsum('kij,kj->ki', matrices, vectors)


def symmetric_cholesky(matrices):
    """Lower Cholesky factors of the symmetric parts of stacked 6x6 mobilities, shape (nb, 6, 6).

    Raises ``SimulationStopped`` when a mobility is not positive definite.
    """
    symmetric = 0.5 * (matrices + np.swapaxes(matrices, 1, 2))
    try:
        return np.linalg.cholesky(symmetric)
    except np.linalg.LinAlgError:
        raise SimulationStopped('the body mobility is not positive definite (Cholesky failed); '
                                'the body is probably too close to the wall: use a smaller dt')


class SingleBodyIntegrator:
    """Advance independent rigid bodies by one Brownian step of ``scheme``.

    Parameters
    ----------
    scheme : str
        ``RFD``, ``FIXMAN`` or ``EM`` (see the module docstring).
    mobility : callable
        ``mobility(locations (nb, 3), orientations (nb, 4)) -> (nb, 6, 6)``.
    force_torque : callable
        ``force_torque(locations, orientations) -> (nb, 6)``: ``[F, T]`` per body.
    kT : float
        Thermal energy.
    is_valid : callable or None
        ``is_valid(locations, orientations) -> (nb,) bool``; None accepts everything.
    rng : numpy.random.Generator or None
        Source of all random numbers (a fresh default generator if None).
    rfd_delta : float
        Size ``delta`` of the random finite difference of ``RFD`` (length
        units for the location, radians for the rotation; 1e-8 as in the
        published boomerang code, a one-sided difference).
    max_attempts : int
        A body whose step is rejected this many times in a row stops the run
        (``SimulationStopped``).

    Attributes
    ----------
    rejections : int
        Trial configurations rejected so far (all bodies together).
    """

    def __init__(self, scheme, mobility, force_torque, kT, is_valid=None, rng=None, rfd_delta=1e-8,
                 max_attempts=1000):
        if scheme not in SCHEMES:
            raise ValueError('unknown scheme %r; choose one of %s' % (scheme, ', '.join(SCHEMES)))
        self.scheme = scheme
        self.mobility = mobility
        self.force_torque = force_torque
        self.kT = float(kT)
        self.is_valid = is_valid if is_valid is not None else (lambda loc, orient: np.ones(len(loc), bool))
        self.rng = rng if rng is not None else np.random.default_rng()
        self.rfd_delta = float(rfd_delta)
        self.max_attempts = int(max_attempts)
        self.rejections = 0
        self._trial = {'RFD': self._rfd_trial, 'FIXMAN': self._fixman_trial, 'EM': self._em_trial}[scheme]

    def step(self, locations, orientations, dt):
        """One step of every body; returns new ``(locations (nb, 3), orientations (nb, 4))``.

        Bodies whose trial is invalid are redrawn (only those) until all are valid.
        """
        locations = np.array(locations, dtype=float).reshape(-1, 3)
        orientations = np.array(orientations, dtype=float).reshape(-1, 4)
        new_locations = locations.copy()
        new_orientations = orientations.copy()
        pending = np.arange(locations.shape[0])
        for _ in range(self.max_attempts):
            trial_locations, trial_orientations, ok = self._trial(locations[pending], orientations[pending], dt)
            ok = ok & self.is_valid(trial_locations, trial_orientations)
            new_locations[pending[ok]] = trial_locations[ok]
            new_orientations[pending[ok]] = trial_orientations[ok]
            self.rejections += int(np.count_nonzero(~ok))
            pending = pending[~ok]
            if pending.size == 0:
                return new_locations, new_orientations
        raise SimulationStopped('%d bodies had %d invalid trial steps in a row (blobs below the wall); '
                                'use a smaller dt' % (pending.size, self.max_attempts))

    def _noise(self, nb):
        return self.rng.standard_normal((nb, 6))

    def _em_trial(self, locations, orientations, dt):
        N = self.mobility(locations, orientations)
        L = symmetric_cholesky(N)
        velocity = _matvec(N, self.force_torque(locations, orientations)) \
            + np.sqrt(2.0 * self.kT / dt) * _matvec(L, self._noise(len(locations)))
        new_locations, new_orientations = move(locations, orientations, dt * velocity)
        return new_locations, new_orientations, np.ones(len(locations), bool)

    def _rfd_trial(self, locations, orientations, dt):
        nb = len(locations)
        N = self.mobility(locations, orientations)
        L = symmetric_cholesky(N)
        W = self._noise(nb)
        W_rfd = self._noise(nb)
        drift = self.kT * rfd(lambda q: _matvec(self.mobility(*q), W_rfd), (locations, orientations), W_rfd,
                              self.rfd_delta, lambda q, scale, W: move(q[0], q[1], scale * W), centred=False,
                              at_configuration=_matvec(N, W_rfd))
        velocity = _matvec(N, self.force_torque(locations, orientations)) \
            + np.sqrt(2.0 * self.kT / dt) * _matvec(L, W) + drift
        new_locations, new_orientations = move(locations, orientations, dt * velocity)
        return new_locations, new_orientations, np.ones(nb, bool)

    def _fixman_trial(self, locations, orientations, dt):
        nb = len(locations)
        N = self.mobility(locations, orientations)
        L = symmetric_cholesky(N)
        W1 = self._noise(nb)
        W2 = self._noise(nb)
        half_step = 0.5 * dt * _matvec(N, self.force_torque(locations, orientations)) \
            + np.sqrt(self.kT * dt) * _matvec(L, W1)
        mid_locations, mid_orientations = move(locations, orientations, half_step)
        ok = np.asarray(self.is_valid(mid_locations, mid_orientations), bool)
        new_locations = locations.copy()
        new_orientations = orientations.copy()
        if np.any(ok):
            idx = np.nonzero(ok)[0]
            N_mid = self.mobility(mid_locations[idx], mid_orientations[idx])
            # L^{-T} (W1 + W2): solve L^T y = W1 + W2.
            y = np.linalg.solve(np.swapaxes(L[idx], 1, 2), (W1[idx] + W2[idx])[:, :, None])[:, :, 0]
            full_step = dt * _matvec(N_mid, self.force_torque(mid_locations[idx], mid_orientations[idx])) \
                + np.sqrt(self.kT * dt) * _matvec(N_mid, y)
            new_locations[idx], new_orientations[idx] = move(locations[idx], orientations[idx], full_step)
        return new_locations, new_orientations, ok
