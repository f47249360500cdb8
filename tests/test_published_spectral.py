"""The published Spectral_Multiblob_Roller folder's inputs read as its own script reads them (issue 45, issue 47).

No published file is read here: the scene is built from parts of our own, as that folder's is made:

* the 12-blob shell is the icosahedron of circumradius 0.7921 (the shell ``shell_N_12_Rg_0_7921_Rh_1``), whose
  edge is ``4 r / sqrt(10 + 2 sqrt 5)`` (the regular icosahedron), so the derived blob radius is known in closed
  form;
* the folder module ``FOLDER_MODULE`` below is our own text written with the published calling convention
  (``force_torque_calculator_sort_by_bodies(bodies, r_vectors, *args, **kwargs)`` with the keywords the folder's
  script passes, the ``set_*`` functions, ``preprocess``/``postprocess``, the closing import of
  ``user_defined_functions``).

The rules of the published form (doc/periodic.md) are applied in the tests by hand: the scaled vertex file, the
blob radius, the raised and wrapped start.  The forces reach the bodies: a torque about +y turns the rollers at
about the rate ``2 pi f`` that an isolated sphere of the particle radius would have and rolls them along +x,
slower than rolling without slip.
"""
import math
import os

import numpy as np
import pytest

from run_scenes import run_in_process

ETA = 0.957e-3
PARTICLE_RADIUS = 1.0155
SHELL_RADIUS = 0.7921
FREQUENCY = 9.0  # the keyword f the folder's script passes


def icosahedron(radius):
    """The 12 vertices of a regular icosahedron of circumradius ``radius``, shape (12, 3)."""
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = []
    for s1 in (-1.0, 1.0):
        for s2 in (-1.0, 1.0):
            vertices += [(0.0, s1, s2 * phi), (s1, s2 * phi, 0.0), (s2 * phi, 0.0, s1)]
    vertices = np.array(vertices)
    return radius * vertices / np.linalg.norm(vertices[0])


def icosahedron_edge(radius):
    """Edge length of the regular icosahedron of circumradius ``radius`` (closed form)."""
    return 4.0 * radius / math.sqrt(10.0 + 2.0 * math.sqrt(5.0))


FOLDER_MODULE = '''"""A force module written the way the published folder modules are (our own text)."""
import numpy as np
import os.path
import scipy.spatial as spatial


def bodies_external_force_torque(bodies, r_vectors, *args, **kwargs):
  g = kwargs.get('g')
  eta = kwargs.get('eta')
  radius = kwargs.get('particle_radius')
  spin = 2.0 * np.pi * kwargs.get('f')
  out = np.zeros((2 * len(bodies), 3))
  for k, b in enumerate(bodies):
    out[2 * k, 2] -= g
    out[2 * k + 1, 1] += spin * 8.0 * np.pi * eta * radius ** 3
  return out


def calc_body_body_forces_python(bodies, r_vectors, *args, **kwargs):
  L = kwargs.get('periodic_length')
  radius = kwargs.get('particle_radius')
  points = np.array([b.location for b in bodies]) % np.where(L > 0, L, np.inf)
  tree = spatial.cKDTree(points, boxsize=L)
  out = np.zeros((2 * len(bodies), 3))
  for i, j in tree.query_pairs(3.5 * radius):
    r = points[j] - points[i]
    r -= np.where(L > 0, np.round(r / np.where(L > 0, L, 1.0)) * L, 0.0)
    push = kwargs.get('repulsion_strength') / kwargs.get('debye_length') * r / np.linalg.norm(r)
    out[2 * i] -= push
    out[2 * j] += push
  return out


def zero_bodies(bodies, *args, **kwargs):
  return np.zeros((2 * len(bodies), 3))


def set_body_body_forces_torques(implementation):
  if implementation == 'python':
    return calc_body_body_forces_python
  return zero_bodies


def set_blob_blob_forces(implementation):
  return None


def force_torque_calculator_sort_by_bodies(bodies, r_vectors, *args, **kwargs):
  out = np.zeros((2 * len(bodies), 3))
  out += bodies_external_force_torque(bodies, r_vectors, *args, **kwargs)
  out += calc_body_body_forces_torques(bodies, r_vectors, *args, **kwargs)
  return out


def preprocess(bodies, *args, **kwargs):
  return


def postprocess(bodies, *args, **kwargs):
  return


if os.path.isfile('user_defined_functions.py'):
  import user_defined_functions
'''


def write_folder(folder, locations, box=16.0, extra='', scheme='deterministic_forward_euler', n_steps=2,
                 module=FOLDER_MODULE):
    """A folder like the published one: the shell one folder up (its inputs name ../Structures), the clones file,
    the input (``extra`` lines added) and the folder module (None: none)."""
    from multi_bodies.files.snapshots import write_clones_file
    from multi_bodies.files.structure_files import write_vertex_file
    structures = folder.parent / 'Structures'
    structures.mkdir(parents=True, exist_ok=True)
    write_vertex_file(structures / 'shell_N_12.vertex', icosahedron(SHELL_RADIUS))
    folder.mkdir(parents=True, exist_ok=True)
    locations = np.asarray(locations, dtype=float)
    write_clones_file(folder / 'rollers.clones', locations, np.tile([1.0, 0.0, 0.0, 0.0], (len(locations), 1)))
    (folder / 'input.dat').write_text(
        'scheme %s\nmobility_vector_prod_implementation spectral\nmobility_blobs_implementation C++\n'
        'blob_blob_force_implementation python\nbody_body_force_torque_implementation python\n'
        'repulsion_strength 0.0326\ndebye_length 0.0406\nrepulsion_strength_wall 0.0326\ndebye_length_wall 0.0406\n'
        'dt 0.01\nn_steps %d\nn_save 1\nsolver_tolerance 1e-8\neta %r\ng 0.0303\nblob_radius %r\nkT 0.0040749841\n'
        'periodic_length %r %r 0\noutput_name run\nsave_clones one_file\n%s'
        'structure ../Structures/shell_N_12.vertex rollers.clones\n'
        % (scheme, n_steps, ETA, PARTICLE_RADIUS, box, box, extra))
    if module is not None:
        (folder / 'multi_bodies_functions.py').write_text(module)
    return folder


def prepared(folder, log=None):
    """(options as read, RunSetup) of the folder's input for the dynamics, the set-up log in ``log`` (a list)."""
    from multi_bodies.files.input_options import parse_input_text
    from multi_bodies.run.run_setup import prepare
    cwd = os.getcwd()
    os.chdir(str(folder))
    try:
        options = parse_input_text((folder / 'input.dat').read_text(), 'input.dat', 'dynamic')
        setup = prepare(options, 'dynamics', log=(lambda line: None) if log is None else log.append)
    finally:
        os.chdir(cwd)
    return options, setup


def folder_script_wrap(x, period):
    """The folder script's loops, as written there."""
    while x < 0:
        x += period
    while x > period:
        x -= period
    return x


# ------------------------------------------------------------------------------------ the published reading
def test_the_published_form_is_read_as_the_folder_script_reads_it(tmp_path):
    """No spectral_* line: the vertex file times blob_radius, the blob radius half the smallest blob distance of the
    scaled shell (the icosahedron's edge in closed form), a body below the particle radius raised to 1.01 of it,
    x and y wrapped into the box by the folder's loops; the hooks see particle_radius = blob_radius of the input."""
    box = 16.0
    start = np.array([[4.0, 4.0, 2.5], [-3.0, 5.0, 0.9], [20.5, -7.0, 3.0], [8.0, 35.0, 1.2]])
    folder = write_folder(tmp_path / 'Spectral', start, box, module=None)
    log = []
    _, setup = prepared(folder, log)
    model = setup.system
    a = 0.5 * icosahedron_edge(PARTICLE_RADIUS * SHELL_RADIUS)
    assert model.blob_radius == pytest.approx(a, rel=1e-12)
    assert model.physics['blob_radius'] == pytest.approx(a, rel=1e-12)
    assert model.physics['particle_radius'] == PARTICLE_RADIUS
    assert np.allclose(setup.bodies[0].reference_configuration, PARTICLE_RADIUS * icosahedron(SHELL_RADIUS),
                       rtol=0, atol=1e-12)
    expected = start.copy()
    expected[start[:, 2] < PARTICLE_RADIUS, 2] = 1.01 * PARTICLE_RADIUS
    for row in expected:
        row[0], row[1] = folder_script_wrap(row[0], box), folder_script_wrap(row[1], box)
    assert np.allclose(model.start_configuration.locations, expected, rtol=0, atol=1e-12)
    assert expected[1, 2] == 1.01 * PARTICLE_RADIUS and expected[2, 0] == pytest.approx(4.5)  # the rules acted
    text = '\n'.join(log)
    assert 'spectral_reading published' in text and '1 of 4 bodies below the particle radius raised' in text
    assert '3 moved by whole periods into the box' in text


@pytest.mark.parametrize('extra', ['spectral_reading package\n', 'spectral_kernel w6\n'])
def test_the_manuals_reading_with_any_spectral_line(tmp_path, extra):
    """spectral_reading package, or any other spectral_* line, keeps the manual's meaning: blob_radius is the blob
    radius, the vertex file as written, the start as written; the log says so."""
    start = np.array([[4.0, 4.0, 2.5], [-3.0, 5.0, 2.0]])
    folder = write_folder(tmp_path / 'Spectral', start, 16.0, extra=extra, module=None)
    log = []
    _, setup = prepared(folder, log)
    assert setup.system.blob_radius == PARTICLE_RADIUS
    assert np.allclose(setup.bodies[0].reference_configuration, icosahedron(SHELL_RADIUS), rtol=0, atol=1e-12)
    assert np.array_equal(setup.system.start_configuration.locations, start)
    assert any(line.startswith('spectral_reading package: blob_radius 1.0155 is the blob radius') for line in log)


@pytest.mark.parametrize('change, fragment', [
    (lambda text: text.replace('periodic_length 16.0 16.0 0', 'periodic_length 16.0 16.0 16.0')
     + 'spectral_reading published\n', 'spectral_reading published is the folder\'s box'),
    (lambda text: text + 'particle_radius 2\n', 'the particle radius is blob_radius'),
    (lambda text: text + 'structure ../Structures/wide.vertex wide.clones\n', 'the spectral kernel has one width'),
])
def test_what_the_published_form_cannot_read_is_one_line(tmp_path, change, fragment):
    from multi_bodies.files.structure_files import write_vertex_file
    from utils import UserInputError
    folder = write_folder(tmp_path / 'Spectral', [[4.0, 4.0, 2.5]], 16.0, module=None)
    write_vertex_file(folder.parent / 'Structures' / 'wide.vertex', icosahedron(2 * SHELL_RADIUS))
    (folder / 'wide.clones').write_text('1\n10 10 4 1 0 0 0\n')
    (folder / 'input.dat').write_text(change((folder / 'input.dat').read_text()))
    with pytest.raises(UserInputError) as refused:
        prepared(folder)
    message = str(refused.value)
    assert fragment in message and message.startswith('input.dat, line') and '\n' not in message, message
    assert 'spectral_reading package' in message


def test_the_package_example_is_the_published_form_of_its_scene(tmp_path):
    """multi_bodies/examples/spectral_rollers writes the published scene the manual's way (the shell scaled by the
    particle radius, half the smallest blob distance as blob_radius, spectral_reading package).  Its shell unscaled
    and blob_radius 1.0155 with no spectral_* line, read in the published form, is the same model: the same blob
    radius as the example's line, the same blobs and start, the same velocities."""
    import shutil
    from multi_bodies.files.structure_files import read_vertex_file, write_vertex_file
    example = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'multi_bodies', 'examples',
                           'spectral_rollers')
    package = tmp_path / 'package'
    shutil.copytree(example, package)
    text = (package / 'inputfile_spectral_rollers.dat').read_text()
    (package / 'input.dat').write_text(text)
    published = tmp_path / 'published'
    shutil.copytree(example, published)
    write_vertex_file(published / 'shell.vertex', read_vertex_file(str(package / 'shell_N_12_Rh_1_0155.vertex'))
                      / PARTICLE_RADIUS)
    lines = []
    for line in text.splitlines():
        name = line.split('#', 1)[0].split()[:1]
        if name == ['spectral_reading']:
            continue
        if name == ['blob_radius']:
            example_radius = float(line.split()[1])
            line = 'blob_radius %r' % PARTICLE_RADIUS
        lines.append(line.replace('shell_N_12_Rh_1_0155.vertex', 'shell.vertex'))
    (published / 'input.dat').write_text('\n'.join(lines) + '\n')
    models = [prepared(folder)[1].system for folder in (package, published)]
    assert models[1].blob_radius == pytest.approx(example_radius, rel=1e-12)
    assert models[0].blob_radius == example_radius
    assert np.allclose(models[1].arrays.reference_blobs, models[0].arrays.reference_blobs, rtol=0, atol=1e-12)
    assert np.array_equal(models[1].start_configuration.locations, models[0].start_configuration.locations)
    velocities = [np.asarray(m.replace(solver_tolerance=1e-10).deterministic_velocities(m.start_configuration)
                             .velocities) for m in models]
    assert np.allclose(velocities[1], velocities[0], rtol=1e-7, atol=1e-9 * np.max(np.abs(velocities[0])))


# ------------------------------------------------------------------------------------------ the folder module
def test_the_folder_module_gives_the_forces_and_the_rollers_roll(tmp_path):
    """Two rollers far apart above the wall: the folder module's forces (gravity, the torque 2 pi f 8 pi eta R^3
    about y) reach the bodies; the angular velocity is 2 pi f within the wall's few percent, and they roll along
    +x slower than without slip."""
    folder = write_folder(tmp_path / 'Spectral', [[4.0, 4.0, 2.5], [12.0, 12.0, 2.5]], 16.0)
    _, setup = prepared(folder)
    model = setup.system
    start = model.start_configuration
    force_torque = model.forces_torques(start)
    torque = 2 * np.pi * FREQUENCY * 8 * np.pi * ETA * PARTICLE_RADIUS ** 3
    assert np.allclose(force_torque, [[0, 0, -0.0303, 0, torque, 0]] * 2, rtol=1e-12, atol=1e-15)
    velocities = np.asarray(model.deterministic_velocities(start).velocities).reshape(-1, 6)
    spin = velocities[:, 4]
    # 2 pi f for a sphere of radius R; the 12-blob shell turns a few percent faster (its rotational radius is a
    # little below its translational one, R), the wall slows it by about 2%: 7% above 2 pi f here.  The frequency
    # of omega_one_roller (10 Hz) or a lost factor would fall outside.
    assert np.all((spin / (2 * np.pi * FREQUENCY) > 0.97) & (spin / (2 * np.pi * FREQUENCY) < 1.15)), spin
    assert np.all(velocities[:, 0] > 0.0) and np.all(velocities[:, 0] < spin * PARTICLE_RADIUS), velocities


def test_the_folder_runs_unchanged_and_rolls(tmp_path):
    """The dynamic script in the folder: two steps, the log names the module and the published reading, the
    rollers move along +x."""
    folder = write_folder(tmp_path / 'Spectral', [[4.0, 4.0, 2.5], [12.0, 12.0, 2.5]], 16.0)
    status, out, err = run_in_process('dynamic', folder, 'input.dat')
    assert status == 0, err
    assert "the folder's own module, read as its published multi_bodies.py reads it" in out
    assert 'f=9' in out and 'spectral_reading published' in out
    lines = (folder / 'run.rollers.config').read_text().split('\n')
    frames = [np.array([row.split() for row in lines[k + 1:k + 3]], dtype=float) for k in (0, 6)]
    assert np.all(frames[1][:, 0] > frames[0][:, 0])
    from multi_bodies.files.input_options import parse_input_text
    from multi_bodies.files.run_inputs import restart_inputs
    options = parse_input_text((folder / 'input.dat').read_text(), 'input.dat', 'dynamic')
    assert ('override', 'multi_bodies_functions.py', str(folder / 'multi_bodies_functions.py')) in \
        restart_inputs(options, str(folder))  # a restart checks its content


def test_the_folder_module_is_refused_where_it_is_not_read(tmp_path):
    """Not the published form (spectral_reading package), the static script, a roller scheme: one line naming the
    file, nothing written."""
    folder = write_folder(tmp_path / 'package', [[4.0, 4.0, 2.5]], 16.0, extra='spectral_reading package\n')
    status, out, err = run_in_process('dynamic', folder, 'input.dat')
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith('warning:')]
    assert status == 2 and len(lines) == 1 and 'multi_bodies_functions.py' in lines[0], err
    assert 'published spectral form' in lines[0] and not (folder / 'run.inputfile').exists()
    static = write_folder(tmp_path / 'static', [[4.0, 4.0, 2.5]], 16.0, scheme='body_mobility')
    status, out, err = run_in_process('static', static, 'input.dat')
    assert status == 2 and 'multi_bodies_functions.py' in err
    rollers = write_folder(tmp_path / 'rollers', [[4.0, 4.0, 2.5]], 16.0, scheme='deterministic_forward_euler_rollers')
    (rollers.parent / 'Structures' / 'shell_N_12.vertex').write_text('1\n0 0 0\n')
    status, out, err = run_in_process('dynamic', rollers, 'input.dat')
    assert status == 2 and 'multi_bodies_functions.py' in err


def test_a_user_file_beside_the_folder_module_acts_as_published(tmp_path):
    """The module imports user_defined_functions.py itself: a rebinding (published style) changes its forces; a
    function of its own that the folder's script would never call is refused by name."""
    folder = write_folder(tmp_path / 'Spectral', [[4.0, 4.0, 2.5]], 16.0)
    (folder / 'user_defined_functions.py').write_text(
        'import numpy as np\nimport multi_bodies_functions\n\n'
        'def no_spin(bodies, r_vectors, *args, **kwargs):\n'
        '    out = np.zeros((2 * len(bodies), 3))\n    out[0::2, 0] = 0.25\n    return out\n\n'
        'multi_bodies_functions.bodies_external_force_torque = no_spin\n')
    _, setup = prepared(folder)
    model = setup.system
    assert np.allclose(model.forces_torques(model.start_configuration), [[0.25, 0, 0, 0, 0, 0]])
    (folder / 'user_defined_functions.py').write_text(
        'import numpy as np\n\ndef bodies_external_force_torque(bodies, r_vectors, **kwargs):\n'
        '    return np.zeros((2 * len(bodies), 3))\n')
    from utils import UserInputError
    with pytest.raises(UserInputError, match='defines bodies_external_force_torque, but beside the folder'):
        prepared(folder)


@pytest.mark.parametrize('module, fragment', [
    (FOLDER_MODULE.replace('def preprocess(bodies', 'def preprocess(bodies,,'), 'multi_bodies_functions.py, line'),
    (FOLDER_MODULE.replace('def force_torque_calculator_sort_by_bodies', 'def renamed'),
     'has no force_torque_calculator_sort_by_bodies'),
    (FOLDER_MODULE.replace('  return out\n\n\ndef preprocess', '  return out[:1]\n\n\ndef preprocess'),
     'returned an array of shape (1, 3)'),
    (FOLDER_MODULE.replace("kwargs.get('f')", "kwargs['omega']"), "KeyError: 'omega'"),
])
def test_a_broken_folder_module_stops_before_the_run(tmp_path, module, fragment):
    """A syntax error, a missing function, a wrong shape, a keyword the folder's script does not pass: one line
    naming the file, before any output."""
    folder = write_folder(tmp_path / 'Spectral', [[4.0, 4.0, 2.5]], 16.0, module=module)
    status, out, err = run_in_process('dynamic', folder, 'input.dat')
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith('warning:')]
    assert status == 2 and len(lines) == 1 and fragment in lines[0], err
    assert 'multi_bodies_functions.py' in lines[0] and 'Traceback' not in out + err
    assert not (folder / 'run.inputfile').exists()


def test_the_imp_stand_in_finds_modules_as_imp_did(monkeypatch):
    """Python 3.12 has no imp: the stand-in's find_module raises ImportError for a missing module only."""
    import importlib.util
    from multi_bodies.solver import user_hooks
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, 'find_spec', lambda name, *a: None if name == 'imp' else real(name, *a))
    stand_in = user_hooks._imp_for_old_modules()
    assert stand_in is not None
    stand_in.find_module('numpy')
    with pytest.raises(ImportError):
        stand_in.find_module('no_module_of_this_name_at_all')


def test_the_names_of_the_folder_module_agree():
    from multi_bodies.files import run_inputs
    from multi_bodies.solver import user_hooks
    assert run_inputs.FOLDER_MODULE_FILE == user_hooks.FOLDER_MODULE_COPY
