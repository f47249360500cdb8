"""Fluid velocity on a rectilinear grid, written as a legacy VTK file.

The grid option ``x0 x1 Nx y0 y1 Ny z0 z1 Nz`` splits the box into
``Nx Ny Nz`` cells (an axis with ``x0 = x1`` and one cell is a single
point: ``... z0 z0 1`` is the plane z = z0, as in the published examples); the velocity is computed at the cell centres (x fastest,
then y, then z) as the flow of the blob constraint forces ``lambda``:
``u(x) = M_source_target(x, r_blobs) lambda`` with sources of radius ``a``
(one number, or the radius of each blob when the vertex files give radii)
and targets of radius ``tracer_radius`` (0 gives the point velocity).

pyvista is imported only when a file is written.
"""
import numpy as np


def grid_edges(grid):
    """Cell edges along x, y, z: tuple of three arrays of length N_axis + 1 (1 on a degenerate axis).

    ``grid`` is ((x0, x1, Nx), (y0, y1, Ny), (z0, z1, Nz)).  An axis with
    ``x0 = x1`` (then ``Nx = 1``) holds one point, so the grid is a plane
    (or a line) of cells of zero thickness; its edge is the single
    coordinate ``x0``, which VTK readers show as a two-dimensional grid.
    """
    return tuple(np.array([low]) if high == low else np.linspace(low, high, cells + 1) for low, high, cells in grid)


def cell_centres(grid):
    """Cell centres ``x0 + d (i + 1/2)``, shape (Nx Ny Nz, 3), x fastest."""
    centres_1d = [low + (high - low) / cells * (np.arange(cells) + 0.5) for low, high, cells in grid]
    zz, yy, xx = np.meshgrid(centres_1d[2], centres_1d[1], centres_1d[0], indexing='ij')
    return np.column_stack((xx.ravel(), yy.ravel(), zz.ravel()))


def grid_memory(grid, num_blobs):
    """Bytes the velocity on ``grid`` needs: the cell centres and velocities (6 doubles a cell) and, for the
    pair-by-pair products, a block of cells x blobs x 3 doubles."""
    cells = 1
    for _, _, n in grid:
        cells *= int(n)
    return 8 * cells * (9 + 3 * int(num_blobs))


def check_grid(grid, num_blobs, where='plot_velocity_field'):
    """Refuse (UserInputError with the memory it would need) a grid too big for this machine."""
    from multi_bodies.run.run_output import refuse_if_too_big
    cells = 1
    for _, _, n in grid:
        cells *= int(n)
    refuse_if_too_big(grid_memory(grid, num_blobs), 'the velocity field on %d cells with %d blobs' % (cells, num_blobs),
                      where, 'give fewer cells Nx Ny Nz')


def velocity_field(grid, r_vectors, lambda_blobs, tracer_radius, mobility):
    """Fluid velocity at the cell centres, shape (Nx Ny Nz, 3), x fastest.

    Parameters
    ----------
    grid : ((x0, x1, Nx), (y0, y1, Ny), (z0, z1, Nz))
    r_vectors : ndarray (N, 3), blob positions (sources).
    lambda_blobs : ndarray (N, 3), blob constraint forces.
    tracer_radius : float, the radius of the tracers at the cell centres (a length)
    mobility : mobility.interface.BlobMobility of the blobs (its ``source_target`` product; the sources have its
        radius or per-blob radii (N,), its viscosity and box).
    """
    check_grid(grid, np.asarray(r_vectors).size // 3)
    targets = cell_centres(grid)
    velocity = mobility.source_target(np.asarray(r_vectors, dtype=float).reshape(-1, 3), targets,
                                      np.asarray(lambda_blobs, dtype=float).reshape(-1), mobility.blob_radius,
                                      tracer_radius)
    return np.asarray(velocity).reshape(-1, 3)


def write_velocity_field_vtk(path, grid, velocity):
    """Write the velocity (shape (Nx Ny Nz, 3), x fastest) on the grid as a legacy ASCII VTK file.

    The file is a rectilinear grid whose cell data ``velocity`` holds one
    vector per cell, written as the active vectors (``VECTORS velocity
    double``), so that ParaView, VisIt and ``pyvista.read`` offer glyphs and
    streamlines of it at once.
    """
    import pyvista
    x_edges, y_edges, z_edges = grid_edges(grid)
    mesh = pyvista.RectilinearGrid(x_edges, y_edges, z_edges)
    mesh.cell_data.set_vectors(np.asarray(velocity, dtype=float).reshape(-1, 3), 'velocity')
    mesh.save(path, binary=False)
    return path
