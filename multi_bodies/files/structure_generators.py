"""Generators of the example rigid bodies, written as ``.vertex`` files.

* Icosahedral shells (spheres): the 12 vertices of an icosahedron, refined by
  repeated midpoint subdivision of its triangles with the new vertices pushed
  onto the sphere, giving 12, 42, 162, 642, 2562, ... blobs.  The blob
  radius is half the smallest distance between two blobs, and the shell is
  scaled so that its translational mobility far from walls (Rotne-Prager-
  Yamakawa blobs) is that of a sphere of hydrodynamic radius 1:
  ``mu_t = 1 / (6 pi eta)``.
* The boomerang of the manual: an apex at the origin and two straight arms
  along +x and +y with equally spaced blobs (15 blobs, spacing 0.3).
* A straight rod of equally spaced blobs along x, centred at the origin.
* The ``.Laplace`` file of a Janus sphere (reaction rate, emitting rate and
  surface mobility per hemisphere) and the ``.slip_length`` file of a sphere
  of uniform slip length, for a given ``.vertex`` file (doc/phoretic.md).
* A single blob at the origin (the body of the roller schemes), and
  ``.clones`` files of bodies on a square lattice at one height, all with the
  identity orientation.

Command line (run from the repository root or anywhere the package is
importable)::

    python -m multi_bodies.files.structure_generators shell --blobs 42 --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators shell --blobs 12 --shell-radius 1 --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators boomerang --arm-blobs 7 --spacing 0.3 --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators rod --blobs 10 --spacing 0.5 --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators blob --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators janus-laplace \\
        --vertex multi_bodies/Structures/shell_N_42_Rg_0_8912_Rh_1.vertex --emitting-front 1 --emitting-back 0 \\
        --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators slip-length \\
        --vertex multi_bodies/Structures/shell_N_162_Rg_0_9497_Rh_1.vertex --slip-length 1000 --output multi_bodies/Structures
    python -m multi_bodies.files.structure_generators lattice --nx 2 --ny 2 --spacing 5 --height 1 --name four_rollers --output multi_bodies/Structures

Each command prints the file it wrote and the blob radius to use with it.
"""
import argparse
import os
import sys

import numpy as np

if __package__ in (None, ''):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from body.geometry import smallest_distance  # noqa: E402,F401 (also the name users of this module import)
from multi_bodies.files.snapshots import write_clones_file  # noqa: E402
from multi_bodies.files.structure_files import write_vertex_file  # noqa: E402


def icosahedron_vertices():
    """Unit icosahedron with a vertex at the north pole, shape (12, 3).

    Order: north pole, upper ring (azimuths 72, 144, ..., 360 degrees),
    lower ring (azimuths 36 + 72 k degrees), south pole.
    """
    ring_z = 1.0 / np.sqrt(5.0)
    ring_rho = 2.0 / np.sqrt(5.0)
    upper = np.deg2rad(72.0 * np.arange(1, 6))
    lower = np.deg2rad(36.0 + 72.0 * np.arange(0, 5))
    vertices = [[0.0, 0.0, 1.0]]
    vertices += [[ring_rho * np.cos(t), ring_rho * np.sin(t), ring_z] for t in upper]
    vertices += [[ring_rho * np.cos(t), ring_rho * np.sin(t), -ring_z] for t in lower]
    vertices += [[0.0, 0.0, -1.0]]
    return np.array(vertices)


def _icosahedron_faces(vertices):
    """Triangles (index triples) of the icosahedron: triples of mutually nearest vertices."""
    dist = np.linalg.norm(vertices[:, None, :] - vertices[None, :, :], axis=2)
    edge = np.min(dist[dist > 0])
    adjacent = np.abs(dist - edge) < 1e-9 * edge
    faces = []
    n = vertices.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                if adjacent[i, j] and adjacent[j, k] and adjacent[i, k]:
                    faces.append((i, j, k))
    return faces


def icosahedral_shell(num_blobs):
    """Unit-radius shell of ``num_blobs`` points (12, 42, 162, 642, 2562, ...), shape (n, 3)."""
    valid = [12]
    while valid[-1] < num_blobs:
        valid.append(4 * valid[-1] - 6)
    if valid[-1] != num_blobs:
        raise ValueError('an icosahedral shell has 12, 42, 162, 642, 2562, ... blobs, not %d' % num_blobs)
    vertices = [tuple(v) for v in icosahedron_vertices()]
    faces = _icosahedron_faces(np.array(vertices))
    for _ in range(len(valid) - 1):
        midpoint_index = {}
        new_faces = []

        def midpoint(i, j):
            key = (min(i, j), max(i, j))
            if key not in midpoint_index:
                m = np.add(vertices[i], vertices[j])
                vertices.append(tuple(m / np.linalg.norm(m)))
                midpoint_index[key] = len(vertices) - 1
            return midpoint_index[key]

        for i, j, k in faces:
            ij, jk, ki = midpoint(i, j), midpoint(j, k), midpoint(k, i)
            new_faces += [(i, ij, ki), (j, jk, ij), (k, ki, jk), (ij, jk, ki)]
        faces = new_faces
    return np.array(vertices)


def bulk_translational_mobility(reference_blobs, blob_radius, eta=None):
    """Translational mobility of a rigid blob body far from walls (RPY blobs), ``trace(N_tt)/3``.

    The dense free-space mobility of the NumPy backend (``mobility.interface``); the body is tracked at the
    origin.  eta : None is the option table's ``eta``.
    """
    if eta is None:
        from multi_bodies.files.input_options import DEFAULTS
        eta = DEFAULTS.eta
    from body.body import K_matrices
    from mobility.interface import Geometry, make_mobility
    blobs = np.asarray(reference_blobs, dtype=float)
    M = make_mobility('python', Geometry('free_space'), eta, blob_radius).dense_matrix(blobs)
    K = K_matrices(blobs[None], np.zeros((1, 3)))[0]
    resistance = K.T @ np.linalg.solve(M, K)
    body_mobility = np.linalg.inv(resistance)
    return float(np.trace(body_mobility[:3, :3]) / 3.0)


def calibrated_shell(num_blobs):
    """Shell of hydrodynamic radius 1: returns (blobs shape (n, 3), blob_radius, shell_radius Rg).

    The blob radius is half the smallest blob distance; the shell radius is
    chosen so that the bulk translational mobility is ``1/(6 pi eta)``.  All
    lengths scale together, so the mobility of the unit shell gives the scale.
    """
    unit = icosahedral_shell(num_blobs)
    unit_blob_radius = 0.5 * smallest_distance(unit)
    mu_unit = bulk_translational_mobility(unit, unit_blob_radius)
    hydrodynamic_radius_unit = 1.0 / (6.0 * np.pi * mu_unit)
    scale = 1.0 / hydrodynamic_radius_unit
    return unit * scale, unit_blob_radius * scale, scale


def boomerang(arm_blobs=7, spacing=0.3):
    """Boomerang: apex at the origin, arms of ``arm_blobs`` blobs along +x and +y, shape (2 arm_blobs + 1, 3).

    Order as in the published file: x arm from the tip inwards, apex, y arm outwards.
    """
    steps = spacing * np.arange(arm_blobs, 0, -1)
    x_arm = np.column_stack((steps, np.zeros(arm_blobs), np.zeros(arm_blobs)))
    y_arm = np.column_stack((np.zeros(arm_blobs), steps[::-1], np.zeros(arm_blobs)))
    return np.concatenate((x_arm, [[0.0, 0.0, 0.0]], y_arm))


def rod(num_blobs, spacing):
    """Straight rod of ``num_blobs`` blobs along x, centred at the origin, shape (n, 3)."""
    x = spacing * (np.arange(num_blobs) - 0.5 * (num_blobs - 1))
    return np.column_stack((x, np.zeros(num_blobs), np.zeros(num_blobs)))


def lattice(nx, ny, spacing, height):
    """Body locations on an ``nx`` by ``ny`` square lattice centred above the origin at ``height``, shape (nx ny, 3).

    x runs fastest; the orientations to go with them are the identity quaternion.
    """
    x = spacing * (np.arange(nx) - 0.5 * (nx - 1))
    y = spacing * (np.arange(ny) - 0.5 * (ny - 1))
    yy, xx = np.meshgrid(y, x, indexing='ij')
    return np.column_stack((xx.ravel(), yy.ravel(), np.full(nx * ny, float(height))))


def squirmer_slip(blobs, B1=1.0, beta=0.0, axis=(1.0, 0.0, 0.0)):
    """Tangential slip of a squirmer on a shell of blobs (body frame), shape (n, 3).

    With ``n`` the unit vector from the centre to a blob and ``cos t = n . e``
    (``e`` the swimming axis): ``u = B1 (1 + beta cos t) (cos t n - e)``,
    i.e. ``B1 (1 + beta cos t) sin t`` along the polar direction, pushing the
    fluid backwards; in free space the sphere swims along ``e`` at ``2 B1 / 3``.
    """
    n = np.asarray(blobs, dtype=float)
    n = n / np.linalg.norm(n, axis=1)[:, None]
    e = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    cos_t = n @ e
    return (B1 * (1.0 + beta * cos_t))[:, None] * (cos_t[:, None] * n - e)


def _surface_normals_and_weights(blobs, weight_radius):
    """Normals ``r / |r_0|`` (n, 3) (unit only when every blob lies on one sphere about the origin, as
    published) and weights ``4 pi R_w^2 / n`` (n,) of body-frame blobs (n, 3)."""
    blobs = np.asarray(blobs, dtype=float).reshape(-1, 3)
    normals = blobs / np.linalg.norm(blobs[0])
    return normals, np.full(blobs.shape[0], 4.0 * np.pi * weight_radius ** 2 / blobs.shape[0])


def janus_laplace_table(blobs, front=(5.0, 0.0, 5.0), back=(5.0, 0.0, 5.0), weight_radius=1.0):
    """The ``.Laplace`` table (n, 7) of a Janus sphere: ``n k alpha mu w`` per blob (doc/phoretic.md).

    front, back : (reaction rate k, emitting rate alpha, surface mobility mu) of the blobs with body-frame
    z > 0 and z < 0; blobs at z = 0 get the average.  Normals and weights as
    :func:`_surface_normals_and_weights` (the published create_laplace_file_janus_sphere.py; its defaults).
    """
    blobs = np.asarray(blobs, dtype=float).reshape(-1, 3)
    normals, weights = _surface_normals_and_weights(blobs, weight_radius)
    front, back = np.asarray(front, dtype=float), np.asarray(back, dtype=float)
    values = np.where(blobs[:, 2:3] > 0, front, np.where(blobs[:, 2:3] < 0, back, 0.5 * (front + back)))
    return np.column_stack((normals, values, weights))


def slip_length_table(blobs, slip_length, weight_radius=1.0):
    """The ``.slip_length`` table (n, 5) of a sphere of uniform slip length: ``n l w`` per blob (doc/phoretic.md).

    Normals and weights as :func:`_surface_normals_and_weights` (the published create_slip_length_file.py).
    """
    normals, weights = _surface_normals_and_weights(blobs, weight_radius)
    return np.column_stack((normals, np.full(weights.size, float(slip_length)), weights))


def write_surface_table(path, table, header):
    """Write a ``.Laplace`` or ``.slip_length`` table with a ``#`` header line (full double precision)."""
    np.savetxt(path, table, header=header, fmt='%.18e')


def _surface_main(args, command):
    """The ``janus-laplace`` and ``slip-length`` commands: the file next to ``--output``; returns its path."""
    from multi_bodies.files.structure_files import read_vertex_file
    blobs = read_vertex_file(args.vertex)
    stem = os.path.splitext(os.path.basename(args.vertex))[0]
    os.makedirs(args.output, exist_ok=True)
    if args.kind == 'janus-laplace':
        front = (args.reaction_front, args.emitting_front, args.mobility_front)
        back = (args.reaction_back, args.emitting_back, args.mobility_back)
        table = janus_laplace_table(blobs, front, back, args.weight_radius)
        suffix = ''.join('_janus_%s' % name for name, f, b in zip(('k', 'alpha', 'M'), front, back) if f != b)
        path = os.path.join(args.output, stem + suffix + '.Laplace')
        header = 'Columns: normals, reaction rate, emitting rate, surface mobility, weights (made by: %s)' % command
    else:
        table = slip_length_table(blobs, args.slip_length, args.weight_radius)
        path = os.path.join(args.output, '%s_slip_length_%s.slip_length' % (stem, ('%g' % args.slip_length)
                                                                             .replace('.', '_')))
        header = 'Columns: normals, slip length, weights (made by: %s)' % command
    write_surface_table(path, table, header)
    print('wrote %s (%d blobs)' % (path, table.shape[0]))
    return path


def _format_number(value):
    return ('%.4f' % value).replace('.', '_')


def main(argv=None):
    parser = argparse.ArgumentParser(description='Write .vertex files of example rigid bodies.')
    sub = parser.add_subparsers(dest='kind', required=True)
    p_shell = sub.add_parser('shell', help='icosahedral shell of hydrodynamic radius 1')
    p_shell.add_argument('--blobs', type=int, required=True, help='12, 42, 162, 642, 2562, ...')
    p_shell.add_argument('--shell-radius', type=float, default=None,
                         help='place the blobs on a sphere of this radius instead of calibrating '
                              'the hydrodynamic radius to 1')
    p_boom = sub.add_parser('boomerang', help='two perpendicular arms meeting at the origin')
    p_boom.add_argument('--arm-blobs', type=int, default=7)
    p_boom.add_argument('--spacing', type=float, default=0.3)
    p_rod = sub.add_parser('rod', help='straight rod along x')
    p_rod.add_argument('--blobs', type=int, required=True)
    p_rod.add_argument('--spacing', type=float, required=True)
    p_slip = sub.add_parser('squirmer-slip', help='slip file of a squirmer on a calibrated shell')
    p_slip.add_argument('--blobs', type=int, required=True, help='12, 42, 162, ... blobs of the shell')
    p_slip.add_argument('--B1', type=float, default=1.0, help='first squirming mode (swimming speed 2 B1/3)')
    p_slip.add_argument('--beta', type=float, default=0.0, help='B2/B1 (pusher < 0 < puller)')
    p_blob = sub.add_parser('blob', help='one blob at the origin (blob.vertex, the body of the roller schemes)')
    p_lattice = sub.add_parser('lattice', help='.clones file of bodies on a square lattice at one height')
    p_lattice.add_argument('--nx', type=int, required=True)
    p_lattice.add_argument('--ny', type=int, default=1)
    p_lattice.add_argument('--spacing', type=float, required=True, help='distance between neighbours')
    p_lattice.add_argument('--height', type=float, required=True, help='z of every body location')
    p_lattice.add_argument('--name', required=True, help='file name without .clones')
    p_janus = sub.add_parser('janus-laplace', help='.Laplace file of a Janus sphere (per-hemisphere k, alpha, mu)')
    p_length = sub.add_parser('slip-length', help='.slip_length file of a sphere of uniform slip length')
    for p in (p_janus, p_length):
        p.add_argument('--vertex', required=True, help='the .vertex file of the sphere (blobs about the origin)')
        p.add_argument('--weight-radius', type=float, default=1.0, help='weights 4 pi R^2 / n (default 1)')
    for half in ('front', 'back'):
        p_janus.add_argument('--reaction-%s' % half, type=float, default=5.0, help='k of z %s 0' % '><'[half == 'back'])
        p_janus.add_argument('--emitting-%s' % half, type=float, default=0.0, help='alpha of that hemisphere')
        p_janus.add_argument('--mobility-%s' % half, type=float, default=5.0, help='mu of that hemisphere')
    p_length.add_argument('--slip-length', type=float, required=True, help='the slip length l >= 0')
    for p in (p_shell, p_boom, p_rod, p_slip, p_blob, p_lattice, p_janus, p_length):
        p.add_argument('--output', default='.', help='folder for the file (default: .)')
    args = parser.parse_args(argv)

    command = 'python -m multi_bodies.files.structure_generators ' + ' '.join(sys.argv[1:] if argv is None else argv)
    if args.kind in ('janus-laplace', 'slip-length'):
        return _surface_main(args, command)
    if args.kind == 'lattice':
        if args.nx < 1 or args.ny < 1:
            parser.error('--nx and --ny must be positive')
        locations = lattice(args.nx, args.ny, args.spacing, args.height)
        orientations = np.tile([1.0, 0.0, 0.0, 0.0], (locations.shape[0], 1))
        os.makedirs(args.output, exist_ok=True)
        path = os.path.join(args.output, args.name + '.clones')
        write_clones_file(path, locations, orientations,
                          comment='made by: %s\n%d x %d bodies, spacing %g, height %g'
                          % (command, args.nx, args.ny, args.spacing, args.height))
        print('wrote %s (%d bodies)' % (path, locations.shape[0]))
        return path
    if args.kind == 'blob':
        blobs = np.zeros((1, 3))
        blob_radius = None
        name = 'blob.vertex'
        note = 'one blob at the origin'
    elif args.kind == 'shell' and args.shell_radius is not None:
        blobs = icosahedral_shell(args.blobs) * args.shell_radius
        blob_radius = 0.5 * smallest_distance(blobs)
        name = 'shell_N_%d_Rg_%s.vertex' % (args.blobs, ('%g' % args.shell_radius).replace('.', '_'))
        note = ('icosahedral shell, %d blobs, shell radius Rg = %.12g (not calibrated)\n'
                'half the nearest-neighbour distance is %.12g' % (args.blobs, args.shell_radius, blob_radius))
    elif args.kind == 'shell':
        blobs, blob_radius, radius = calibrated_shell(args.blobs)
        name = 'shell_N_%d_Rg_%s_Rh_1.vertex' % (args.blobs, _format_number(radius))
        note = ('icosahedral shell, %d blobs, shell radius Rg = %.12g, hydrodynamic radius 1\n'
                'use blob_radius %.12g' % (args.blobs, radius, blob_radius))
    elif args.kind == 'squirmer-slip':
        shell, _, radius = calibrated_shell(args.blobs)
        blobs = squirmer_slip(shell, args.B1, args.beta)
        blob_radius = None
        name = 'shell_N_%d_Rg_%s_Rh_1_squirmer_B1_%s.slip' % (args.blobs, _format_number(radius),
                                                              ('%g' % args.B1).replace('.', '_'))
        note = ('squirmer slip (body frame, axis +x), B1 = %g, beta = %g, for shell_N_%d_Rg_%s_Rh_1.vertex'
                % (args.B1, args.beta, args.blobs, _format_number(radius)))
    elif args.kind == 'boomerang':
        blobs = boomerang(args.arm_blobs, args.spacing)
        blob_radius = None
        name = 'boomerang_N_%d.vertex' % blobs.shape[0]
        note = 'boomerang, %d blobs per arm, spacing %g' % (args.arm_blobs, args.spacing)
    else:
        blobs = rod(args.blobs, args.spacing)
        blob_radius = None
        name = 'rod_N_%d.vertex' % args.blobs
        note = 'rod along x, %d blobs, spacing %g' % (args.blobs, args.spacing)
    os.makedirs(args.output, exist_ok=True)
    path = os.path.join(args.output, name)
    write_vertex_file(path, blobs, comment='made by: %s\n%s' % (command, note))
    print('wrote %s (%d blobs)' % (path, blobs.shape[0]))
    if blob_radius is not None:
        print('blob_radius %.12g' % blob_radius)
    return path


if __name__ == '__main__':
    main()
