"""Mean-square displacements of rigid bodies from trajectories (Delong et al., J. Chem. Phys. 2015, section III).

The displacement between two configurations ``(x0, R0)`` and ``(x1, R1)`` is
the 6-vector ``[P1 - P0, u]``: ``P = x + R p`` is the tracking point (``p``
fixed in the body frame; ``p = 0`` tracks the body location) and
``u = (1/2) sum_i e_i(0) x e_i(1)`` the rotational displacement, with
``e_i = R[:, i]`` the body axes in the lab frame (for a small rotation by
the vector ``phi``, ``u ~ phi``).  The MSD at lag ``k`` is the 6x6 average
of ``d d^T`` over all time origins of a trajectory; error bars come from the
spread of the per-trajectory MSDs over independent trajectories.
"""
import numpy as np

from body.geometry import rotation_matrices


def rotational_displacements(R0, R1):
    """``u = (1/2) sum_i R0[:, i] x R1[:, i]`` for stacks of rotations (n, 3, 3) -> (n, 3)."""
    return 0.5 * np.sum(np.cross(np.swapaxes(R0, 1, 2), np.swapaxes(R1, 1, 2)), axis=1)


def tracking_points(locations, orientations, point=(0.0, 0.0, 0.0)):
    """Lab-frame positions ``x + R(q) p`` of the body-frame point ``p``; shapes (n, 3), (n, 4) -> (n, 3)."""
    R = rotation_matrices(np.asarray(orientations, dtype=float).reshape(-1, 4))
    return np.asarray(locations, dtype=float).reshape(-1, 3) + R @ np.asarray(point, dtype=float)


def lagged_msd(locations, orientations, lags, point=(0.0, 0.0, 0.0)):
    """6x6 MSD of one trajectory at each lag (in steps), averaged over time origins.

    Parameters
    ----------
    locations : ndarray, shape (n, 3)
    orientations : ndarray, shape (n, 4)
    lags : sequence of int
        Lags in samples, each ``< n`` (0 gives zeros).
    point : (3,) body-frame tracking point.

    Returns
    -------
    ndarray, shape (len(lags), 6, 6); rows and columns ``x, y, z, u_x, u_y, u_z``.
    """
    R = rotation_matrices(np.asarray(orientations, dtype=float).reshape(-1, 4))
    P = np.asarray(locations, dtype=float).reshape(-1, 3) + R @ np.asarray(point, dtype=float)
    n = P.shape[0]
    out = np.zeros((len(lags), 6, 6))
    for k, lag in enumerate(lags):
        lag = int(lag)
        if lag <= 0:
            continue
        if lag >= n:
            raise ValueError('lag %d is not shorter than the trajectory (%d samples)' % (lag, n))
        d = np.concatenate((P[lag:] - P[:-lag], rotational_displacements(R[:-lag], R[lag:])), axis=1)
        out[k] = d.T @ d / d.shape[0]
    return out


def msd_statistics(trajectories, lags, point=(0.0, 0.0, 0.0)):
    """Mean MSD over trajectories and its standard error.

    ``trajectories``: list of ``(locations (n, 3), orientations (n, 4))``.
    Returns ``(mean (L, 6, 6), standard_error (L, 6, 6))``; the error is
    ``std / sqrt(n_trajectories)`` (zeros for a single trajectory).
    """
    per_run = np.array([lagged_msd(loc, orient, lags, point) for loc, orient in trajectories])
    mean = per_run.mean(axis=0)
    if len(per_run) < 2:
        return mean, np.zeros_like(mean)
    return mean, per_run.std(axis=0, ddof=1) / np.sqrt(len(per_run))
