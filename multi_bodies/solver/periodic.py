"""Periodic and confined domains of a run: the spectral product behind ``mobility_vector_prod_implementation spectral``.

The input file's options (``doc/periodic.md``, ``doc/options.md``) become a :class:`SpectralDomain`: the geometry
(``mobility.interface.Geometry``: triply periodic, doubly periodic open, above a bottom wall, in a slit), the
kernel, the noise and the near-wall rule.  The domain makes the run's mobilities:

* the matrix-free product of the problems (``vector_mobility``): the spectral backend, force-only kernel;
* the couplings of rollers (``roller_mobility``): the spectral backend with the monopole/dipole kernel pair,
  one product giving U and W;
* the dense blocks of the preconditioners (``blobs_mobility``): the spectral product has no dense blocks, so
  the blocks are those of the geometry's own direct self-mobility: Rotne-Prager-Blake above the wall
  (``DPBW``), the nearer wall in a slit (:class:`NearerWallBlocks`), Rotne-Prager-Yamakawa in free space
  (``TP``, ``DP``); any such approximation leaves the solution exact (GMRES), only the iteration count
  depends on it (doc/periodic.md has the counts of the alternatives).

and says which configurations are invalid: a blob centre below the bottom wall or above the top wall of a slit
is an invalid configuration (the step is rejected, as above the single wall); a blob that leaves the heights the
grid was built for (open geometry, or above ``zmax`` over a wall) stops the run with one line naming the body,
the height and the option to change.  x and y (and z in the triply periodic box) are wrapped into the box by the
product, as the published folder does; body locations are never wrapped.

Floor 3 (``multi_bodies.solver``).
"""
import warnings
from dataclasses import dataclass

import numpy as np

from mobility.interface import (Geometry, PERIODIC_GEOMETRIES, BlobMobility, implementation_geometry,
                                make_mobility)
from mobility.spectral_mobility import SpectralMobility, spectral_parameters_for
from multi_bodies.files.scheme_table import scheme_has
from utils import SimulationStopped, UserInputError

SPECTRAL = 'spectral'
# The domain height of the published Spectral_Multiblob_Roller folder: its multi_bodies.py passes zmin 0 and
# zmax 9.1740639106166668 to DoublyPeriodicStokes (DPBW), whatever the input file says.
PUBLISHED_ZMAX = 9.1740639106166668
GEOMETRY_CHOICES = ('auto',) + PERIODIC_GEOMETRIES
KERNELS = ('w6', 'w5', 'w4', 'w6w5', 'w6w4', 'w5w4')
FORCE_ONLY_KERNELS = ('w6', 'w5', 'w4')
NOISES = ('lanczos', 'fluctuating')
WALL_GEOMETRIES = ('doubly_periodic_wall', 'doubly_periodic_slit')
# Relative difference between a requested period and the spectral grid's (a whole number of cells) that counts
# as equal (the grid's period is Nx h, computed from the request: round-off only when they are the same box).
PERIOD_TOLERANCE = 1e-9


@dataclass(frozen=True)
class SpectralDomain:
    """The periodic or confined domain of a run with the spectral product.

    geometry : mobility.interface.Geometry, one of the periodic kinds (``periodic_length`` the periods,
        ``z_bounds`` the heights the grid covers: the walls of ``doubly_periodic_wall`` (bottom) and
        ``doubly_periodic_slit`` (both)).
    kernel : the spectral kernel name (``w6`` ... ; force-only problems use the monopole of a pair name).
    noise : 'lanczos' or 'fluctuating' (exact, triply periodic only).
    near_wall : the near-wall rule of ``mobility.spectral_mobility.SpectralMobility`` ('published').
    """
    geometry: Geometry
    kernel: str = 'w6'
    noise: str = 'lanczos'
    near_wall: str = 'published'

    @property
    def kind(self):
        return self.geometry.kind

    @property
    def periodic_length(self):
        return self.geometry.periodic_length

    @property
    def z_bounds(self):
        return self.geometry.z_bounds

    @property
    def top_wall(self):
        """Height of the top wall (slit), or None."""
        return self.z_bounds[1] if self.kind == 'doubly_periodic_slit' else None

    @property
    def checks_heights(self):
        """True where heights are bounded (every geometry but the triply periodic box)."""
        return self.kind != 'triply_periodic'

    def force_kernel(self):
        """The force-only kernel of ``kernel`` (a pair name's monopole: ``w6w4`` -> ``w6``)."""
        return self.kernel[:2]

    def mobility(self, eta, blob_radius, rotation=False):
        """The spectral ``BlobMobility`` of the run (:class:`RunSpectralMobility`): force-only kernel, or with
        ``rotation`` the kernel pair (``w6`` with torques is the w6/w6 pair)."""
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')  # the whole-cells note of square boxes: check_grid_periods compared them
            return RunSpectralMobility(self.geometry, eta, blob_radius,
                                       kernel=self.kernel if rotation else self.force_kernel(), rotation=rotation,
                                       near_wall=self.near_wall if self.geometry.has_wall else None,
                                       noise=self.noise)

    def block_geometry(self):
        """The direct geometry whose dense blocks precondition the solves: above a wall for ``DPBW`` and the slit
        (the nearer wall), free space otherwise."""
        return Geometry('single_wall' if self.kind in WALL_GEOMETRIES else 'free_space')

    def block_mobility(self, blobs_name, eta, blob_radius):
        """The preconditioners' dense blocks: the backend of ``blobs_name`` (``python``, ``C++``, ...) in
        :meth:`block_geometry` (no periodic images, as the blocks have always been built)."""
        backend, _ = implementation_geometry(blobs_name)
        blocks = make_mobility(backend, self.block_geometry(), eta, blob_radius, dense_matrices=True)
        if self.kind == 'doubly_periodic_slit':
            return NearerWallBlocks(blocks, self.top_wall)
        return blocks

    def invalid_bodies(self, body_arrays, r_vectors):
        """Indices of bodies with a blob centre through a wall (below z = 0 over a wall, above the top wall of a
        slit); raises SimulationStopped when a blob leaves the heights the grid covers (see module docstring)."""
        r = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
        if not self.checks_heights:
            return np.zeros(0, dtype=int)
        z = r[:, 2]
        low, high = self.z_bounds
        bad = np.zeros(z.shape, dtype=bool)
        if self.kind in WALL_GEOMETRIES:
            bad |= z < low
        if self.kind == 'doubly_periodic_slit':
            bad |= z > high
        outside = (z > high) if self.kind == 'doubly_periodic_wall' else (
            (z < low) | (z > high) if self.kind == 'doubly_periodic_open' else np.zeros(z.shape, dtype=bool))
        if np.any(outside):
            i = int(np.argmax(outside))
            body = int(body_arrays.blob_body_index[i])
            raise SimulationStopped('body %d has a blob at z = %.6g, outside the heights [%g, %g] of the spectral '
                                    'grid (spectral_z_bounds); restart from the last saved step with wider '
                                    'spectral_z_bounds' % (body, z[i], low, high))
        return np.unique(body_arrays.blob_body_index[bad])


class NearerWallBlocks(BlobMobility):
    """Dense blocks of a slit from a single-wall mobility: each body (or pair of bodies) with its blobs' mean
    height above ``top / 2`` is mirrored through the mid-plane, so it sees the top wall at its distance
    (``S M(r') S``, ``r' = (x, y, top - z)``, ``S = diag(1, 1, -1)`` per blob); the others see the bottom wall.

    Only :meth:`dense_matrix` (a body (n, 3) or a stack (nb, n, 3)) is meant to be used; products go to the
    bottom-wall mobility.
    """

    def __init__(self, wall_mobility, top):
        self.wall_mobility = wall_mobility
        self.top = float(top)
        self.backend, self.geometry, self.eta = wall_mobility.backend, wall_mobility.geometry, wall_mobility.eta
        self.blob_radius, self.periodic_length = wall_mobility.blob_radius, wall_mobility.periodic_length
        self.has_rotation = wall_mobility.has_rotation

    def replace(self, eta=None, blob_radius=None, periodic_length=None):
        inner = self.wall_mobility.replace(eta, blob_radius, periodic_length)
        return self if inner is self.wall_mobility else NearerWallBlocks(inner, self.top)

    def velocities(self, r_vectors, forces):
        return self.wall_mobility.velocities(r_vectors, forces)

    def dense_matrix(self, r_vectors):
        r = np.array(r_vectors, dtype=float)
        stack = r if r.ndim == 3 else r.reshape(1, -1, 3)
        flip = stack[:, :, 2].mean(axis=1) > 0.5 * self.top
        stack = stack.copy()
        stack[flip, :, 2] = self.top - stack[flip, :, 2]
        blocks = np.array(self.wall_mobility.dense_matrix(stack if r.ndim == 3 else stack[0]), dtype=float)
        blocks = blocks.reshape(stack.shape[0], 3 * stack.shape[1], 3 * stack.shape[1])
        if np.any(flip):
            sign = np.tile([1.0, 1.0, -1.0], stack.shape[1])
            blocks[flip] *= sign[None, :, None] * sign[None, None, :]
        return blocks if r.ndim == 3 else blocks[0]


SPECTRAL_OPTIONS = ('spectral_geometry', 'spectral_z_bounds', 'spectral_kernel', 'spectral_noise',
                    'spectral_reading')


def uses_spectral(options):
    """True when the input asks for the spectral product."""
    return options.mobility_vector_prod_implementation == SPECTRAL


def check_spectral_options(options):
    """Options of the spectral product set without it: one line naming the first (they would do nothing)."""
    if uses_spectral(options):
        return
    for name in SPECTRAL_OPTIONS:
        if options.is_set(name):
            raise UserInputError('%s: %s is an option of the spectral product; set mobility_vector_prod_implementation '
                                 'spectral or remove the line' % (options.where(name), name))


def spectral_geometry_kind(options):
    """The geometry kind of ``spectral_geometry`` (``auto``: above the wall with ``periodic_length Lx Ly 0``, as
    the published folder, and triply periodic with ``Lx Ly Lz``)."""
    kind = options.spectral_geometry
    if kind != 'auto':
        return kind
    return 'triply_periodic' if options.periodic_length[2] > 0 else 'doubly_periodic_wall'


def top_wall_height(options):
    """Height of the top wall of a spectral slit (``spectral_z_bounds``' zmax), or None: the default physics repels
    blobs from it as from the bottom wall (``physics.blob_external_forces``, keyword ``top_wall``)."""
    if not uses_spectral(options) or spectral_geometry_kind(options) != 'doubly_periodic_slit':
        return None
    return None if options.spectral_z_bounds is None else float(options.spectral_z_bounds[1])


def spectral_domain(options, rollers=False, blob_radius=None):
    """The :class:`SpectralDomain` of validated input ``options`` (``mobility_vector_prod_implementation spectral``),
    or a one-line UserInputError naming the option and line: periods, z bounds, kernel, noise, the scheme and the
    other options that cannot go with it.  ``rollers``: a roller scheme (torques: a kernel pair); ``blob_radius``:
    the radius of the spectral kernel (default ``options.blob_radius``)."""
    where = options.where
    scheme = options.scheme
    surface = [spec.where for spec in list(options.structures) + list(options.obstacles)
               if spec.laplace_file or spec.slip_length_file]
    if surface:
        raise UserInputError('%s: .Laplace and .slip_length bodies solve their surface problems with the wall\'s '
                             'direct kernels; the spectral product does not serve them (use a direct '
                             'mobility_vector_prod_implementation)' % surface[0])
    if scheme_has(scheme, 'lubrication'):
        raise UserInputError('%s: the lubrication schemes take their far field from the wall tables, not from the '
                             'spectral product; use a direct mobility_vector_prod_implementation'
                             % where('mobility_vector_prod_implementation'))
    kind = spectral_geometry_kind(options)
    Lx, Ly, Lz = options.periodic_length
    if Lx <= 0 or Ly <= 0:
        raise UserInputError('%s: mobility_vector_prod_implementation spectral needs a box periodic in x and y: '
                             'periodic_length Lx Ly 0 (Lx, Ly > 0; above the wall), or Lx Ly Lz for a triply '
                             'periodic box' % where('periodic_length'))
    if kind == 'triply_periodic' and Lz <= 0:
        raise UserInputError('%s: spectral_geometry triply_periodic needs periodic_length Lx Ly Lz with Lz > 0'
                             % where('periodic_length'))
    if kind != 'triply_periodic' and Lz > 0:
        raise UserInputError('%s: periodic_length along z is %g, but spectral_geometry %s is not periodic in z; set '
                             'the third value to 0 or choose spectral_geometry triply_periodic'
                             % (where('periodic_length'), Lz, kind))
    z_bounds = options.spectral_z_bounds
    if z_bounds is None:
        if kind == 'doubly_periodic_wall':
            z_bounds = (0.0, PUBLISHED_ZMAX)
        elif kind in ('doubly_periodic_slit', 'doubly_periodic_open'):
            raise UserInputError('%s: spectral_geometry %s needs spectral_z_bounds zmin zmax (%s)'
                                 % (where('spectral_geometry'), kind,
                                    'the walls: zmin 0 and the height of the top wall'
                                    if kind == 'doubly_periodic_slit' else 'the heights the blobs may take'))
    else:
        low, high = z_bounds
        if not high > low:
            raise UserInputError('%s: spectral_z_bounds zmin zmax needs zmin < zmax, got %g %g'
                                 % (where('spectral_z_bounds'), low, high))
        if kind in WALL_GEOMETRIES and low != 0.0:
            raise UserInputError('%s: spectral_z_bounds: the bottom wall is at z = 0 in this package (gravity, the '
                                 'wall repulsion and the wall check measure heights from it); write 0 %g'
                                 % (where('spectral_z_bounds'), high))
        if kind == 'triply_periodic':
            raise UserInputError('%s: spectral_z_bounds is not used by spectral_geometry triply_periodic (its z '
                                 'period is the third periodic_length); remove the line' % where('spectral_z_bounds'))
    geometry = Geometry(kind, (Lx, Ly, Lz if kind == 'triply_periodic' else 0.0), z_bounds)
    kernel = options.spectral_kernel
    if not rollers and kernel not in FORCE_ONLY_KERNELS:
        raise UserInputError('%s: spectral_kernel %s is a kernel pair for torques (roller schemes); rigid bodies '
                             'use the force-only kernels w6, w5, w4' % (where('spectral_kernel'), kernel))
    if rollers and kernel == 'w4':
        raise UserInputError('%s: spectral_kernel w4 has no dipole kernel for the rollers\' torques; use w6, w5, '
                             'w6w5, w6w4 or w5w4' % where('spectral_kernel'))
    if options.spectral_noise == 'fluctuating' and kind != 'triply_periodic':
        raise UserInputError('%s: spectral_noise fluctuating (exact noise) exists in the triply periodic box only; '
                             'use lanczos in %s' % (where('spectral_noise'), kind))
    if rollers and options.domain == 'no_wall':
        raise UserInputError('%s: domain no_wall: with the spectral product the walls are those of spectral_geometry '
                             '(%s); remove the line' % (where('domain'), kind))
    if options.domain == 'in_plane' and kind not in WALL_GEOMETRIES:
        raise UserInputError('%s: domain in_plane needs a wall (spectral_geometry doubly_periodic_wall or '
                             'doubly_periodic_slit), not %s' % (where('domain'), kind))
    domain = SpectralDomain(geometry, kernel, options.spectral_noise)
    check_grid_periods(domain, options, rollers, options.blob_radius if blob_radius is None else blob_radius)
    return domain


def overlap_warning(options, bodies, blob_radius):
    """The ``warning:`` text (or None) for blobs of one body closer to each other than the blob radius.

    The spectral kernels of such blobs overlap so much that the blob mobility is nearly singular and GMRES may not
    converge (the published Spectral_Multiblob_Roller inputs read as the manual says: blobs of radius 1.0155 on a
    shell of radius 0.79, 0.83 apart; 180 GMRES iterations for 128 of its rollers where the direct product needs
    18, no convergence in 1,000 for its 2,048).  That folder's own script scaled the vertex file by
    ``blob_radius`` and used half the smallest blob distance as the blob radius (doc/periodic.md)."""
    seen = {}
    for body in bodies:
        blobs = np.asarray(body.reference_configuration, dtype=float).reshape(-1, 3)
        if body.ID in seen or len(blobs) < 2:
            continue
        distances = np.linalg.norm(blobs[:, None] - blobs[None], axis=2)[np.triu_indices(len(blobs), 1)]
        seen[body.ID] = float(distances.min())
    crowded = {name: d for name, d in seen.items() if d < blob_radius}
    if not crowded:
        return None
    name, d = next(iter(crowded.items()))
    return ('%s: blob_radius %g is larger than the smallest blob distance %g of the bodies of %s: with the spectral '
            'product such overlapping blobs make the mobility nearly singular and GMRES may not converge. The '
            'published Spectral_Multiblob_Roller folder\'s own script scaled its vertex file by blob_radius and used '
            'half the smallest blob distance as the blob radius, which spectral_reading published does (the default '
            'without other spectral_* lines; doc/periodic.md)'
            % (options.where('blob_radius'), blob_radius, d, name))


def check_grid_periods(domain, options, rollers, blob_radius):
    """The spectral grid's periods must be the ones asked for: DoublyPeriodicStokes' selection fixes the spacing
    h from x and makes Ly (and the triply periodic Lz) a whole number of cells, enlarging it otherwise.  A run
    whose product saw another box than its forces and outputs would be silently wrong: refused, naming the
    period that fits (the box of the published folder is square and passes)."""
    kernel = domain.kernel if rollers else domain.force_kernel()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')  # the whole-cells note: compared below
            p = spectral_parameters_for(domain.geometry, blob_radius, kernel, rotation=rollers)
    except UserInputError as err:
        raise UserInputError('%s: spectral product: %s' % (options.where('periodic_length'), err))
    asked = list(options.periodic_length)
    used = [p.Lx, p.Ly] + ([p.Lz] if domain.kind == 'triply_periodic' else [])
    for axis, (want, got) in enumerate(zip(asked, used)):
        if abs(got - want) > PERIOD_TOLERANCE * want:
            h = (p.hx, p.hy, getattr(p, 'hz', p.hx) or p.hx)[axis]
            fitted = list(asked)
            fitted[axis] = round(want / h) * h if round(want / h) > 0 else h
            raise UserInputError('%s: periodic_length: the spectral grid for blob_radius %g (kernel %s) has the '
                                 'spacing h = %.10g and needs %s to be a whole number of cells; %g would become %.10g. '
                                 'Use periodic_length %s (or a square box in x and y)'
                                 % (options.where('periodic_length'), blob_radius, kernel, h, 'xyz'[axis], want, got,
                                    ' '.join('%.10g' % v for v in fitted)))


class RunSpectralMobility(SpectralMobility):
    """The run's spectral product: a position the product refuses (a blob outside the grid's heights, reached by
    a trial or random-finite-difference configuration before the step's validity check) stops the run with
    ``SimulationStopped`` (one line, the files up to the last saved step written) instead of a user-input error."""

    def _at(self, r_vectors):
        try:
            return super()._at(r_vectors)
        except UserInputError as err:
            raise SimulationStopped('%s; restart from the last saved step with wider spectral_z_bounds'
                                    % str(err).rstrip('.')) from None
