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
    """Single-blob rollers: only blob positions move; velocities (N, 3) (``rollers`` in the registry)."""

    def stochastic_velocity(self, context, r_vectors, dt_fraction=1.0, with_drift=True):
        """Noise ``sqrt(2kT/(f dt)) M^{1/2} z`` plus (optionally) the RFD drift. Draws z (3N), then W (3N)."""
        z = context.rng.standard_normal(3 * context.num_blobs)
        velocity = context.roller_noise(r_vectors, z, self.noise_factor(dt_fraction))
        if with_drift and self.kT > 0 and self.thermal_drift:
            W = context.rng.standard_normal(3 * context.num_blobs)
            velocity = velocity + context.roller_drift(r_vectors, W, self.kT, self.delta)
        return velocity

    def drift(self, context, r_vectors):
        """RFD drift alone (draws W (3N) first)."""
        if self.kT == 0:
            return np.zeros_like(r_vectors)
        W = context.rng.standard_normal(3 * context.num_blobs)
        if not self.thermal_drift:
            return np.zeros_like(r_vectors)
        return context.roller_drift(r_vectors, W, self.kT, self.delta)


class StochasticFirstOrderRollers(StochasticRollerScheme):
    """``r += dt (v_det + noise + drift)``.  Draws: z, W (3N each)."""
    name = 'stochastic_first_order_rollers'

    def attempt(self, context, state, old):
        r = context.model.blob_positions(old)
        v, state = self.roller_velocities(context, state, old)
        v = v + self.stochastic_velocity(context, r)
        return self.move(old, v, self.dt), v, state


class StochasticAdamsBashforthRollers(StochasticRollerScheme):
    """Adams-Bashforth deterministic velocity plus noise and drift (the manual's recommendation for rollers)."""
    name = 'stochastic_adams_bashforth_rollers'

    def attempt(self, context, state, old):
        r = context.model.blob_positions(old)
        v_det, state = self.roller_velocities(context, state, old)
        v, state = self.multistep(state, v_det, self.stochastic_velocity(context, r))
        return self.move(old, v, self.dt), v, state


class StochasticMidPointRollers(StochasticRollerScheme):
    """Midpoint: noise at r^n and at the midpoint, drift at r^n.  Draws: W (drift), z1, z2 (3N each)."""
    name = 'stochastic_mid_point_rollers'

    def attempt(self, context, state, old):
        r = context.model.blob_positions(old)
        d = self.drift(context, r)
        s1 = self.stochastic_velocity(context, r, dt_fraction=0.5, with_drift=False)
        v_det, state = self.roller_velocities(context, state, old)
        mid = self.move(old, v_det + s1, 0.5 * self.dt)
        self.check(context, state, mid)
        r_mid = context.model.blob_positions(mid)
        s2 = self.stochastic_velocity(context, r_mid, dt_fraction=0.5, with_drift=False)
        v_mid, state = self.roller_velocities(context, state, mid)
        v = v_mid + d + 0.5 * (s1 + s2)
        return self.move(old, v, self.dt), v, state


class StochasticTrapezoidalRollers(StochasticRollerScheme):
    """Trapezoidal: predictor ``r + dt (v1 + s)``, then the average of the two deterministic velocities.

    Draws: W (drift), z (3N each).
    """
    name = 'stochastic_trapezoidal_rollers'

    def attempt(self, context, state, old):
        r = context.model.blob_positions(old)
        d = self.drift(context, r)
        s = self.stochastic_velocity(context, r, with_drift=False)
        v1, state = self.roller_velocities(context, state, old)
        predictor = self.move(old, v1 + s, self.dt)
        self.check(context, state, predictor)
        v2, state = self.roller_velocities(context, state, predictor)
        v = 0.5 * (v1 + v2) + d + s
        return self.move(old, v, self.dt), v, state


ROLLER_SCHEME_CLASSES = (StochasticFirstOrderRollers, StochasticAdamsBashforthRollers, StochasticMidPointRollers,
                         StochasticTrapezoidalRollers)
