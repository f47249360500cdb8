"""Shipped tables for a sphere of radius R above a no-slip wall, with their provenance.

1. ``EXACT_SPHERE_WALL``: the exact self mobilities of a rigid sphere whose
   centre is at height ``h`` above a plane wall, from the series solutions in
   bispherical coordinates (``cosh alpha = h / R``):

   * translation perpendicular to the wall: Brenner, Chem. Eng. Sci. 16, 242
     (1961);
   * rotation about the wall normal: Jeffery, Proc. London Math. Soc. 14, 327
     (1915), ``T = 8 pi eta R^3 omega sinh^3(alpha) sum_n csch^3(n alpha)``;
   * translation parallel to the wall and rotation about an axis parallel to
     it (coupled 2x2 resistance problem): O'Neill, Mathematika 11, 67 (1964),
     and Dean & O'Neill, Mathematika 10, 13 (1963); the 2x2 resistance block
     ``[x translation, y rotation]`` is inverted to give mobilities.

   Each row: ``h/R: (mu_par, mu_perp, rot_par, rot_perp, coupling)``,
   normalised by ``1/(6 pi eta R)`` (translation), ``1/(8 pi eta R^3)``
   (rotation) and ``1/(6 pi eta R^2)`` (coupling, rolling sense).  The series
   were summed to convergence in all printed digits (300 against 1200 terms);
   reciprocity of the coupling holds to 4e-12; the values agree to 7 digits
   with the independent wall-sphere resistance table of the StupidCFD
   collection (e.g. h/R = 1.1: Brenner factor 11.45916, Jeffery factor
   1.117065).  The two perpendicular columns are also computed here directly
   from the Brenner and Jeffery series (``brenner_perpendicular``,
   ``jeffery_rotation_perpendicular``), which reproduce the table.

2. ``SHELL_MODEL_ERRORS``: relative errors of the four self mobilities of
   the calibrated icosahedral shells (``multi_bodies.files.structure_generators
   calibrated_shell``, blob radius and shell radius scaled with R) against
   table 1, measured by ``doc/charts/sphere_accuracy_vs_cost.py`` (the chart
   of ``doc/accuracy_vs_cost.md``).  Used by the advisor's ``--quick`` mode.

Functions give the exact values at any height with ``h/R >= 1.01``:
perpendicular columns from the series, parallel columns by interpolating the
ratio of the table to a far-field expansion (monotone cubic in
``log(h/R - 1)``; beyond ``h/R = 10`` the expansions themselves, which agree
with the table at 10 to 5 digits).
"""
import numpy as np

# h/R -> (mu_par, mu_perp, rot_par, rot_perp, coupling); exact (see the module docstring).
EXACT_SPHERE_WALL = {
    1.01: (0.29612, 0.00981, 0.45228, 0.84513, 3.654e-2),
    1.05: (0.38703, 0.04633, 0.60324, 0.87326, 3.201e-2),
    1.1: (0.44305, 0.08727, 0.68955, 0.89520, 2.703e-2),
    1.2: (0.51279, 0.15771, 0.78434, 0.92318, 1.994e-2),
    1.5: (0.62681, 0.31197, 0.90069, 0.96237, 9.355e-3),
    2.0: (0.72321, 0.47047, 0.95991, 0.98432, 3.488e-3),
    3.0: (0.81489, 0.63727, 0.98834, 0.99537, 8.217e-4),
    5.0: (0.88821, 0.77816, 0.99750, 0.99900, 1.227e-4),
    10.0: (0.94386, 0.88795, 0.99969, 0.99987, 8.503e-6),
}
SMALLEST_TABLED_HEIGHT = 1.01
COMPONENTS = ('translation parallel', 'translation perpendicular', 'rotation parallel', 'rotation perpendicular')

# Shell errors (model / exact - 1) of (par, perp, rot par, rot perp) at h/R, from doc/accuracy_vs_cost.md.
# Far from the wall (h/R >= 5) the errors are those of the bulk rotational radius.
SHELL_MODEL_ERRORS = {
    12: {1.1: (-0.101, 0.645, 0.059, 0.099), 1.5: (-0.003, 0.039, 0.087, 0.082),
         2.0: (-0.001, 0.006, 0.081, 0.079), 5.0: (0.000, 0.000, 0.078, 0.078)},
    42: {1.1: (-0.019, 0.265, 0.094, 0.063), 1.5: (-0.002, -0.003, 0.062, 0.058),
         2.0: (0.000, -0.002, 0.058, 0.057), 5.0: (0.000, 0.000, 0.056, 0.056)},
    162: {1.1: (-0.003, 0.115, 0.033, 0.019), 1.5: (-0.001, -0.001, 0.018, 0.017),
          2.0: (0.000, 0.000, 0.017, 0.017), 5.0: (0.000, 0.000, 0.017, 0.017)},
    642: {1.1: (0.000, 0.063, 0.009, 0.004), 1.5: (0.000, 0.001, 0.004, 0.004),
          2.0: (0.000, 0.000, 0.004, 0.004), 5.0: (0.000, 0.000, 0.004, 0.004)},
}


def _alpha(h_over_R):
    return np.arccosh(float(h_over_R))


def brenner_perpendicular(h_over_R, terms=2000):
    """Mobility of a sphere moving towards the wall, ``mu_perp 6 pi eta R`` (Brenner 1961), for h/R > 1."""
    alpha = _alpha(h_over_R)
    n = np.arange(1, terms + 1, dtype=float)
    n = n[(n + 0.5) * alpha < 300.0]  # later terms vanish in double precision
    numerator = 2.0 * np.sinh((2 * n + 1) * alpha) + (2 * n + 1) * np.sinh(2 * alpha)
    denominator = 4.0 * np.sinh((n + 0.5) * alpha) ** 2 - (2 * n + 1) ** 2 * np.sinh(alpha) ** 2
    weights = n * (n + 1) / ((2 * n - 1) * (2 * n + 3))
    drag = 4.0 / 3.0 * np.sinh(alpha) * np.sum(weights * (numerator / denominator - 1.0))
    return 1.0 / drag


def jeffery_rotation_perpendicular(h_over_R, terms=4000):
    """Rotational mobility about the wall normal, ``rot_perp 8 pi eta R^3`` (Jeffery 1915), for h/R > 1."""
    alpha = _alpha(h_over_R)
    n = np.arange(1, terms + 1, dtype=float)
    n = n[n * alpha < 200.0]
    torque = np.sinh(alpha) ** 3 * np.sum(1.0 / np.sinh(n * alpha) ** 3)
    return 1.0 / torque


def _parallel_far_field(h_over_R):
    """Method-of-reflections expansions (Faucheux & Libchaber 1994 for translation; leading rotlet image)."""
    x = 1.0 / np.asarray(h_over_R, dtype=float)
    translation = 1 - 9 * x / 16 + x ** 3 / 8 - 45 * x ** 4 / 256 - x ** 5 / 16
    rotation = 1 - 5 * x ** 3 / 16
    return translation, rotation


def _parallel_ratio_interpolants():
    from scipy.interpolate import PchipInterpolator
    heights = np.array(sorted(EXACT_SPHERE_WALL))
    table = np.array([EXACT_SPHERE_WALL[h] for h in heights])
    far_translation, far_rotation = _parallel_far_field(heights)
    variable = np.log(heights - 1.0)
    return (PchipInterpolator(variable, table[:, 0] / far_translation),
            PchipInterpolator(variable, table[:, 2] / far_rotation))


_INTERPOLANTS = []


def exact_self_mobilities(h_over_R):
    """Exact ``(mu_par, mu_perp, rot_par, rot_perp)`` (normalised as the table) at centre height h/R.

    Returns None below ``h/R = 1.01``, where the shipped table stops.
    """
    h = float(h_over_R)
    if h < SMALLEST_TABLED_HEIGHT - 1e-12:
        return None
    if not _INTERPOLANTS:
        _INTERPOLANTS.extend(_parallel_ratio_interpolants())
    far_translation, far_rotation = _parallel_far_field(h)
    tabled = [k for k in EXACT_SPHERE_WALL if abs(k - h) <= 1e-9 * k]
    if tabled:
        return np.array(EXACT_SPHERE_WALL[tabled[0]][:4])
    if h > max(EXACT_SPHERE_WALL):
        par, rot_par = far_translation, far_rotation
    else:
        par = far_translation * float(_INTERPOLANTS[0](np.log(h - 1.0)))
        rot_par = far_rotation * float(_INTERPOLANTS[1](np.log(h - 1.0)))
    return np.array([par, brenner_perpendicular(h), rot_par, jeffery_rotation_perpendicular(h)])


def shipped_shell_errors(num_blobs, h_over_R):
    """Signed errors of the calibrated ``num_blobs`` shell at h/R from ``SHELL_MODEL_ERRORS``, or None.

    Linear interpolation in ``log(h/R - 1)`` between the charted heights
    1.1 to 5; above 5 the h/R = 5 row (bulk errors); None below 1.1.
    """
    rows = SHELL_MODEL_ERRORS.get(int(num_blobs))
    h = float(h_over_R)
    if rows is None or h < 1.1 - 1e-12:
        return None
    heights = np.array(sorted(rows))
    values = np.array([rows[k] for k in heights])
    if h >= heights[-1]:
        return values[-1].copy()
    variable = np.log(heights - 1.0)
    return np.array([np.interp(np.log(h - 1.0), variable, values[:, j]) for j in range(4)])
