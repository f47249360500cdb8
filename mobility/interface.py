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

The registry (:func:`register_backend`) holds every backend with what it serves (geometries, dense
matrices, device) and the ONE preference order of the package, :data:`PREFERENCE`: ``auto``
(``mobility.choose``), the advisor, the lubrication far field, the published faces and the benchmarks
read it (:func:`usable_backends`, :func:`preferred_backend`); nothing else names an order.

Floor 2 of the house (it uses ``stochastic_forcing`` for the default noise); the backends below it
(``mobility.backends`` and the modules it loads) are floor 1.  The package reaches every blob mobility
through this module; ``doc/adding_a_backend.md`` says how a new backend plugs in.
"""
import copy
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


def _checked_eta(eta):
    eta = float(eta)
    if not np.isfinite(eta) or eta <= 0:
        raise UserInputError('the viscosity eta must be positive and finite, got %r' % eta)
    return eta


def _checked_radius(blob_radius):
    """One radius (a float) or per-blob radii (a flat float array), positive and finite."""
    radius = np.asarray(blob_radius, dtype=float)
    if not np.all(np.isfinite(radius)) or np.any(radius <= 0):
        raise UserInputError('blob radii must be positive and finite')
    return float(radius) if radius.ndim == 0 else radius.reshape(radius.shape if radius.ndim == 2 else -1)


def _read_only_length(periodic_length):
    length = np.array(periodic_length, dtype=float).reshape(3)
    length.flags.writeable = False
    return length


# ------------------------------------------------------------------ the interface
class BlobMobility:
    """The blob mobility of one backend in one geometry (base class; see the module docstring).

    Subclasses implement :meth:`velocities` and whatever else they can; the defaults here give the
    noise by Lanczos over :meth:`velocities`, the drift by a random finite difference, the grand product from
    the couplings and the paired product as two products.  A method a backend cannot offer raises
    ``utils.UserInputError`` naming the backend and what to use instead.

    Attributes
    ----------
    backend : str, the registry name (``python``, ``C++``, ``pycuda``, ``spectral``, ...)
    geometry : Geometry (None for :class:`FunctionMobility`, whose geometry is its functions')
    eta : float, viscosity
    blob_radius : float, or per-blob radii (N,) (a stack (nb, n) for the dense blocks of stacked bodies)
    periodic_length : (3,) read-only array, the box of the geometry (0: not periodic along that axis)
    has_rotation : bool, whether :meth:`coupling` and :meth:`product` give angular velocities and take torques
    pairs_in_one_pass : bool, whether :meth:`paired_velocities` makes both products in one pass over the pairs
    product_in_one_pass : bool, whether :meth:`product` gives ``U`` and ``W`` from forces and torques in one
        product (the spectral backend) rather than as the sum of the couplings
    near_field_domain : 'single_wall', 'no_wall' or None: the domain of the compiled near-field loop of the
        neighbour preconditioner (``_preconditioner_cpp.rigid_near_field``) when that loop reproduces this
        mobility's dense blocks (the C++ backend in those geometries); None otherwise.
    relative_accuracy : float, how closely the products hold the laws of the exact mobility of the geometry
        (symmetry ``x . M y = y . M x``, agreement of equivalent products), relative to ``|M|``: rounding
        (1e-12) for the pair sums; a grid method states its discretisation's (the interface tests use it).
    """
    backend = 'abstract'
    has_rotation = False
    pairs_in_one_pass = False
    product_in_one_pass = False
    near_field_domain = None
    relative_accuracy = 1e-12

    def __init__(self, geometry, eta, blob_radius):
        if not isinstance(geometry, Geometry):
            raise TypeError('geometry must be a mobility.interface.Geometry, got %r' % (geometry,))
        self.geometry = geometry
        self.eta = _checked_eta(eta)
        self.blob_radius = _checked_radius(blob_radius)
        self.periodic_length = _read_only_length(geometry.periodic_length)

    def __repr__(self):
        return '%s(%r, %s, eta=%g)' % (type(self).__name__, self.backend,
                                       getattr(self.geometry, 'kind', 'functions'), self.eta)

    def replace(self, eta=None, blob_radius=None, periodic_length=None):
        """This mobility with another viscosity, blob radius (or radii) or pseudo-periodic box; None keeps one.

        Returns ``self`` when nothing changes.  Used for the dense blocks of a part of the blobs (a body, a
        stack of bodies, pairs of bodies: ``replace(blob_radius=their radii)``) and by the published function
        forms (:func:`published_function`).  A mobility made by :func:`make_mobility` is made again by its
        factory (with the same options); any other is copied with the new values.
        """
        if (eta is None or float(eta) == self.eta) and (blob_radius is None or _same_radius(blob_radius,
                                                                                            self.blob_radius)) \
                and (periodic_length is None or np.array_equal(np.asarray(periodic_length, dtype=float).reshape(-1),
                                                                self.periodic_length)):
            return self
        eta = self.eta if eta is None else eta
        blob_radius = self.blob_radius if blob_radius is None else blob_radius
        geometry = self.geometry
        if periodic_length is not None and geometry is not None:
            geometry = Geometry(geometry.kind, periodic_length, geometry.z_bounds)
        options = getattr(self, '_registry_options', None)
        if options is not None:
            return make_mobility(self.backend, geometry, eta, blob_radius, **options)
        twin = copy.copy(self)
        twin.eta, twin.blob_radius = _checked_eta(eta), _checked_radius(blob_radius)
        if periodic_length is not None:
            twin.geometry, twin.periodic_length = geometry, _read_only_length(periodic_length)
        return twin

    # -------------------------------------------------------------- products
    def velocities(self, r_vectors, forces):
        """``M_UF f``: blob velocities (3N,) from blob forces (3N,) at ``r_vectors`` (N, 3)."""
        raise NotImplementedError

    def coupling(self, kind, r_vectors, vector):
        """One block of the grand mobility: ``kind`` in :data:`mobility.PRODUCT_KINDS`
        (``trans_times_force``, ``trans_times_torque``, ``rot_times_force``, ``rot_times_torque``); (3N,)."""
        if kind == 'trans_times_force':
            return self.velocities(r_vectors, vector)
        self.check_coupling(kind)
        raise UserInputError('the %s mobility in geometry %s has no %s product'
                             % (self.backend, getattr(self.geometry, 'kind', 'of its functions'), kind))

    def check_coupling(self, kind):
        """Raise the ``UserInputError`` that :meth:`coupling` raises for ``kind`` where this mobility has no such
        coupling (before any product is made)."""
        if kind not in PRODUCT_KINDS:
            raise UserInputError('unknown blob product %r; known: %s' % (kind, ', '.join(PRODUCT_KINDS)))
        if kind != 'trans_times_force' and not self.has_rotation:
            raise UserInputError('the %s mobility in geometry %s has no %s product (blobs with torques need a '
                                 'backend with rotation)' % (self.backend, getattr(self.geometry, 'kind',
                                                                                   'of its functions'), kind))

    def product(self, r_vectors, forces=None, torques=None):
        """``(U, W)`` = the grand mobility times ``[forces; torques]`` (each (3N,), None counts as zero).

        ``W`` is None when the backend has no rotation (then torques must be None).  ``U = M_UF F + M_UT T``
        and ``W = M_WF F + M_WT T`` are summed in that order (the couplings' numbers, added once).
        """
        n = np.size(r_vectors) // 3
        if forces is None and torques is None:
            forces = np.zeros(3 * n)
        if not self.has_rotation:
            if torques is not None:
                raise UserInputError('the %s mobility in geometry %s takes no torques'
                                     % (self.backend, getattr(self.geometry, 'kind', 'of its functions')))
            return self.velocities(r_vectors, forces), None
        U = W = None
        if forces is not None:
            U = np.asarray(self.coupling('trans_times_force', r_vectors, forces)).reshape(-1)
            W = np.asarray(self.coupling('rot_times_force', r_vectors, forces)).reshape(-1)
        if torques is not None:
            U_T = np.asarray(self.coupling('trans_times_torque', r_vectors, torques)).reshape(-1)
            W_T = np.asarray(self.coupling('rot_times_torque', r_vectors, torques)).reshape(-1)
            U = U_T if U is None else U + U_T
            W = W_T if W is None else W + W_T
        return U, W

    def paired_velocities(self, r_vectors, forces_1, forces_2):
        """``(M f1, M f2)`` at one configuration (one pass over the pairs where ``pairs_in_one_pass``)."""
        return self.velocities(r_vectors, forces_1), self.velocities(r_vectors, forces_2)

    def dense_matrix(self, r_vectors):
        """The dense blob mobility ``M_UF`` (3N, 3N) at ``r_vectors`` (N, 3); a stack (nb, n, 3) gives
        (nb, 3n, 3n), each body alone (``blob_radius`` one number or (nb, n))."""
        raise UserInputError('the %s mobility in geometry %s builds no dense matrices; use python or C++ for '
                             'mobility_blobs_implementation' % (self.backend, getattr(self.geometry, 'kind', '-')))

    def cross_blocks(self, r_i, r_j):
        """The off-diagonal blocks of the dense mobility of pairs of bodies: r_i (P, ni, 3), r_j (P, nj, 3) ->
        (P, 3ni, 3nj) (rows: the blobs of r_i[p]; no periodic images; one blob radius), or None where this
        backend has no kernel for them: the caller takes them from :meth:`dense_matrix` of the pairs."""
        return None

    def source_target(self, sources, targets, forces, radius_sources, radius_targets):
        """Velocity (3Nt,) at ``targets`` (Nt, 3) of radius ``radius_targets`` from ``forces`` (3Ns,) on
        ``sources`` (Ns, 3) of radius ``radius_sources`` (the velocity field of the static script)."""
        self.check_source_target()
        raise NotImplementedError

    def check_source_target(self):
        """Raise the ``UserInputError`` of :meth:`source_target` where this mobility has none (before any work)."""
        raise UserInputError('the %s mobility in geometry %s has no source-target product'
                             % (self.backend, getattr(self.geometry, 'kind', '-')))

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


def _same_radius(new, old):
    new = np.asarray(new, dtype=float)
    return new.shape == np.shape(old) and bool(np.all(new == old))


# ------------------------------------------------------------------ the direct backends
_GEOMETRY_DOMAIN = {'free_space': 'no_wall', 'single_wall': 'single_wall', 'free_surface': 'free_surface'}
_DOMAIN_GEOMETRY = {domain: kind for kind, domain in _GEOMETRY_DOMAIN.items()}
_DOMAIN_SUFFIX = {'no_wall': '_no_wall', 'single_wall': '', 'free_surface': '_free_surface'}


class DirectMobility(BlobMobility):
    """Pairwise sums of the closed-form blob mobilities (``python``, ``C++``, ``pycuda``).

    Rotne-Prager-Yamakawa in free space, Rotne-Prager-Blake above the wall (regularised for blobs that
    overlap each other or the wall), the free-slip surface (translation only), with the published
    pseudo-periodic images where ``geometry.periodic_length`` has non-zero components.
    precision : 'double', or 'single' (compiled backends, one radius: the pair formulas in single precision).

    Every product is the backend's function of ``mobility.backends`` called with this object's viscosity,
    radius and box (the same numbers as the published function forms).  ``paired_velocities`` is one pass
    over the pairs for the C++ wall and free-space products of one radius without periodic images, and so is
    ``product`` with any periodic box (all four couplings: ``grand_product_in_one_pass``);
    ``cross_blocks`` and ``near_field_domain`` are the C++ backend's (wall and free space).
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
        # the GPU's fused multiply-adds change the last digits; single precision keeps about six
        self.relative_accuracy = 1e-5 if precision == 'single' else 1e-10 if backend == 'pycuda' else 1e-12
        self._velocities = _direct.mobility_vector_product(self.name, precision)  # raises when not usable here
        self._couplings = {}
        self._matrix = self._cross = None
        self.near_field_domain = self.domain if backend == 'C++' and self.domain != 'free_surface' else None
        self._pair = None
        if (backend == 'C++' and self.domain != 'free_surface' and precision == 'double'
                and np.ndim(self.blob_radius) == 0 and not np.any(self.periodic_length)):
            module = _direct.load_backend('C++')
            if getattr(module, 'has_product_two', lambda: False)():  # an extension built before it: no pairing
                self._pair = module.trans_times_force_two
        self.pairs_in_one_pass = self._pair is not None
        # the grand product in one pass over the pairs: C++, wall or free space, one radius (any periodic box).
        # product_in_one_pass stays False: the rollers, which need U only, take fewer instructions from the two
        # couplings trans_times_force + trans_times_torque than from the one-pass U and W (doc/performance.md)
        self._grand = None
        if (backend == 'C++' and self.domain != 'free_surface' and precision == 'double'
                and np.ndim(self.blob_radius) == 0):
            module = _direct.load_backend('C++')
            if getattr(module, 'has_grand_product', lambda: False)():  # an extension built before it: four products
                self._grand = module.grand_product
        self.grand_product_in_one_pass = self._grand is not None

    def replace(self, eta=None, blob_radius=None, periodic_length=None):
        twin = super().replace(eta, blob_radius, periodic_length)
        if twin is self or getattr(self, '_registry_options', None) is not None:
            return twin
        return DirectMobility(self.backend, twin.geometry, twin.eta, twin.blob_radius, self.precision)

    def velocities(self, r_vectors, forces):
        return self._velocities(r_vectors, forces, self.eta, self.blob_radius, self.periodic_length)

    def coupling(self, kind, r_vectors, vector):
        if kind == 'trans_times_force':
            return self.velocities(r_vectors, vector)
        if kind not in self._couplings:
            self._couplings[kind] = _direct.blob_product(self.name, kind)
        return self._couplings[kind](r_vectors, vector, self.eta, self.blob_radius, self.periodic_length)

    def product(self, r_vectors, forces=None, torques=None):
        """``(U, W)`` of forces and torques; one pass over the pairs for all four couplings where
        ``grand_product_in_one_pass`` (the C++ wall and free-space products of one radius), else the four
        couplings summed."""
        if self._grand is None or (forces is None and torques is None):
            return super().product(r_vectors, forces, torques)
        if forces is None or torques is None:
            n = np.size(r_vectors) // 3
            forces = np.zeros(3 * n) if forces is None else forces
            torques = np.zeros(3 * n) if torques is None else torques
        return self._grand(r_vectors, forces, torques, self.eta, self.blob_radius, self.periodic_length,
                           self.domain == 'single_wall')

    def paired_velocities(self, r_vectors, forces_1, forces_2):
        if self._pair is None:
            return super().paired_velocities(r_vectors, forces_1, forces_2)
        return self._pair(r_vectors, forces_1, forces_2, self.eta, self.blob_radius, self.domain == 'single_wall')

    def dense_matrix(self, r_vectors):
        if self._matrix is None:
            self._matrix = _direct.blob_mobility_matrix(self.name)  # raises for pycuda (no dense matrices)
        return self._matrix(r_vectors, self.eta, self.blob_radius, self.periodic_length)

    def cross_blocks(self, r_i, r_j):
        if self._cross is None:
            self._cross = _direct.blob_cross_blocks(self.name) or False
        if self._cross is False or np.ndim(self.blob_radius):
            return None
        return self._cross(r_i, r_j, self.eta, self.blob_radius)

    def source_target(self, sources, targets, forces, radius_sources, radius_targets):
        product = _direct.source_target_product(self.name)
        return product(sources, targets, forces, radius_sources, radius_targets, self.eta, self.periodic_length)

    def check_source_target(self):
        _direct.source_target_product(self.name)


# ------------------------------------------------------------------ functions of the published form
class FunctionMobility(BlobMobility):
    """A :class:`BlobMobility` over functions of the published form (code written against them: tests,
    users' scripts, the building blocks' older signatures).

    velocities : ``f(r (N, 3), v (3N,), eta, a, periodic_length) -> (3N,)`` or None
    dense_matrix : ``f(r (n, 3), eta, a) -> (3n, 3n)`` or None
    stacked_dense_matrix : ``f(r (nb, n, 3), eta, a) -> (nb, 3n, 3n)`` or None (None: ``dense_matrix`` once per
        body of a stack)
    cross_blocks : ``f(r_i (P, ni, 3), r_j (P, nj, 3), eta, a) -> (P, 3ni, 3nj)`` (or None where it cannot), or None
    near_field_domain : as :class:`BlobMobility`.
    eta, blob_radius, periodic_length : what the functions are called with.
    """
    backend = 'functions'

    def __init__(self, eta, blob_radius, periodic_length=(0.0, 0.0, 0.0), velocities=None, dense_matrix=None,
                 stacked_dense_matrix=None, cross_blocks=None, near_field_domain=None):
        self.geometry = None
        self.eta = _checked_eta(eta)
        self.blob_radius = _checked_radius(blob_radius)
        self.periodic_length = _read_only_length(periodic_length)
        self._velocities, self._matrix, self._stacked, self._cross = (velocities, dense_matrix, stacked_dense_matrix,
                                                                      cross_blocks)
        self.near_field_domain = near_field_domain

    def velocities(self, r_vectors, forces):
        if self._velocities is None:
            raise TypeError('this FunctionMobility was given no velocities function')
        return self._velocities(r_vectors, forces, self.eta, self.blob_radius, self.periodic_length)

    def dense_matrix(self, r_vectors):
        if self._stacked is not None and np.ndim(r_vectors) == 3:
            return self._stacked(r_vectors, self.eta, self.blob_radius)
        if self._matrix is None:
            if self._stacked is not None:
                return self._stacked(r_vectors, self.eta, self.blob_radius)
            raise TypeError('this FunctionMobility was given no dense matrix function')
        if np.ndim(r_vectors) == 3:  # the function once per body (set-up only)
            radius = self.blob_radius
            return np.stack([self._matrix(r_body, self.eta, radius if np.ndim(radius) == 0 else radius[k])
                             for k, r_body in enumerate(r_vectors)])
        return self._matrix(r_vectors, self.eta, self.blob_radius)

    def cross_blocks(self, r_i, r_j):
        if self._cross is None or np.ndim(self.blob_radius):
            return None
        return self._cross(r_i, r_j, self.eta, self.blob_radius)


def as_blob_mobility(mobility, eta=None, blob_radius=None, periodic_length=None, role='velocities', **functions):
    """A :class:`BlobMobility` from the mobility argument of a building block.

    ``mobility`` a BlobMobility: itself (eta, blob_radius and the functions must then be None: it carries
    its own).  Otherwise a function of the published form whose ``role`` is ``velocities`` or
    ``dense_matrix`` (:class:`FunctionMobility`), called with ``eta``, ``blob_radius`` and
    ``periodic_length`` (None: no box); ``functions``: the other functions of :class:`FunctionMobility`.
    """
    if isinstance(mobility, BlobMobility):
        given = [name for name, value in (('eta', eta), ('blob_radius', blob_radius)) if value is not None]
        given += [name for name, value in functions.items() if value is not None]
        if given:
            raise TypeError('%s given with a BlobMobility, which carries its own' % ', '.join(given))
        return mobility
    if eta is None or blob_radius is None:
        raise TypeError('a mobility function of the published form needs eta and blob_radius')
    functions[role] = mobility
    return FunctionMobility(eta, blob_radius, (0.0, 0.0, 0.0) if periodic_length is None else periodic_length,
                            **functions)


def published_function(mobility, method='velocities'):
    """The published function form of a method of ``mobility`` (for scripts written against the functions).

    method ``velocities`` or a coupling kind: ``f(r_vectors, vector, eta, a, periodic_length=None) -> (3N,)``;
    ``dense_matrix``: ``f(r_vectors, eta, a, periodic_length=None) -> (3N, 3N)`` (or a stack).  The arguments
    reconfigure the mobility (:meth:`BlobMobility.replace`; None keeps its box), so the numbers are those of
    the backend's own function.
    """
    if method == 'dense_matrix':
        def matrix(r_vectors, eta, a, periodic_length=None):
            return mobility.replace(eta=eta, blob_radius=a, periodic_length=periodic_length).dense_matrix(r_vectors)
        return matrix
    if method != 'velocities' and method not in PRODUCT_KINDS:
        raise ValueError('published_function: method %r is not velocities, dense_matrix or one of %s'
                         % (method, ', '.join(PRODUCT_KINDS)))

    def product(r_vectors, vector, eta, a, periodic_length=None):
        return mobility.replace(eta=eta, blob_radius=a, periodic_length=periodic_length).coupling(
            'trans_times_force' if method == 'velocities' else method, r_vectors, vector)
    return product


# ------------------------------------------------------------------ the registry
_FACTORIES = {}     # backend name -> factory(geometry, eta, blob_radius, **options) -> BlobMobility
_GEOMETRIES_OF = {}  # backend name -> geometries it serves
_DENSE = {}          # backend name -> True when it builds dense matrices (mobility_blobs_implementation)
_DEVICE = {}         # backend name -> 'cpu' or 'gpu'
_CHECKS = {}         # backend name -> check() -> None when usable here, else the reason
# One preference order for every choice of a backend (fastest first where several are usable).
PREFERENCE = []


def register_backend(name, factory, geometries, rank=None, dense_matrices=False, device='cpu', check=None):
    """Add a backend to the registry.

    name : str; factory : ``factory(geometry, eta, blob_radius, **options) -> BlobMobility``;
    geometries : the :data:`GEOMETRIES` it serves; rank : its place in :data:`PREFERENCE` (None: last);
    dense_matrices : whether its mobilities build dense matrices (:meth:`BlobMobility.dense_matrix`);
    device : 'cpu' or 'gpu'; check : ``check() -> None`` when it can run here, else the reason (a str);
    None: always usable (its factory still raises a clear error when it cannot).
    """
    unknown = set(geometries) - set(GEOMETRIES)
    if unknown:
        raise ValueError('register_backend %s: unknown geometries %s' % (name, ', '.join(sorted(unknown))))
    if device not in ('cpu', 'gpu'):
        raise ValueError("register_backend %s: device must be 'cpu' or 'gpu', got %r" % (name, device))
    _FACTORIES[name] = factory
    _GEOMETRIES_OF[name] = tuple(geometries)
    _DENSE[name] = bool(dense_matrices)
    _DEVICE[name] = device
    _CHECKS[name] = check
    if name in PREFERENCE:
        PREFERENCE.remove(name)
    PREFERENCE.insert(len(PREFERENCE) if rank is None else rank, name)


def registered_backends(geometry=None, dense_matrices=False, device=None):
    """Names of the registered backends in preference order: all, or those serving ``geometry`` (a Geometry or
    a kind), building dense matrices (``dense_matrices=True``), on ``device`` ('cpu' or 'gpu')."""
    kind = getattr(geometry, 'kind', geometry)
    return [name for name in PREFERENCE if (kind is None or kind in _GEOMETRIES_OF[name])
            and (not dense_matrices or _DENSE[name]) and (device is None or _DEVICE[name] == device)]


def unusable_reason(backend):
    """None when ``backend`` can run here, else why not (a str); an unknown name is a UserInputError."""
    if backend not in _FACTORIES:
        raise UserInputError('unknown mobility backend %r; known: %s' % (backend, ', '.join(PREFERENCE)))
    check = _CHECKS[backend]
    return None if check is None else check()


def is_usable(backend):
    """True when the registered ``backend`` can run here."""
    return unusable_reason(backend) is None


def usable_backends(geometry=None, dense_matrices=False, device=None):
    """:func:`registered_backends` that can run here, in preference order."""
    return [name for name in registered_backends(geometry, dense_matrices, device) if is_usable(name)]


def preferred_backend(geometry=None, dense_matrices=False, device=None):
    """The first usable backend of :data:`PREFERENCE` with those needs (a clear UserInputError when none)."""
    usable = usable_backends(geometry, dense_matrices, device)
    if not usable:
        raise UserInputError('no usable mobility backend%s%s%s; registered: %s'
                             % ('' if geometry is None else ' for geometry %s' % getattr(geometry, 'kind', geometry),
                                ' with dense matrices' if dense_matrices else '',
                                '' if device is None else ' on the %s' % device.upper(), ', '.join(PREFERENCE)))
    return usable[0]


def make_mobility(backend, geometry, eta, blob_radius, dense_matrices=False, **options):
    """The :class:`BlobMobility` of ``backend`` in ``geometry`` (a clear ``UserInputError`` when it cannot run
    here or does not serve that geometry; with ``dense_matrices=True``, also when it builds no dense
    matrices).  ``options`` go to the backend's factory (``precision`` for the direct backends)."""
    if backend not in _FACTORIES:
        raise UserInputError('unknown mobility backend %r; known: %s' % (backend, ', '.join(PREFERENCE)))
    if geometry.kind not in _GEOMETRIES_OF[backend]:
        serving = registered_backends(geometry)
        raise UserInputError('the %s backend does not serve geometry %s; backends that do: %s'
                             % (backend, geometry.kind, ', '.join(serving) or 'none'))
    if dense_matrices and not _DENSE[backend]:
        raise UserInputError('the %s backend builds no dense blob matrices (mobility_blobs_implementation); '
                             'backends that do: %s' % (backend, ', '.join(registered_backends(
                                 geometry, dense_matrices=True)) or 'none'))
    mobility = _FACTORIES[backend](geometry, eta, blob_radius, **options)
    mobility._registry_options = dict(options)
    return mobility


def implementation_name(backend, geometry):
    """The implementation name of ``backend`` in a direct ``geometry`` (a Geometry or a kind): ``C++``,
    ``python_no_wall``, ``pycuda_free_surface``, ... (the backend's name and the geometry's suffix)."""
    return backend + _DOMAIN_SUFFIX[_GEOMETRY_DOMAIN[getattr(geometry, 'kind', geometry)]]


def _registered_names():
    """{implementation name: (backend, geometry kind)} of the registered backends other than the manual's own
    (``mobility.backends``) in the direct geometries they serve."""
    return {implementation_name(backend, kind): (backend, kind) for backend in PREFERENCE
            if backend not in _direct.BACKEND_NAMES for kind in _GEOMETRIES_OF[backend] if kind in DIRECT_GEOMETRIES}


def implementation_names():
    """Every implementation name an input file may give: the manual's (``python``, ``C++``, ``pycuda``, the
    aliases ``numba`` and ``radii_*``, each with ``_no_wall`` and ``_free_surface``) and those of any other
    registered backend in the direct geometries it serves (its name with the same suffixes)."""
    return list(_direct.all_names()) + list(_registered_names())


def implementation_geometry(name, periodic_length=(0.0, 0.0, 0.0)):
    """``(backend, Geometry)`` of an implementation name (``C++``, ``python_no_wall``, ``numba``,
    ``pycuda_free_surface``, ``radii_numba``, ..., or a registered backend's name with a suffix) with the
    pseudo-periodic box ``periodic_length``; an unknown name is a UserInputError listing the known ones."""
    registered = _registered_names()
    if name in registered:
        backend, kind = registered[name]
        return backend, Geometry(kind, periodic_length)
    try:
        backend, domain = _direct.split_domain(name)
    except UserInputError:
        raise UserInputError('unknown mobility implementation %r; known names: %s'
                             % (name, ', '.join(implementation_names()))) from None
    return backend, Geometry(_DOMAIN_GEOMETRY[domain], periodic_length)


def from_implementation_name(name, eta, blob_radius, periodic_length=(0.0, 0.0, 0.0), dense_matrices=False,
                             **options):
    """The :class:`BlobMobility` of an implementation name (:func:`implementation_geometry`) with the
    pseudo-periodic box ``periodic_length``."""
    backend, geometry = implementation_geometry(name, periodic_length)
    return make_mobility(backend, geometry, eta, blob_radius, dense_matrices=dense_matrices, **options)


def _direct_factory(backend):
    def factory(geometry, eta, blob_radius, **options):
        return DirectMobility(backend, geometry, eta, blob_radius, **options)
    return factory


def _direct_check(backend):
    def check():
        return None if _direct.is_usable(backend) else _direct.available_implementations()[backend]
    return check


for _backend, _dense, _device in (('pycuda', False, 'gpu'), ('C++', True, 'cpu'), ('python', True, 'cpu')):
    register_backend(_backend, _direct_factory(_backend), DIRECT_GEOMETRIES, dense_matrices=_dense, device=_device,
                     check=_direct_check(_backend))


def _spectral_factory(geometry, eta, blob_radius, **options):
    """The spectral product (``mobility.spectral_mobility``), loaded on first use by its module name, as
    ``mobility.backends`` loads the direct backends (it sits beside this module and imports it)."""
    import importlib
    return importlib.import_module('mobility.spectral_mobility').SpectralMobility(geometry, eta, blob_radius, **options)


register_backend('spectral', _spectral_factory, PERIODIC_GEOMETRIES)


def _spectral_gpu_factory(geometry, eta, blob_radius, **options):
    """The spectral product on an NVIDIA GPU (``mobility.spectral_gpu_mobility``, CuPy), loaded on first use."""
    import importlib
    return importlib.import_module('mobility.spectral_gpu_mobility').SpectralGpuMobility(geometry, eta, blob_radius,
                                                                                         **options)


def _spectral_gpu_check():
    import importlib
    return importlib.import_module('mobility.spectral_gpu_mobility').unusable_reason()


register_backend('spectral_gpu', _spectral_gpu_factory, PERIODIC_GEOMETRIES, rank=PREFERENCE.index('spectral'),
                 device='gpu', check=_spectral_gpu_check)
