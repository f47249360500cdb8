"""VTK series for ParaView (vtk_output.py, clones_to_vtk.py, save_vtk) and pictures (render.py).

What is asserted comes from outside the code under test: blob positions and
body axes from the package's ``Body`` class applied to the saved ``.clones``
files (round trip to round-off), blob velocities from the rigid-body law
``v + w x (r - location)`` written out here, times ``step * dt`` from the
input file, the geometry of the primary box, and pixel colours of the
picture in the regions where the scene puts the wall and the bodies.
"""
import importlib
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest

import utils
from body.body import Body
from multi_bodies.files import snapshots as snapshot_files
from multi_bodies.files.snapshots import read_clones_file, write_clones_file
from multi_bodies.files.structure_files import read_vertex_file, write_vertex_file
from multi_bodies.run.vtk_output import periodic_shifts

REPO = Path(__file__).resolve().parents[1]
STRUCTURES = REPO / 'multi_bodies' / 'Structures'
DYNAMIC = importlib.import_module('multi_bodies.multi_bodies')
CONVERTER = importlib.import_module('multi_bodies.clones_to_vtk')
STATIC = importlib.import_module('multi_bodies.multi_bodies_utilities')
BLOB_RADIUS = 0.25
DT = 0.05
N_STEPS = 4
TYPES = (('boomerang_N_15', 2), ('shell_N_12_Rg_1', 3))
WALL_RGB = np.array([0.78, 0.78, 0.78])


def needs(module, reason):
    """The module, or skip the test with ``reason`` when it cannot be imported."""
    try:
        return importlib.import_module(module)
    except ImportError:
        pytest.skip(reason)


def needs_pyvista():
    return needs('pyvista', 'pyvista is not installed: the VTK files cannot be read back')


def random_quaternions(rng, count):
    q = rng.normal(size=(count, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def write_input(path, options, structures):
    lines = ['%s %s' % item for item in options.items()]
    lines += ['structure ' + ' '.join(s) for s in structures]
    path.write_text('\n'.join(lines) + '\n')


def dynamic_input(run_dir, **changes):
    """A two-structure run (2 boomerangs, 3 shells) with rotated bodies, in ``run_dir``."""
    rng = np.random.default_rng(13)
    structures = []
    for (name, count), x0 in zip(TYPES, (-4.0, 4.0)):
        shutil.copy(STRUCTURES / (name + '.vertex'), run_dir / (name + '.vertex'))
        locations = np.column_stack((x0 + 4.0 * np.arange(count), rng.uniform(-3, 3, count),
                                     rng.uniform(4, 6, count)))
        write_clones_file(run_dir / (name + '.clones'), locations, random_quaternions(rng, count))
        structures.append((name + '.vertex', name + '.clones'))
    options = {'scheme': 'deterministic_forward_euler', 'mobility_blobs_implementation': 'python',
               'mobility_vector_prod_implementation': 'python', 'blob_blob_force_implementation': 'None',
               'dt': DT, 'n_steps': N_STEPS, 'n_save': 1, 'eta': 1.0, 'g': 1.0, 'blob_radius': BLOB_RADIUS,
               'solver_tolerance': 1e-6, 'output_name': 'out/run'}
    options.update(changes)
    write_input(run_dir / 'input.dat', options, structures)
    return 'input.dat'


@pytest.fixture(scope='module')
def dynamic_run(tmp_path_factory):
    """The run, saved with save_vtk True, in a folder of its own; returns that folder."""
    run_dir = tmp_path_factory.mktemp('vtk_run')
    input_name = dynamic_input(run_dir, save_vtk='True')
    cwd = os.getcwd()
    os.chdir(run_dir)
    try:
        assert DYNAMIC.main(['--input-file', input_name]) == 0
    finally:
        os.chdir(cwd)
    return run_dir


def blobs_by_body_code(run_dir, step):
    """Blob positions (N, 3), body axes (Nb, 3, 3) and locations of ``step`` from Body and the .clones files."""
    positions, rotations, locations = [], [], []
    for name, _ in TYPES:
        reference = read_vertex_file(str(run_dir / (name + '.vertex')))
        clones = run_dir / 'out' / ('run.%s.%s.clones' % (name, str(step).zfill(8)))
        for location, orientation in zip(*read_clones_file(str(clones))):
            body = Body(location, orientation, reference, BLOB_RADIUS)
            positions.append(body.get_r_vectors())
            rotations.append(body.rotation_matrix())
            locations.append(body.location)
    return np.concatenate(positions), np.array(rotations), np.array(locations)


def check_step_files(run_dir, step):
    pyvista = needs_pyvista()
    expected_blobs, expected_rotations, expected_locations = blobs_by_body_code(run_dir, step)
    blobs = pyvista.read(str(run_dir / 'out' / ('run.blobs.%s.vtp' % str(step).zfill(8))))
    assert np.allclose(blobs.points, expected_blobs, rtol=0, atol=1e-12)
    assert np.all(blobs.point_data['radius'] == BLOB_RADIUS)
    blob_counts = [15] * 2 + [12] * 3
    assert np.array_equal(blobs.point_data['body_index'], np.repeat(np.arange(5), blob_counts))
    assert list(blobs.point_data['structure']) == ['boomerang_N_15'] * 30 + ['shell_N_12_Rg_1'] * 36
    bodies = pyvista.read(str(run_dir / 'out' / ('run.bodies.%s.vtp' % str(step).zfill(8))))
    assert np.allclose(bodies.points, expected_locations, rtol=0, atol=1e-12)
    for axis in range(3):
        assert np.allclose(bodies.point_data['axis_%d' % (axis + 1)], expected_rotations[:, :, axis], atol=1e-12)
    return expected_blobs


# ------------------------------------------------------------------ round trip
def test_blob_positions_of_every_step_match_the_body_code(dynamic_run, monkeypatch):
    """save_vtk files, then the converter's files, against Body applied to the .clones of the same step."""
    steps = range(N_STEPS + 1)
    first = [check_step_files(dynamic_run, step) for step in steps]
    assert not np.allclose(first[0], first[-1])  # the bodies moved: the steps are not one configuration
    for path in (dynamic_run / 'out').glob('*.vtp'):
        path.unlink()
    monkeypatch.chdir(dynamic_run)
    assert CONVERTER.main(['--input-file', 'input.dat']) == 0
    for step in steps:
        check_step_files(dynamic_run, step)


def test_pvd_lists_every_saved_step_at_step_times_and_reads_as_time_series(dynamic_run):
    pyvista = needs_pyvista()
    for kind in ('blobs', 'bodies'):
        pvd = dynamic_run / 'out' / ('run.%s.pvd' % kind)
        entries = ElementTree.parse(str(pvd)).getroot().find('Collection').findall('DataSet')
        assert [e.get('file') for e in entries] == ['run.%s.%s.vtp' % (kind, str(s).zfill(8))
                                                    for s in range(N_STEPS + 1)]
        assert np.allclose([float(e.get('timestep')) for e in entries], DT * np.arange(N_STEPS + 1), atol=1e-15)
        reader = pyvista.get_reader(str(pvd))
        assert np.allclose(reader.time_values, DT * np.arange(N_STEPS + 1), atol=1e-15)
    reader.set_active_time_value(reader.time_values[2])
    expected_locations = blobs_by_body_code(dynamic_run, 2)[2]
    assert np.allclose(reader.read()[0].points, expected_locations, atol=1e-12)


def test_restart_keeps_the_earlier_steps_in_the_pvd(tmp_path, monkeypatch):
    needs_pyvista()
    input_name = dynamic_input(tmp_path, save_vtk='True', n_steps=2)
    monkeypatch.chdir(tmp_path)
    assert DYNAMIC.main(['--input-file', input_name]) == 0
    input_name = dynamic_input(tmp_path, save_vtk='True', n_steps=4, initial_step=1)
    assert DYNAMIC.main(['--input-file', input_name]) == 0
    entries = ElementTree.parse('out/run.blobs.pvd').getroot().find('Collection').findall('DataSet')
    assert [float(e.get('timestep')) for e in entries] == pytest.approx(DT * np.arange(5), abs=1e-15)


def test_one_file_snapshots_convert_to_the_same_positions(tmp_path, monkeypatch):
    """save_clones one_file, n_save 2: steps 0, 2, 4 and the positions of the one_file_per_step run."""
    pyvista = needs_pyvista()
    input_name = dynamic_input(tmp_path, save_clones='one_file', n_save=2)
    monkeypatch.chdir(tmp_path)
    assert DYNAMIC.main(['--input-file', input_name]) == 0
    assert CONVERTER.main(['--input-file', input_name]) == 0
    entries = ElementTree.parse('out/run.blobs.pvd').getroot().find('Collection').findall('DataSet')
    assert [float(e.get('timestep')) for e in entries] == pytest.approx([0.0, 2 * DT, 4 * DT], abs=1e-15)
    per_step = tmp_path / 'per_step'
    per_step.mkdir()
    monkeypatch.chdir(per_step)
    assert DYNAMIC.main(['--input-file', dynamic_input(per_step)]) == 0
    for step in (0, 2, 4):
        expected = blobs_by_body_code(per_step, step)[0]
        mesh = pyvista.read(str(tmp_path / 'out' / ('run.blobs.%s.vtp' % str(step).zfill(8))))
        assert np.allclose(mesh.points, expected, rtol=0, atol=1e-12)


def test_monte_carlo_snapshots_without_time_step_are_numbered_by_step(tmp_path, monkeypatch):
    """The Monte Carlo script saves the same .clones names and has no dt: the .pvd time of step k is k."""
    pyvista = needs_pyvista()
    input_name = dynamic_input(tmp_path)
    text = (tmp_path / input_name).read_text().splitlines()
    (tmp_path / 'mcmc.dat').write_text('\n'.join(line for line in text if not line.startswith(('dt ', 'scheme '))))
    (tmp_path / 'out').mkdir()
    rng = np.random.default_rng(8)
    for step in (0, 10, 20):
        for name, count in TYPES:
            locations, orientations = read_clones_file(str(tmp_path / (name + '.clones')))
            write_clones_file(tmp_path / 'out' / ('run.%s.%s.clones' % (name, str(step).zfill(8))),
                              locations + rng.normal(size=locations.shape), random_quaternions(rng, count))
    monkeypatch.chdir(tmp_path)
    assert CONVERTER.main(['--input-file', 'mcmc.dat']) == 0
    reader = pyvista.get_reader('out/run.blobs.pvd')
    assert reader.time_values == [0.0, 10.0, 20.0]
    for step in (0, 10, 20):
        mesh = pyvista.read('out/run.blobs.%s.vtp' % str(step).zfill(8))
        assert np.allclose(mesh.points, blobs_by_body_code(tmp_path, step)[0], rtol=0, atol=1e-12)


def test_static_mobility_run_gives_rigid_body_blob_velocities_and_shares_the_velocity_field_frame(tmp_path,
                                                                                                  monkeypatch):
    """Static problem: one step, velocities of .velocities.dat; blob velocity = v + w x (r - location)."""
    pyvista = needs_pyvista()
    dynamic_input(tmp_path)
    grid = (-6.0, 10.0, 4, -4.0, 4.0, 2, 0.5, 8.0, 3)
    options = {'scheme': 'mobility', 'mobility_blobs_implementation': 'python',
               'mobility_vector_prod_implementation': 'python', 'blob_blob_force_implementation': 'None',
               'eta': 1.0, 'g': 1.0, 'blob_radius': BLOB_RADIUS, 'solver_tolerance': 1e-8, 'output_name': 'out/run',
               'plot_velocity_field': ' '.join(str(v) for v in grid)}
    write_input(tmp_path / 'static.dat', options, [(n + '.vertex', n + '.clones') for n, _ in TYPES])
    monkeypatch.chdir(tmp_path)
    assert STATIC.main(['--input-file', 'static.dat']) == 0
    assert CONVERTER.main(['--input-file', 'static.dat']) == 0
    velocities = np.loadtxt('out/run.velocities.dat')
    positions, _, locations = [], None, []
    for name, _ in TYPES:
        reference = read_vertex_file(name + '.vertex')
        for location, orientation in zip(*read_clones_file(name + '.clones')):
            body = Body(location, orientation, reference, BLOB_RADIUS)
            positions.append(body.get_r_vectors())
            locations.append(np.repeat(body.location[None], body.Nblobs, axis=0))
    body_of_blob = np.repeat(np.arange(5), [15] * 2 + [12] * 3)
    r, arm = np.concatenate(positions), np.concatenate(positions) - np.concatenate(locations)
    v, w = velocities[body_of_blob, :3], velocities[body_of_blob, 3:]
    rigid = v + np.stack((w[:, 1] * arm[:, 2] - w[:, 2] * arm[:, 1], w[:, 2] * arm[:, 0] - w[:, 0] * arm[:, 2],
                          w[:, 0] * arm[:, 1] - w[:, 1] * arm[:, 0]), axis=1)
    blobs = pyvista.read('out/run.blobs.00000000.vtp')
    assert np.allclose(blobs.points, r, atol=1e-12)
    assert np.allclose(blobs.point_data['velocity'], rigid, rtol=1e-12, atol=1e-14)
    bodies = pyvista.read('out/run.bodies.00000000.vtp')
    assert np.allclose(bodies.point_data['velocity'], velocities[:, :3], rtol=1e-12, atol=0)
    assert np.allclose(bodies.point_data['angular_velocity'], velocities[:, 3:], rtol=1e-12, atol=0)
    field = pyvista.read('out/run.velocity_field.vtk')
    # Same frame: the field's grid is the option's box, in the length unit of the blob positions, no offset.
    assert np.allclose(field.bounds, (grid[0], grid[1], grid[3], grid[4], grid[6], grid[7]))
    assert field.n_cells == grid[2] * grid[5] * grid[8]


def test_slip_of_active_bodies_is_the_slip_file_rotated_with_the_body(tmp_path, monkeypatch):
    pyvista = needs_pyvista()
    rng = np.random.default_rng(5)
    reference = read_vertex_file(str(STRUCTURES / 'rod_N_10.vertex'))
    write_vertex_file(tmp_path / 'rod.vertex', reference)
    slip = rng.normal(size=reference.shape)
    write_vertex_file(tmp_path / 'rod.slip', slip)  # a .slip file has the layout of a .vertex file
    quaternions = random_quaternions(rng, 2)
    write_clones_file(tmp_path / 'rod.clones', [[0, 0, 3], [3, 0, 3]], quaternions)
    options = {'scheme': 'body_mobility', 'blob_radius': BLOB_RADIUS, 'output_name': 'run'}
    write_input(tmp_path / 'in.dat', options, [('rod.vertex', 'rod.clones', 'rod.slip')])
    monkeypatch.chdir(tmp_path)
    assert CONVERTER.main(['--input-file', 'in.dat']) == 0
    written = pyvista.read('run.blobs.00000000.vtp').point_data['slip']
    expected = np.concatenate([slip @ Body([0, 0, 0], q, reference, BLOB_RADIUS).rotation_matrix().T
                               for q in quaternions])
    assert np.allclose(written, expected, atol=1e-13)


# ------------------------------------------------------------------ periodic box
def test_periodic_shifts_bring_locations_into_the_primary_box():
    rng = np.random.default_rng(3)
    locations = rng.uniform(-25, 25, size=(200, 3))
    lengths = np.array([7.0, 4.0, 0.0])
    shifts = periodic_shifts(locations, lengths)
    wrapped = locations + shifts
    assert np.all((wrapped[:, :2] >= 0) & (wrapped[:, :2] < lengths[:2]))
    assert np.array_equal(wrapped[:, 2], locations[:, 2])  # not periodic along z: untouched
    assert np.allclose(shifts[:, :2] / lengths[:2], np.round(shifts[:, :2] / lengths[:2]), atol=1e-12)


def test_wrap_periodic_moves_whole_bodies(tmp_path, monkeypatch):
    pyvista = needs_pyvista()
    dynamic_input(tmp_path)
    options = {'scheme': 'body_mobility', 'blob_radius': BLOB_RADIUS, 'output_name': 'run',
               'periodic_length': '5 5 0'}
    write_input(tmp_path / 'in.dat', options, [(n + '.vertex', n + '.clones') for n, _ in TYPES])
    monkeypatch.chdir(tmp_path)
    assert CONVERTER.main(['--input-file', 'in.dat']) == 0
    plain_bodies = pyvista.read('run.bodies.00000000.vtp').points
    plain_blobs = pyvista.read('run.blobs.00000000.vtp').points
    assert CONVERTER.main(['--input-file', 'in.dat', '--wrap-periodic']) == 0
    bodies = pyvista.read('run.bodies.00000000.vtp').points
    blobs = pyvista.read('run.blobs.00000000.vtp').points
    assert np.all((bodies[:, :2] >= 0) & (bodies[:, :2] < 5.0))
    assert np.any(np.abs(bodies - plain_bodies) > 1.0)  # some bodies started outside the box
    body_of_blob = np.repeat(np.arange(5), [15] * 2 + [12] * 3)
    assert np.allclose(blobs - bodies[body_of_blob], plain_blobs - plain_bodies[body_of_blob], atol=1e-12)


# ------------------------------------------------------------------ readers of saved series
def test_config_reader_drops_an_incomplete_last_snapshot(tmp_path):
    rng = np.random.default_rng(1)
    snapshots = [np.column_stack((rng.normal(size=(3, 3)), random_quaternions(rng, 3))) for _ in range(3)]
    text = ''.join('3\n' + ''.join(' '.join(repr(float(v)) for v in row) + '\n' for row in snap) for snap in snapshots)
    text += '3\n' + ' '.join(repr(float(v)) for v in snapshots[0][0]) + '\n'  # a stop while the fourth was written
    (tmp_path / 'run.a.config').write_text(text)
    locations, orientations = snapshot_files.read_config_series(str(tmp_path / 'run.a.config'))
    assert locations.shape == (3, 3, 3) and orientations.shape == (3, 3, 4)
    assert np.allclose(locations, np.array(snapshots)[:, :, :3], rtol=1e-15, atol=0)
    assert np.allclose(orientations, np.array(snapshots)[:, :, 3:], rtol=1e-15, atol=1e-16)


def test_clones_series_reader_sorts_steps_and_ignores_partial_files(tmp_path):
    for step in (123456789, 20, 3):
        write_clones_file(tmp_path / ('run.a.%s.clones' % str(step).zfill(8)), [[step, 0, 1]], [[2, 0, 0, 0]])
    (tmp_path / 'run.a.00000040.clones.part').write_text('1\n')
    steps, locations, orientations = snapshot_files.read_clones_series(str(tmp_path / 'run'), 'a')
    assert steps.tolist() == [3, 20, 123456789]
    assert locations[:, 0, 0].tolist() == [3, 20, 123456789]
    assert np.allclose(orientations[:, 0], [1, 0, 0, 0])  # normalised as the structure reader does
    with pytest.raises(utils.UserInputError, match='saved steps are 3, 20, 123456789'):
        snapshot_files.read_clones_series(str(tmp_path / 'run'), 'a', steps=[7])


# ------------------------------------------------------------------ pictures
def render_scene(tmp_path, extra_args, size=(320, 240)):
    """Two shells: body 0 (blue) at x = -3 and body 1 (orange) at x = +3, seen along +y; run render.py."""
    needs('matplotlib', 'render.py needs matplotlib (installed with pyvista)')
    shutil.copy(STRUCTURES / 'shell_N_12_Rg_1.vertex', tmp_path / 'shell.vertex')
    write_clones_file(tmp_path / 'shell.clones', [[-3.0, 0.0, 3.0], [3.0, 0.0, 3.0]], [[1, 0, 0, 0]] * 2)
    write_input(tmp_path / 'in.dat', {'scheme': 'body_mobility', 'blob_radius': 0.4, 'output_name': 'run'},
                [('shell.vertex', 'shell.clones')])
    env = {k: v for k, v in os.environ.items() if k not in ('DISPLAY', 'WAYLAND_DISPLAY', 'MPLBACKEND')}
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    result = subprocess.run([sys.executable, str(REPO / 'multi_bodies' / 'render.py'), '--input-file', 'in.dat',
                             '--size', str(size[0]), str(size[1]), '--view', '20', '-90'] + list(extra_args),
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    return result


def pixel_classes(path):
    import matplotlib.image
    from matplotlib.colors import rgb_to_hsv
    image = matplotlib.image.imread(str(path))[:, :, :3].astype(float)
    hsv = rgb_to_hsv(np.clip(image, 0, 1))
    wall = np.all(np.abs(image - WALL_RGB) < 0.04, axis=2)

    def of_hue(rgb):
        hue = rgb_to_hsv(np.array(rgb))[0]
        return (np.abs(hsv[:, :, 0] - hue) < 0.03) & (hsv[:, :, 1] > 0.5) & (hsv[:, :, 2] > 0.2)

    return image, wall, of_hue([0.122, 0.467, 0.706]), of_hue([1.0, 0.498, 0.055])


def check_picture(path, size):
    image, wall, blue, orange = pixel_classes(path)
    assert image.shape[:2] == (size[1], size[0])
    rows, cols = np.indices(wall.shape)
    assert wall.mean() > 0.05, 'the wall is not drawn'
    assert rows[wall].mean() > 0.5 * size[1], 'the wall is not in the lower half'
    for body, side in ((blue, 'left'), (orange, 'right')):
        assert body.mean() > 0.003, 'the %s body is not drawn' % side
        assert rows[body].mean() < rows[wall].mean(), 'the %s body is not above the wall' % side
    assert cols[blue].mean() < 0.5 * size[0] < cols[orange].mean()


def test_render_writes_a_png_with_wall_and_bodies_on_the_matplotlib_fallback(tmp_path):
    result = render_scene(tmp_path, ['--backend', 'matplotlib', '--png', 'picture.png'])
    assert result.returncode == 0, result.stderr
    check_picture(tmp_path / 'picture.png', (320, 240))


def test_render_with_pyvista_off_screen_draws_the_same_scene(tmp_path):
    needs_pyvista()
    probe = subprocess.run([sys.executable, '-c', 'import pyvista; p = pyvista.Plotter(off_screen=True); '
                            'p.add_mesh(pyvista.Sphere()); p.screenshot(return_img=True)'],
                           capture_output=True, timeout=120)
    if probe.returncode != 0:
        pytest.skip('pyvista cannot render off-screen on this machine (the matplotlib fallback is tested)')
    result = render_scene(tmp_path, ['--backend', 'pyvista', '--png', 'picture.png'])
    assert result.returncode == 0, result.stderr
    # without a display VTK warned "bad X server connection" at every run (issue 47); no warning now
    assert 'X server' not in result.stderr and 'WARN' not in result.stderr, result.stderr
    check_picture(tmp_path / 'picture.png', (320, 240))


def test_render_movie_has_one_frame_per_saved_step(dynamic_run):
    needs('matplotlib', 'render.py needs matplotlib (installed with pyvista)')
    Image = needs('PIL.Image', 'GIFs are written through Pillow (installed with matplotlib)')
    env = {k: v for k, v in os.environ.items() if k not in ('DISPLAY', 'WAYLAND_DISPLAY')}
    env['PYTHONPATH'] = str(REPO)
    result = subprocess.run([sys.executable, str(REPO / 'multi_bodies' / 'render.py'), '--input-file', 'input.dat',
                             '--backend', 'matplotlib', '--size', '160', '120', '--movie', 'run.gif'],
                            cwd=dynamic_run, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    with Image.open(dynamic_run / 'run.gif') as movie:
        assert movie.size == (160, 120)
        assert movie.n_frames == N_STEPS + 1


def test_render_of_a_step_not_saved_says_which_are(tmp_path):
    result = render_scene(tmp_path, ['--backend', 'matplotlib', '--step', '5'])
    assert result.returncode == 2
    assert 'no saved step 5' in result.stderr and 'saved steps are 0' in result.stderr
    assert 'Traceback' not in result.stderr
