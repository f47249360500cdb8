"""Brownian schemes of single-blob rollers (SPEC §5.2; Balboa Usabiaga et al., J. Chem. Phys. 146, 134104, 2017),
floor 5.

Rollers are single blobs whose positions alone move (velocities (N, 3)); their drift comes from random finite
differences of the blob mobility and their noise from Lanczos on it (``Model.roller_drift``,
``Model.roller_noise``).  The step machinery (rejections, random draws, the Adams-Bashforth history) is
:class:`quaternion_integrator.stochastic_schemes.StochasticScheme`'s.
"""
import numpy as np

from quaternion_integrator.stochastic_schemes import StochasticScheme
class StochasticRollerScheme(StochasticScheme):
    """Single-blob rollers: only blob positions move; velocities (N, 3)."""
    rollers = True

    def stochastic_velocity(self, work, rng, r_vectors, dt_fraction=1.0, with_drift=True):
        """Noise ``sqrt(2kT/(f dt)) M^{1/2} z`` plus (optionally) the RFD drift. Draws z (3N), then W (3N)."""
        z = rng.standard_normal(3 * work.num_blobs)
        velocity = work.roller_noise(r_vectors, z, self.noise_factor(dt_fraction))
        if with_drift and self.kT > 0 and self.thermal_drift:
            W = rng.standard_normal(3 * work.num_blobs)
            velocity = velocity + work.roller_drift(r_vectors, W, self.kT, self.delta)
        return velocity

    def drift(self, work, rng, r_vectors):
        """RFD drift alone (draws W (3N) first)."""
        if self.kT == 0:
            return np.zeros_like(r_vectors)
        W = rng.standard_normal(3 * work.num_blobs)
        if not self.thermal_drift:
            return np.zeros_like(r_vectors)
        return work.roller_drift(r_vectors, W, self.kT, self.delta)


class StochasticFirstOrderRollers(StochasticRollerScheme):
    """``r += dt (v_det + noise + drift)``.  Draws: z, W (3N each)."""
    name = 'stochastic_first_order_rollers'

    def attempt(self, work, step_index, rng, old):
        r = work.blob_positions(old)
        v = self.roller_velocities(work, old) + self.stochastic_velocity(work, rng, r)
        return self.move(old, v, self.dt), v


class StochasticAdamsBashforthRollers(StochasticRollerScheme):
    """Adams-Bashforth deterministic velocity plus noise and drift (the manual's recommendation for rollers)."""
    name = 'stochastic_adams_bashforth_rollers'

    def attempt(self, work, step_index, rng, old):
        r = work.blob_positions(old)
        v_det = self.roller_velocities(work, old)
        v = self.multistep(work, v_det, self.stochastic_velocity(work, rng, r))
        return self.move(old, v, self.dt), v


class StochasticMidPointRollers(StochasticRollerScheme):
    """Midpoint: noise at r^n and at the midpoint, drift at r^n.  Draws: W (drift), z1, z2 (3N each)."""
    name = 'stochastic_mid_point_rollers'

    def attempt(self, work, step_index, rng, old):
        r = work.blob_positions(old)
        d = self.drift(work, rng, r)
        s1 = self.stochastic_velocity(work, rng, r, dt_fraction=0.5, with_drift=False)
        v_det = self.roller_velocities(work, old)
        mid = self.move(old, v_det + s1, 0.5 * self.dt)
        self.check(work, mid)
        r_mid = work.blob_positions(mid)
        s2 = self.stochastic_velocity(work, rng, r_mid, dt_fraction=0.5, with_drift=False)
        v = self.roller_velocities(work, mid) + d + 0.5 * (s1 + s2)
        return self.move(old, v, self.dt), v


class StochasticTrapezoidalRollers(StochasticRollerScheme):
    """Trapezoidal: predictor ``r + dt (v1 + s)``, then the average of the two deterministic velocities.

    Draws: W (drift), z (3N each).
    """
    name = 'stochastic_trapezoidal_rollers'

    def attempt(self, work, step_index, rng, old):
        r = work.blob_positions(old)
        d = self.drift(work, rng, r)
        s = self.stochastic_velocity(work, rng, r, with_drift=False)
        v1 = self.roller_velocities(work, old)
        predictor = self.move(old, v1 + s, self.dt)
        self.check(work, predictor)
        v = 0.5 * (v1 + self.roller_velocities(work, predictor)) + d + s
        return self.move(old, v, self.dt), v


ROLLER_SCHEME_CLASSES = (StochasticFirstOrderRollers, StochasticAdamsBashforthRollers, StochasticMidPointRollers,
                         StochasticTrapezoidalRollers)
