"""The spectral Stokes product ``[U; W] = M [F; T]`` of blobs in a periodic or confined box.

:class:`SpectralStokes` holds a discretisation (:class:`~mobility.spectral.parameters.SpectralParameters`) and
a viscosity; :meth:`SpectralStokes.set_positions` prepares the blobs' stencils (kept until the next
positions), :meth:`SpectralStokes.product` spreads, solves and interpolates.  Two paths compute the same
numbers: the compiled one (C++ with OpenMP for spreading, interpolation and the per-wavenumber solves,
``scipy.fft`` for the transforms, in place on one grid) by default, and the NumPy one
(``mobility.spectral.reference``) with ``path='numpy'`` or the environment variable
``RMB_SPECTRAL_PATH=numpy``.
"""
import os
import time

import numpy as np

from utils import UserInputError

from . import reference
from .stencil import make_stencil, wrap_positions

PATHS = ('compiled', 'numpy')
PHASES = ('spread', 'fft', 'solve', 'interpolate')


def compiled_available():
    """True when the extension ``mobility._spectral_cpp`` is built."""
    try:
        from . import compiled  # noqa: F401
    except ImportError:
        return False
    return True


def choose_path(path=None):
    """The path to use: ``path`` if given, else ``RMB_SPECTRAL_PATH``, else 'compiled' where built."""
    chosen = path if path is not None else os.environ.get('RMB_SPECTRAL_PATH') or None
    if chosen is None:
        return 'compiled' if compiled_available() else 'numpy'
    if chosen not in PATHS:
        raise UserInputError('spectral path %r: one of %s (RMB_SPECTRAL_PATH or path=)' % (chosen, ', '.join(PATHS)))
    if chosen == 'compiled' and not compiled_available():
        raise UserInputError('the compiled spectral product (mobility._spectral_cpp) is not built; run '
                             '"python3 setup.py build_ext --inplace" or use path=\'numpy\'')
    return chosen


def as_blob_array(values, n, name):
    """``values`` as a float (n, 3) array; accepts (n, 3) or flat (3n,); one-line errors otherwise."""
    a = np.asarray(values, dtype=float)
    if a.shape == (n, 3):
        out = a
    elif a.shape == (3 * n,):
        out = a.reshape(n, 3)
    else:
        raise UserInputError('spectral product: %s must have shape (%d, 3) or (%d,), got %s'
                             % (name, n, 3 * n, a.shape))
    if not np.all(np.isfinite(out)):
        bad = int(np.argmax(~np.all(np.isfinite(out), axis=1)))
        raise UserInputError('spectral product: %s of blob %d is not finite (%s)' % (name, bad, out[bad]))
    return out


def check_positions(parameters, r_vectors):
    """Blob positions as (N, 3) floats, or a one-line ``UserInputError``: wrong shape, NaN/inf, a blob below a
    wall, above the top wall of a slit, or outside the heights the grid was built for."""
    r = np.asarray(r_vectors, dtype=float)
    if r.ndim == 1 and r.size % 3 == 0:
        r = r.reshape(-1, 3)
    if r.ndim != 2 or r.shape[1] != 3 or r.shape[0] == 0:
        raise UserInputError('spectral product: positions must have shape (N, 3) with N >= 1, got %s'
                             % (np.shape(r_vectors),))
    finite = np.all(np.isfinite(r), axis=1)
    if not np.all(finite):
        bad = int(np.argmin(finite))
        raise UserInputError('spectral product: the position of blob %d is not finite (%s)' % (bad, r[bad]))
    p = parameters
    if p.z_range is not None:
        z = r[:, 2]
        low, high = p.z_range
        below = z < low
        above = z > high
        if np.any(below):
            i = int(np.argmax(below))
            if p.geometry in ('DPBW', 'DPSC'):
                raise UserInputError('spectral product: blob %d at z = %.17g is below the wall at z = %.17g'
                                     % (i, z[i], low))
            raise UserInputError('spectral product: blob %d at z = %.17g is below the heights [%g, %g] the grid '
                                 'was built for (set z bounds that contain every blob)' % (i, z[i], low, high))
        if np.any(above):
            i = int(np.argmax(above))
            if p.geometry == 'DPSC':
                raise UserInputError('spectral product: blob %d at z = %.17g is above the top wall at z = %.17g'
                                     % (i, z[i], high))
            raise UserInputError('spectral product: blob %d at z = %.17g is above the heights [%g, %g] the grid '
                                 'was built for (set z bounds that contain every blob)' % (i, z[i], low, high))
    return r


class SpectralStokes:
    """The spectral mobility product in one discretisation.

    parameters : SpectralParameters; eta : viscosity; path : 'compiled', 'numpy' or None (the default:
    ``RMB_SPECTRAL_PATH``, else compiled where built); workers : threads of the FFTs (None: OpenMP's count).

    Attributes: ``timings`` (dict, seconds of the phases of the last product: spread, fft, solve,
    interpolate; and prepare, of the last :meth:`set_positions`), ``n_blobs``.
    """

    def __init__(self, parameters, eta, path=None, workers=None):
        eta = float(eta)
        if not np.isfinite(eta) or eta <= 0:
            raise UserInputError('spectral product: the viscosity must be positive and finite, got %r' % eta)
        self._uammd = None
        if parameters.rules == 'uammd':    # libMobility's (UAMMD's) rules: mobility.spectral.uammd
            from .uammd import UammdStokes
            self._uammd = UammdStokes(parameters, eta, choose_path(path), workers)
            path = self._uammd.path
        self.parameters = parameters
        self.eta = eta
        self.path = choose_path(path)
        self.timings = {}
        self.n_blobs = 0
        self._monopole = None
        self._dipole = None
        self._prepared = False
        self._engine = None
        if self.path == 'compiled':
            from .compiled import CompiledEngine
            self._engine = CompiledEngine(parameters, eta, workers)

    def __repr__(self):
        p = self.parameters
        return 'SpectralStokes(%s, %d x %d x %d, eta=%g, %s)' % (p.geometry, p.Nx, p.Ny, p.Nz, self.eta, self.path)

    @property
    def has_torque(self):
        return self.parameters.has_torque

    def set_positions(self, r_vectors):
        """Prepare the stencils of the blobs at ``r_vectors`` (N, 3) (or flat (3N,)); x and y (TP: also z)
        are wrapped into the periodic box, z is checked against the walls and the grid's heights."""
        start = time.perf_counter()
        p = self.parameters
        r = check_positions(p, r_vectors)
        if self._uammd is not None:
            self._uammd.set_positions(r)
            self.n_blobs, self._prepared = r.shape[0], True
            self.timings['prepare'] = time.perf_counter() - start
            return
        rel = wrap_positions(p, r)
        self._monopole = self._dipole = None
        monopole = make_stencil(p, p.monopole, rel)
        dipole = make_stencil(p, p.dipole, rel, derivative=True) if p.has_torque else None
        self.n_blobs = r.shape[0]
        if self._engine is not None:
            self._engine.prepare(monopole, dipole)   # the engine keeps its own layout; these are dropped
        else:
            self._monopole, self._dipole = monopole, dipole
        self._prepared = True
        self.timings['prepare'] = time.perf_counter() - start

    def product(self, forces=None, torques=None):
        """``(U, W)``: blob velocities (N, 3) and, with a dipole kernel, angular velocities (N, 3) (else None)
        from forces (N, 3) and torques (N, 3) (either may be None: zero; flat (3N,) accepted).

        Triply periodic: the mean force is dropped (no mean flow), as DoublyPeriodicStokes does; DP (open z):
        the k = 0 (xy-mean) flow is zero at every height, as the library does.
        """
        if not self._prepared:
            raise UserInputError('spectral product: call set_positions before product')
        n = self.n_blobs
        F = None if forces is None else as_blob_array(forces, n, 'forces')
        T = None if torques is None else as_blob_array(torques, n, 'torques')
        if T is not None and not self.has_torque:
            raise UserInputError('spectral product: torques need a discretisation with a dipole kernel '
                                 '(has_torque=True)')
        if self._uammd is not None:
            U, W = self._uammd.product(F, T)
            self.timings.update(self._uammd.timings)
            return U, W
        if self._engine is not None:
            U, W, timings = self._engine.product(F, T, want_rotation=self.has_torque)
            self.timings.update(timings)
            return U, W
        return self._numpy_product(F, T)

    def _numpy_product(self, F, T):
        p = self.parameters
        clock = time.perf_counter
        t0 = clock()
        grid = np.zeros((3, p.Nz, p.Ny, p.Nx))
        if F is not None:
            reference.spread_forces(p, self._monopole, F, grid)
        if T is not None:
            reference.spread_torques(p, self._dipole, T, grid)
        t1 = clock()
        velocity = reference.solve(p, self.eta, grid)
        del grid
        t2 = clock()
        U = reference.interpolate_velocities(p, self._monopole, velocity)
        W = reference.interpolate_rotations(p, self._dipole, velocity) if self.has_torque else None
        t3 = clock()
        self.timings.update(spread=t1 - t0, fft=0.0, solve=t2 - t1, interpolate=t3 - t2)
        return U, W
