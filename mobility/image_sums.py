"""Pseudo-periodic blob products with any number of rings of images, and their truly periodic limit above a wall.

The package's direct products with ``periodic_length Lx Ly 0`` are the published pseudo-periodic sums: each
target sees every source at its minimum image and at the eight images around it (one ring).  Here the ring
count is a parameter: with ``rings = n`` a source is summed at the minimum image ``d`` and at ``d + (i Lx, j Ly,
0)`` for ``|i|, |j| <= n``, ``(2n + 1)^2`` images, with the same pair formulas (``mobility.pair_formulas``: the
Rotne-Prager-Yamakawa blob and, above the wall, the Rotne-Prager-Blake corrections of Swan and Brady, the wall
regularisation of blobs closer than a radius).  ``rings = 1`` is the package's pseudo-periodic product (equal to
round-off, tested).

Above a no-slip wall the far field of a point force or torque decays like ``1/rho^3`` along the wall, so the
image sum converges absolutely to the truly periodic mobility of the same blobs; the images beyond ring ``n``
(farther than about ``n L``) contribute ``c_1/n + O(1/n^2)`` (their integral over the plane outside the square).
:func:`periodic_limit` extrapolates the partial sums at ``n/2`` and ``n`` (Richardson, first order) and
estimates the remaining error from the same extrapolation one level coarser.  In free space (and above a
free-slip surface) the Stokeslet decays like ``1/rho`` and the ring sums diverge: no limit is offered there.

Products are of a subset of target blobs (``targets``: indices) from every source blob, vectorised over
(targets x sources) blocks of at most :data:`PAIRS_PER_BLOCK` pairs, so memory stays bounded.  Cost: targets x
sources x (2n + 1)^2 pair evaluations per coupling.

Shapes and units: ``r_vectors`` (N, 3) lengths; ``forces``, ``torques`` (N, 3); velocities (T, 3) in
length/time, angular velocities (T, 3) in 1/time (viscosity ``eta``, blob radius ``a``).
"""
import numpy as np

from . import pair_formulas as pf
from .periodic import wall_regularisation, wrap_axis

PAIRS_PER_BLOCK = 1 << 17
# coupling -> (pair function, power of the blob radius in the unit 1/(8 pi eta a^p), source vector, output)
COUPLINGS = {'trans_times_force': (pf.trans_times_force_pairs, 1, 'forces', 'U'),
             'rot_times_force': (pf.rot_times_force_pairs, 2, 'forces', 'W'),
             'trans_times_torque': (pf.trans_times_torque_pairs, 2, 'torques', 'U'),
             'rot_times_torque': (pf.rot_times_torque_pairs, 3, 'torques', 'W')}


def ring_shifts(n):
    """Integer image offsets (m, 2) of ring ``n``: the (i, j) with ``max(|i|, |j|) == n`` (ring 0: (0, 0))."""
    if n == 0:
        return np.zeros((1, 2), dtype=int)
    k = np.arange(-n, n + 1)
    i, j = np.meshgrid(k, k, indexing='ij')
    on_ring = np.maximum(np.abs(i), np.abs(j)) == n
    return np.column_stack([i[on_ring], j[on_ring]])


def ring_sums(r_vectors, eta, a, periodic_length, rings, forces=None, torques=None, targets=None, wall=True,
              rotation=False):
    """Partial image sums of the blob products at every ring count in ``rings``.

    r_vectors : (N, 3) blob positions; eta : viscosity; a : blob radius (one for all blobs);
    periodic_length : (Lx, Ly, Lz) with Lx, Ly > 0 and Lz = 0 (the images are in x and y);
    rings : ring counts n >= 1 (e.g. (1, 2, 3, 8, 16)); forces, torques : (N, 3) or None (zero);
    targets : indices (T,) of the target blobs (default all), or target positions (T, 3) (blobs of radius ``a``
    that carry no force); wall : the Rotne-Prager-Blake products above the
    wall at z = 0 (False: free-space Rotne-Prager-Yamakawa, whose ring sums diverge: ring counts small only);
    rotation : also the angular velocities.

    Returns ``{n: (U (T, 3), W (T, 3) or None)}``: the velocities summed over the images of rings 0..n.
    The torque couplings need ``rotation`` or torques (as the products of rollers).
    """
    r = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    if not (L[0] > 0 and L[1] > 0) or L[2] != 0:
        raise ValueError('ring sums need periodic_length Lx Ly 0 with Lx, Ly > 0, got %s' % (L,))
    rings = sorted({int(n) for n in rings})
    if not rings or rings[0] < 1:
        raise ValueError('ring counts must be >= 1, got %s' % (rings,))
    a = float(a)
    n_blobs = r.shape[0]
    if targets is not None and np.ndim(targets) == 2:       # positions of their own
        r = np.concatenate([r, np.asarray(targets, dtype=float).reshape(-1, 3)])
        targets = np.arange(n_blobs, r.shape[0])
    else:
        targets = np.arange(n_blobs) if targets is None else np.asarray(targets, dtype=int).reshape(-1)
    vectors = {'forces': None if forces is None else np.asarray(forces, dtype=float).reshape(n_blobs, 3),
               'torques': None if torques is None else np.asarray(torques, dtype=float).reshape(n_blobs, 3)}
    if wall:
        z_eff, damping = wall_regularisation(r[:, 2], a)
    else:
        z_eff, damping = r[:, 2], np.ones(r.shape[0])
    scaled = np.column_stack([r[:, 0], r[:, 1], z_eff]) / a
    damping_targets = damping[targets]
    t = scaled[targets]
    scaled, damping = scaled[:n_blobs], damping[:n_blobs]
    Lx, Ly = L[0] / a, L[1] / a
    kinds = [kind for kind, (_, _, source, output) in COUPLINGS.items()
             if vectors[source] is not None and (output == 'U' or rotation)]
    damped = {name: None if v is None else v * damping[:, None] for name, v in vectors.items()}
    totals = {'U': np.zeros((targets.size, 3)), 'W': np.zeros((targets.size, 3)) if rotation else None}
    out = {}
    sources_per_block = max(1, PAIRS_PER_BLOCK // max(1, targets.size))
    for n in range(rings[-1] + 1):
        shifts = ring_shifts(n)
        for start in range(0, n_blobs, sources_per_block):
            s = scaled[start:start + sources_per_block]
            # images of one group side by side along the source axis: (targets, images x sources)
            group = max(1, PAIRS_PER_BLOCK // max(1, targets.size * s.shape[0]))
            dx = wrap_axis(t[:, 0:1] - s[None, :, 0], Lx)
            dy = wrap_axis(t[:, 1:2] - s[None, :, 1], Ly)
            for first in range(0, len(shifts), group):
                ij = shifts[first:first + group]
                images = ij.shape[0]
                rx = (dx[:, None, :] + (ij[:, 0] * Lx)[None, :, None]).reshape(targets.size, -1)
                ry = (dy[:, None, :] + (ij[:, 1] * Ly)[None, :, None]).reshape(targets.size, -1)
                rz = np.tile(t[:, 2:3] - s[None, :, 2], (1, images))
                zt, zs = t[:, 2:3], np.tile(s[:, 2], images)[None, :]
                for kind in kinds:
                    pair, power, source, output = COUPLINGS[kind]
                    v = np.tile(damped[source][start:start + sources_per_block], (images, 1))
                    ux, uy, uz = pair(rx, ry, rz, zt, zs, v[None, :, 0], v[None, :, 1], v[None, :, 2], wall=wall)
                    scale = 1.0 / (8.0 * np.pi * eta * a ** power)
                    totals[output][:, 0] += scale * ux
                    totals[output][:, 1] += scale * uy
                    totals[output][:, 2] += scale * uz
        if n in rings:
            d = damping_targets[:, None]
            out[n] = (totals['U'] * d, None if totals['W'] is None else totals['W'] * d)
    return out


def tiled_velocities(mobility, r_vectors, forces, periodic_length, rings, targets=None):
    """Partial image sums of ``M_UF f`` over whole tiles of the box, through a source-target product.

    mobility : a ``mobility.interface.BlobMobility`` above the wall without periodic images (its
    ``source_target``, e.g. the C++ backend's, compiled: about 30 times the speed of :func:`ring_sums`);
    r_vectors, forces : (N, 3); periodic_length : (Lx, Ly, 0); rings : ring counts n >= 1; targets : indices
    (T,) (default all).

    The blobs are wrapped into the box and every source is summed at its tiles ``(i Lx, j Ly)``, ``|i|, |j| <=
    n``, around the box (not around each target's minimum image, as the published sums and :func:`ring_sums`
    do): the partial sums differ from :func:`ring_sums` at each n by images of the outermost ring, and both
    converge to the same periodic limit (:func:`periodic_limit`).  Returns ``{n: (U (T, 3), None)}``.
    """
    r = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    f = np.asarray(forces, dtype=float).reshape(-1, 3)
    L = np.asarray(periodic_length, dtype=float).reshape(3)
    if not (L[0] > 0 and L[1] > 0) or L[2] != 0:
        raise ValueError('tiled sums need periodic_length Lx Ly 0 with Lx, Ly > 0, got %s' % (L,))
    rings = sorted({int(n) for n in rings})
    wrapped = r.copy()
    wrapped[:, :2] -= np.floor(wrapped[:, :2] / L[:2]) * L[:2]
    targets = np.arange(r.shape[0]) if targets is None else np.asarray(targets, dtype=int).reshape(-1)
    target_positions = wrapped[targets]
    radius = mobility.blob_radius
    total = np.zeros((targets.size, 3))
    out = {}
    for n in range(rings[-1] + 1):
        shifts = ring_shifts(n) * L[:2]
        sources = (wrapped[None, :, :] + np.column_stack([shifts, np.zeros(len(shifts))])[:, None, :]).reshape(-1, 3)
        total += np.asarray(mobility.source_target(sources, target_positions, np.tile(f, (len(shifts), 1)), radius,
                                                   radius)).reshape(-1, 3)
        if n in rings:
            out[n] = (total.copy(), None)
    return out


def periodic_limit(sums):
    """The truly periodic limit of ring sums above a wall, by Richardson extrapolation in 1/n.

    sums : ``{n: (U, W)}`` of :func:`ring_sums` holding at least the ring counts n/4, n/2 and n of its largest
    n (a power of two times the smallest is simplest: e.g. 4, 8, 16).  With ``S(n) = S_inf + c/n + O(1/n^2)``
    the limit is ``2 S(n) - S(n/2)``; its error is estimated as the change of that extrapolation from the
    level below, ``|[2 S(n) - S(n/2)] - [2 S(n/2) - S(n/4)]|`` (relative, largest of U and W).

    Returns ``(U, W, estimated_error)``: U (T, 3), W (T, 3) or None, the relative error estimate (a float).
    """
    n = max(sums)
    if n % 4 or (n // 2) not in sums or (n // 4) not in sums:
        raise ValueError('periodic_limit needs the ring counts n/4, n/2 and n (got %s)' % sorted(sums))
    parts = []
    for index in (0, 1):
        if sums[n][index] is None:
            parts.append((None, 0.0))
            continue
        fine = 2.0 * sums[n][index] - sums[n // 2][index]
        coarse = 2.0 * sums[n // 2][index] - sums[n // 4][index]
        scale = np.linalg.norm(fine)
        parts.append((fine, float(np.linalg.norm(fine - coarse) / scale) if scale > 0 else 0.0))
    return parts[0][0], parts[1][0], max(parts[0][1], parts[1][1])


def relative_error(values, reference):
    """``|values - reference| / |reference|`` (Frobenius norms over all blobs and components; 0 for a zero
    reference and equal values)."""
    values, reference = np.asarray(values, dtype=float), np.asarray(reference, dtype=float)
    scale = np.linalg.norm(reference)
    difference = np.linalg.norm(values - reference)
    return float(difference / scale) if scale > 0 else (0.0 if difference == 0 else np.inf)
