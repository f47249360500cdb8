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
``dpstokes_parameters``).

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


class SpectralMobility(BlobMobility):
    """The spectral (force-coupling) blob mobility in a periodic geometry (see the module docstring)."""
    backend = 'spectral'

    def __init__(self, geometry, eta, blob_radius, kernel='w6', rotation=False, parameters=None, path=None,
                 workers=None, whole_cells_tolerance=1e-9):
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
        self.stokes = SpectralStokes(parameters, self.eta, path=path, workers=workers)
        self._positions = None

    def _at(self, r_vectors):
        """The product object set at ``r_vectors`` (prepared again only when they differ from the last)."""
        r = np.asarray(r_vectors, dtype=float)
        if self._positions is None or r.shape != self._positions.shape or not np.array_equal(r, self._positions):
            self.stokes.set_positions(r)
            self._positions = np.array(r, copy=True)
        return self.stokes

    def _grand(self, r_vectors, forces, torques):
        n = np.size(r_vectors) // 3
        if forces is None and torques is None:
            forces = np.zeros(3 * n)
        U, W = self._at(r_vectors).product(forces, torques)
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

    @property
    def timings(self):
        """Seconds of the phases of the last product (spread, fft, solve, interpolate) and of the preparation."""
        return dict(self.stokes.timings)
