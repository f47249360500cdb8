"""Time and memory of the trajectory analyses (doc/analysis.md) on large suspensions.

A synthetic quasi-2-d suspension (uniform positions in a periodic box, a new
frame per read, so the benchmark itself holds no trajectory) of ``--particles``
particles at area density ``--density`` is analysed for ``--frames`` frames:

* g(r) in the plane, ``--r-max`` (default 10) and 100 bins (k-d tree pair counts);
* S(k) on the box wavevectors ``|n| <= --k-index-max`` (default 32: 65 x 33 = 2,145 wavevectors);
* F(k, t) (4 shells of box wavevectors) and the MSDs, lags up to ``--max-lag`` (default 100), on
  ``--fkt-frames`` frames (default 150: more than the largest lag, so the buffer of time origins is full
  and the cost per frame is that of a long trajectory).

Each analysis runs alone through ``analyse`` (chunks of frames as a run is
read); the table gives seconds per frame, the time extrapolated to
``--extrapolate`` frames (default 1e4) and the peak memory that the analysis
allocated (``tracemalloc``, numpy's arrays included; the chunk of frames read
at once, at most 64 MiB, is part of it).  Reading the text
``.config`` snapshots is timed apart (``--read-frames``), since it is usually
the larger cost.

    python benchmarks/bench_analysis.py [--particles 10000] [--frames 20] [--extrapolate 10000]
"""
import argparse
import os
import platform
import sys
import tempfile
import time
import tracemalloc

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from multi_bodies.analysis.pair_correlation import PairCorrelation  # noqa: E402
from multi_bodies.analysis.structure_factor import StructureFactor  # noqa: E402
from multi_bodies.analysis.time_correlations import TimeCorrelations, lag_list, shell_wavevectors  # noqa: E402
from multi_bodies.analysis.trajectories import ConfigSeries, analyse  # noqa: E402
from multi_bodies.files import snapshots  # noqa: E402


class SyntheticSource:
    """Uniform random frames, made when read (frame f from seed f): no trajectory in memory."""

    def __init__(self, frames, particles, box, step=0.0):
        self.n_frames, self.n_particles, self.periodic_length = frames, particles, np.asarray(box, dtype=float)
        self.frame_interval, self.label, self.step = 1.0, 'synthetic', step
        self.start = np.random.default_rng(0).random((particles, 3)) * [box[0], box[1], 1.0]

    def read(self, first, stop):
        if self.step > 0:  # Brownian-like: small displacements from a fixed start (for the time correlations)
            return np.stack([self.start + np.random.default_rng(f).normal(0, self.step, self.start.shape)
                             for f in range(first, stop)])
        return np.stack([np.random.default_rng(f).random((self.n_particles, 3)) * [self.periodic_length[0],
                                                                                    self.periodic_length[1], 1.0]
                         for f in range(first, stop)])


def measure(make_accumulator, source, generation_seconds):
    """(seconds per frame without the frame generation, peak MiB allocated) of one analysis."""
    accumulator = make_accumulator()
    tracemalloc.start()
    start = time.perf_counter()
    analyse([source], [accumulator], blocks=10)
    accumulator.result()
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1] / 2 ** 20
    tracemalloc.stop()
    return (seconds - generation_seconds) / source.n_frames, peak


def generation_cost(source):
    start = time.perf_counter()
    for first in range(0, source.n_frames, 8):
        source.read(first, min(first + 8, source.n_frames))
    return time.perf_counter() - start


def reading_cost(particles, frames):
    """Seconds per frame to index and read a ``.config`` series of ``frames`` snapshots (text)."""
    with tempfile.TemporaryDirectory() as folder:
        name = os.path.join(folder, 'run')
        rng = np.random.default_rng(1)
        quaternions = np.tile([1.0, 0, 0, 0], (particles, 1))
        for index in range(frames):
            snapshots.append_config_snapshot(snapshots.config_name(name, 'b'), rng.random((particles, 3)),
                                             quaternions, new_file=index == 0)
        start = time.perf_counter()
        source = ConfigSeries(name, ['b'], 1.0, 1, (1, 1, 0))
        source.read(0, source.n_frames)
        return (time.perf_counter() - start) / frames


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--particles', type=int, default=10000)
    parser.add_argument('--frames', type=int, default=20, help='frames analysed (default 20)')
    parser.add_argument('--extrapolate', type=int, default=10000, help='frames of the extrapolated column')
    parser.add_argument('--density', type=float, default=0.1, help='particles per unit area (default 0.1)')
    parser.add_argument('--r-max', type=float, default=10.0)
    parser.add_argument('--k-index-max', type=int, default=32)
    parser.add_argument('--max-lag', type=int, default=100)
    parser.add_argument('--fkt-frames', type=int, default=150)
    parser.add_argument('--read-frames', type=int, default=5, help='.config frames read for the reading cost')
    args = parser.parse_args()
    L = float(np.sqrt(args.particles / args.density))
    box = (L, L, 0.0)
    plain = SyntheticSource(args.frames, args.particles, box)
    base = generation_cost(plain)
    moving = SyntheticSource(args.fkt_frames, args.particles, box, step=0.1)
    base_moving = generation_cost(moving)
    wavevectors, groups, _, _ = shell_wavevectors(box, [2 * np.pi * n / L for n in (1, 2, 4, 8)])
    lags = lag_list(args.max_lag)
    cases = [
        ('g(r) 2-d, r_max %g, 100 bins' % args.r_max, lambda: PairCorrelation(box, args.r_max, 100, 2), plain, base),
        ('S(k) 2-d, |n| <= %d (%d wavevectors)' % (args.k_index_max, (2 * args.k_index_max + 1) *
                                                   args.k_index_max + args.k_index_max),
         lambda: StructureFactor(box, args.k_index_max, 2), plain, base),
        ('F(k,t) %d wavevectors + MSD, %d lags to %d' % (len(wavevectors), len(lags), args.max_lag),
         lambda: TimeCorrelations(1.0, lags, box, wavevectors, groups, 2), moving, base_moving),
    ]
    print('machine: %s, %s, %d cores, numpy %s' % (platform.processor() or platform.machine(), platform.system(),
                                                  os.cpu_count(), np.__version__))
    print('%d particles, box %.1f x %.1f (density %g), %d frames analysed; extrapolated to %d frames'
          % (args.particles, L, L, args.density, args.frames, args.extrapolate))
    print('| analysis | s / frame | s for %d frames | peak memory (MiB) |' % args.extrapolate)
    print('|---|---|---|---|')
    for label, make, source, generation in cases:
        seconds, peak = measure(make, source, generation)
        print('| %s | %.4f | %.0f | %.0f |' % (label, seconds, seconds * args.extrapolate, peak))
    if args.read_frames > 0:
        seconds = reading_cost(args.particles, args.read_frames)
        print('| reading a .config series (text) | %.4f | %.0f | - |' % (seconds, seconds * args.extrapolate))


if __name__ == '__main__':
    main()
