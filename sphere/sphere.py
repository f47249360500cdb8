"""One sphere above a no-slip wall, with its centre of mass displaced from its centre.

Delong, Balboa Usabiaga and Donev, J. Chem. Phys. 143, 144107 (2015),
section IV.C.  The sphere (radius ``a``) is tracked at its geometric centre,
at height ``h`` above the wall ``z = 0``; gravity acts at the centre of mass,
``R(q) com_offset`` away from the centre, so it also makes a torque.  No
blobs are used: the 6x6 mobility (rows ``v, w``; columns ``F, T``; about the
centre) depends on ``h`` only and comes from one of two models.

``best`` (``best_known_mobility``), the best (semi-)analytic results known:

* perpendicular translation: P. Huang and K. S. Breuer, Phys. Rev. E 76,
  046307 (2007), ``mu_perp = (6 d^2 + 2 d) / (6 d^2 + 9 d + 2)`` with the gap
  ``d = (h - a)/a`` (the approximation of Bevan and Prieve, J. Chem. Phys.
  113, 1228 (2000)); within 0.7% of Brenner's exact series for h <= 2a and
  0.3% beyond;
* parallel translation: lubrication theory of A. J. Goldman, R. G. Cox and
  H. Brenner, Chem. Eng. Sci. 22, 637 (1967) below ``h = 1.03212 a`` (where
  the two curves cross; the published code switched at 1.02979 a, where its
  Goldman curve, with the force-rotation resistance doubled, crossed) and the method of reflections of L. P. Faucheux and
  A. J. Libchaber, Phys. Rev. E 49, 5158 (1994) above,
  ``1 - 9x/16 + x^3/8 - 45x^4/256 - x^5/16`` with ``x = a/h``
  (error about -4% at h = 1.1a, below 0.3% for h >= 2a);
* rotation (parallel and perpendicular) and the rotation-translation
  coupling: natural cubic splines of a table computed with this package's
  162-blob icosahedral shell (``mobility.162-blob.dat`` next to this file,
  made by ``make_mobility_table.py``, which documents the command).  Beyond
  the table the far-field forms ``1 - c x^3`` (rotation) and ``c x^4``
  (coupling) continue it.

``swan-brady`` (``swan_brady_mobility``): the self terms of one blob of the
Rotne-Prager-Blake tensor (J. W. Swan and J. F. Brady, Phys. Fluids 19,
113306 (2007)), what a single-blob roller uses; with the regularisation of
the mobility package for ``h < a``.

Normalisation: translation ``1/(6 pi eta a)``, rotation ``1/(8 pi eta a^3)``,
coupling ``1/(6 pi eta a^2)``.  The coupling has the rolling sense: a force
``F_x`` along the wall turns the sphere with ``w_y = +c F_x`` (and
``w_x = -c F_y``), like a wheel rolling on the wall (Goldman, Cox and
Brenner 1967).  The published sphere code had the opposite sign in its
single-blob function and the same sign on all four coupling entries in its
best-known function; both are corrected here.
"""
import os

import numpy as np
from scipy.interpolate import CubicSpline

from body.geometry import rotation_matrices

ETA = 1.0          # viscosity
A = 0.5            # sphere radius
M = 0.5            # weight (mass times g)
KT = 0.2           # thermal energy
H = 3.5            # initial height of the centre
REPULSION_STRENGTH = 2.0
DEBYE_LENGTH = 0.5
COM_OFFSET = (0.0, 0.0, -0.1)  # centre of mass in the body frame, relative to the centre

# Crossing of goldman_parallel and faucheux_parallel (the published 1.02979 is the crossing of a
# Goldman curve whose force-rotation resistance was doubled by a wrong prefactor, 6 pi a 2 for 6 pi a^2).
GOLDMAN_FAUCHEUX_SWITCH = 1.032123
TABLE_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'mobility.162-blob.dat')


# ------------------------------------------------------------ scalar mobilities (normalised)
def huang_breuer_perpendicular(h, a):
    """Perpendicular translational mobility / (1/(6 pi eta a)) at centre height ``h`` (array)."""
    d = (np.asarray(h, dtype=float) - a) / a
    return (6.0 * d ** 2 + 2.0 * d) / (6.0 * d ** 2 + 9.0 * d + 2.0)


def faucheux_parallel(h, a):
    """Parallel translational mobility / (1/(6 pi eta a)) by the method of reflections."""
    x = a / np.asarray(h, dtype=float)
    return 1.0 - 9.0 * x / 16.0 + x ** 3 / 8.0 - 45.0 * x ** 4 / 256.0 - x ** 5 / 16.0


def goldman_resistance(h, a):
    """Lubrication resistances of Goldman, Cox and Brenner (1967) for the gap ``d = (h - a)/a`` (d << 1).

    Returns dimensionless ``(F_t, F_r, T_t, T_r)``: force on a translating
    sphere in units of ``6 pi eta a U``, force on a rotating sphere in units of
    ``6 pi eta a^2 Omega``, torques in units of ``8 pi eta a^2 U`` and
    ``8 pi eta a^3 Omega``.
    """
    log_gap = np.log((np.asarray(h, dtype=float) - a) / a)
    return (-(8.0 / 15.0) * log_gap + 0.9588, -(2.0 / 15.0) * log_gap - 0.2526,
            -0.1 * log_gap - 0.1895, -0.4 * log_gap + 0.3817)


def goldman_parallel(h, a):
    """Parallel translational mobility / (1/(6 pi eta a)) from the inverted GCB resistance (free rotation)."""
    F_t, F_r, T_t, T_r = goldman_resistance(h, a)
    # Dimensional resistance (eta = a = 1, factor pi dropped): [[6 F_t, 6 F_r], [8 T_t, 8 T_r]].
    det = 6.0 * F_t * 8.0 * T_r - 6.0 * F_r * 8.0 * T_t
    return 6.0 * (8.0 * T_r) / det


def parallel_translation(h, a):
    """Goldman-Cox-Brenner below ``h = 1.032123 a``, Faucheux-Libchaber above (normalised)."""
    h = np.asarray(h, dtype=float)
    near = h < GOLDMAN_FAUCHEUX_SWITCH * a
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(near, goldman_parallel(np.where(near, h, 2.0 * a), a), faucheux_parallel(h, a))


class RotationTable:
    """Cubic splines of the rotational mobilities of a blob-shell sphere above a wall.

    The file has one row per height: ``h/R, par, perp, rot_par, rot_perp,
    coupling`` (normalised as in the module docstring, ``R`` the sphere
    radius); ``#`` lines are comments.  Natural cubic splines interpolate the
    last three columns; above the last row ``1 - c x^3`` and ``c x^4``
    (``x = R/h``), with ``c`` matching the last row, continue them; below
    the first row the first row is used.
    """

    def __init__(self, path=TABLE_FILE):
        self.path = path
        table = np.loadtxt(path, comments='#')
        if table.ndim != 2 or table.shape[1] != 6 or table.shape[0] < 4:
            raise ValueError('%s: expected rows "h/R par perp rot_par rot_perp coupling"' % path)
        self.table = table
        self.h = table[:, 0]
        self.splines = [CubicSpline(self.h, table[:, k], bc_type='natural') for k in (3, 4, 5)]
        h_end = self.h[-1]
        self.far_coefficients = ((1.0 - table[-1, 3]) * h_end ** 3, (1.0 - table[-1, 4]) * h_end ** 3,
                                 table[-1, 5] * h_end ** 4)

    def __call__(self, h_over_R):
        """``(rot_par, rot_perp, coupling)``, each with the shape of ``h_over_R``."""
        h = np.clip(np.asarray(h_over_R, dtype=float), self.h[0], None)
        inside = h <= self.h[-1]
        h_in = np.where(inside, h, self.h[-1])
        c_par, c_perp, c_coupling = self.far_coefficients
        far = (1.0 - c_par / h ** 3, 1.0 - c_perp / h ** 3, c_coupling / h ** 4)
        return tuple(np.where(inside, spline(h_in), f) for spline, f in zip(self.splines, far))


_table_cache = {}


def rotation_table(path=TABLE_FILE):
    """The ``RotationTable`` of ``path``, read once."""
    if path not in _table_cache:
        _table_cache[path] = RotationTable(path)
    return _table_cache[path]


def assemble_mobility(h, eta, a, par, perp, rot_par, rot_perp, coupling):
    """6x6 mobilities (nb, 6, 6) from normalised scalars at the heights ``h`` (nb,)."""
    nb = np.asarray(h).reshape(-1).shape[0]
    t, r, c = 1.0 / (6.0 * np.pi * eta * a), 1.0 / (8.0 * np.pi * eta * a ** 3), 1.0 / (6.0 * np.pi * eta * a ** 2)
    N = np.zeros((nb, 6, 6))
    N[:, 0, 0] = N[:, 1, 1] = t * np.reshape(par, -1)
    N[:, 2, 2] = t * np.reshape(perp, -1)
    N[:, 3, 3] = N[:, 4, 4] = r * np.reshape(rot_par, -1)
    N[:, 5, 5] = r * np.reshape(rot_perp, -1)
    coupling = c * np.reshape(coupling, -1)
    # Rolling sense: w_y = +c F_x, w_x = -c F_y (and the symmetric u_x = +c T_y, u_y = -c T_x).
    N[:, 4, 0] = N[:, 0, 4] = coupling
    N[:, 3, 1] = N[:, 1, 3] = -coupling
    return N


def best_known_mobility(h, eta=ETA, a=A, table=None):
    """Best (semi-)analytic 6x6 mobility of a sphere at centre heights ``h`` (nb,), shape (nb, 6, 6)."""
    h = np.asarray(h, dtype=float).reshape(-1)
    rot_par, rot_perp, coupling = (table or rotation_table())(h / a)
    return assemble_mobility(h, eta, a, parallel_translation(h, a), huang_breuer_perpendicular(h, a),
                             rot_par, rot_perp, coupling)


def swan_brady_scalars(h, a):
    """Normalised single-blob self mobilities ``(par, perp, rot_par, rot_perp, coupling)`` at heights ``h``.

    Rotne-Prager-Blake self terms (Swan and Brady 2007) at ``h_eff = max(h, a)``,
    all multiplied by ``(min(h/a, 1))^2`` (the mobility package's regularisation).
    """
    h = np.asarray(h, dtype=float)
    x = a / np.maximum(h, a)
    damping = np.minimum(h / a, 1.0) ** 2
    par = 1.0 - (9.0 * x - 2.0 * x ** 3 + x ** 5) / 16.0
    perp = 1.0 - (9.0 * x - 4.0 * x ** 3 + x ** 5) / 8.0
    rot_par = 1.0 - 5.0 * x ** 3 / 16.0
    rot_perp = 1.0 - x ** 3 / 8.0
    # (1/8) x^4 in units of 1/(8 pi eta a^2) is (3/32) x^4 in units of 1/(6 pi eta a^2).
    coupling = 3.0 * x ** 4 / 32.0
    return tuple(damping * v for v in (par, perp, rot_par, rot_perp, coupling))


def swan_brady_mobility(h, eta=ETA, a=A):
    """Single-blob (Rotne-Prager-Blake self) 6x6 mobility at centre heights ``h`` (nb,), shape (nb, 6, 6)."""
    h = np.asarray(h, dtype=float).reshape(-1)
    return assemble_mobility(h, eta, a, *swan_brady_scalars(h, a))


MOBILITY_MODELS = {'best': best_known_mobility, 'swan-brady': swan_brady_mobility}


# ------------------------------------------------------------ forces and the model
def wall_potential(h, a=A, strength=REPULSION_STRENGTH, length=DEBYE_LENGTH):
    """Wall repulsion ``strength exp(-(h - a)/length) / (h - a)`` (``inf`` for ``h <= a``)."""
    gap = np.asarray(h, dtype=float) - a
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        energy = strength * np.exp(-gap / length) / gap
    return np.where(gap > 0.0, energy, np.inf)


def wall_force(h, a=A, strength=REPULSION_STRENGTH, length=DEBYE_LENGTH):
    """z-force of the wall repulsion at centre height ``h > a``."""
    gap = np.asarray(h, dtype=float) - a
    return strength * (gap / length + 1.0) * np.exp(-gap / length) / gap ** 2


class SphereModel:
    """Forces, mobility and validity of independent spheres (stacks ``locations (nb, 3)``, ``orientations (nb, 4)``).

    Parameters
    ----------
    mobility_model : str
        ``best`` or ``swan-brady``.
    eta, a, weight, repulsion_strength, debye_length : float
    com_offset : (3,) centre of mass minus centre, in the body frame.
    """

    def __init__(self, mobility_model='best', eta=ETA, a=A, weight=M, repulsion_strength=REPULSION_STRENGTH,
                 debye_length=DEBYE_LENGTH, com_offset=COM_OFFSET):
        if mobility_model not in MOBILITY_MODELS:
            raise ValueError('unknown sphere mobility %r; choose %s' % (mobility_model, ', '.join(MOBILITY_MODELS)))
        self.mobility_model = mobility_model
        self.eta, self.a, self.weight = float(eta), float(a), float(weight)
        self.repulsion_strength, self.debye_length = float(repulsion_strength), float(debye_length)
        self.com_offset = np.asarray(com_offset, dtype=float).reshape(3)
        self._mobility = MOBILITY_MODELS[mobility_model]

    def mobility(self, locations, orientations):
        """6x6 mobility about the centre, shape (nb, 6, 6)."""
        return self._mobility(np.asarray(locations, dtype=float).reshape(-1, 3)[:, 2], self.eta, self.a)

    def force_torque(self, locations, orientations):
        """Gravity at the centre of mass and the wall repulsion at the centre: ``[F, T]``, shape (nb, 6)."""
        locations = np.asarray(locations, dtype=float).reshape(-1, 3)
        arms = rotation_matrices(np.asarray(orientations, dtype=float).reshape(-1, 4)) @ self.com_offset
        gravity = np.zeros_like(locations)
        gravity[:, 2] = -self.weight
        force = gravity.copy()
        force[:, 2] += wall_force(locations[:, 2], self.a, self.repulsion_strength, self.debye_length)
        return np.concatenate((force, np.cross(arms, gravity)), axis=1)

    def potential(self, locations, orientations):
        """Potential energy (nb,): weight times centre-of-mass height plus the wall repulsion."""
        locations = np.asarray(locations, dtype=float).reshape(-1, 3)
        arms = rotation_matrices(np.asarray(orientations, dtype=float).reshape(-1, 4)) @ self.com_offset
        return self.weight * (locations[:, 2] + arms[:, 2]) + wall_potential(
            locations[:, 2], self.a, self.repulsion_strength, self.debye_length)

    def is_valid(self, locations, orientations):
        """True where the sphere is above the wall, ``h > a``."""
        return np.asarray(locations, dtype=float).reshape(-1, 3)[:, 2] > self.a

    def equilibrium_height_density(self, h, kT=KT):
        """Unnormalised Gibbs-Boltzmann density of the centre height, ``exp(-(M h + U_wall(h))/kT)``."""
        h = np.asarray(h, dtype=float)
        energy = self.weight * h + wall_potential(h, self.a, self.repulsion_strength, self.debye_length)
        finite = np.isfinite(energy)
        reference = np.min(energy[finite]) if np.any(finite) else 0.0
        return np.where(finite, np.exp(-(np.where(finite, energy, reference) - reference) / kT), 0.0)
