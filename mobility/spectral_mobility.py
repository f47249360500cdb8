"""The spectral product as a backend of the package's mobility interface (``mobility.interface``, backend
``spectral``): truly periodic boxes at linear cost.

    from mobility.interface import Geometry, make_mobility
    box = Geometry('doubly_periodic_wall', periodic_length=(64.0, 64.0, 0.0), z_bounds=(0.0, 10.0))
    mob = make_mobility('spectral', box, eta=1.0, blob_radius=1.0)
    U = mob.velocities(r_vectors, forces)              # (3N,)

Geometries (``mobility.interface.PERIODIC_GEOMETRIES``) and the method's names: ``triply_periodic`` = TP
(periods ``periodic_length``; z_bounds, if given, only place the grid), ``doubly_periodic_open`` = DP,
``doubly_periodic_wall`` = DPBW (wall at ``z_bounds[0]``), ``doubly_periodic_slit`` = DPSC (walls at both
``z_bounds``).  Blob heights must lie within ``z_bounds``.

Options of the factory: ``kernel`` ('w6' default; force only 'w6', 'w5', 'w4'; with rotation 'w6', 'w5',
'w6w5', 'w6w4', 'w5w4'), ``rotation`` (False: translation only, the force-only kernels; True: torques and
angular velocities with the monopole/dipole kernel pairs), ``parameters`` (a ready
``mobility.spectral.SpectralParameters``, which then fixes everything, e.g. libMobility's selection),
``path`` ('compiled' or 'numpy'), ``workers`` (FFT threads), ``whole_cells_tolerance`` (see
``dpstokes_parameters``), ``near_wall`` (None: the product as it is; 'published': blobs closer than one radius
to a wall are moved to one radius from it and their forces, torques and velocities multiplied by
distance/radius, as the published ``Spectral_Multiblob_Roller`` folder does: see :meth:`SpectralMobility.near_wall_factors`),
``noise`` ('lanczos', or 'fluctuating': the exact triply periodic noise of
``mobility.spectral.fluctuations`` at about half a product's cost).

``product(r, F, T)`` gives U and W of one spectral product (``product_in_one_pass``); ``dense_matrix`` builds
the (symmetric part of the) matrix column by column from products (3N products: small systems only).

The stencils of the last positions are kept and made again when the positions change (compared entry by
entry with a copy), so repeated products at one configuration (Krylov iterations, Lanczos) pay the
preparation once.  Floor 2 of the house (beside ``mobility.interface``).
"""
import numpy as np

from utils import UserInputError

from .interface import PERIODIC_GEOMETRIES, BlobMobility
from .spectral import SpectralStokes, dpstokes_parameters

SPECTRAL_GEOMETRY = {'triply_periodic': 'TP', 'doubly_periodic_open': 'DP', 'doubly_periodic_wall': 'DPBW',
                     'doubly_periodic_slit': 'DPSC'}
# How closely the products hold the exact mobility's laws (symmetry, agreement of equivalent products),
# relative to |M| (``BlobMobility.relative_accuracy``): rounding in TP; the Chebyshev discretisation is not
# symmetric (collocation at the nodes against Clenshaw-Curtis weighted interpolation): up to 3e-4 measured
# with a blob 1.2 R above a wall and torques (doc/spectral.md).
RELATIVE_ACCURACY = {'TP': 1e-12, 'DP': 5e-4, 'DPBW': 5e-4, 'DPSC': 5e-4}


def spectral_parameters_for(geometry, blob_radius, kernel='w6', rotation=False, whole_cells_tolerance=1e-9):
    """DoublyPeriodicStokes' discretisation of a ``mobility.interface.Geometry`` for blobs of one radius."""
    kind = SPECTRAL_GEOMETRY[geometry.kind]
    Lx, Ly, Lz = geometry.periodic_length
    if kind == 'TP':
        zmin = 0.0 if geometry.z_bounds is None else geometry.z_bounds[0]
        zmax = zmin + Lz
    else:
        zmin, zmax = geometry.z_bounds
    return dpstokes_parameters(blob_radius, kind, Lx, Ly, zmin, zmax, kernel=kernel, has_torque=rotation,
                               whole_cells_tolerance=whole_cells_tolerance)


def _times_factors(vectors, factors):
    """Per-blob vectors (N, 3) (or flat) times ``factors`` (N,) (NumPy), in the vectors' own array namespace
    (NumPy, or CuPy for the GPU backend, whose arrays stay on the device)."""
    if isinstance(vectors, np.ndarray) or type(vectors).__module__.split('.')[0] != 'cupy':
        return np.asarray(vectors, dtype=float).reshape(-1, 3) * factors[:, None]
    import cupy
    return vectors.reshape(-1, 3) * cupy.asarray(factors)[:, None]


class SpectralMobility(BlobMobility):
    """The spectral (force-coupling) blob mobility in a periodic geometry (see the module docstring)."""
    backend = 'spectral'

    product_in_one_pass = True
    NEAR_WALL = (None, 'published')
    NOISES = ('lanczos', 'fluctuating')

    def __init__(self, geometry, eta, blob_radius, kernel='w6', rotation=False, parameters=None, path=None,
                 workers=None, whole_cells_tolerance=1e-9, near_wall=None, noise='lanczos'):
        super().__init__(geometry, eta, blob_radius)
        if geometry.kind not in PERIODIC_GEOMETRIES:
            raise UserInputError('the spectral backend serves %s, not %s' % (', '.join(PERIODIC_GEOMETRIES),
                                                                            geometry.kind))
        if not isinstance(self.blob_radius, float):
            raise UserInputError('the spectral backend takes one blob radius for all blobs (its kernel has one '
                                 'width), got per-blob radii')
        if parameters is None:
            parameters = spectral_parameters_for(geometry, self.blob_radius, kernel, rotation, whole_cells_tolerance)
        elif parameters.geometry != SPECTRAL_GEOMETRY[geometry.kind]:
            raise UserInputError('spectral parameters for geometry %s given for %s' % (parameters.geometry,
                                                                                      geometry.kind))
        self.parameters = parameters
        self.has_rotation = parameters.has_torque
        self.relative_accuracy = RELATIVE_ACCURACY[parameters.geometry]
        self.stokes = self._product_engine(parameters, path, workers)
        self._positions = None
        if near_wall not in self.NEAR_WALL:
            raise UserInputError('spectral near_wall %r: None or published' % (near_wall,))
        if noise not in self.NOISES:
            raise UserInputError('spectral noise %r: one of %s' % (noise, ', '.join(self.NOISES)))
        if noise == 'fluctuating' and parameters.geometry != 'TP':
            raise UserInputError('the fluctuating (exact) spectral noise exists in the triply periodic geometry only, '
                                 'not in %s; use the Lanczos noise there' % geometry.kind)
        self.near_wall = near_wall if parameters.geometry in ('DPBW', 'DPSC') else None
        self.noise_method = noise

    def _product_engine(self, parameters, path, workers):
        """The object that computes the products (``set_positions``, ``product``, ``timings``): the CPU product
        here; the GPU backend (``mobility.spectral_gpu_mobility``) gives its array product instead."""
        return SpectralStokes(parameters, self.eta, path=path, workers=workers)

    def _at(self, r_vectors):
        """The product object set at ``r_vectors`` (prepared again only when they differ from the last)."""
        r = np.asarray(r_vectors, dtype=float)
        if self._positions is None or r.shape != self._positions.shape or not np.array_equal(r, self._positions):
            self.stokes.set_positions(r)
            self._positions = np.array(r, copy=True)
        return self.stokes

    def near_wall_factors(self, r_vectors):
        """``(r_effective (N, 3), factors (N,) or None)`` of ``near_wall='published'``.

        A blob whose distance ``d`` to a wall is below the blob radius ``a`` is moved to ``a`` from that wall
        and its force, torque and velocities are multiplied by ``d / a`` (so ``B M(r_effective) B`` stays
        symmetric positive definite and vanishes at the wall), as the published folder's product does for the
        bottom wall (``shift_heights`` and ``damping_matrix_B`` of its ``FCMJoint_MB.py``); here the top wall of
        a slit is treated the same way.  ``factors`` None: no blob is that close (or ``near_wall`` None).
        """
        r = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
        if self.near_wall is None:
            return r, None
        a = self.blob_radius
        low, high = self.parameters.z_range
        distance = r[:, 2] - low
        if self.parameters.geometry == 'DPSC':
            distance = np.minimum(distance, high - r[:, 2])
        close = distance < a
        if not np.any(close):
            return r, None
        shifted = r.copy()
        below = close & (r[:, 2] - low < a)
        shifted[below, 2] = low + a
        if self.parameters.geometry == 'DPSC':
            shifted[close & ~below, 2] = high - a
        factors = np.where(close, np.maximum(distance, 0.0) / a, 1.0)
        return shifted, factors

    def _grand(self, r_vectors, forces, torques):
        n = np.size(r_vectors) // 3
        if forces is None and torques is None:
            forces = np.zeros(3 * n)
        r, factors = self.near_wall_factors(r_vectors)
        if factors is not None:
            forces = None if forces is None else _times_factors(forces, factors)
            torques = None if torques is None else _times_factors(torques, factors)
        U, W = self._at(r).product(forces, torques)
        if factors is not None:
            U = _times_factors(U, factors)
            W = None if W is None else _times_factors(W, factors)
        return U.reshape(-1), (None if W is None else W.reshape(-1))

    def velocities(self, r_vectors, forces):
        return self._grand(r_vectors, forces, None)[0]

    def coupling(self, kind, r_vectors, vector):
        self.check_coupling(kind)
        if kind == 'trans_times_force':
            return self.velocities(r_vectors, vector)
        from_torque = kind.endswith('torque')
        U, W = self._grand(r_vectors, None if from_torque else vector, vector if from_torque else None)
        return U if kind.startswith('trans') else W

    def product(self, r_vectors, forces=None, torques=None):
        """``(U, W)`` in one spectral product (forces and torques spread together); W None without rotation."""
        if torques is not None and not self.has_rotation:
            raise UserInputError('the spectral mobility was made without rotation (rotation=False) and takes no '
                                 'torques')
        return self._grand(r_vectors, forces, torques)

    def dense_matrix(self, r_vectors):
        """The symmetric part of ``M_UF`` (3N, 3N) at ``r_vectors`` (N, 3), column by column (3N products).

        For small systems (the dense schemes, the static problems' body mobility): the spectral product has no
        closed-form blocks, so it is not registered with dense matrices (``mobility_blobs_implementation``), and
        stacks of bodies (nb, n, 3) are refused (a body alone in the periodic box is not what the
        preconditioners need: runs take their blocks from the direct geometry's mobility).  In the
        Chebyshev geometries the product is symmetric only to the discretisation's accuracy
        (``relative_accuracy``), so the symmetric part ``(M + M^T)/2`` is returned (a Cholesky factor exists).
        """
        r = np.asarray(r_vectors, dtype=float)
        if r.ndim == 3:
            raise UserInputError('the spectral mobility builds no per-body dense blocks; take them from a direct '
                                 'mobility (mobility_blobs_implementation)')
        r = r.reshape(-1, 3)
        size = r.size
        columns = np.empty((size, size))
        unit = np.zeros(size)
        for j in range(size):
            unit[j] = 1.0
            columns[:, j] = self.velocities(r, unit)
            unit[j] = 0.0
        return 0.5 * (columns + columns.T)

    def noise(self, r_vectors, z, tolerance=1e-8, max_iterations=1000, factor=1.0, matvec=None):
        """``factor M^{1/2} z``: Lanczos over the product (``noise='lanczos'``, the default, or whenever ``matvec``
        is given), or the exact triply periodic noise (``noise='fluctuating'``: grid normals drawn from a
        generator seeded with the bits of ``z``, ``mobility.spectral.fluctuations``; iterations 0).

        In the Chebyshev geometries the product is not exactly symmetric (``relative_accuracy``): Lanczos builds
        its tridiagonal matrix as if it were, so the noise has the covariance of a matrix within that relative
        accuracy of the product's symmetric part (tests/test_periodic.py measures it).
        """
        if self.noise_method != 'fluctuating' or matvec is not None:
            return super().noise(r_vectors, z, tolerance, max_iterations, factor, matvec)
        from stochastic_forcing import LanczosResult
        from .spectral.fluctuations import generator_from_normals, triply_periodic_noise
        r, _ = self.near_wall_factors(r_vectors)
        U = triply_periodic_noise(self.parameters, self.eta, r, generator_from_normals(z), factor)
        return LanczosResult(U.reshape(-1), 0, True, 0.0)

    @property
    def timings(self):
        """Seconds of the phases of the last product (spread, fft, solve, interpolate) and of the preparation."""
        return dict(self.stokes.timings)
