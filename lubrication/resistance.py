"""Near-field resistance of sphere pairs and of spheres above the wall, vectorised over many pairs / spheres.

Method: Sprinkle, van der Wee, Luo, Driscoll and Donev, "Driven dynamics in dense suspensions of
microrollers", Soft Matter 16, 7982 (2020), as implemented in the published RigidMultiblobsWall
``Lubrication/Lubrication_Class.cc`` (described in ``doc/lubrication.md``).  The formulas and the table
hand-overs below are the published ones, so the published numbers are reproduced; the code is this
package's own, written with NumPy over arrays of pairs and spheres.

Units.  Distances enter normalised by the sphere radius: ``r = |r_2 - r_1| / a`` (centre distance) and
``h = z / a`` (height of the centre above the wall).  Blocks are returned in force units:
``f0 = 6 pi eta a`` (force / velocity), ``f1 = 6 pi eta a^2`` (force / angular velocity, torque / velocity),
``f2 = 6 pi eta a^3`` (torque / angular velocity); :func:`resistance_factors`.

Layouts.  A pair block (12, 12) maps ``[U1 W1 U2 W2]`` to ``[F1 T1 F2 T2]`` with the unit vector
``r_hat = (r_2 - r_1) / |r_2 - r_1|``; a wall block (6, 6) maps ``[U W]`` to ``[F T]`` of one sphere and
holds the wall part only (the free-space single-sphere resistance is subtracted, so pair and wall terms
add up).

The gap clamp ``firm_delta`` (the published ``debye_cut``, default 1e-4): a gap ``r - 2`` (``h - 1``)
below ``firm_delta`` is evaluated at ``firm_delta``, so overlapping spheres get a large but finite
resistance.

Hand-over between formulas (``handover``, the input option ``lubrication_handover``):

* ``'published'`` (default): the published switches at ``r = 2.006``, ``2.1`` and ``h = 1.01``, ``1.1``,
  with their jumps of a few per cent (X11A 43.81 -> 41.65 at r = 2.006, the wall normal 10.43 -> 10.00 at
  h = 1.1), and the pair terms ending abruptly at the cutoff.
* ``'smooth'``: across each switch, over the window of :data:`SMOOTH_WINDOWS`, the blocks are the
  convex blend ``(1 - w) R_left + w R_right`` with the C1 weight ``w = 3 t^2 - 2 t^3``,
  ``t = (x - lo) / (hi - lo)`` clipped to [0, 1]; the pair terms (R_sup and R_MB alike) are multiplied by
  ``1 - w`` over ``[cutoff - CUTOFF_WINDOW, cutoff]``.  Outside the windows the values are the published
  ones exactly.  A convex blend of two positive semidefinite Delta_R blocks is positive semidefinite,
  so Delta_R stays so wherever both formulas give it so (tested).
"""
import numpy as np

from multi_bodies.files.input_options import DEFAULTS
from utils import UserInputError

from . import tables

DEFAULT_FIRM_DELTA = DEFAULTS.firm_delta  # gap clamp in units of a (the option table's firm_delta)
HANDOVERS = ('published', 'smooth')
# Windows (lo, hi) of the smooth hand-over, in units of a: chosen where both formulas are defined (the WS
# table covers r 2.002..2.2, the JO table 2.099..5.001), each a small part of the range of its formulas.
SMOOTH_WINDOWS = {
    'near_contact': (2.004, 2.008),   # pair: near-contact asymptotics -> WS mobility table (switch at 2.006)
    'mobility_table': (2.099, 2.13),  # pair: WS mobility table -> JO resistance table (switch at 2.1)
    'wall_near': (1.008, 1.012),      # wall Y^a, X^c: lubrication forms -> 2562-blob table (switch at 1.01)
    'wall_far': (1.09, 1.11),         # wall X^a, Y^b, Y^c: lubrication forms -> 2562-blob table (switch at 1.1)
}
CUTOFF_WINDOW = 0.25                  # pair terms tapered to zero over [cutoff - 0.25, cutoff]

# Switches of the published pair resistance R_sup (Lubrication_Class.cc ResistPairSup)
NEAR_CONTACT_END = 2.0 + 0.006 - 1e-8   # r <= this: near-contact asymptotic forms (Townsend 2018)
MOBILITY_TABLE_END = 2.0 + 0.1 + 1e-8   # r <= this: two-sphere mobility table, inverted; beyond: JO table
# Switches of the published wall resistance R_sup (WallResistMatrix): asymptotic forms for h <= these
WALL_NORMAL_END = 1.0 + 0.1             # X^a (Cox and Brenner 1967)
WALL_PARALLEL_END = 1.0 + 0.01          # Y^a (Goldman, Cox and Brenner 1967)
WALL_COUPLING_END = 1.0 + 0.1           # Y^b
WALL_NORMAL_ROTATION_END = 1.0 + 0.01   # X^c
WALL_PARALLEL_ROTATION_END = 1.0 + 0.1  # Y^c
ZETA_3 = 1.2020569                      # Riemann zeta(3), as published


def check_handover(handover):
    """Raise UserInputError unless ``handover`` is one this package implements."""
    if handover not in HANDOVERS:
        raise UserInputError('lubrication_handover %r is not available; use published (the published switches '
                             'between formulas, the default) or smooth (a C1 blend across each switch)'
                             % (handover,))


def smooth_weight(x, window):
    """The C1 weight ``3 t^2 - 2 t^3``, ``t = (x - lo) / (hi - lo)`` clipped to [0, 1]: (n,) for x (n,)."""
    lo, hi = window
    t = np.clip((np.asarray(x, dtype=float) - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def cutoff_taper(r, cutoff, handover=DEFAULTS.lubrication_handover):
    """Factor (n,) of the pair terms at distances r (n,) (units of a): 1 (published) or, smooth,
    ``1 - w`` over ``[cutoff - CUTOFF_WINDOW, cutoff]`` (1 below, 0 at the cutoff)."""
    check_handover(handover)
    r = np.asarray(r, dtype=float).reshape(-1)
    if handover == 'published':
        return np.ones_like(r)
    return 1.0 - smooth_weight(r, (cutoff - CUTOFF_WINDOW, cutoff))


def check_firm_delta(firm_delta):
    """The gap clamp as a float; UserInputError unless it is a positive number."""
    try:
        value = float(firm_delta)
    except (TypeError, ValueError):
        raise UserInputError('firm_delta %r is not a number; give the smallest gap (in units of the radius) at '
                             'which the lubrication is evaluated, e.g. 1e-4' % (firm_delta,)) from None
    if not value > 0 or not np.isfinite(value):
        raise UserInputError('firm_delta = %r must be a positive gap in units of the radius (default 1e-4)' % value)
    return value


def resistance_factors(eta, a):
    """``(6 pi eta a, 6 pi eta a^2, 6 pi eta a^3)``: the normalisations of the A, B and C blocks."""
    f = 6.0 * np.pi * float(eta) * float(a)
    return (f, f * a, f * a * a)


def clamp_gap(distance, contact, firm_delta):
    """Distances (n,) with gaps ``distance - contact`` below ``firm_delta`` set to ``contact + firm_delta``."""
    distance = np.asarray(distance, dtype=float).reshape(-1)
    return np.where(distance - contact < firm_delta, firm_delta + contact, distance)


# ------------------------------------------------------------------------------------------ pair scalars
def near_contact_scalars(r):
    """Near-contact two-sphere resistance scalars at distances r (n,) (Townsend 2018, arXiv:1802.08226).

    The lambda = 1 Jeffrey-Onishi asymptotic forms with the published coefficients; B scalars carry the
    factor -2/3 and C scalars 4/3 that convert from ``4 pi mu a^2``, ``8 pi mu a^3`` to ``6 pi eta a^n``.
    Returns (self_scalars (n, 5), pair_scalars (n, 5)) in the order X^A, Y^A, Y^B, X^C, Y^C.
    """
    eps = np.asarray(r, dtype=float) - 2.0
    log_inv = np.log(1.0 / eps)
    eps_log = eps * log_inv
    self_scalars = np.stack((
        0.995419 + 0.25 / eps + 0.225 * log_inv + 0.0267857 * eps_log,
        0.998317 + 0.166667 * log_inv,
        -0.666667 * (0.23892 - 0.25 * log_inv - 0.125 * eps_log),
        1.33333 * (1.0518 - 0.125 * eps_log),
        1.33333 * (0.702834 + 0.2 * log_inv + 0.188 * eps_log)), axis=1)
    pair_scalars = np.stack((
        -0.350153 - 0.25 / eps - 0.225 * log_inv - 0.0267857 * eps_log,
        -0.273652 - 0.166667 * log_inv,
        -0.666667 * (-0.00162268 + 0.25 * log_inv + 0.125 * eps_log),
        1.33333 * (-0.150257 + 0.125 * eps_log),
        1.33333 * (-0.027464 + 0.05 * log_inv + 0.062 * eps_log)), axis=1)
    return self_scalars, pair_scalars


def table_pair_scalars(name, r):
    """Scalars of pair table ``name`` ('JO', 'WS', 'MB') at distances r (n,): (self (n, 5), pair (n, 5)).

    Linear interpolation; outside the table the edge row (the published rule).
    """
    table = tables.pair_table(name)
    both = np.concatenate((table.self_scalars, table.pair_scalars), axis=1)
    values, _, _ = tables.interpolate(table.x, both, r)
    return values[:, :5], values[:, 5:]


# ------------------------------------------------------------------------------------------- pair blocks
def _direction_tensors(r_hat):
    r_hat = np.asarray(r_hat, dtype=float).reshape(-1, 3)
    squeeze = r_hat[:, :, None] * r_hat[:, None, :]
    shear = np.eye(3) - squeeze
    x, y, z = r_hat[:, 0], r_hat[:, 1], r_hat[:, 2]
    zero = np.zeros_like(x)
    cross = np.stack((np.stack((zero, -z, y), axis=1),      # cross @ v = r_hat x v
                      np.stack((z, zero, -x), axis=1),
                      np.stack((-y, x, zero), axis=1)), axis=1)
    return squeeze, shear, cross


def pair_blocks(r_hat, self_scalars, pair_scalars, factors):
    """12 x 12 blocks ``[F1 T1 F2 T2] = R [U1 W1 U2 W2]`` from scalars, one per pair.

    r_hat : (n, 3) unit vectors from sphere 1 to sphere 2; self_scalars, pair_scalars : (n, 5)
    (X^A, Y^A, Y^B, X^C, Y^C of "11" and "12"); factors : (f0, f1, f2) multiplying the A, B, C blocks.
    Returns (n, 12, 12): ``A = f0 (X rr + Y (I - rr))``, ``B = f1 Y^B [r_hat]_x``,
    ``C = f2 (X rr + Y (I - rr))``, in the published arrangement of signs (symmetric).
    """
    f0, f1, f2 = factors
    r_hat = np.asarray(r_hat, dtype=float).reshape(-1, 3)
    squeeze, shear, cross = _direction_tensors(r_hat)
    s = np.asarray(self_scalars, dtype=float)
    p = np.asarray(pair_scalars, dtype=float)

    def tensor(f, X, Y):
        return f * (X[:, None, None] * squeeze + Y[:, None, None] * shear)

    A11, A12 = tensor(f0, s[:, 0], s[:, 1]), tensor(f0, p[:, 0], p[:, 1])
    C11, C12 = tensor(f2, s[:, 3], s[:, 4]), tensor(f2, p[:, 3], p[:, 4])
    B11, B12 = f1 * s[:, 2, None, None] * cross, f1 * p[:, 2, None, None] * cross
    R = np.empty((r_hat.shape[0], 12, 12))
    rows = ((A11, -B11, A12, B12),
            (B11, C11, B12, C12),
            (A12, -B12, A11, B11),
            (-B12, C12, -B11, C11))
    for i, row in enumerate(rows):
        for j, block in enumerate(row):
            R[:, 3 * i:3 * i + 3, 3 * j:3 * j + 3] = block
    return R


def pair_resistance_sup(r, r_hat, factors, firm_delta=DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover):
    """Resolved two-sphere resistance R_sup, (n, 12, 12), at distances r (n,) (units of a) along r_hat (n, 3).

    Published branches, after the gap clamp: ``r <= 2.006`` near-contact asymptotics
    (:func:`near_contact_scalars`); ``2.006 < r <= 2.1`` the two-sphere mobility table
    ``mob_scalars_WS.txt``, assembled as a 12 x 12 mobility and inverted; beyond, the Jeffrey-Onishi
    resistance table ``res_scalars_JO.txt`` (edge row past r = 5.001).  ``handover='smooth'``: the three
    blended across :data:`SMOOTH_WINDOWS` ``near_contact`` and ``mobility_table``.
    """
    check_handover(handover)
    r = clamp_gap(r, 2.0, firm_delta)
    r_hat = np.asarray(r_hat, dtype=float).reshape(-1, 3)
    if handover == 'smooth':
        return _pair_resistance_sup_smooth(r, r_hat, factors)
    R = np.empty((r.shape[0], 12, 12))
    near = r <= NEAR_CONTACT_END
    middle = ~near & (r <= MOBILITY_TABLE_END)
    far = ~near & ~middle
    if np.any(near):
        R[near] = pair_blocks(r_hat[near], *near_contact_scalars(r[near]), factors)
    if np.any(middle):
        R[middle] = _mobility_table_resistance(r[middle], r_hat[middle], factors)
    if np.any(far):
        R[far] = pair_blocks(r_hat[far], *table_pair_scalars('JO', r[far]), factors)
    return R


def _mobility_table_resistance(r, r_hat, factors):
    mobility_factors = tuple(1.0 / f for f in factors)
    inverse = np.linalg.inv(pair_blocks(r_hat, *table_pair_scalars('WS', r), mobility_factors))
    return 0.5 * (inverse + np.swapaxes(inverse, 1, 2))  # exactly symmetric (the inverse is, to rounding)


def _pair_resistance_sup_smooth(r, r_hat, factors):
    """``(1 - w1) R_near + w1 (1 - w2) R_WS + w2 R_JO`` (w1, w2 the weights of the two windows)."""
    w1 = smooth_weight(r, SMOOTH_WINDOWS['near_contact'])
    w2 = smooth_weight(r, SMOOTH_WINDOWS['mobility_table'])
    R = np.zeros((r.shape[0], 12, 12))
    near, middle, far = w1 < 1, (w1 > 0) & (w2 < 1), w2 > 0
    if np.any(near):
        R[near] += (1.0 - w1[near])[:, None, None] * pair_blocks(r_hat[near], *near_contact_scalars(r[near]),
                                                                 factors)
    if np.any(middle):
        R[middle] += (w1[middle] * (1.0 - w2[middle]))[:, None, None] * _mobility_table_resistance(
            r[middle], r_hat[middle], factors)
    if np.any(far):
        R[far] += w2[far][:, None, None] * pair_blocks(r_hat[far], *table_pair_scalars('JO', r[far]), factors)
    return R


def pair_resistance_blob_model(r, r_hat, factors, firm_delta=DEFAULT_FIRM_DELTA):
    """Resistance R_MB of two single RPY blobs (the far-field model's own), (n, 12, 12), from
    ``res_scalars_MB_1.txt`` (gap clamp, linear interpolation, edge rows outside the table)."""
    r = clamp_gap(r, 2.0, firm_delta)
    return pair_blocks(r_hat, *table_pair_scalars('MB', r), factors)


# ------------------------------------------------------------------------------------------- wall blocks
def wall_blocks(scalars, factors):
    """6 x 6 wall blocks ``[F T] = R [U W]`` from wall-part resistance scalars, one per sphere.

    scalars : (n, 5) columns ``X^a - 1, Y^a - 1, Y^b, X^c - 4/3, Y^c - 4/3`` (bulk already subtracted);
    factors : (f0, f1, f2).  Returns (n, 6, 6) in the published layout (wall normal along z).
    """
    f0, f1, f2 = factors
    s = np.asarray(scalars, dtype=float)
    R = np.zeros((s.shape[0], 6, 6))
    R[:, 0, 0] = R[:, 1, 1] = f0 * s[:, 1]
    R[:, 2, 2] = f0 * s[:, 0]
    R[:, 0, 4] = R[:, 4, 0] = f1 * s[:, 2]
    R[:, 1, 3] = R[:, 3, 1] = -f1 * s[:, 2]
    R[:, 3, 3] = R[:, 4, 4] = f2 * s[:, 4]
    R[:, 5, 5] = f2 * s[:, 3]
    return R


def wall_scalars_sup(h, firm_delta=DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover):
    """Wall-part resistance scalars of a resolved sphere at heights h (n,) (units of a): (n, 5).

    Columns ``X^a - 1, Y^a - 1, Y^b, max(X^c - 4/3, 0), max(Y^c - 4/3, 0)`` (normalised).  Away from the
    wall: the 2562-blob mobility table (``mob_scalars_wall_MB_2562_eig_thresh.txt``) interpolated and
    inverted analytically (``1/X^a``, ``Y^c / (Y^a Y^c - Y^b^2)``, ...); beyond its top, ``X^a = 1 - 9/(8h)``,
    ``Y^a = 1 - 9/(16h)``, ``Y^b = 0``, ``X^c = Y^c = 3/4``; below its bottom the first row.  Near the wall
    the published lubrication forms (Cox and Brenner 1967; Goldman, Cox and Brenner 1967) replace the
    table: X^a for h <= 1.1, Y^a for h <= 1.01, Y^b for h <= 1.1, X^c for h <= 1.01, Y^c for h <= 1.1
    (``handover='smooth'``: blended across :data:`SMOOTH_WINDOWS` ``wall_near`` and ``wall_far``).
    """
    check_handover(handover)
    h = clamp_gap(h, 1.0, firm_delta)
    eps = h - 1.0
    table = tables.wall_table('sup')
    mob, _, above = tables.interpolate(table.x, table.scalars, h)
    if np.any(above):
        mob[above] = np.stack((1.0 - (9.0 / 8.0) / h[above], 1.0 - (9.0 / 16.0) / h[above],
                               np.zeros(np.count_nonzero(above)), np.full(np.count_nonzero(above), 0.75),
                               np.full(np.count_nonzero(above), 0.75)), axis=1)
    Xa, Ya, Yb, Xc, Yc = mob.T
    denominator = Ya * Yc - Yb * Yb
    with np.errstate(divide='ignore', invalid='ignore'):
        log_eps = np.log(eps)
    near_normal = 1.0 / eps - 0.2 * log_eps + 0.971280
    near_parallel = -(8.0 / 15.0) * log_eps + 0.9588
    near_coupling = (4.0 / 3.0) * ((0.1 * log_eps + 0.1895) - 0.4576 * eps)
    near_normal_rotation = (4.0 / 3.0) * (ZETA_3 - 3.0 * (np.pi * np.pi / 6.0 - 1.0) * eps)
    near_parallel_rotation = (4.0 / 3.0) * (-0.4 * log_eps + 0.3817 + 1.4578 * eps)
    if handover == 'smooth':
        w_near, w_far = smooth_weight(h, SMOOTH_WINDOWS['wall_near']), smooth_weight(h, SMOOTH_WINDOWS['wall_far'])
        RXa = (1.0 - w_far) * near_normal + w_far * (1.0 / Xa)
        RYa = (1.0 - w_near) * near_parallel + w_near * (Yc / denominator)
        RYb = (1.0 - w_far) * near_coupling + w_far * (-Yb / denominator)
        RXc = (1.0 - w_near) * near_normal_rotation + w_near * (1.0 / Xc)
        RYc = (1.0 - w_far) * near_parallel_rotation + w_far * (Ya / denominator)
    else:
        RXa = np.where(h > WALL_NORMAL_END, 1.0 / Xa, near_normal)
        RYa = np.where(h > WALL_PARALLEL_END, Yc / denominator, near_parallel)
        RYb = np.where(h > WALL_COUPLING_END, -Yb / denominator, near_coupling)
        RXc = np.where(h > WALL_NORMAL_ROTATION_END, 1.0 / Xc, near_normal_rotation)
        RYc = np.where(h > WALL_PARALLEL_ROTATION_END, Ya / denominator, near_parallel_rotation)
    return np.stack((RXa - 1.0, RYa - 1.0, RYb, np.maximum(RXc - 4.0 / 3.0, 0.0),
                     np.maximum(RYc - 4.0 / 3.0, 0.0)), axis=1)


def wall_scalars_blob_model(h, firm_delta=DEFAULT_FIRM_DELTA):
    """Wall-part resistance scalars of one RPB blob at heights h (n,): (n, 5), columns as
    :func:`wall_scalars_sup` (no clip).  Table ``res_scalars_wall_MB.txt``; beyond its top
    ``X^a = 1/(1 - 9/(8h))``, ``Y^a = 1/(1 - 9/(16h))``, ``Y^b = 0``, ``X^c = Y^c = 4/3``."""
    h = clamp_gap(h, 1.0, firm_delta)
    table = tables.wall_table('MB')
    res, _, above = tables.interpolate(table.x, table.scalars, h)
    if np.any(above):
        n = np.count_nonzero(above)
        res[above] = np.stack((1.0 / (1.0 - (9.0 / 8.0) / h[above]), 1.0 / (1.0 - (9.0 / 16.0) / h[above]),
                               np.zeros(n), np.full(n, 1.0 / 0.75), np.full(n, 1.0 / 0.75)), axis=1)
    Xa, Ya, Yb, Xc, Yc = res.T
    return np.stack((Xa - 1.0, Ya - 1.0, Yb, Xc - 4.0 / 3.0, Yc - 4.0 / 3.0), axis=1)


def wall_resistance_sup(h, factors, firm_delta=DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover):
    """Wall part of the resolved sphere's resistance at heights h (n,): (n, 6, 6) (:func:`wall_scalars_sup`)."""
    return wall_blocks(wall_scalars_sup(h, firm_delta, handover), factors)


def wall_resistance_blob_model(h, factors, firm_delta=DEFAULT_FIRM_DELTA):
    """Wall part of one RPB blob's resistance at heights h (n,): (n, 6, 6) (:func:`wall_scalars_blob_model`)."""
    return wall_blocks(wall_scalars_blob_model(h, firm_delta), factors)
