"""The Fourier transforms of one spectral product under each FFT library that installs from a wheel (issue 44).

The spectral product (``mobility/spectral/compiled.py``) transforms three grid components of shape
(Nz, Ny, Nx) per product, forward and back: a real-to-complex transform along x (row blocks of 8 MB) and a
complex transform along y (doubly periodic geometries; also along z in the triply periodic box).  This script
runs exactly that pattern on a random grid of the timing scenes' sizes with each library it finds:

* ``scipy``: ``scipy.fft`` (pocketfft, shipped with SciPy), ``workers`` = OpenMP's thread count: what the
  package uses;
* ``numpy``: ``numpy.fft`` (one thread, no workers argument);
* ``pyfftw``: ``pyfftw.interfaces.scipy_fft`` (FFTW 3 from the ``pyFFTW`` wheel), ``threads`` as above,
  planner ``FFTW_ESTIMATE`` and, separately, ``FFTW_MEASURE`` (its planning seconds printed apart; plans cached);
* ``mkl_fft``: ``mkl_fft.interfaces.scipy_fft`` (Intel MKL from the ``mkl_fft`` wheel).

Rounds are interleaved (one forward + backward of each library per round), ``--repeats`` rounds after one
warm-up round; printed: median wall and CPU seconds per forward + backward of the three components, the ratio
to ``scipy``, and the largest difference of the result from ``scipy``'s relative to the largest value.

    python3 benchmarks/bench_fft.py --grids 490x491x33 1536x1536x33
    /path/to/venv-with-pyfftw/bin/python benchmarks/bench_fft.py      # the wheels live in their own venv

No package import: any interpreter with numpy and scipy runs it.
"""
import argparse
import os
import statistics
import time

import numpy as np
import scipy.fft as sfft

BLOCK_BYTES = 8 * 2 ** 20


def workers():
    return int(os.environ.get('OMP_NUM_THREADS', os.cpu_count() or 1))


def transform_pair(module, grid, periodic_z, **options):
    """Forward (rfft along x by row blocks, fft along y [and z]) then backward of each component, as the
    product does; ``grid``: (3, Nz, Ny, Nx) real, overwritten with the round trip.  Returns the spectrum of the
    first component."""
    _, Nz, Ny, Nx = grid.shape
    axes = (0, 1) if periodic_z else (1,)
    first = None
    for c in range(3):
        rows = grid[c].reshape(Nz * Ny, Nx)
        per_block = max(1, BLOCK_BYTES // (16 * (Nx // 2 + 1)))
        spectrum = np.empty((Nz * Ny, Nx // 2 + 1), dtype=np.complex128)
        for start in range(0, Nz * Ny, per_block):
            block = slice(start, min(start + per_block, Nz * Ny))
            spectrum[block] = module.rfft(rows[block], axis=-1, **options)
        spectrum = module.fftn(spectrum.reshape(Nz, Ny, Nx // 2 + 1), axes=axes, **options)
        if first is None:
            first = spectrum.copy()
        back = module.ifftn(spectrum, axes=axes, **options).reshape(Nz * Ny, Nx // 2 + 1)
        for start in range(0, Nz * Ny, per_block):
            block = slice(start, min(start + per_block, Nz * Ny))
            rows[block] = module.irfft(back[block], n=Nx, axis=-1, **options)
    return first


def libraries(threads):
    """name -> (module, options, set-up note)."""
    found = {'scipy': (sfft, {'workers': threads}, 'pocketfft (SciPy %s)' % __import__('scipy').__version__),
             'numpy': (np.fft, {}, 'numpy.fft (NumPy %s), one thread' % np.__version__)}
    try:
        import pyfftw
        import pyfftw.interfaces.scipy_fft as fftw_scipy
        pyfftw.interfaces.cache.enable()
        pyfftw.interfaces.cache.set_keepalive_time(600)
        found['pyfftw'] = (fftw_scipy, {'workers': threads, 'planner_effort': 'FFTW_ESTIMATE'},
                           'pyFFTW %s, FFTW_ESTIMATE' % pyfftw.__version__)
        found['pyfftw-measure'] = (fftw_scipy, {'workers': threads, 'planner_effort': 'FFTW_MEASURE'},
                                   'pyFFTW %s, FFTW_MEASURE (planning in the warm-up round)' % pyfftw.__version__)
    except ImportError:
        pass
    try:
        import mkl_fft
        import mkl_fft.interfaces.scipy_fft as mkl_scipy
        found['mkl_fft'] = (mkl_scipy, {'workers': threads}, 'mkl_fft %s' % mkl_fft.__version__)
    except ImportError:
        pass
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--grids', nargs='+', default=['490x491x33', '1536x1536x33', '490x491x19'],
                        help='Nx x Ny x Nz; Nz 19 is taken as the triply periodic box (fft along z too)')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    threads = workers()
    found = libraries(threads)
    cpu = next((line.split(':', 1)[1].strip() for line in open('/proc/cpuinfo') if line.startswith('model name')),
               '?') if os.path.exists('/proc/cpuinfo') else '?'
    print('CPU %s, %d threads (OMP_NUM_THREADS or all cores); %s' % (cpu, threads, '; '.join(
        '%s: %s' % (name, note) for name, (_, _, note) in found.items())))
    print('%14s %16s %10s %10s %10s %12s' % ('grid', 'library', 'wall s', 'CPU s', 'x scipy', 'max diff'))
    for text in args.grids:
        Nx, Ny, Nz = (int(v) for v in text.lower().split('x'))
        periodic_z = Nz == 19
        source = np.random.default_rng(7).standard_normal((3, Nz, Ny, Nx))
        times = {name: [] for name in found}
        spectra = {}
        for round_ in range(args.repeats + 1):
            for name, (module, options, _) in found.items():
                grid = source.copy()
                wall0, cpu0 = time.perf_counter(), time.process_time()
                spectrum = transform_pair(module, grid, periodic_z, **options)
                wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
                if round_ > 0:
                    times[name].append((wall, cpu))
                spectra[name] = spectrum
                del grid
        reference = spectra['scipy']
        scale = np.abs(reference).max()
        base = statistics.median(w for w, _ in times['scipy'])
        for name in found:
            wall = statistics.median(w for w, _ in times[name])
            cpu = statistics.median(c for _, c in times[name])
            diff = np.abs(spectra[name] - reference).max() / scale
            print('%14s %16s %10.3f %10.3f %10.2f %12.1e' % (text, name, wall, cpu, base / wall, diff))


if __name__ == '__main__':
    main()
