"""Metropolis sampler of equilibrium configurations of rigid bodies above a wall (SPEC section 9).

Moves (``mcmc_move``):

* ``all_bodies`` (default, the published algorithm): every step proposes
  to move every body at once, ``x' = x + U(-D, D)^3`` and
  ``q' = from_rotation(N(0, 1)^3 * theta) q`` (D = max_translation, theta =
  max_angle_shift), and accepts the whole proposal when
  ``U(0, 1) < exp(-(E' - E)/kT)``.  Random numbers of one step, in order:
  translations (Nb, 3), rotation normals (Nb, 3), one uniform.
* ``one_body``: every step is a sweep over the bodies in order; body k
  alone is proposed to move as above and accepted on its own energy change,
  which costs O(blobs of body k x N) instead of a full energy.  Random
  numbers of one sweep: translations (Nb, 3), normals (Nb, 3), uniforms (Nb,).

Step sizes: ``max_translation`` (default ``0.1 a``) and ``max_angle_shift``
(default ``max_translation`` over the largest body length).  During the
first ``n_burn_in`` steps they are scaled every ``ADAPT_INTERVAL``
proposals by ``exp(ADAPT_GAIN (acceptance of the window - target_acceptance))`` (the
ratio between them kept, the angle capped at pi); afterwards they stay fixed,
so the chain that follows samples exp(-U/kT) exactly.

Quaternions are not renormalised (as in the dynamic code).
"""
import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from many_bodyMCMC.mcmc_energy import quaternion_product_scalars, quaternion_products, quaternions_from_rotations
from multi_bodies.files.input_options import DEFAULTS  # the keyword defaults are the option table's
from stochastic_forcing import generators

ADAPT_INTERVAL = 50  # proposals per adaptation window during the burn-in
ADAPT_GAIN = 1.5  # log step-size change per unit of acceptance error (the acceptance falls ~0.5 per e-fold)
MOVES = ('all_bodies', 'one_body')


class MetropolisSampler:
    """The chain: configuration, step sizes, counters.

    Parameters
    ----------
    energy : many_bodyMCMC.mcmc_energy.MCMCEnergy
    locations : (Nb, 3); orientations : (Nb, 4) scalar-first quaternions (copied)
    kT : float, the temperature (energy units)
    max_translation, max_angle_shift : floats, proposal sizes
    move : 'all_bodies' or 'one_body'
    n_burn_in : int, steps with step-size adaptation
    target_acceptance : float in (0, 1)
    """

    def __init__(self, energy, locations, orientations, kT, max_translation, max_angle_shift, move=DEFAULTS.mcmc_move,
                 n_burn_in=DEFAULTS.n_burn_in, target_acceptance=DEFAULTS.target_acceptance):
        if move not in MOVES:
            raise ValueError('move must be one of %s' % (MOVES,))
        self.energy, self.kT, self.move = energy, float(kT), move
        self.locations = np.array(locations, dtype=float).reshape(-1, 3)
        self.orientations = np.array(orientations, dtype=float).reshape(-1, 4)
        self.max_translation, self.max_angle_shift = float(max_translation), float(max_angle_shift)
        self.n_burn_in, self.target_acceptance = int(n_burn_in), float(target_acceptance)
        self.proposals = self.accepted = self.invalid = 0
        self.proposals_after_burn_in = self.accepted_after_burn_in = 0
        self.window_proposals = self.window_accepted = 0
        self.refresh()

    def refresh(self):
        """Recompute blob positions and the energy of the current configuration."""
        self.r_vectors = self.energy.blob_positions(self.locations, self.orientations)
        self.current_energy = self.energy.total(self.locations, self.orientations, self.r_vectors)

    # -------------------------------------------------------------------------------- one step
    def _accept(self, delta, uniform):
        # U(0,1) < exp(-dU/kT), written so that exp never overflows; inf and nan are rejected
        return delta <= 0.0 or uniform < math.exp(-delta / self.kT)

    def step(self, step, rng):
        """Advance the chain by step number ``step`` (0-based) with the generator ``rng``."""
        nb = self.locations.shape[0]
        translations = rng.uniform(-self.max_translation, self.max_translation, (nb, 3))
        rotations = quaternions_from_rotations(rng.standard_normal((nb, 3)) * self.max_angle_shift)
        if self.move == 'all_bodies':
            uniform = rng.random()
            locations = self.locations + translations
            orientations = quaternion_products(rotations, self.orientations)
            r_vectors = self.energy.blob_positions(locations, orientations)
            energy = self.energy.total(locations, orientations, r_vectors)
            delta = energy - self.current_energy
            accepted = self._accept(delta, uniform)
            if accepted:
                self.locations, self.orientations, self.r_vectors = locations, orientations, r_vectors
                self.current_energy = energy
            self._count(step, 1, int(accepted), int(math.isinf(energy)))
            return
        uniforms = rng.random(nb).tolist()
        accepted = invalid = 0
        offsets = self.energy.offsets
        # the sweep changes copies: the arrays it started from (a ChainState's) stay as they were
        self.locations, self.orientations = self.locations.copy(), self.orientations.copy()
        self.r_vectors = self.r_vectors.copy()
        new_locations = self.locations + translations
        rotations = rotations.tolist()
        for k in range(nb):
            location = new_locations[k]
            orientation = np.array(quaternion_product_scalars(rotations[k], self.orientations[k].tolist()))
            delta, body_r = self.energy.body_change(k, location, orientation, self.r_vectors, self.locations,
                                                    self.orientations)
            if math.isinf(delta) and delta > 0:
                invalid += 1
            if self._accept(delta, uniforms[k]):
                self.locations[k], self.orientations[k] = location, orientation
                self.r_vectors[offsets[k]:offsets[k + 1]] = body_r
                self.current_energy += delta
                accepted += 1
        self._count(step, nb, accepted, invalid)

    def _count(self, step, proposals, accepted, invalid):
        self.proposals += proposals
        self.accepted += accepted
        self.invalid += invalid
        if step >= self.n_burn_in:
            self.proposals_after_burn_in += proposals
            self.accepted_after_burn_in += accepted
            return
        self.window_proposals += proposals
        self.window_accepted += accepted
        if self.window_proposals >= ADAPT_INTERVAL:
            self.adapt()

    def adapt(self):
        """Scale both step sizes by exp(ADAPT_GAIN (window acceptance - target)); start a new window."""
        ratio = self.window_accepted / self.window_proposals
        factor = math.exp(ADAPT_GAIN * (ratio - self.target_acceptance))
        self.max_translation *= factor
        self.max_angle_shift = min(self.max_angle_shift * factor, math.pi)
        self.window_proposals = self.window_accepted = 0

    # -------------------------------------------------------------------------------- counters, restart
    def acceptance_ratio(self):
        return self.accepted / self.proposals if self.proposals else 0.0

    def info_lines(self):
        """Lines of ``.MCMC_info``: the published four, then further counters."""
        after = (self.accepted_after_burn_in / self.proposals_after_burn_in
                 if self.proposals_after_burn_in else 0.0)
        return ['acceptance ratio = %r' % self.acceptance_ratio(),
                'accepted_moves = %d' % self.accepted,
                'final max_translation = %r' % self.max_translation,
                'final max_angle_shift = %r' % self.max_angle_shift,
                'proposals = %d' % self.proposals,
                'invalid_proposals = %d' % self.invalid,
                'acceptance ratio after burn-in = %r' % after,
                'mcmc_move = %s' % self.move]

    def get_state(self):
        """Everything an exact restart needs besides the generator (exact arrays, sizes, counters)."""
        return {'locations': self.locations.copy(), 'orientations': self.orientations.copy(),
                'max_translation': self.max_translation, 'max_angle_shift': self.max_angle_shift,
                'counters': (self.proposals, self.accepted, self.invalid, self.proposals_after_burn_in,
                             self.accepted_after_burn_in, self.window_proposals, self.window_accepted)}

    def set_state(self, state):
        self.locations = np.array(state['locations'], dtype=float).reshape(-1, 3)
        self.orientations = np.array(state['orientations'], dtype=float).reshape(-1, 4)
        self.max_translation, self.max_angle_shift = state['max_translation'], state['max_angle_shift']
        (self.proposals, self.accepted, self.invalid, self.proposals_after_burn_in, self.accepted_after_burn_in,
         self.window_proposals, self.window_accepted) = state['counters']
        self.refresh()

    # -------------------------------------------------------------------------------- the chain as values
    def chain_state(self, step, rng_state):
        """The chain now as a :class:`ChainState` at step index ``step`` with the generator state ``rng_state``."""
        return ChainState(step=int(step), locations=self.locations, orientations=self.orientations,
                          r_vectors=self.r_vectors, energy=self.current_energy,
                          max_translation=self.max_translation, max_angle_shift=self.max_angle_shift,
                          counters=(self.proposals, self.accepted, self.invalid, self.proposals_after_burn_in,
                                    self.accepted_after_burn_in, self.window_proposals, self.window_accepted),
                          rng_state=rng_state)

    def load(self, state):
        """Take the chain of the :class:`ChainState` ``state`` (its arrays, energy, sizes and counters; nothing is
        recomputed)."""
        self.locations, self.orientations, self.r_vectors = state.locations, state.orientations, state.r_vectors
        self.current_energy = state.energy
        self.max_translation, self.max_angle_shift = state.max_translation, state.max_angle_shift
        (self.proposals, self.accepted, self.invalid, self.proposals_after_burn_in, self.accepted_after_burn_in,
         self.window_proposals, self.window_accepted) = state.counters


@dataclass(frozen=True)
class ChainState:
    """The run state of a Monte Carlo chain (a value: a step makes a new one, the arrays are not changed).

    step : int, the index of the next step; locations (Nb, 3), orientations (Nb, 4) scalar-first quaternions,
    r_vectors (N, 3) the blob positions; energy : float, the energy of the configuration (kT units of the
    potentials); max_translation, max_angle_shift : the proposal sizes; counters : the seven counts of
    :meth:`MetropolisSampler.get_state` (proposals, accepted, invalid, proposals and accepted after the burn-in,
    the adaptation window's proposals and accepted); rng_state : the generator's ``bit_generator.state`` before
    the next step.
    """
    step: int
    locations: np.ndarray
    orientations: np.ndarray
    r_vectors: np.ndarray
    energy: float
    max_translation: float
    max_angle_shift: float
    counters: tuple
    rng_state: Optional[dict] = None

    @property
    def invalid(self):
        return self.counters[2]

    def acceptance_ratio(self):
        proposals, accepted = self.counters[0], self.counters[1]
        return accepted / proposals if proposals else 0.0

    def sampler_record(self):
        """The restart record's ``sampler`` entry (``MetropolisSampler.get_state``'s form, copies)."""
        return {'locations': self.locations.copy(), 'orientations': self.orientations.copy(),
                'max_translation': self.max_translation, 'max_angle_shift': self.max_angle_shift,
                'counters': tuple(self.counters)}


class MetropolisChain:
    """Monte Carlo as a scheme of the run loop: ``step(model, state) -> state`` with the generator's state in
    the run state (``ChainState.rng_state``), as the dynamic schemes' ``RunState``.

    ``sampler``: the :class:`MetropolisSampler` whose ``step`` advances the chain (its rules: moves, acceptance,
    burn-in adaptation); ``model``: the energy (unused: the sampler holds it).
    """

    def __init__(self, sampler):
        self.sampler = sampler
        self._live = None  # (the rng_state dict this chain's last step returned, the generator that is there)

    def init(self, step, rng_state):
        """The chain's state at step index ``step`` (the sampler as it is now) with the generator state
        ``rng_state``."""
        return self.sampler.chain_state(step, rng_state)

    def generator(self, state):
        """The generator a step from ``state`` draws from: made from ``state.rng_state``, or, when ``state`` is the
        one this chain's last step returned, the generator that step left there (the same numbers, without
        making a generator at every step of a long chain)."""
        if self._live is not None and self._live[0] is state.rng_state:
            return self._live[1]
        return generators.from_state(state.rng_state)

    def step(self, model, state):
        """The state after Monte Carlo step ``state.step`` (one move of all bodies or one sweep): draws from a
        generator at ``state.rng_state``; ``state`` is left unchanged."""
        sampler = self.sampler
        sampler.load(state)
        rng = self.generator(state)
        self._live = None  # while it draws, the generator is at no state's rng_state
        sampler.step(state.step, rng)
        rng_state = rng.bit_generator.state
        self._live = (rng_state, rng)
        return sampler.chain_state(state.step + 1, rng_state)
