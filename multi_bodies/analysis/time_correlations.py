"""Time correlations over lags: intermediate scattering function F(k, t) and mean-square displacements.

For lags ``t = l * tau`` (tau the time between the frames used):

* ``msd_xy(t) = < |Δx|^2 + |Δy|^2 >``, ``msd_z(t) = < Δz^2 >`` (lengths squared), Δ over the lag,
  averaged over particles and time origins;
* self part ``F_s(k, t) = < cos(k . Δr_j) >`` (particles, origins, the wavevectors of a shell);
* collective ``F(k, t) = Re < rho_k(t0 + t) rho_k(t0)^* > / N`` (origins, shell), so ``F(k, 0) = S(k)``;
  it needs the box's wavevectors (periodic x, y in the plane; x, y, z in 3-d).

Free Brownian particles with diffusion coefficient D: ``msd_xy = 4 D t``,
``msd_z = 2 D t`` and ``F_s = F = exp(-D k^2 t)`` (ideal gas: the cross terms of
F vanish on average).  Positions are used as saved (the package saves them
unwrapped: a body that leaves the periodic box keeps its coordinate); set
``unwrap`` for trajectories written inside the box, which undoes jumps of more
than half a box length between consecutive frames.

Streaming: the time origins of the last ``max_lag + 1`` frames (positions and
the per-particle phases ``exp(i k . r_j)``) are kept in a buffer and each new
frame is correlated with its origins at the chosen lags.  Every
``origin_every``-th frame is an origin (default: every frame, or the smallest
spacing that keeps the buffer under ``BUFFER_BYTES``, 1 GiB), so the memory is
about ``(max_lag / origin_every + 1) N (3 + 2 n_k) * 8`` bytes whatever the number
of frames.  Each pair of frames counts in the block (replica) of its origin.
"""
import numpy as np

from multi_bodies.analysis.structure_factor import half_space
from multi_bodies.analysis.trajectories import BlockSums, block_mean_and_error
from utils import UserInputError, refuse_if_too_big

BUFFER_BYTES = 1024 ** 3


def lag_list(max_lag, count=48):
    """Lags in frames: 0, 1, ..., max_lag when max_lag <= count, else 0 and ``count`` log-spaced ones."""
    max_lag = int(max_lag)
    if max_lag < 1:
        raise UserInputError('the largest lag must be at least 1 frame, got %d' % max_lag)
    if max_lag <= count:
        return np.arange(max_lag + 1)
    return np.unique(np.concatenate([[0], np.round(np.logspace(0, np.log10(max_lag), count)).astype(int)]))


def shell_wavevectors(periodic_length, k_values, dimension=2, per_shell=12, where='F(k,t)'):
    """Wavevectors (n_k, d) and their shell index (n_k,) for each target wavenumber of ``k_values``.

    Periodic box (x, y in the plane; x, y, z in 3-d): the half-space box wavevectors with
    ``| |k| - k_target | <= w / 2``, ``w = 2 pi / largest length`` (at most ``per_shell`` of them, evenly
    picked); the shell's |k| is their mean.  Otherwise: k_target along each axis (self part only).
    Returns wavevectors, groups, shell |k| (n_shells,), periodic (bool).  ``where`` (the option giving
    ``k_values``) names the refusal of a wavenumber that is not a positive finite number, or whose box of
    candidate wavevectors does not fit in memory (checked before it is made).
    """
    box = np.asarray(periodic_length, dtype=float).reshape(3)[:dimension]
    vectors, groups, magnitudes = [], [], []
    periodic = bool(np.all(box > 0))
    for shell, target in enumerate(np.atleast_1d(np.asarray(k_values, dtype=float))):
        if not (target > 0 and np.isfinite(target)):
            raise UserInputError('%s: wavenumbers must be positive finite numbers, got %g' % (where, target))
        if periodic:
            width = 2.0 * np.pi / box.max()
            reach = (target + width) * box / (2.0 * np.pi)
            with np.errstate(over='ignore'):
                candidates = float(np.prod(2.0 * np.ceil(reach) + 1.0))
            refuse_if_too_big(candidates * 8 * (3 * dimension + 2), 'the box of wavevectors around |k| = %g (%.3g '
                              'of them)' % (target, candidates), where, 'ask for smaller wavenumbers')
            n_max = np.ceil(reach).astype(int)
            ranges = [np.arange(-m, m + 1) for m in n_max]
            grid = np.stack(np.meshgrid(*ranges, indexing='ij'), axis=-1).reshape(-1, dimension)
            grid = grid[half_space(grid)]
            k = 2.0 * np.pi * grid / box
            chosen = k[np.abs(np.linalg.norm(k, axis=1) - target) <= 0.5 * width + 1e-12 * target]
            if len(chosen) == 0:
                raise UserInputError('no box wavevector with |k| near %g' % target)
            if len(chosen) > per_shell:
                chosen = chosen[np.linspace(0, len(chosen) - 1, per_shell).astype(int)]
        else:
            chosen = target * np.eye(dimension)
        vectors.append(chosen)
        groups.append(np.full(len(chosen), shell))
        magnitudes.append(np.linalg.norm(chosen, axis=1).mean())
    return np.concatenate(vectors), np.concatenate(groups), np.array(magnitudes), periodic


class TimeCorrelations:
    """Accumulator of the MSDs and F(k, t) (see module docstring).

    time_step : time between the frames used; lags : lags in frames (int array, from :func:`lag_list`);
    periodic_length : (3,); wavevectors : (n_k, d) or None (no F); groups : (n_k,) shell of each;
    dimension : 2 (F from x, y) or 3; collective : also the collective F (needs the box wavevectors);
    msd : compute the MSDs; unwrap : undo periodic jumps between frames;
    origin_every : frames between time origins (None: 1, or larger when the buffer would pass BUFFER_BYTES).
    """

    def __init__(self, time_step, lags, periodic_length, wavevectors=None, groups=None, dimension=2,
                 collective=True, msd=True, unwrap=False, origin_every=None):
        self.time_step, self.lags = float(time_step), np.asarray(lags, dtype=int)
        self.box = np.asarray(periodic_length, dtype=float).reshape(3)
        self.wavevectors = None if wavevectors is None else np.asarray(wavevectors, dtype=float)
        self.groups = None if groups is None else np.asarray(groups, dtype=int)
        self.dimension, self.collective, self.msd, self.unwrap = dimension, collective, msd, unwrap
        n_k = 0 if self.wavevectors is None else len(self.wavevectors)
        self.msd_sums = BlockSums((len(self.lags), 2))
        self.self_sums = BlockSums((len(self.lags), n_k))
        self.collective_sums = BlockSums((len(self.lags), n_k))
        self.n_particles, self.buffer, self.previous, self.frames = None, {}, None, 0
        self.origin_every = origin_every

    def start_source(self):
        self.buffer, self.previous = {}, None

    def _check_memory(self, n_particles):
        n_k = 0 if self.wavevectors is None else len(self.wavevectors)
        per_frame = n_particles * (3 + 2 * n_k) * 8
        if self.origin_every is None:
            self.origin_every = 1
            while (self.lags.max() // self.origin_every + 1) * per_frame > BUFFER_BYTES:
                self.origin_every += 1
        self.origin_every = int(self.origin_every)
        if self.origin_every < 1 or per_frame > BUFFER_BYTES:
            raise UserInputError('F(k,t)/MSD: one frame of %d particles and %d wavevectors needs more than the %.1f '
                                 'GiB buffer (or origin_every < 1); give fewer --k-values'
                                 % (n_particles, n_k, BUFFER_BYTES / 1024 ** 3))

    def add(self, positions, frames, blocks):
        positions = np.asarray(positions, dtype=float)
        if self.n_particles is None:
            self.n_particles = positions.shape[1]
            self._check_memory(self.n_particles)
        periodic = np.flatnonzero(self.box > 0)
        for frame_positions, frame, block in zip(positions, frames, blocks):
            frame_positions = frame_positions.copy()
            if self.unwrap and self.previous is not None and len(periodic):
                jump = frame_positions[:, periodic] - self.previous[:, periodic]
                frame_positions[:, periodic] -= np.round(jump / self.box[periodic]) * self.box[periodic]
            self.previous = frame_positions
            self.frames += 1
            phases = rho = None
            if self.wavevectors is not None:
                angles = frame_positions[:, :self.dimension] @ self.wavevectors.T  # (N, n_k)
                phases = np.concatenate([np.cos(angles), np.sin(angles)], axis=1)  # (N, 2 n_k): Re, Im of exp(i k.r)
                rho = phases.sum(axis=0)
            if int(frame) % self.origin_every == 0:
                self.buffer[int(frame)] = (frame_positions, phases, rho, int(block))
            self.buffer.pop(int(frame) - int(self.lags.max()) - 1, None)
            for row, lag in enumerate(self.lags):
                origin = self.buffer.get(int(frame) - int(lag))
                if origin is None:
                    continue
                origin_positions, origin_phases, origin_rho, origin_block = origin
                if self.msd:
                    step = frame_positions - origin_positions
                    squares = np.einsum('ja,ja->a', step, step) / len(step)
                    values = [squares[0] + squares[1], squares[2]]
                    self.msd_sums.add(origin_block, values, 1.0, index=row)
                if phases is not None:
                    n_k = phases.shape[1] // 2  # Re(e_t e_o^*) = cos cos' + sin sin'
                    products = np.einsum('jk,jk->k', phases, origin_phases) / len(phases)
                    self_part = products[:n_k] + products[n_k:]
                    self.self_sums.add(origin_block, self_part, 1.0, index=row)
                    if self.collective:
                        n_k = len(rho) // 2
                        collective = (rho[:n_k] * origin_rho[:n_k] + rho[n_k:] * origin_rho[n_k:]) / len(phases)
                        self.collective_sums.add(origin_block, collective, 1.0, index=row)

    def _by_shell(self, sums):
        """Average over the wavevectors of each shell, per block: (B, lags, shells)."""
        shells = self.groups.max() + 1
        count = np.bincount(self.groups, minlength=shells)
        out = np.zeros(sums.sums.shape[:2] + (shells,))
        for shell in range(shells):
            out[:, :, shell] = sums.sums[:, :, self.groups == shell].sum(axis=2) / count[shell]
        return block_mean_and_error(out, sums.weights[:, :, :1])

    def result(self):
        """dict: lag (n_lags,) frames, time (n_lags,), msd_xy, msd_z and their errors (n_lags,);
        with wavevectors: Fs, Fs_error, F, F_error (n_lags, n_shells); blocks, particles."""
        if self.n_particles is None:
            raise UserInputError('F(k,t)/MSD: no frame was analysed')
        out = {'lag': self.lags, 'time': self.lags * self.time_step, 'particles': self.n_particles,
               'frames': self.frames, 'origin_every': self.origin_every,
               'blocks': int((self.msd_sums.weights[:, 0, 0] > 0).sum() if self.msd else
                             (self.self_sums.weights[:, 0, 0] > 0).sum()),
               'origins': (self.msd_sums.weights if self.msd else self.self_sums.weights)[:, :, 0].sum(axis=0)}
        if self.msd:
            mean, error = self.msd_sums.mean_and_error()
            out.update(msd_xy=mean[:, 0], msd_xy_error=error[:, 0], msd_z=mean[:, 1], msd_z_error=error[:, 1])
        if self.wavevectors is not None:
            out['Fs'], out['Fs_error'] = self._by_shell(self.self_sums)
            if self.collective:
                out['F'], out['F_error'] = self._by_shell(self.collective_sums)
        return out
