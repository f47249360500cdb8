"""Blob-pair mobility formulas, vectorised over arrays of pairs (NumPy).

This module is the readable reference of every pair formula in the package;
the compiled backends (``cpp/blob_pair_kernels.h``, shared by C++ and CUDA)
implement the same equations and are tested against it.

Conventions (see SPEC.md §4.1, §5.2 and VALIDATION.md §1):

* ``rx, ry, rz``: target minus source, in units of the blob radius ``a``,
  arrays of any common (broadcastable) shape.
* ``zt, zs``: heights of target and source in units of ``a``, already raised
  to ``max(z, a)`` (the wall regularisation of Balboa, Delmotte and Donev
  2017); the wall image of the source sits at ``-zs``.
* Free-space Rotne-Prager-Yamakawa (RPY) terms come in units of
  ``1/(8 pi eta a)`` (trans-trans), ``1/(8 pi eta a^2)`` (rot-trans and
  trans-rot) and ``1/(8 pi eta a^3)`` (rot-rot).
* Wall corrections are those of Swan and Brady, Phys. Fluids 19, 113306
  (2007), appendices B and C, in the same units, with the right-handed sign
  of the rotation-translation coupling (a sphere pushed along a wall rolls
  on it).

Every function is branch-free: the self term ``r = 0`` is the generic
formula with a zero reciprocal distance, and the wall self term is the
generic wall pair formula evaluated at ``r_x = r_y = 0`` (the two agree
exactly), so distinct blobs at the same point are finite too.
"""
import numpy as np


def _safe_reciprocal_distance(r2):
    """1/sqrt(r2) where r2 > 0, and 0 where r2 == 0 (same shape as r2)."""
    with np.errstate(divide='ignore'):
        inv = 1.0 / np.sqrt(r2)
    inv[r2 == 0.0] = 0.0
    return inv


def rpy_trans_trans(rx, ry, rz):
    """Free RPY trans-trans coefficients: M = c_iso I + c_rr r r^T.

    Returns ``(c_iso, c_rr)`` in units of 1/(8 pi eta a); ``r r^T`` uses the
    unnormalised displacement (units of a).
    """
    r2 = rx * rx + ry * ry + rz * rz
    rinv = _safe_reciprocal_distance(r2)
    r = r2 * rinv
    rinv2 = rinv * rinv
    far = r >= 2.0
    c_iso = np.where(far, rinv * (1.0 + (2.0 / 3.0) * rinv2), (4.0 / 3.0) * (1.0 - (9.0 / 32.0) * r))
    c_rr = np.where(far, rinv * rinv2 * (1.0 - 2.0 * rinv2), 0.125 * rinv)
    return c_iso, c_rr


def wall_trans_trans(rx, ry, zt, zs):
    """Swan-Brady wall correction to trans-trans, units 1/(8 pi eta a).

    Returns ``(ex, ey, ez, f1, f2, f3, f4, f5)`` with
    ``dM_ab = f1 d_ab + f2 e_a e_b + f3 e_a d_bz + f4 d_az e_b + f5 d_az d_bz``
    where ``e`` is the unit vector from the image of the source to the target.
    """
    Rz = zt + zs
    R2 = rx * rx + ry * ry + Rz * Rz
    Rinv = 1.0 / np.sqrt(R2)
    Rinv3 = Rinv * Rinv * Rinv
    Rinv5 = Rinv3 * Rinv * Rinv
    ex, ey, ez = rx * Rinv, ry * Rinv, Rz * Rinv
    ez2 = ez * ez
    hh = zs / Rz
    f1 = -(3.0 * (1.0 + 2.0 * hh * (1.0 - hh) * ez2) * Rinv
           + 2.0 * (1.0 - 3.0 * ez2) * Rinv3 - 2.0 * (1.0 - 5.0 * ez2) * Rinv5) / 3.0
    f2 = -(3.0 * (1.0 - 6.0 * hh * (1.0 - hh) * ez2) * Rinv
           - 6.0 * (1.0 - 5.0 * ez2) * Rinv3 + 10.0 * (1.0 - 7.0 * ez2) * Rinv5) / 3.0
    f3 = (2.0 / 3.0) * ez * (3.0 * hh * (1.0 - 6.0 * (1.0 - hh) * ez2) * Rinv
                             - 6.0 * (1.0 - 5.0 * ez2) * Rinv3 + 10.0 * (2.0 - 7.0 * ez2) * Rinv5)
    f4 = (2.0 / 3.0) * ez * (3.0 * hh * Rinv - 10.0 * Rinv5)
    f5 = -(4.0 / 3.0) * (3.0 * hh * hh * ez2 * Rinv + 3.0 * ez2 * Rinv3 + (2.0 - 15.0 * ez2) * Rinv5)
    return ex, ey, ez, f1, f2, f3, f4, f5


def rpy_rot_trans(rx, ry, rz):
    """Free RPY rot-trans coefficient c: omega_i = c (F_j x r), units 1/(8 pi eta a^2)."""
    r2 = rx * rx + ry * ry + rz * rz
    rinv = _safe_reciprocal_distance(r2)
    r = r2 * rinv
    return np.where(r >= 2.0, rinv * rinv * rinv, 0.5 * (1.0 - 0.375 * r))


def wall_rot_trans(rx, ry, zt, zs):
    """Wall correction to rot-trans (omega_i from F_j), units 1/(8 pi eta a^2).

    Returns ``(ex, ey, ez, k1, k2, k3, k4)`` with
    ``omega = -k1 (F x e) - (k2 F_z + k3 e.F) (z x e) - k4 (F_y, -F_x, 0)``.
    """
    Rz = zt + zs
    R2 = rx * rx + ry * ry + Rz * Rz
    Rinv = 1.0 / np.sqrt(R2)
    Rinv2 = Rinv * Rinv
    Rinv4 = Rinv2 * Rinv2
    ex, ey, ez = rx * Rinv, ry * Rinv, Rz * Rinv
    ez2 = ez * ez
    hh = zs / Rz
    k1 = Rinv2
    k2 = 2.0 * (6.0 * hh * ez2 * Rinv2 + (1.0 - 10.0 * ez2) * Rinv4)
    k3 = -2.0 * ez * (3.0 * hh * Rinv2 - 5.0 * Rinv4)
    k4 = -2.0 * ez * (hh * Rinv2 - Rinv4)
    return ex, ey, ez, k1, k2, k3, k4


def rpy_rot_rot(rx, ry, rz):
    """Free RPY rot-rot coefficients: M = d_iso I + d_rr r r^T, units 1/(8 pi eta a^3)."""
    r2 = rx * rx + ry * ry + rz * rz
    rinv = _safe_reciprocal_distance(r2)
    r = r2 * rinv
    rinv2 = rinv * rinv
    far = r >= 2.0
    d_iso = np.where(far, -0.5 * rinv * rinv2, 1.0 - (27.0 / 32.0) * r + (5.0 / 64.0) * r * r2)
    d_rr = np.where(far, 1.5 * rinv * rinv2 * rinv2, (9.0 / 32.0) * rinv - (3.0 / 64.0) * r)
    return d_iso, d_rr


def wall_rot_rot(rx, ry, zt, zs):
    """Wall correction to rot-rot, units 1/(8 pi eta a^3).

    Returns ``(ex, ey, ez, g)`` with ``dM = g [ (1 - 6 e_z^2)/2 I - (3/2) e e^T
    + 3 e_z z e^T + 3 (z x e)(z x e)^T ]``, ``g = 1/|R|^3``.
    """
    Rz = zt + zs
    R2 = rx * rx + ry * ry + Rz * Rz
    Rinv = 1.0 / np.sqrt(R2)
    return rx * Rinv, ry * Rinv, Rz * Rinv, Rinv * Rinv * Rinv


# ---------------------------------------------------------------------------
# Products: each returns the sum over the last axis (sources) of the pair
# blocks applied to the source vectors (vx, vy, vz broadcast against r).

def trans_times_force_pairs(rx, ry, rz, zt, zs, fx, fy, fz, wall):
    """Velocity (units 1/(8 pi eta a)) from forces; arrays (targets, sources)."""
    c_iso, c_rr = rpy_trans_trans(rx, ry, rz)
    rf = c_rr * (rx * fx + ry * fy + rz * fz)
    ux = c_iso * fx + rf * rx
    uy = c_iso * fy + rf * ry
    uz = c_iso * fz + rf * rz
    if wall:
        ex, ey, ez, f1, f2, f3, f4, f5 = wall_trans_trans(rx, ry, zt, zs)
        ef = ex * fx + ey * fy + ez * fz
        along_e = f2 * ef + f3 * fz
        ux += f1 * fx + along_e * ex
        uy += f1 * fy + along_e * ey
        uz += f1 * fz + along_e * ez + f4 * ef + f5 * fz
    return ux.sum(axis=-1), uy.sum(axis=-1), uz.sum(axis=-1)


def rot_times_force_pairs(rx, ry, rz, zt, zs, fx, fy, fz, wall):
    """Angular velocity (units 1/(8 pi eta a^2)) of targets from source forces."""
    c = rpy_rot_trans(rx, ry, rz)
    wx = c * (fy * rz - fz * ry)
    wy = c * (fz * rx - fx * rz)
    wz = c * (fx * ry - fy * rx)
    if wall:
        ex, ey, ez, k1, k2, k3, k4 = wall_rot_trans(rx, ry, zt, zs)
        along_zxe = k2 * fz + k3 * (ex * fx + ey * fy + ez * fz)
        wx -= k1 * (fy * ez - fz * ey) - along_zxe * ey + k4 * fy
        wy -= k1 * (fz * ex - fx * ez) + along_zxe * ex - k4 * fx
        wz -= k1 * (fx * ey - fy * ex)
    return wx.sum(axis=-1), wy.sum(axis=-1), wz.sum(axis=-1)


def trans_times_torque_pairs(rx, ry, rz, zt, zs, tx, ty, tz, wall):
    """Velocity (units 1/(8 pi eta a^2)) of targets from source torques.

    The block is the transpose of the rot-trans block with target and source
    exchanged (the grand mobility is symmetric): the geometry is taken from
    the source's point of view, ``r' = -r`` and heights swapped.
    """
    c = rpy_rot_trans(rx, ry, rz)
    ux = c * (ty * rz - tz * ry)
    uy = c * (tz * rx - tx * rz)
    uz = c * (tx * ry - ty * rx)
    if wall:
        ex, ey, ez, k1, k2, k3, k4 = wall_rot_trans(-rx, -ry, zs, zt)
        zxe_t = -ey * tx + ex * ty
        ux += k1 * (ty * ez - tz * ey) - k3 * zxe_t * ex + k4 * ty
        uy += k1 * (tz * ex - tx * ez) - k3 * zxe_t * ey - k4 * tx
        uz += k1 * (tx * ey - ty * ex) - (k2 + k3 * ez) * zxe_t
    return ux.sum(axis=-1), uy.sum(axis=-1), uz.sum(axis=-1)


def rot_times_torque_pairs(rx, ry, rz, zt, zs, tx, ty, tz, wall):
    """Angular velocity (units 1/(8 pi eta a^3)) of targets from source torques."""
    d_iso, d_rr = rpy_rot_rot(rx, ry, rz)
    rt = d_rr * (rx * tx + ry * ty + rz * tz)
    wx = d_iso * tx + rt * rx
    wy = d_iso * ty + rt * ry
    wz = d_iso * tz + rt * rz
    if wall:
        ex, ey, ez, g = wall_rot_rot(rx, ry, zt, zs)
        et = ex * tx + ey * ty + ez * tz
        zxe_t = -ey * tx + ex * ty
        iso = 0.5 * (1.0 - 6.0 * ez * ez)
        wx += g * (iso * tx - 1.5 * et * ex - 3.0 * zxe_t * ey)
        wy += g * (iso * ty - 1.5 * et * ey + 3.0 * zxe_t * ex)
        wz += g * (iso * tz - 1.5 * et * ez + 3.0 * ez * et)
    return wx.sum(axis=-1), wy.sum(axis=-1), wz.sum(axis=-1)


def unequal_rpy_coefficients(r2, bt, as_):
    """Free RPY tensor of a target of radius ``bt`` and a source of radius ``as_`` at squared distance ``r2``.

    Zuk, Wajnryb, Mizerski and Szymczak, J. Fluid Mech. 741, R5 (2014):
    ``M = c_iso I + c_rr r r^T`` in units of 1/(8 pi eta) (physical lengths),
    with the far (``r >= bt + as_``), overlap and containment
    (``r <= |bt - as_|``) branches.  Equal radii give the standard RPY tensor.
    Arrays broadcast; returns ``(c_iso, c_rr)``.
    """
    r2 = np.asarray(r2, dtype=float)
    rinv = _safe_reciprocal_distance(np.array(r2, copy=True))
    r = r2 * rinv
    rinv2 = rinv * rinv
    sum_sq = bt * bt + as_ * as_
    diff = bt - as_
    far = r >= bt + as_
    contained = r <= np.abs(diff)
    with np.errstate(divide='ignore', invalid='ignore'):
        # far field, 1/(8 pi eta) units: [(1 + s/(3r^2)) I + (1 - s/r^2) rr/r^2] / r
        far_iso = rinv * (1.0 + sum_sq * rinv2 / 3.0)
        far_rr = rinv * rinv2 * (1.0 - sum_sq * rinv2)
        # overlapping spheres; 1/(6 pi eta b a) = (4/3)/(8 pi eta b a)
        pref = (4.0 / 3.0) / (bt * as_)
        rinv3 = rinv2 * rinv
        lap_iso = pref * (16.0 * (bt + as_) * r * r2 - (diff * diff + 3.0 * r2) ** 2) * rinv3 / 32.0
        lap_rr = pref * 3.0 * (diff * diff - r2) ** 2 * rinv3 * rinv2 / 32.0
        # one sphere inside the other: 1/(6 pi eta max(b, a))
        in_iso = (4.0 / 3.0) / np.maximum(bt, as_)
    c_iso = np.where(far, far_iso, np.where(contained, in_iso, lap_iso))
    c_rr = np.where(far | contained, np.where(far, far_rr, 0.0), lap_rr)
    return c_iso, c_rr


def trans_times_force_unequal_radii_pairs(rx, ry, rz, zt, zs, bt, as_, fx, fy, fz, wall):
    """Velocity of targets of radius ``bt`` from forces on sources of radius ``as_``.

    Physical units (no scaling by a): positions, radii and heights as they
    are, heights already raised to ``max(z, radius)``.  Result in units of
    1/(8 pi eta).  Free part: the RPY tensor for unequal spheres of Zuk,
    Wajnryb, Mizerski and Szymczak, J. Fluid Mech. 741, R5 (2014), with its
    overlap and containment branches.  Wall part: the Rotne-Prager-Blake
    image system with Faxen corrections for the two radii (Swan and Brady
    2007, generalised to unequal radii as in the published code).
    """
    c_iso, c_rr = unequal_rpy_coefficients(rx * rx + ry * ry + rz * rz, bt, as_)
    rf = c_rr * (rx * fx + ry * fy + rz * fz)
    ux = c_iso * fx + rf * rx
    uy = c_iso * fy + rf * ry
    uz = c_iso * fz + rf * rz
    if wall:
        wx, wy, wz = _wall_unequal_radii_apply(rx, ry, zt, zs, bt, as_, fx, fy, fz)
        ux = ux + wx
        uy = uy + wy
        uz = uz + wz
    return ux.sum(axis=-1), uy.sum(axis=-1), uz.sum(axis=-1)


def _wall_unequal_radii_apply(rx, ry, zt, zs, bt, as_, fx, fy, fz):
    """Image-system correction for unequal radii, applied to f; units 1/(8 pi eta).

    With R = target - image(source) = (r_x, r_y, zt + zs), x3 = zt, y3 = zs,
    J = z z^T and P = diag(1, 1, -1), the block is -W P with
    W = [(1 + s/3R^2) I + (1 - s/R^2) RR/R^2]/R
        + 2[-J/R - x3 R z^T/R^3 - y3 z R^T/R^3 + x3 y3 (I/R^3 - 3 RR/R^5)]
        + (2b^2/3)[-J/R^3 + 3 Rz R z^T/R^5 - y3 (3 Rz I/R^5 + 3 z R^T/R^5 + 3 R z^T/R^5 - 15 Rz RR/R^7)]
        + (2a^2/3)[-J/R^3 + 3 Rz z R^T/R^5 - x3 (3 Rz I/R^5 + 3 z R^T/R^5 + 3 R z^T/R^5 - 15 Rz RR/R^7)]
        + (2a^2b^2/3)[-I/R^5 + 5 Rz^2 I/R^7 - 2J/R^5 + 10 Rz (z R^T + R z^T)/R^7 + 5 RR/R^7 - 35 Rz^2 RR/R^9],
    s = a^2 + b^2 (b: target radius, a: source radius).
    """
    Rz = zt + zs
    R2 = rx * rx + ry * ry + Rz * Rz
    Rinv = 1.0 / np.sqrt(R2)
    Rinv2 = Rinv * Rinv
    Rinv3 = Rinv2 * Rinv
    Rinv5 = Rinv3 * Rinv2
    Rinv7 = Rinv5 * Rinv2
    Rinv9 = Rinv7 * Rinv2
    b2 = bt * bt
    a2 = as_ * as_
    s = a2 + b2
    # W = w_I I + w_RR R R^T + w_J J + w_Rz R z^T + w_zR z R^T
    w_I = (Rinv * (1.0 + s * Rinv2 / 3.0) + 2.0 * zt * zs * Rinv3
           - (2.0 * b2 / 3.0) * zs * 3.0 * Rz * Rinv5 - (2.0 * a2 / 3.0) * zt * 3.0 * Rz * Rinv5
           + (2.0 * a2 * b2 / 3.0) * (-Rinv5 + 5.0 * Rz * Rz * Rinv7))
    w_RR = (Rinv3 * (1.0 - s * Rinv2) - 6.0 * zt * zs * Rinv5
            + (2.0 * b2 / 3.0) * zs * 15.0 * Rz * Rinv7 + (2.0 * a2 / 3.0) * zt * 15.0 * Rz * Rinv7
            + (2.0 * a2 * b2 / 3.0) * (5.0 * Rinv7 - 35.0 * Rz * Rz * Rinv9))
    w_J = -2.0 * Rinv - (2.0 * b2 / 3.0) * Rinv3 - (2.0 * a2 / 3.0) * Rinv3 - (4.0 * a2 * b2 / 3.0) * Rinv5
    w_Rz = (-2.0 * zt * Rinv3 + (2.0 * b2 / 3.0) * (3.0 * Rz * Rinv5 - 3.0 * zs * Rinv5)
            - (2.0 * a2 / 3.0) * zt * 3.0 * Rinv5 + (2.0 * a2 * b2 / 3.0) * 10.0 * Rz * Rinv7)
    w_zR = (-2.0 * zs * Rinv3 - (2.0 * b2 / 3.0) * zs * 3.0 * Rinv5
            + (2.0 * a2 / 3.0) * (3.0 * Rz * Rinv5 - 3.0 * zt * Rinv5) + (2.0 * a2 * b2 / 3.0) * 10.0 * Rz * Rinv7)
    # velocity = -W P f, with P f = (fx, fy, -fz)
    gz = -fz
    Rg = rx * fx + ry * fy + Rz * gz
    ux = -(w_I * fx + w_RR * Rg * rx + w_Rz * gz * rx)
    uy = -(w_I * fy + w_RR * Rg * ry + w_Rz * gz * ry)
    uz = -(w_I * gz + w_RR * Rg * Rz + w_J * gz + w_Rz * gz * Rz + w_zR * Rg)
    return ux, uy, uz


def free_surface_trans_times_force_pairs(rx, ry, rz, zt, zs, fx, fy, fz):
    """Velocity (units 1/(8 pi eta a)) above a free-slip surface at z = 0, one radius (units of a).

    The RPY tensor of the pair plus that of the target and the mirror image
    of the source (``R = (rx, ry, zt + zs)``) applied to the mirrored force
    ``(fx, fy, -fz)``; heights not regularised.  Arrays (targets, sources).
    """
    ux, uy, uz = _rpy_apply(*rpy_trans_trans(rx, ry, rz), rx, ry, rz, fx, fy, fz)
    Rz = zt + zs
    wx, wy, wz = _rpy_apply(*rpy_trans_trans(rx, ry, Rz), rx, ry, Rz, fx, fy, -fz)
    return (ux + wx).sum(axis=-1), (uy + wy).sum(axis=-1), (uz + wz).sum(axis=-1)


def free_surface_unequal_radii_pairs(rx, ry, rz, zt, zs, bt, as_, fx, fy, fz):
    """As :func:`free_surface_trans_times_force_pairs` with radii ``bt`` (targets) and ``as_`` (sources).

    Physical units, result in units of 1/(8 pi eta); the free RPY tensor of
    :func:`unequal_rpy_coefficients` for the pair and for the mirror image.
    """
    ux, uy, uz = _rpy_apply(*unequal_rpy_coefficients(rx * rx + ry * ry + rz * rz, bt, as_), rx, ry, rz, fx, fy, fz)
    Rz = zt + zs
    wx, wy, wz = _rpy_apply(*unequal_rpy_coefficients(rx * rx + ry * ry + Rz * Rz, bt, as_), rx, ry, Rz,
                            fx, fy, -fz)
    return (ux + wx).sum(axis=-1), (uy + wy).sum(axis=-1), (uz + wz).sum(axis=-1)


def _rpy_apply(c_iso, c_rr, rx, ry, rz, fx, fy, fz):
    """``(c_iso I + c_rr r r^T) f`` per pair (no sum)."""
    rf = c_rr * (rx * fx + ry * fy + rz * fz)
    return c_iso * fx + rf * rx, c_iso * fy + rf * ry, c_iso * fz + rf * rz


def wall_regularisation(z, radius, xp=np):
    """Raised heights and damping factors of blobs near the wall.

    ``z`` (...,) heights, ``radius`` (scalar or (...,)) blob radii, same length
    unit; ``xp`` the array module (numpy or cupy).  Returns ``(z_eff, damping)``
    of the shape of ``z``: ``z_eff = max(z, radius)``, ``damping = 1`` for
    ``z >= radius``, else ``z / radius`` (0 for a point blob, radius 0).
    """
    z = xp.asarray(z, dtype=xp.float64)
    radius = xp.asarray(radius, dtype=xp.float64)
    safe_radius = xp.where(radius > 0, radius, 1.0)
    damping = xp.where(z >= radius, 1.0, xp.where(radius > 0, z / safe_radius, 0.0))
    return xp.maximum(z, radius), damping
