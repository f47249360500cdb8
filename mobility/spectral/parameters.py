"""The discretisation of the spectral Stokes product: one frozen parameter object, and the
DoublyPeriodicStokes selection of it from a blob radius and a box.

The method (force coupling with exponential-of-semicircle kernels, Fourier in the periodic directions,
Chebyshev in z) is that of Hashemi, Pelaez, Natesh, Sprinkle, Maxian, Gan and Donev, "Computing
hydrodynamic interactions in confined doubly periodic geometries in linear time", J. Chem. Phys. 158,
154101 (2023).  The exponential-of-semicircle ("ES") kernel is Barnett, Magland and af Klinteberg's
(SIAM J. Sci. Comput. 41, C479, 2019).  The selection rules, tables and polynomial radius fits below are
those of the DoublyPeriodicStokes CPU library (github.com/stochasticHydroTools/DoublyPeriodicStokes,
``GridAndKernelConfig.py``), re-stated in this package's words; ``doc/spectral.md`` explains them.

Every length is in the caller's units; nothing here depends on the viscosity.
"""
import cmath
import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from utils import UserInputError

# The four geometries: triply periodic; doubly periodic with z open, above a bottom wall, in a slit.
GEOMETRIES = ('TP', 'DP', 'DPBW', 'DPSC')
# The usable range of the total ES exponent beta (outside it the radius fits are not trusted).
BETA_RANGE = (4.0, 18.0)
# Discretisation rules beyond the numbers of SpectralParameters (see its docstring).
RULES = ('dpstokes', 'uammd')

# ------------------------------------------------------------------ DoublyPeriodicStokes' tables
# Force-only kernels: kernel type -> (w, beta/w).  With torques: type -> (w_m, w_d, beta_m/w_m, beta_d/w_d).
FORCE_ONLY_TABLE = {0: (6, 1.714), 1: (5, 1.886), 2: (4, 1.785)}
TORQUE_TABLE = {0: (6, 6, 1.3267, 2.2160), 1: (5, 5, 1.3055, 2.2320), 3: (6, 5, 1.3261, 1.7584),
                4: (6, 4, 1.5728, 1.5115), 5: (5, 4, 1.3536, 1.7147)}
# The kernel names of this package (and of mobility.libmobility's ``kernel=`` keyword) and the library's types.
FORCE_ONLY_KERNELS = {'w6': 0, 'w5': 1, 'w4': 2}
TORQUE_KERNELS = {'w6': 0, 'w5': 1, 'w6w5': 3, 'w6w4': 4, 'w5w4': 5}

# Degree-10 polynomial fits (highest power first) of the library: the dimensionless radius R/(w h) of a
# monopole (C_M) and of a dipole (C_D) ES kernel against the total beta, and beta against R/(w h) (the
# *_INV fits; separate fits, not exact inverses).  From the triply periodic self-mobility of one kernel.
C_M = (1.377360225705533e-14, -2.780166372816629e-12, 2.448353284693753e-10, -1.237430413656322e-08,
       3.979148502148348e-07, -8.561766184042201e-06, 0.0001272679847510219, -0.001354403465648405,
       0.01097749452611932, -0.07481288697153615, 0.5542048130466118)
C_D = (-4.547131634839802e-15, 9.269149081395723e-13, -8.100791156357088e-11, 3.923458768903104e-09,
       -1.120891440829999e-07, 1.758862781905333e-06, -6.91617984068661e-06, -0.0002952983095968742,
       0.006854380595771486, -0.07755569487992697, 0.6862730778816093)
C_M_INV = (4131643418.193291, -10471683395.26777, 11833009228.6429, -7851132955.882548, 3388121732.651829,
           -994285251.2185925, 201183449.7086889, -27776767.88241613, 2515647.646492857, -136305.2970161326,
           3445.959503226691)
C_D_INV = (39129605.95992675, -141095001.9380851, 226461386.9399433, -213225975.7007014, 130589579.4920038,
           -54470021.75408537, 15723274.21737542, -3119398.842468358, 411336.473729197, -33239.91568304499,
           1311.988715157221)
# Buffer of the Chebyshev grid beyond the blobs' heights, in units of the monopole half-width w_m h / 2.
BUFFER_FACTOR = 1.5


# ------------------------------------------------------------------ helpers
def nearest_smooth(n):
    """The first of n, n+1, n-1, n+2, n-2, ... (n + i before n - i) whose prime factors are all in 2, 3, 5, 7."""
    def smooth(m):
        if m < 1:
            return False
        for p in (2, 3, 5, 7):
            while m % p == 0:
                m //= p
        return m == 1
    for i in range(0, max(n, 1) + 1):
        if smooth(n + i):
            return n + i
        if i and smooth(n - i):
            return n - i
    return 1


def clenshaw_curtis(n_intervals, half_length):
    """Nodes and weights of the (n_intervals + 1)-point Clenshaw-Curtis rule on [-half_length, half_length].

    Nodes ``half_length cos(pi j / n_intervals)``, j = 0..n_intervals (first node at +half_length);
    weights as in Trefethen, "Spectral Methods in MATLAB" (SIAM 2000), program clencurt.
    Returns ``(nodes, weights)``, each (n_intervals + 1,).
    """
    n = int(n_intervals)
    theta = np.pi * np.arange(n + 1) / n
    weights = np.zeros(n + 1)
    inner = theta[1:-1]
    v = np.ones(n - 1)
    if n % 2 == 0:
        weights[0] = weights[n] = 1.0 / (n * n - 1)
        for k in range(1, n // 2):
            v -= 2.0 * np.cos(2 * k * inner) / (4 * k * k - 1)
        v -= np.cos(n * inner) / (n * n - 1)
    else:
        weights[0] = weights[n] = 1.0 / (n * n)
        for k in range(1, (n - 1) // 2 + 1):
            v -= 2.0 * np.cos(2 * k * inner) / (4 * k * k - 1)
    weights[1:-1] = 2.0 * v / n
    return half_length * np.cos(theta), half_length * weights


def es_kernel(offsets, beta, alpha):
    """The unnormalised ES kernel ``exp(beta (sqrt(1 - d^2/alpha^2) - 1))`` at offsets ``d`` (|d| <= alpha)."""
    d = np.asarray(offsets, dtype=float)
    return np.exp(beta * (np.sqrt(1.0 - d * d / (alpha * alpha)) - 1.0))


def es_normalisation(beta, alpha, nodes=1000):
    """Integral of the ES kernel over [-alpha, alpha] by the ``nodes``-point Clenshaw-Curtis rule (a length)."""
    s, v = clenshaw_curtis(nodes - 1, alpha)
    return float(np.cumsum(es_kernel(s, beta, alpha) * v)[-1])  # summed in node order, as the library does


def dipole_threshold(beta, alpha):
    """Support half-width of the ES derivative kernel: the local minimum of |phi'| next to the edge
    (closed form in complex arithmetic, principal branches, real part taken at the end), a length."""
    b = float(beta)
    c = (8 * b * b + 12 * cmath.sqrt(81 - 12 * b * b) - 108) * b
    c13 = c ** (1.0 / 3.0)
    return (cmath.sqrt(6 * c13 / b + 24 * b / c13 + 12)).real * alpha / 6.0


# ------------------------------------------------------------------ the parameter object
@dataclass(frozen=True)
class KernelParameters:
    """One ES kernel on the grid, per direction (x, y, z).

    The weight of a grid node at offsets (dx, dy, dz) from a blob is
    ``phi_x(dx) phi_y(dy) phi_z(dz)`` with ``phi_c(d) = exp(beta_c (sqrt(1 - d^2/alpha_c^2) - 1)) / norm_c``
    (units 1/length per direction, so the 3-D weight is a density, 1/length^3); the derivative kernel
    (torques) is its derivative with respect to the node coordinate.

    width : (wx, wy, wz) ints, grid nodes under the kernel along each direction (wz is used only on the
        uniform z grid of TP; on a Chebyshev z grid the nodes are all those within ``threshold[2]``).
    beta : (bx, by, bz), the total ES exponents (dimensionless).
    alpha : (ax, ay, az), the half-widths (lengths) at which the kernel's square root vanishes.
    norm : (nx, ny, nz), the 1-D normalisations (lengths): each 1-D factor is divided by its norm.
    threshold : (tx, ty, tz), the support half-widths (lengths): an x or y (TP: also z) offset with
        |d| > threshold is replaced by +threshold (DoublyPeriodicStokes' clamping rule); on a Chebyshev z
        grid only nodes with |d| <= threshold are used.
    """
    width: tuple
    beta: tuple
    alpha: tuple
    norm: tuple
    threshold: tuple

    def __post_init__(self):
        for name in ('width', 'beta', 'alpha', 'norm', 'threshold'):
            value = tuple(getattr(self, name))
            if len(value) != 3:
                raise ValueError('KernelParameters.%s needs three values (x, y, z), got %r' % (name, value))
            object.__setattr__(self, name, tuple(int(v) for v in value) if name == 'width'
                               else tuple(float(v) for v in value))


@dataclass(frozen=True)
class SpectralParameters:
    """Everything that fixes the spectral discretisation (frozen; two selections build it: DoublyPeriodicStokes'
    :func:`dpstokes_parameters` and libMobility's in ``mobility.spectral.libmobility_parameters``).

    geometry : 'TP' (triply periodic), 'DP' (doubly periodic, z open), 'DPBW' (doubly periodic, no-slip wall
        at z = z0), 'DPSC' (doubly periodic slit, no-slip walls at z = z0 and z = z0 + Lz).
    Nx, Ny, Nz : grid points; along z the Chebyshev extreme points (DP geometries) or the uniform periodic
        grid (TP).
    hx, hy : grid spacings in x and y (lengths); Lx = Nx hx and Ly = Ny hy are the periods used.
    Lx, Ly : the periods in x and y actually used (lengths).
    x0, y0 : grid origins: nodes at ``x0 + i hx``, ``y0 + j hy`` (DoublyPeriodicStokes: 0; UAMMD: -L/2).
    z0, Lz : the z grid spans [z0, z0 + Lz]; TP: nodes ``z0 + k hz`` with period Lz = Nz hz; DP geometries:
        Chebyshev nodes ``z0 + (Lz/2)(1 + cos(pi k/(Nz-1)))``, k = 0..Nz-1 (top first).
    hz : TP z spacing (length); None in the DP geometries.
    z_range : (zlo, zhi) the heights blobs may have (checked by the product); TP: None (z is periodic).
    monopole : KernelParameters of the force kernel.
    dipole : KernelParameters of the torque (derivative) kernel, or None for a force-only discretisation.
    radius : the hydrodynamic radius the selection aimed at (length; for reports).
    selection : a word naming the rule that made these numbers ('dpstokes', 'libmobility', ...).
    rules : the discretisation rules beyond these numbers: 'dpstokes' (DoublyPeriodicStokes': clamped kernel
        edges, ghost folding by geometry, derivative kernels for torques, conjugate-averaged wall corrections
        of unpaired modes; what this module's products implement) or 'uammd' (UAMMD's, behind libMobility:
        see ``mobility.spectral.libmobility_parameters``).
    """
    geometry: str
    Nx: int
    Ny: int
    Nz: int
    hx: float
    hy: float
    Lx: float
    Ly: float
    z0: float
    Lz: float
    monopole: KernelParameters
    dipole: KernelParameters = None
    hz: float = None
    x0: float = 0.0
    y0: float = 0.0
    z_range: tuple = None
    radius: float = None
    selection: str = 'custom'
    notes: tuple = field(default=(), compare=False)
    rules: str = 'dpstokes'

    def __post_init__(self):
        if self.geometry not in GEOMETRIES:
            raise UserInputError('spectral geometry must be one of %s, got %r' % (', '.join(GEOMETRIES), self.geometry))
        if self.rules not in RULES:
            raise UserInputError('spectral rules must be one of %s, got %r' % (', '.join(RULES), self.rules))
        for name in ('Nx', 'Ny', 'Nz'):
            object.__setattr__(self, name, int(getattr(self, name)))
        for name in ('hx', 'hy', 'Lx', 'Ly', 'z0', 'Lz', 'x0', 'y0'):
            object.__setattr__(self, name, float(getattr(self, name)))
        if self.geometry == 'TP':
            if self.hz is None:
                raise UserInputError('a triply periodic discretisation needs the z spacing hz')
            object.__setattr__(self, 'hz', float(self.hz))
        elif self.Nz < 3:
            raise UserInputError('a Chebyshev z grid needs at least 3 points, got Nz = %d' % self.Nz)
        if self.z_range is not None:
            object.__setattr__(self, 'z_range', (float(self.z_range[0]), float(self.z_range[1])))
        for kernel in (self.monopole, self.dipole):
            if kernel is None:
                continue
            for beta in kernel.beta:
                if not BETA_RANGE[0] <= beta <= BETA_RANGE[1]:
                    raise UserInputError('the kernel shape beta = %.4g is outside [%g, %g]: the grid cannot '
                                         'represent this blob radius (change the radius or the box)'
                                         % ((beta,) + BETA_RANGE))
            widths = (self.Nx, self.Ny) + ((self.Nz,) if self.geometry == 'TP' else ())
            for n, w, axis in zip(widths, kernel.width, 'xyz'):
                if w > n:
                    raise UserInputError('the box is smaller than the kernel: %d grid points along %s, the kernel '
                                         'covers %d (enlarge the box)' % (n, axis, w))

    # -------------------------------------------------------------- derived quantities
    @property
    def has_torque(self):
        """True when the discretisation has a dipole kernel (angular velocities and torques)."""
        return self.dipole is not None

    @property
    def is_chebyshev(self):
        """True for the doubly periodic geometries (Chebyshev z grid)."""
        return self.geometry != 'TP'

    @property
    def walls(self):
        """Heights of the no-slip walls (a tuple, empty without walls)."""
        return {'TP': (), 'DP': (), 'DPBW': (self.z0,), 'DPSC': (self.z0, self.z0 + self.Lz)}[self.geometry]

    def z_nodes(self):
        """z of the grid nodes relative to z0, (Nz,): TP ``k hz``; DP geometries Chebyshev, top first."""
        if self.geometry == 'TP':
            return np.arange(self.Nz) * self.hz
        return (self.Lz / 2.0) * (1.0 + np.cos(np.pi * np.arange(self.Nz) / (self.Nz - 1)))

    def z_weights(self):
        """Quadrature weights of the z nodes (lengths), (Nz,): TP hz; DP geometries Clenshaw-Curtis on [0, Lz]."""
        if self.geometry == 'TP':
            return np.full(self.Nz, self.hz)
        return clenshaw_curtis(self.Nz - 1, self.Lz / 2.0)[1]

    def describe(self):
        """A dict of the numbers (for reports and the benchmark)."""
        out = {'geometry': self.geometry, 'Nx': self.Nx, 'Ny': self.Ny, 'Nz': self.Nz, 'hx': self.hx, 'hy': self.hy,
               'hz': self.hz, 'Lx': self.Lx, 'Ly': self.Ly, 'z0': self.z0, 'Lz': self.Lz, 'x0': self.x0,
               'y0': self.y0, 'selection': self.selection}
        for name, kernel in (('monopole', self.monopole), ('dipole', self.dipole)):
            if kernel is not None:
                out[name] = {'width': kernel.width, 'beta': kernel.beta, 'alpha': kernel.alpha, 'norm': kernel.norm,
                             'threshold': kernel.threshold}
        return out


# ------------------------------------------------------------------ DoublyPeriodicStokes' selection
def _kernel_type(kernel, has_torque):
    table = TORQUE_KERNELS if has_torque else FORCE_ONLY_KERNELS
    if isinstance(kernel, (int, np.integer)) and not isinstance(kernel, bool):
        if kernel not in (TORQUE_TABLE if has_torque else FORCE_ONLY_TABLE):
            raise UserInputError('kernel type %d is not one of DoublyPeriodicStokes\' %s types %s'
                                 % (kernel, 'torque' if has_torque else 'force-only',
                                    sorted(TORQUE_TABLE if has_torque else FORCE_ONLY_TABLE)))
        return int(kernel)
    if kernel not in table:
        raise UserInputError('kernel %r: one of %s %s' % (kernel, ', '.join(table),
                                                          '(with torques)' if has_torque else '(force only)'))
    return table[kernel]


def _whole_cells(length, h, tolerance, name, notes):
    """Cells along a length (DoublyPeriodicStokes: ceil(L/h) and L enlarged to whole cells unless L/h is an
    integer; a ratio within ``tolerance`` of an integer counts as one here unless tolerance is 0)."""
    r = length / h
    if round(r) == r:
        return int(round(r)), length
    if tolerance > 0 and abs(r - round(r)) < tolerance:
        notes.append('%s/h = %.17g is a whole number of cells up to round-off: %d cells, %s = %d h '
                     '(DoublyPeriodicStokes would add a cell)' % (name, r, round(r), name, round(r)))
        return int(round(r)), h * round(r)
    n = int(math.ceil(r))
    return n, h * n


def _es_kernel_parameters(w, beta, alpha, threshold):
    norm = es_normalisation(beta, alpha)
    return KernelParameters(width=(w, w, w), beta=(beta,) * 3, alpha=(alpha,) * 3, norm=(norm,) * 3,
                            threshold=(threshold,) * 3)


def dpstokes_parameters(radius, geometry, Lx, Ly, zmin, zmax, kernel='w6', has_torque=False,
                        whole_cells_tolerance=1e-9, warn=True):
    """DoublyPeriodicStokes' grid and kernel selection (its CPU library, ``optInd = 0``, ``fac = 1.5``).

    radius : the blob's hydrodynamic radius R (length); geometry : 'TP', 'DP', 'DPBW' or 'DPSC';
    Lx, Ly : the requested periods (the grid starts at x = y = 0); zmin, zmax : the blobs' height range
        (DPBW: wall at zmin; DPSC: walls at zmin and zmax; TP: the z period is zmax - zmin);
    kernel : force only 'w6', 'w5', 'w4'; with torques 'w6', 'w5', 'w6w5', 'w6w4', 'w5w4' (monopole width,
        then dipole width), or the library's kernel type number;
    has_torque : whether the discretisation carries torques and angular velocities;
    whole_cells_tolerance : Ly/h (TP: Lz/h) within this of an integer is taken as that integer; 0 reproduces
        the library exactly, which then adds a cell for ratios like 49.00000000000001.

    The rules: h0 = R / (w_m c_m(beta_table)); Nx = the nearest 7-smooth number to floor(Lx/h0); h = Lx/Nx;
    beta from the inverse radius fits at R/(w h); Ly (and the TP z period) enlarged to whole cells;
    Chebyshev Nz = nearest_smooth(pi / arcsin(h/H)) + 1 over the blobs' range plus the buffers
    1.5 w_m h / 2 (DP: both ends; DPBW: top).  Returns :class:`SpectralParameters`.
    """
    notes = []
    if geometry not in GEOMETRIES:
        raise UserInputError('spectral geometry must be one of %s, got %r' % (', '.join(GEOMETRIES), geometry))
    values = {'radius': radius, 'Lx': Lx, 'Ly': Ly, 'zmin': zmin, 'zmax': zmax}
    for name, value in values.items():
        if not np.isfinite(float(value)):
            raise UserInputError('spectral parameters: %s must be finite, got %r' % (name, value))
    radius, Lx, Ly, zmin, zmax = (float(values[k]) for k in ('radius', 'Lx', 'Ly', 'zmin', 'zmax'))
    if radius <= 0 or Lx <= 0 or Ly <= 0:
        raise UserInputError('spectral parameters: the radius and the periods must be positive (radius %g, '
                             'Lx %g, Ly %g)' % (radius, Lx, Ly))
    if not zmax > zmin:
        raise UserInputError('spectral parameters: zmax (%g) must exceed zmin (%g)' % (zmax, zmin))
    ktype = _kernel_type(kernel, has_torque)
    if has_torque:
        w_m, w_d, bw_m_table, _ = TORQUE_TABLE[ktype]
    else:
        w_m, bw_m_table = FORCE_ONLY_TABLE[ktype]
        w_d = None
    h0 = radius / (w_m * np.polyval(C_M, w_m * bw_m_table))
    Nx = nearest_smooth(int(math.floor(Lx / h0)))
    if Nx < 1:
        raise UserInputError('spectral parameters: the box (Lx = %g) is smaller than one grid cell (%g)' % (Lx, h0))
    h = Lx / Nx
    c_m = radius / (w_m * h)
    beta_m = float(np.polyval(C_M_INV, c_m) / w_m) * w_m
    betas = [beta_m]
    if has_torque:
        c_d = radius / (w_d * h)
        beta_d = float(np.polyval(C_D_INV, c_d) / w_d) * w_d
        betas.append(beta_d)
    for beta in betas:
        if not BETA_RANGE[0] <= beta <= BETA_RANGE[1]:
            raise UserInputError('spectral parameters: the kernel shape beta = %.4g for radius %g on the grid '
                                 'h = %.6g is outside [%g, %g]: the grid cannot represent this radius (change the '
                                 'radius, the box or the kernel)' % ((beta, radius, h) + BETA_RANGE))
    Ny, Ly_used = _whole_cells(Ly, h, whole_cells_tolerance, 'Ly', notes)
    alpha_m = radius / (2 * c_m)
    monopole = _es_kernel_parameters(w_m, beta_m, alpha_m, alpha_m)
    dipole = None
    if has_torque:
        alpha_d = radius / (2 * c_d)
        t_d = dipole_threshold(beta_d, alpha_d)
        dipole = _es_kernel_parameters(int(round(2 * t_d / h)), beta_d, alpha_d, t_d)
        # the width follows from the threshold as the library computes it
    monopole = KernelParameters(width=(int(round(2 * alpha_m / h)),) * 3, beta=monopole.beta, alpha=monopole.alpha,
                                norm=monopole.norm, threshold=monopole.threshold)
    buffer = BUFFER_FACTOR * w_m * h / 2.0
    below, above = {'TP': (0.0, 0.0), 'DP': (buffer, buffer), 'DPBW': (0.0, buffer), 'DPSC': (0.0, 0.0)}[geometry]
    z0 = zmin - below
    Lz = (zmax + above) - z0
    hz = None
    if geometry == 'TP':
        Nz, Lz = _whole_cells(Lz, h, whole_cells_tolerance, 'Lz', notes)
        hz = h
        z_range = None
    else:
        half = Lz / 2.0
        if h >= half:
            raise UserInputError('spectral parameters: the z extent %g is too small for the grid spacing %g'
                                 % (Lz, h))
        n = int(math.ceil(math.pi / (math.acos(-h / half) - math.pi / 2)))
        Nz = nearest_smooth(n) + 1
        z_range = (zmin, zmax)
    if warn:
        for note in notes:
            warnings.warn('dpstokes_parameters: ' + note, stacklevel=2)
    return SpectralParameters(geometry=geometry, Nx=Nx, Ny=Ny, Nz=Nz, hx=h, hy=h, Lx=Lx, Ly=Ly_used, z0=z0, Lz=Lz,
                              hz=hz, monopole=monopole, dipole=dipole, z_range=z_range, radius=radius,
                              selection='dpstokes', notes=tuple(notes))


def refined_parameters(parameters, factor):
    """The same kernels on a grid ``factor`` times finer (an integer >= 1): a convergence check of the product.

    The continuous kernels (their beta, half-width alpha, normalisation and support) are kept and the spacing
    divided by ``factor``, so each kernel covers ``factor`` times as many grid points; the periods and the z
    extent are unchanged, and the Chebyshev Nz follows from the new spacing by the rule of
    :func:`dpstokes_parameters` (TP: ``factor`` times the z cells).  As ``factor`` grows the product converges
    to the force-coupling mobility of the continuous kernels (the grid's position dependence and the
    quadrature error vanish).  Returns :class:`SpectralParameters` (selection ``'<selection> refined xN'``).
    """
    import dataclasses
    m = int(factor)
    if m != factor or m < 1:
        raise UserInputError('refined_parameters: the factor must be a whole number >= 1, got %r' % (factor,))
    p = parameters
    if m == 1:
        return p
    hx, hy = p.hx / m, p.hy / m

    def finer(kernel):
        if kernel is None:
            return None
        spacing = (hx, hy, p.hz / m if p.geometry == 'TP' else hx)
        return dataclasses.replace(kernel, width=tuple(int(round(2 * t / h)) for t, h in
                                                       zip(kernel.threshold, spacing)))
    changes = dict(Nx=p.Nx * m, Ny=p.Ny * m, hx=hx, hy=hy, monopole=finer(p.monopole), dipole=finer(p.dipole),
                   selection='%s refined x%d' % (p.selection, m))
    if p.geometry == 'TP':
        changes.update(Nz=p.Nz * m, hz=p.hz / m)
    else:
        half = p.Lz / 2.0
        h = min(hx, hy)
        if h >= half:
            raise UserInputError('refined_parameters: the z extent %g is too small for the spacing %g' % (p.Lz, h))
        changes['Nz'] = nearest_smooth(int(math.ceil(math.pi / (math.acos(-h / half) - math.pi / 2)))) + 1
    return dataclasses.replace(p, **changes)
