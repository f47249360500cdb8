"""libMobility's grid and kernel selection for its ``DPStokes`` solver, as a :class:`SpectralParameters`.

libMobility (github stochasticHydroTools/libMobility, its DPStokes solver over UAMMD's doubly periodic
Stokes module) chooses the discretisation of the method of Hashemi et al. (J. Chem. Phys. 158, 154101, 2023)
differently from the DoublyPeriodicStokes CPU library (:func:`mobility.spectral.dpstokes_parameters`).  The
rules below are libMobility's, re-stated (``doc/libmobility.md`` explains them):

* kernel: force only the ES kernel of width w = 4 with nominal ``beta = 1.785 w`` and grid spacing
  ``h = a / 1.205``; with torques w = 6 for forces and torques, ``beta = 1.327 w``, torque kernel
  ``beta_d = 2.217 w``, ``h = a / 1.731``; half-width ``alpha = w / 2`` grid units;
* grid: ``Nx = floor(Lx / h)`` raised to even (Ny alike).  With ``allow_changing_box_size`` the periods become
  ``Nx h`` and ``Ny h`` and the nominal betas stay; otherwise ``hx = Lx / Nx``, ``hy = Ly / Ny``,
  ``h = min(hx, hy)``, and beta is refitted per direction from ``a / (w hx)`` and ``a / (w hy)`` through the
  degree-10 polynomial inverses of the radius fits (monopole, and dipole for the torque kernel), z taking
  the smaller of the two; a refitted beta outside [4, 18] is refused;
* z: open widens both ends by ``0.75 w h``, one wall raises zmax by ``0.75 w h``, a slit keeps its walls; the
  extent must exceed 2a; ``Nz = floor(pi / asin(h / (Lz/2)) + 1)`` made odd; Chebyshev nodes over the widened
  extent, grid centred on x = y = 0 (nodes at ``-L/2 + i h``);
* the 1-D kernels ``phi_c(d) = E(d / a_c) / (n_c a_c)``, ``E(s) = exp(beta_c (sqrt(1 - (s/alpha)^2) - 1))``
  inside the half-width and 0 beyond, ``a_x = hx``, ``a_y = hy``, ``a_z = min(hx, hy)``, ``n_c`` the
  composite Simpson integral of E over [-alpha, alpha] with 40000 subintervals.

The discretisation rules that go with these numbers (the kernel's zero edge, the mirror image in z, the
pressure derivative, the wall corrections of unpaired modes, torques by the spectral curl) are
``rules='uammd'``, computed by :mod:`mobility.spectral.uammd`.  Floor 1 of the house.
"""
import math

import numpy as np

from utils import UserInputError

from .parameters import BETA_RANGE, C_D_INV, C_M_INV, KernelParameters, SpectralParameters

# libMobility's kernel choices: (w, nominal beta / w, radius / h) force only; with torques also the torque
# kernel's (w_d, beta_d / w_d).
FORCE_ONLY = dict(w=4, beta_over_w=1.785, radius_over_h=1.205)
WITH_TORQUE = dict(w=6, beta_over_w=1.327, radius_over_h=1.731, w_d=6, beta_d_over_w=2.217)
SIMPSON_INTERVALS = 40000
# z modes of libMobility's DPStokes and the geometries of the spectral core.
Z_MODES = {'open': 'DP', 'single_wall': 'DPBW', 'two_walls': 'DPSC'}


def ascending_polynomial(coefficients, x):
    """``sum_i c_i x^i`` with ``coefficients`` highest power first (numpy order), accumulated from the
    constant term up with the powers formed by repeated multiplication (libMobility's evaluation order)."""
    order = len(coefficients) - 1
    total = coefficients[order]
    power = x
    for i in range(1, order + 1):
        total += coefficients[order - i] * power
        power *= x
    return total


def es_unit(s, beta, alpha):
    """The unnormalised ES kernel in grid units, zero beyond the half-width: s (array) offsets in cells."""
    z = np.asarray(s, dtype=float) / alpha
    z2 = z * z
    inside = z2 <= 1.0
    return np.where(inside, np.exp(beta * (np.sqrt(np.where(inside, 1.0 - z2, 0.0)) - 1.0)), 0.0)


def simpson_normalisation(beta, alpha, intervals=SIMPSON_INTERVALS):
    """Composite Simpson integral of :func:`es_unit` over [-alpha, alpha] (grid units), ``intervals`` even."""
    step = 2.0 * alpha / intervals
    s = -alpha + np.arange(intervals + 1) * step
    weights = np.full(intervals + 1, 2.0)
    weights[1::2] = 4.0
    weights[0] = weights[-1] = 1.0
    return math.fsum(weights * es_unit(s, beta, alpha)) * step / 3.0


def unit_kernel(w, betas, scales):
    """KernelParameters of a libMobility kernel of width w with per-direction betas (bx, by, bz) and grid
    scales (hx, hy, min(hx, hy)): alpha = (w/2) a_c, norm = n_c a_c (lengths), threshold = alpha."""
    alpha = 0.5 * w
    norms = [simpson_normalisation(b, alpha) for b in betas]
    return KernelParameters(width=(w, w, w), beta=tuple(betas), alpha=tuple(alpha * a for a in scales),
                            norm=tuple(n * a for n, a in zip(norms, scales)),
                            threshold=tuple(alpha * a for a in scales))


def _refit(coefficients, radius, w, h, what):
    beta = ascending_polynomial(coefficients, radius / (w * h))
    if not BETA_RANGE[0] <= beta <= BETA_RANGE[1]:
        raise UserInputError('[DPStokes] Could not find (h,beta) within interp range: the %s kernel needs beta = '
                             '%.4g on the grid h = %.6g for radius %g (outside [%g, %g]); the particle radius and '
                             'grid spacing are incompatible: try a square domain or allowChangingBoxSize=True'
                             % ((what, beta, h, radius) + BETA_RANGE))
    return beta


def libmobility_parameters(radius, z_mode, Lx, Ly, zmin, zmax, include_angular=False,
                           allow_changing_box_size=False):
    """libMobility's DPStokes discretisation (see the module docstring).

    radius : hydrodynamic radius a (length); z_mode : 'open', 'single_wall' or 'two_walls';
    Lx, Ly : periods; zmin, zmax : the z extent given to setParameters (a wall at zmin with 'single_wall',
    walls at both with 'two_walls'); include_angular : torques and angular velocities (w = 6 kernels);
    allow_changing_box_size : whether Lx, Ly may become whole numbers of the nominal cell.

    Returns ``(parameters, stored)``: the :class:`SpectralParameters` (``rules='uammd'``,
    ``selection='libmobility'``) and the dict ``{'Lx', 'Ly', 'zmin', 'zmax'}`` of the values libMobility
    keeps after initialize (the changed periods, the widened z extent).
    """
    if z_mode not in Z_MODES:
        raise UserInputError('[DPStokes] This is a doubly periodic solver: periodicityZ must be one of %s with '
                             "libMobility's parameter selection, got %r" % (', '.join(Z_MODES), z_mode))
    values = dict(radius=radius, Lx=Lx, Ly=Ly, zmin=zmin, zmax=zmax)
    for name, value in values.items():
        if not np.isfinite(float(value)):
            raise UserInputError('[DPStokes] %s must be finite, got %r' % (name, value))
    radius, Lx, Ly, zmin, zmax = (float(values[k]) for k in ('radius', 'Lx', 'Ly', 'zmin', 'zmax'))
    if radius <= 0 or Lx <= 0 or Ly <= 0:
        raise UserInputError('[DPStokes] the radius and the periods must be positive (hydrodynamicRadius %g, Lx %g, '
                             'Ly %g)' % (radius, Lx, Ly))
    choice = WITH_TORQUE if include_angular else FORCE_ONLY
    w = choice['w']
    h = radius / choice['radius_over_h']
    nominal = choice['beta_over_w'] * w
    Nx = int(math.floor(Lx / h))
    Nx += Nx % 2
    Ny = int(math.floor(Ly / h))
    Ny += Ny % 2
    if Nx < w or Ny < w:
        raise UserInputError('[DPStokes] the box (%g x %g) is smaller than the kernel: %d x %d cells of h = %g for '
                             'a kernel of %d cells; enlarge Lx, Ly' % (Lx, Ly, Nx, Ny, h, w))
    if allow_changing_box_size:
        Lx, Ly = Nx * h, Ny * h
        hx = hy = h
        betas = (nominal, nominal, nominal)
        betas_d = (choice['beta_d_over_w'] * choice['w_d'],) * 3 if include_angular else None
    else:
        hx, hy = Lx / Nx, Ly / Ny
        bx = _refit(C_M_INV, radius, w, hx, 'force')
        by = _refit(C_M_INV, radius, w, hy, 'force')
        betas = (bx, by, min(bx, by))
        betas_d = None
        if include_angular:
            w_d = choice['w_d']
            bxd = _refit(C_D_INV, radius, w_d, hx, 'torque')
            byd = _refit(C_D_INV, radius, w_d, hy, 'torque')
            betas_d = (bxd, byd, min(bxd, byd))
        h = min(hx, hy)
    widen = 1.5 * w * h / 2.0
    if z_mode == 'open':
        zmax += widen
        zmin -= widen
    elif z_mode == 'single_wall':
        zmax += widen
    Lz = zmax - zmin
    if not Lz > 2.0 * radius:
        raise UserInputError('[DPStokes] The box size in z is too small: zmax - zmin = %g must exceed the particle '
                             'diameter %g (widen zmin, zmax)' % (Lz, 2.0 * radius))
    nz_real = math.pi / math.asin(h / (Lz / 2.0)) + 1.0
    Nz = int(math.floor(nz_real)) + int(math.ceil(nz_real)) % 2
    scales = (hx, hy, min(hx, hy))
    monopole = unit_kernel(w, betas, scales)
    dipole = unit_kernel(choice['w_d'], betas_d, scales) if include_angular else None
    geometry = Z_MODES[z_mode]
    # heights a blob may have: libMobility refuses only crossings of walls; the grid's extent bounds the rest
    z_range = {'DP': (zmin, zmax), 'DPBW': (float(values['zmin']), zmax),
               'DPSC': (float(values['zmin']), float(values['zmax']))}[geometry]
    parameters = SpectralParameters(geometry=geometry, Nx=Nx, Ny=Ny, Nz=Nz, hx=hx, hy=hy, Lx=Lx, Ly=Ly, z0=zmin,
                                    Lz=Lz, monopole=monopole, dipole=dipole, x0=-0.5 * Lx, y0=-0.5 * Ly,
                                    z_range=z_range, radius=radius, selection='libmobility', rules='uammd')
    return parameters, dict(Lx=Lx, Ly=Ly, zmin=zmin, zmax=zmax)
