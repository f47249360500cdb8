"""The spectral Stokes product on an array namespace: NumPy on any machine, CuPy on an NVIDIA GPU.

:class:`ArrayStokes` computes what :class:`~mobility.spectral.product.SpectralStokes` computes (DoublyPeriodicStokes'
rules, the four geometries, forces and torques) with its grid, transforms and solves in the arrays of ``xp``:

* the kernel weights of the blobs are made on the host (``mobility.spectral.stencil``, O(N)) and kept on the
  device in the layout of :class:`~mobility.spectral.grid_kernels.GridStencil`;
* spreading and interpolation are the ``kernels`` module's four functions: ``mobility.spectral.grid_kernels``
  (NumPy, the default) or the raw CUDA kernels of ``mobility.spectral.cuda_kernels`` (with ``xp = cupy``);
* the transforms and the solves are ``mobility.spectral.reference.solve`` with ``xp``: ``cupy.fft`` on the GPU,
  the Chebyshev boundary-value problems vectorised over the wavenumbers as array operations (two tridiagonal
  chains per mode, eliminated along z), the wall corrections per mode, the mean flow.

With ``xp = numpy`` the same statements run here, so the tests check this path against the CPU product to
round-off on any machine; the GPU backend (``mobility.spectral_gpu_mobility``, registry name ``spectral_gpu``)
runs them with CuPy.  Floor 1 of the house; it imports no GPU library itself.
"""
import time

import numpy as np

from utils import UserInputError

from . import grid_kernels, reference
from .product import as_blob_array, check_positions
from .stencil import make_stencil, wrap_positions


class ArrayStokes:
    """The spectral product of one discretisation in the arrays of ``xp``.

    parameters : SpectralParameters (``rules`` 'dpstokes'); eta : viscosity; xp : numpy or cupy; kernels : a
    module with ``spread_forces``, ``spread_torques``, ``interpolate_velocities``, ``interpolate_rotations``
    (default: the NumPy functions of ``mobility.spectral.grid_kernels``, which need ``xp = numpy``).

    ``set_positions(r (N, 3))`` (NumPy positions), ``product(F, T) -> (U, W)``: forces and torques (N, 3) or
    (3N,), NumPy or of ``xp``; the results are NumPy arrays when the inputs are, else arrays of ``xp`` (kept on
    the device).  ``timings``: seconds of the phases of the last product (spread, solve, interpolate; the
    transforms are in solve) and of the last preparation.
    """

    path = 'array'

    def __init__(self, parameters, eta, xp=np, kernels=None):
        if parameters.rules != 'dpstokes':
            raise UserInputError('the array (GPU) spectral product implements DoublyPeriodicStokes\' rules only, not '
                                 '%r; use the CPU product' % parameters.rules)
        eta = float(eta)
        if not np.isfinite(eta) or eta <= 0:
            raise UserInputError('spectral product: the viscosity must be positive and finite, got %r' % eta)
        self.parameters = parameters
        self.eta = eta
        self.xp = xp
        self.kernels = grid_kernels if kernels is None else kernels
        self.timings = {}
        self.n_blobs = 0
        self._monopole = self._dipole = None

    def __repr__(self):
        p = self.parameters
        return 'ArrayStokes(%s, %d x %d x %d, eta=%g, %s)' % (p.geometry, p.Nx, p.Ny, p.Nz, self.eta,
                                                               self.xp.__name__)

    @property
    def has_torque(self):
        return self.parameters.has_torque

    def _synchronise(self):
        if self.xp is not np:
            self.xp.cuda.Stream.null.synchronize()

    def set_positions(self, r_vectors):
        """Make the kernel weights of the blobs at ``r_vectors`` (N, 3) (host) and keep them in ``xp``."""
        start = time.perf_counter()
        p = self.parameters
        r = check_positions(p, r_vectors)
        rel = wrap_positions(p, r)
        self._monopole = grid_kernels.grid_stencil(p, make_stencil(p, p.monopole, rel), self.xp)
        self._dipole = (grid_kernels.grid_stencil(p, make_stencil(p, p.dipole, rel, derivative=True), self.xp)
                        if p.has_torque else None)
        self.n_blobs = r.shape[0]
        self.timings['prepare'] = time.perf_counter() - start

    def product(self, forces=None, torques=None):
        """``(U, W)``: velocities (N, 3) and, with a dipole kernel, angular velocities (N, 3) (else None)."""
        if self._monopole is None:
            raise UserInputError('spectral product: call set_positions before product')
        xp, n, p = self.xp, self.n_blobs, self.parameters
        on_host = not any(self._on_device(v) for v in (forces, torques))
        F = None if forces is None else self._device_vectors(forces, 'forces')
        T = None if torques is None else self._device_vectors(torques, 'torques')
        if T is not None and not self.has_torque:
            raise UserInputError('spectral product: torques need a discretisation with a dipole kernel '
                                 '(has_torque=True)')
        clock = time.perf_counter
        t0 = clock()
        grid = xp.zeros((3, p.Nz, p.Ny, p.Nx))
        if F is not None:
            self.kernels.spread_forces(grid, self._monopole, F)
        if T is not None:
            self.kernels.spread_torques(grid, self._dipole, T)
        self._synchronise()
        t1 = clock()
        velocity = xp.ascontiguousarray(reference.solve(p, self.eta, grid, xp))
        del grid
        self._synchronise()
        t2 = clock()
        U = self.kernels.interpolate_velocities(velocity, self._monopole)
        W = self.kernels.interpolate_rotations(velocity, self._dipole) if self.has_torque else None
        self._synchronise()
        t3 = clock()
        self.timings.update(spread=t1 - t0, solve=t2 - t1, interpolate=t3 - t2)
        if on_host and xp is not np:
            U = xp.asnumpy(U)
            W = None if W is None else xp.asnumpy(W)
        assert U.shape == (n, 3)
        return U, W

    def _on_device(self, values):
        """True for an array of ``xp`` other than NumPy (a CuPy array)."""
        return self.xp is not np and isinstance(values, self.xp.ndarray)

    def _device_vectors(self, values, name):
        """(N, 3) float64 array of ``xp`` from NumPy or ``xp`` values (checked for shape and finiteness)."""
        n = self.n_blobs
        if not self._on_device(values):
            return self.xp.asarray(as_blob_array(values, n, name))
        xp = self.xp
        a = values.astype(xp.float64)
        if a.shape == (3 * n,):
            a = a.reshape(n, 3)
        if a.shape != (n, 3):
            raise UserInputError('spectral product: %s must have shape (%d, 3) or (%d,), got %s'
                                 % (name, n, 3 * n, a.shape))
        if not bool(xp.all(xp.isfinite(a))):
            raise UserInputError('spectral product: %s are not all finite' % name)
        return a
