"""One interface for every blob mobility: a backend in a geometry, configured once, applied at any positions.

libMobility's idea (one small interface that every hydrodynamic solver implements) in this package's
words.  A :class:`BlobMobility` is one backend (``python``, ``C++``, ``pycuda``, ``spectral``, ...) in one
:class:`Geometry`, made once with the viscosity and the blob radius (or radii); every product then takes
the blob positions:

    from mobility.interface import Geometry, make_mobility
    mob = make_mobility('C++', Geometry('single_wall'), eta=1.0, blob_radius=0.5)
    U = mob.velocities(r_vectors, forces)                 # M_UF f, (3N,)
    U, W = mob.product(r_vectors, forces, torques)        # [U; W] = M [F; T] where the backend has rotation
    Mz = mob.noise(r_vectors, z, tolerance=1e-8)          # M^{1/2} z (LanczosResult; Lanczos by default)
    d = mob.divergence(r_vectors, W, delta)               # one random-finite-difference sample of div_r M

Positions are an argument of every call, never state of the object: a run's model is a value and its run
state holds the configuration.  A backend that prepares work per configuration (the spectral product's
kernel weights) may keep it for the last positions it saw; the numbers never depend on that.

The manual's implementation names (``C++``, ``python_no_wall``, ``pycuda_free_surface``, ``numba``,
``radii_*``) name a backend and a geometry together: :func:`from_implementation_name` reads them.

Shapes and units: ``r_vectors`` (N, 3) lengths; forces, torques, velocities flat (3N,) interleaved
(x0, y0, z0, x1, ...); ``eta`` viscosity; ``blob_radius`` a length, or (N,) per-blob radii where the
backend supports them.

Floor 2 of the house (it uses ``stochastic_forcing`` for the default noise); the backends below it
(``mobility.backends`` and the modules it loads) are floor 1.  The package reaches every blob mobility
through this module; ``doc/adding_a_backend.md`` says how a new backend plugs in.
"""
from dataclasses import dataclass

import numpy as np

from utils import UserInputError

from . import backends as _direct
from .product_names import PRODUCT_KINDS

# ------------------------------------------------------------------ geometries
# direct geometries: pairwise sums of closed-form kernels, with the published pseudo-periodic images where
# ``periodic_length`` has non-zero components
DIRECT_GEOMETRIES = ('free_space', 'single_wall', 'free_surface')
# spectral geometries: truly periodic boxes (the periods in ``periodic_length``, z bounds in ``z_bounds``)
PERIODIC_GEOMETRIES = ('triply_periodic', 'doubly_periodic_open', 'doubly_periodic_wall', 'doubly_periodic_slit')
GEOMETRIES = DIRECT_GEOMETRIES + PERIODIC_GEOMETRIES


@dataclass(frozen=True)
class Geometry:
    """Where the fluid is.

    kind : one of :data:`GEOMETRIES`.
        ``free_space``; ``single_wall`` (no-slip wall at z = 0, fluid above); ``free_surface`` (free-slip
        plane at z = 0); ``triply_periodic``; ``doubly_periodic_open`` (periodic in x, y, unbounded in z);
        ``doubly_periodic_wall`` (periodic in x, y, no-slip wall at ``z_bounds[0]``); ``doubly_periodic_slit``
        (periodic in x, y, no-slip walls at both ``z_bounds``).
    periodic_length : (Lx, Ly, Lz)
        Direct geometries: the published pseudo-periodic box (0: not periodic along that axis).
        Periodic geometries: the periods (Lz used by ``triply_periodic`` only).
    z_bounds : (zmin, zmax) or None
        Periodic geometries other than ``triply_periodic``: the extent of the blobs' heights (and the walls).
    """
    kind: str = 'single_wall'
    periodic_length: tuple = (0.0, 0.0, 0.0)
    z_bounds: tuple = None

    def __post_init__(self):
        if self.kind not in GEOMETRIES:
            raise UserInputError('unknown geometry %r; one of %s' % (self.kind, ', '.join(GEOMETRIES)))
        length = np.asarray(self.periodic_length, dtype=float).reshape(-1)
        if length.size != 3 or not np.all(np.isfinite(length)) or np.any(length < 0):
            raise UserInputError('periodic_length must be three finite lengths >= 0, got %r' % (self.periodic_length,))
        object.__setattr__(self, 'periodic_length', tuple(float(x) for x in length))
        if self.kind in PERIODIC_GEOMETRIES:
            needed = 3 if self.kind == 'triply_periodic' else 2
            if np.any(length[:needed] <= 0):
                raise UserInputError('geometry %s needs periodic lengths > 0 along %s, got %r'
                                     % (self.kind, 'x, y and z' if needed == 3 else 'x and y', self.periodic_length))
        if self.z_bounds is not None:
            bounds = np.asarray(self.z_bounds, dtype=float).reshape(-1)
            if bounds.size != 2 or not np.all(np.isfinite(bounds)) or not bounds[1] > bounds[0]:
                raise UserInputError('z_bounds must be (zmin, zmax) with zmin < zmax, got %r' % (self.z_bounds,))
            object.__setattr__(self, 'z_bounds', (float(bounds[0]), float(bounds[1])))
        elif self.kind in PERIODIC_GEOMETRIES and self.kind != 'triply_periodic':
            raise UserInputError('geometry %s needs z_bounds (zmin, zmax)' % self.kind)

    @property
    def has_wall(self):
        """True when a no-slip wall bounds the fluid (blob centres may not cross it)."""
        return self.kind in ('single_wall', 'doubly_periodic_wall', 'doubly_periodic_slit')

    @property
    def is_periodic(self):
        """True for the truly periodic geometries (not the pseudo-periodic images of the direct ones)."""
        return self.kind in PERIODIC_GEOMETRIES


# ------------------------------------------------------------------ the interface
class BlobMobility:
    """The blob mobility of one backend in one geometry (base class; see the module docstring).

    Subclasses implement :meth:`velocities` and whatever else they can; the defaults here give the
    noise by Lanczos over :meth:`velocities` and the drift by a random finite difference.  A method a
    backend cannot offer raises ``utils.UserInputError`` naming the backend and what to use instead.

    Attributes
    ----------
    backend : str, the registry name (``python``, ``C++``, ``pycuda``, ``spectral``, ...)
    geometry : Geometry
    eta : float, viscosity
    blob_radius : float or (N,) per-blob radii
    has_rotation : bool, whether :meth:`coupling` and :meth:`product` give angular velocities and take torques
    """
    backend = 'abstract'
    has_rotation = False

    def __init__(self, geometry, eta, blob_radius):
        if not isinstance(geometry, Geometry):
            raise TypeError('geometry must be a mobility.interface.Geometry, got %r' % (geometry,))
        eta = float(eta)
        if not np.isfinite(eta) or eta <= 0:
            raise UserInputError('the viscosity eta must be positive and finite, got %r' % eta)
        radius = np.asarray(blob_radius, dtype=float)
        if not np.all(np.isfinite(radius)) or np.any(radius <= 0):
            raise UserInputError('blob radii must be positive and finite')
        self.geometry = geometry
        self.eta = eta
        self.blob_radius = float(radius) if radius.ndim == 0 else radius.reshape(-1)

    def __repr__(self):
        return '%s(%r, %s, eta=%g)' % (type(self).__name__, self.backend, self.geometry.kind, self.eta)

    # -------------------------------------------------------------- products
    def velocities(self, r_vectors, forces):
        """``M_UF f``: blob velocities (3N,) from blob forces (3N,) at ``r_vectors`` (N, 3)."""
        raise NotImplementedError

    def coupling(self, kind, r_vectors, vector):
        """One block of the grand mobility: ``kind`` in :data:`mobility.PRODUCT_KINDS`
        (``trans_times_force``, ``trans_times_torque``, ``rot_times_force``, ``rot_times_torque``); (3N,)."""
        if kind == 'trans_times_force':
            return self.velocities(r_vectors, vector)
        if kind not in PRODUCT_KINDS:
            raise UserInputError('unknown blob product %r; known: %s' % (kind, ', '.join(PRODUCT_KINDS)))
        raise UserInputError('the %s mobility in geometry %s has no %s product (blobs with torques need a backend '
                             'with rotation)' % (self.backend, self.geometry.kind, kind))

    def product(self, r_vectors, forces=None, torques=None):
        """``(U, W)`` = the grand mobility times ``[forces; torques]`` (each (3N,), None counts as zero).

        ``W`` is None when the backend has no rotation (then torques must be None).
        """
        n = np.size(r_vectors) // 3
        if forces is None and torques is None:
            forces = np.zeros(3 * n)
        if not self.has_rotation:
            if torques is not None:
                raise UserInputError('the %s mobility in geometry %s takes no torques' % (self.backend,
                                                                                         self.geometry.kind))
            return self.velocities(r_vectors, forces), None
        U = np.zeros(3 * n)
        W = np.zeros(3 * n)
        if forces is not None:
            U += self.coupling('trans_times_force', r_vectors, forces)
            W += self.coupling('rot_times_force', r_vectors, forces)
        if torques is not None:
            U += self.coupling('trans_times_torque', r_vectors, torques)
            W += self.coupling('rot_times_torque', r_vectors, torques)
        return U, W

    def paired_velocities(self, r_vectors, forces_1, forces_2):
        """``(M f1, M f2)`` at one configuration (a backend may do both in one pass)."""
        return self.velocities(r_vectors, forces_1), self.velocities(r_vectors, forces_2)

    def dense_matrix(self, r_vectors):
        """The dense blob mobility ``M_UF`` (3N, 3N) at ``r_vectors`` (N, 3); a stack (nb, n, 3) gives (nb, 3n, 3n)."""
        raise UserInputError('the %s mobility in geometry %s builds no dense matrices; use python or C++ for '
                             'mobility_blobs_implementation' % (self.backend, self.geometry.kind))

    def source_target(self, sources, targets, forces, radius_sources, radius_targets):
        """Velocity (3Nt,) at ``targets`` (Nt, 3) of radius ``radius_targets`` from ``forces`` (3Ns,) on
        ``sources`` (Ns, 3) of radius ``radius_sources`` (the velocity field of the static script)."""
        raise UserInputError('the %s mobility in geometry %s has no source-target product'
                             % (self.backend, self.geometry.kind))

    # -------------------------------------------------------------- fluctuations
    def noise(self, r_vectors, z, tolerance=1e-8, max_iterations=1000, factor=1.0, matvec=None):
        """``factor * M^{1/2} z`` by Lanczos over :meth:`velocities` (a ``stochastic_forcing.LanczosResult``).

        z : (3N,) standard normal; tolerance : relative change at which Lanczos stops; matvec : the
        product to take the root of (default ``M_UF`` at ``r_vectors``).  A backend with an exact or
        cheaper root overrides this.
        """
        from stochastic_forcing import lanczos_square_root
        r = np.asarray(r_vectors, dtype=float)
        if matvec is None:
            def matvec(v):
                return self.velocities(r, v)
        return lanczos_square_root(matvec, z, tolerance, max_iterations=max_iterations, factor=factor)

    def divergence(self, r_vectors, W, delta):
        """One random-finite-difference sample of ``div_r . M_UF`` (3N,):
        ``[M(r + delta/2 W) W - M(r - delta/2 W) W] / delta`` (its mean over W ~ N(0, 1) is the divergence).

        W : (3N,) standard normal; delta : the step, a length (libMobility and the published schemes use
        ``1e-3 a`` to ``1e-4 a``).  Zero in geometries where the divergence vanishes is still computed: the
        difference is then zero to rounding.
        """
        r = np.asarray(r_vectors, dtype=float)
        W = np.asarray(W, dtype=float).reshape(-1)
        step = 0.5 * delta * W.reshape(r.shape)
        return (self.velocities(r + step, W) - self.velocities(r - step, W)) / delta


# ------------------------------------------------------------------ the direct backends
_GEOMETRY_DOMAIN = {'free_space': 'no_wall', 'single_wall': 'single_wall', 'free_surface': 'free_surface'}
_DOMAIN_SUFFIX = {'no_wall': '_no_wall', 'single_wall': '', 'free_surface': '_free_surface'}


class DirectMobility(BlobMobility):
    """Pairwise sums of the closed-form blob mobilities (``python``, ``C++``, ``pycuda``).

    Rotne-Prager-Yamakawa in free space, Rotne-Prager-Blake above the wall (regularised for blobs that
    overlap each other or the wall), the free-slip surface (translation only), with the published
    pseudo-periodic images where ``geometry.periodic_length`` has non-zero components.
    precision : 'double', or 'single' (compiled backends, one radius: the pair formulas in single precision).
    """

    def __init__(self, backend, geometry, eta, blob_radius, precision='double'):
        super().__init__(geometry, eta, blob_radius)
        if geometry.kind not in DIRECT_GEOMETRIES:
            raise UserInputError('the %s backend sums blob pairs in %s; geometry %s needs the spectral backend'
                                 % (backend, ', '.join(DIRECT_GEOMETRIES), geometry.kind))
        self.backend = backend
        self.domain = _GEOMETRY_DOMAIN[geometry.kind]
        self.name = backend + _DOMAIN_SUFFIX[self.domain]  # the manual's implementation name
        self.precision = precision
        self.has_rotation = self.domain != 'free_surface'
        self._velocities = _direct.mobility_vector_product(self.name, precision)  # raises when not usable here
        self._couplings = {}

    def velocities(self, r_vectors, forces):
        return self._velocities(r_vectors, forces, self.eta, self.blob_radius, self.geometry.periodic_length)

    def coupling(self, kind, r_vectors, vector):
        if kind == 'trans_times_force':
            return self.velocities(r_vectors, vector)
        if kind not in self._couplings:
            self._couplings[kind] = _direct.blob_product(self.name, kind)
        return self._couplings[kind](r_vectors, vector, self.eta, self.blob_radius, self.geometry.periodic_length)

    def dense_matrix(self, r_vectors):
        matrix = _direct.blob_mobility_matrix(self.name)
        return matrix(r_vectors, self.eta, self.blob_radius, self.geometry.periodic_length)

    def source_target(self, sources, targets, forces, radius_sources, radius_targets):
        product = _direct.source_target_product(self.name)
        return product(sources, targets, forces, radius_sources, radius_targets, self.eta,
                       self.geometry.periodic_length)


# ------------------------------------------------------------------ the registry
_FACTORIES = {}     # backend name -> factory(geometry, eta, blob_radius, **options) -> BlobMobility
_GEOMETRIES_OF = {}  # backend name -> geometries it serves
# One preference order for every choice of a backend (fastest first where several are usable).
PREFERENCE = []


def register_backend(name, factory, geometries, rank=None):
    """Add a backend to the registry.

    name : str; factory : ``factory(geometry, eta, blob_radius, **options) -> BlobMobility``;
    geometries : the :data:`GEOMETRIES` it serves; rank : its place in :data:`PREFERENCE` (None: last).
    """
    unknown = set(geometries) - set(GEOMETRIES)
    if unknown:
        raise ValueError('register_backend %s: unknown geometries %s' % (name, ', '.join(sorted(unknown))))
    _FACTORIES[name] = factory
    _GEOMETRIES_OF[name] = tuple(geometries)
    if name in PREFERENCE:
        PREFERENCE.remove(name)
    PREFERENCE.insert(len(PREFERENCE) if rank is None else rank, name)


def registered_backends():
    """Names of the registered backends in preference order."""
    return list(PREFERENCE)


def make_mobility(backend, geometry, eta, blob_radius, **options):
    """The :class:`BlobMobility` of ``backend`` in ``geometry`` (a clear ``UserInputError`` when it cannot run
    here or does not serve that geometry)."""
    if backend not in _FACTORIES:
        raise UserInputError('unknown mobility backend %r; known: %s' % (backend, ', '.join(PREFERENCE)))
    if geometry.kind not in _GEOMETRIES_OF[backend]:
        serving = [name for name in PREFERENCE if geometry.kind in _GEOMETRIES_OF[name]]
        raise UserInputError('the %s backend does not serve geometry %s; backends that do: %s'
                             % (backend, geometry.kind, ', '.join(serving) or 'none'))
    return _FACTORIES[backend](geometry, eta, blob_radius, **options)


def from_implementation_name(name, eta, blob_radius, periodic_length=(0.0, 0.0, 0.0), **options):
    """The :class:`BlobMobility` of a manual implementation name (``C++``, ``python_no_wall``, ``numba``,
    ``pycuda_free_surface``, ``radii_numba``, ...) with the pseudo-periodic box ``periodic_length``."""
    backend, domain = _direct.split_domain(name)
    geometry = Geometry({'no_wall': 'free_space', 'single_wall': 'single_wall',
                         'free_surface': 'free_surface'}[domain], periodic_length)
    return make_mobility(backend, geometry, eta, blob_radius, **options)


def _direct_factory(backend):
    def factory(geometry, eta, blob_radius, **options):
        return DirectMobility(backend, geometry, eta, blob_radius, **options)
    return factory


for _backend in ('pycuda', 'C++', 'python'):
    register_backend(_backend, _direct_factory(_backend), DIRECT_GEOMETRIES)
