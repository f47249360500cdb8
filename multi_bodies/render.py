"""A picture, or an animation, of the saved steps of a run, without ParaView.

Run from the folder the run was started in (as the other scripts)::

    python render.py --input-file inputfile_dynamic.dat [--step k] [--png out.png] [--movie out.gif]

Blobs are drawn as spheres of the blob radius, the wall ``z = 0`` as a grey
plane with each blob's footprint (darker grey, straight below the blob, so
that heights can be read), each body in its own colour (matplotlib's ``tab10`` colours, body 0
first, in input order).  ``--step`` picks a saved step (default: the last
one); ``--png`` writes a picture of it (default name
``output_name.<step, 8 digits>.png`` when neither ``--png`` nor ``--movie`` is
given); ``--movie`` writes every saved step as a GIF (matplotlib's Pillow
writer).

``--backend pyvista`` renders off-screen with pyvista (VTK); ``matplotlib``
draws with matplotlib's 3-D axes, which works on any machine without a
display; ``auto`` (default) uses pyvista where it can render, else
matplotlib.  Which snapshots are read is explained in ``clones_to_vtk.py``
(dynamic and Monte Carlo runs, both ``save_clones`` modes, static problems).
"""
import argparse
import os
import subprocess
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from body.body import Configuration  # noqa: E402
from multi_bodies.files.input_options import read_input_file  # noqa: E402
from multi_bodies.run.vtk_output import load_run, periodic_shifts, run_configurations  # noqa: E402

WALL_RGB = (0.78, 0.78, 0.78)
SHADOW_RGB = (0.62, 0.62, 0.62)  # each blob's footprint on the wall, straight below it: shows the height
BACKGROUND_RGB = (1.0, 1.0, 1.0)
LIGHT = np.array([0.35, -0.55, 0.76]) / np.linalg.norm([0.35, -0.55, 0.76])
TAB10 = np.array([[0.122, 0.467, 0.706], [1.0, 0.498, 0.055], [0.173, 0.627, 0.173], [0.839, 0.153, 0.157],
                  [0.580, 0.404, 0.741], [0.549, 0.337, 0.294], [0.890, 0.467, 0.761], [0.498, 0.498, 0.498],
                  [0.737, 0.741, 0.133], [0.090, 0.745, 0.812]])


def body_colours(num_bodies):
    """RGB in [0, 1] of each body, shape (Nb, 3): tab10 colours, cycled."""
    return TAB10[np.arange(num_bodies) % len(TAB10)]


class Scene:
    """What every frame shares: blob radius, body of each blob, colours, wall and camera.

    ``wall``: (x0, x1, y0, y1) of the wall rectangle, wide enough for every
    frame; ``z_top``: highest blob top over all frames; ``view``:
    (elevation, azimuth) in degrees.
    """

    def __init__(self, body_arrays, all_blob_positions, view, periodic_length=(0.0, 0.0, 0.0), wrap=False):
        """``all_blob_positions``: iterable of (N, 3) arrays, the frames to be drawn."""
        self.blob_radius = body_arrays.blob_radius
        self.blob_body_index = body_arrays.blob_body_index
        self.colours = body_colours(body_arrays.num_bodies)[self.blob_body_index]
        low, high = np.full(3, np.inf), np.full(3, -np.inf)
        for r_vectors in all_blob_positions:  # one frame at a time: a long run need not fit in memory
            r_vectors = np.asarray(r_vectors).reshape(-1, 3)
            low, high = np.minimum(low, r_vectors.min(axis=0)), np.maximum(high, r_vectors.max(axis=0))
        low, high = low - self.blob_radius, high + self.blob_radius
        lengths = np.asarray(periodic_length, dtype=float)
        if wrap:
            for axis in (0, 1):
                if lengths[axis] > 0:
                    low[axis], high[axis] = min(low[axis], 0.0), max(high[axis], lengths[axis])
        margin = max(1.0, 0.25 * float(np.max(high[:2] - low[:2])))
        self.wall = (low[0] - margin, high[0] + margin, low[1] - margin, high[1] + margin)
        self.z_top = max(float(high[2]), 1.0)
        self.view = view


def sphere_faces(resolution):
    """Quadrilaterals of a unit sphere: vertices (F, 4, 3) and outward face normals (F, 3)."""
    longitudes = np.linspace(0.0, 2.0 * np.pi, 2 * resolution + 1)
    latitudes = np.linspace(0.0, np.pi, resolution + 1)
    lon0, lat0 = np.meshgrid(longitudes[:-1], latitudes[:-1], indexing='ij')
    lon1, lat1 = np.meshgrid(longitudes[1:], latitudes[1:], indexing='ij')

    def point(lon, lat):
        return np.stack((np.sin(lat) * np.cos(lon), np.sin(lat) * np.sin(lon), np.cos(lat)), axis=-1)

    quads = np.stack((point(lon0, lat0), point(lon1, lat0), point(lon1, lat1), point(lon0, lat1)), axis=2)
    quads = quads.reshape(-1, 4, 3)
    normals = quads.mean(axis=1)
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    return quads, normals


def render_matplotlib(scene, r_vectors, title, size):
    """Frame as an RGB array (H, W, 3) of uint8, drawn with matplotlib's 3-D axes (Agg, no display)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    width, height = size
    dpi = 100
    fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=BACKGROUND_RGB)
    ax = fig.add_axes((0.0, 0.0, 1.0, 0.94), projection='3d', facecolor=BACKGROUND_RGB)
    ax.computed_zorder = False
    x0, x1, y0, y1 = scene.wall
    wall = Poly3DCollection([[(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]],
                            facecolors=[WALL_RGB], edgecolors='none', zorder=0)
    ax.add_collection3d(wall)
    r_vectors = np.asarray(r_vectors).reshape(-1, 3)
    angles = np.linspace(0.0, 2.0 * np.pi, 13)[:-1]
    disc = np.column_stack((np.cos(angles), np.sin(angles), np.zeros_like(angles)))
    footprints = r_vectors[:, None, :] * np.array([1.0, 1.0, 0.0]) + scene.blob_radius * disc[None, :, :]
    ax.add_collection3d(Poly3DCollection(footprints, facecolors=[SHADOW_RGB], edgecolors='none', zorder=0.5))
    resolution = 6 if r_vectors.shape[0] <= 2000 else 3
    quads, normals = sphere_faces(resolution)
    faces = r_vectors[:, None, None, :] + scene.blob_radius * quads[None, :, :, :]
    shade = 0.55 + 0.45 * np.clip(normals @ LIGHT, 0.0, 1.0)
    colours = scene.colours[:, None, :] * shade[None, :, None]
    blobs = Poly3DCollection(faces.reshape(-1, 4, 3), facecolors=colours.reshape(-1, 3), edgecolors='none',
                             zorder=1)
    ax.add_collection3d(blobs)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_zlim(0.0, scene.z_top)
    ax.set_box_aspect((x1 - x0, y1 - y0, scene.z_top))
    ax.view_init(elev=scene.view[0], azim=scene.view[1])
    ax.set_axis_off()
    fig.text(0.5, 0.97, title, ha='center', va='center', fontsize=10)
    fig.canvas.draw()
    frame = np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy()
    plt.close(fig)
    return frame


def quiet_vtk_without_display():
    """Without an X display (no ``DISPLAY``, Linux) VTK logs "bad X server connection" for every off-screen window,
    although it renders without one; its warnings are then kept off stderr (its errors still show)."""
    if not sys.platform.startswith('linux') or os.environ.get('DISPLAY') or os.environ.get('WAYLAND_DISPLAY'):
        return
    try:
        from vtkmodules.vtkCommonCore import vtkLogger
    except ImportError:
        return
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)


def render_pyvista(scene, r_vectors, title, size):
    """Frame as an RGB array (H, W, 3) of uint8, rendered off-screen by pyvista."""
    import pyvista
    quiet_vtk_without_display()
    plotter = pyvista.Plotter(off_screen=True, window_size=list(size))
    plotter.set_background(BACKGROUND_RGB)
    x0, x1, y0, y1 = scene.wall
    plotter.add_mesh(pyvista.Plane(center=((x0 + x1) / 2, (y0 + y1) / 2, 0.0), direction=(0, 0, 1),
                                   i_size=x1 - x0, j_size=y1 - y0), color=WALL_RGB, lighting=False)
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    footprints = pyvista.PolyData(r_vectors * np.array([1.0, 1.0, 0.0]) + np.array([0.0, 0.0, 1e-3 * scene.z_top]))
    plotter.add_mesh(footprints.glyph(geom=pyvista.Disc(inner=0.0, outer=scene.blob_radius, c_res=24), scale=False,
                                      orient=False), color=SHADOW_RGB, lighting=False)
    points = pyvista.PolyData(r_vectors)
    points.point_data['rgb'] = (255 * scene.colours).astype(np.uint8)
    glyphs = points.glyph(geom=pyvista.Sphere(radius=scene.blob_radius, theta_resolution=16, phi_resolution=12),
                          scale=False, orient=False)
    plotter.add_mesh(glyphs, scalars='rgb', rgb=True, smooth_shading=True)
    plotter.add_text(title, position='upper_edge', font_size=10, color='black')
    elevation, azimuth = np.radians(scene.view)
    focal = np.array(((x0 + x1) / 2, (y0 + y1) / 2, scene.z_top / 2))
    direction = np.array((np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)))
    plotter.camera.focal_point = focal
    plotter.camera.position = focal + 10.0 * max(x1 - x0, y1 - y0) * direction
    plotter.camera.up = (0.0, 0.0, 1.0)
    plotter.reset_camera()
    frame = np.asarray(plotter.screenshot(return_img=True))[:, :, :3].copy()
    plotter.close()
    return frame


def pyvista_can_render():
    """True when pyvista renders off-screen here (tried in a child process, so a crash cannot stop us)."""
    probe = ('import pyvista; p = pyvista.Plotter(off_screen=True, window_size=[16, 16]); '
             'p.add_mesh(pyvista.Sphere()); p.screenshot(return_img=True); p.close()')
    try:
        result = subprocess.run([sys.executable, '-c', probe], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return result.returncode == 0


def choose_renderer(name):
    if name == 'matplotlib':
        return render_matplotlib
    if name == 'pyvista':
        try:
            import pyvista  # noqa: F401
        except ImportError:
            raise utils.UserInputError('--backend pyvista: pyvista is not installed (python3 -m pip install '
                                       'pyvista), or use --backend matplotlib')
        return render_pyvista
    if pyvista_can_render():
        return render_pyvista
    print('pyvista cannot render off-screen here: drawing with matplotlib')
    return render_matplotlib


def write_png(path, frame):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    plt.imsave(path, frame)


def write_gif(path, frames, size, fps):
    """GIF of RGB frames (an iterable of (H, W, 3) uint8, each rendered when needed) through matplotlib's
    Pillow writer; returns the number of frames."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.animation import PillowWriter
    width, height = size
    fig = plt.figure(figsize=(width / 100.0, height / 100.0), dpi=100)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    image = ax.imshow(np.zeros((height, width, 3), dtype=np.uint8), interpolation='nearest')
    writer = PillowWriter(fps=fps)
    count = 0
    with writer.saving(fig, path, dpi=100):
        for frame in frames:
            image.set_data(frame)
            writer.grab_frame()
            count += 1
    plt.close(fig)
    return count


def frame_title(options, step):
    if options.dt > 0:
        return '%s   step %d   t = %.6g' % (os.path.basename(options.output_name), step, step * options.dt)
    return '%s   step %d' % (os.path.basename(options.output_name), step)


def main(argv=None):
    parser = argparse.ArgumentParser(description='Draw a saved step of a run as a PNG, or all steps as a GIF '
                                                 '(see doc/visualisation.md).')
    parser.add_argument('--input-file', required=True, help='input file of the run')
    parser.add_argument('--step', type=int, default=None, help='saved step to draw (default: the last)')
    parser.add_argument('--png', default=None, help='picture to write (default output_name.<step>.png)')
    parser.add_argument('--movie', default=None, help='GIF of every saved step to write')
    parser.add_argument('--backend', choices=('auto', 'pyvista', 'matplotlib'), default='auto')
    parser.add_argument('--size', type=int, nargs=2, default=(800, 600), metavar=('WIDTH', 'HEIGHT'),
                        help='picture size in pixels (default 800 600)')
    parser.add_argument('--view', type=float, nargs=2, default=(25.0, -60.0), metavar=('ELEVATION', 'AZIMUTH'),
                        help='camera elevation and azimuth in degrees (default 25 -60)')
    parser.add_argument('--fps', type=float, default=5.0, help='frames per second of the GIF (default 5)')
    parser.add_argument('--every', type=int, default=1, help='GIF of every n-th saved step only (default 1)')
    parser.add_argument('--wrap-periodic', action='store_true',
                        help='draw the bodies in the primary box [0, L) of the periodic axes')
    args = parser.parse_args(argv)
    if args.every < 1:
        raise utils.UserInputError('--every: give a positive number of saved steps between frames')
    if not (args.fps > 0 and np.isfinite(args.fps)):
        raise utils.UserInputError('--fps %g: give a positive number of frames per second (default 5)' % args.fps)
    if args.movie is not None and os.path.splitext(args.movie)[1].lower() != '.gif':
        raise utils.UserInputError('--movie %s: render.py writes GIF movies only; give a name ending in .gif (an '
                                   'mp4 can be made from the GIF or from the PNGs, e.g. with ffmpeg)' % args.movie)
    if min(args.size) < 16:
        raise utils.UserInputError('--size: give a width and height of at least 16 pixels')

    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise utils.UserInputError('render.py draws and writes pictures with matplotlib, which is not installed; '
                                   'install it with "python3 -m pip install matplotlib"')
    options = read_input_file(args.input_file)
    body_arrays, types = load_run(options)
    steps, locations, orientations = run_configurations(options, body_arrays, types)
    if args.step is not None and args.step not in set(steps.tolist()):
        raise utils.UserInputError('--step %d: no saved step %d for %s; saved steps are %s'
                                   % (args.step, args.step, args.input_file, utils.describe_steps(steps)))
    index = len(steps) - 1 if args.step is None else steps.tolist().index(args.step)
    chosen = range(0, len(steps), args.every) if args.movie else [index]

    def blob_positions(i):
        """Blob positions (N, 3) of saved step number ``i``."""
        r_vectors = body_arrays.blob_positions(Configuration(locations[i], orientations[i]))
        if args.wrap_periodic:
            r_vectors = r_vectors + periodic_shifts(locations[i], options.periodic_length)[body_arrays.blob_body_index]
        return r_vectors

    scene = Scene(body_arrays, (blob_positions(i) for i in sorted(set(chosen) | {index})), args.view,
                  options.periodic_length, args.wrap_periodic)
    render = choose_renderer(args.backend)
    size = tuple(args.size)

    if args.png is not None or args.movie is None:
        path = args.png or '%s.%s.png' % (options.output_name, str(int(steps[index])).zfill(8))
        write_png(path, render(scene, blob_positions(index), frame_title(options, int(steps[index])), size))
        print('wrote %s (step %d)' % (path, int(steps[index])))
    if args.movie is not None:
        frames = (render(scene, blob_positions(i), frame_title(options, int(steps[i])), size) for i in chosen)
        count = write_gif(args.movie, frames, size, args.fps)
        print('wrote %s (%d steps)' % (args.movie, count))
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
