"""The published phoretic and slip-length example folders (Laplace_sphere, chiral_phoretic_particle, FreeSlip) run
unchanged with this package's multi_bodies.py, their trajectories equal to the published ones; their missing files
get a clear message; the generators write the published .Laplace and .slip_length files (doc/phoretic.md)."""
import importlib.util
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO_ROOT
from multi_bodies.files.snapshots import read_config_series
from multi_bodies.files import structure_generators

PUBLISHED = 'published_2025/phoretic/multi_bodies'
SCRIPT = str(REPO_ROOT / 'multi_bodies' / 'multi_bodies.py')
RUNS = {  # folder: (input file, the published .config it wrote)
    'Laplace_sphere': ('inputfile.dat', 'run.shell.config'),
    'chiral_phoretic_particle': ('inputfile_chiral_phoretic_particle.dat',
                                 'data/run_chiral_phoretic_particle.two_sprinklers.config'),
    'FreeSlip': ('inputfile.dat', 'run.blob.config'),
}


@pytest.fixture
def published_copy(reference_dir, tmp_path):
    """A copy of the published tree (inputs, structures, user files; none of the published outputs)."""
    source = reference_dir / PUBLISHED
    target = tmp_path / 'multi_bodies'
    shutil.copytree(source, target, ignore=shutil.ignore_patterns('run.*', 'run_*', 'probe_*.py'))
    return target


def _run(folder, input_name):
    return subprocess.run([sys.executable, SCRIPT, '--input-file', input_name], cwd=folder, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.parametrize('name', sorted(RUNS))
def test_published_folder_runs_unchanged(reference_dir, published_copy, name):
    folder = published_copy / 'examples' / name
    input_name, config = RUNS[name]
    if name == 'chiral_phoretic_particle':
        shutil.rmtree(folder / 'data', ignore_errors=True)  # the published folder has no data/ folder
    if name == 'FreeSlip' and importlib.util.find_spec('numexpr') is None:
        # its user_defined_functions.py imports numexpr (unused, and its slip function returns zero)
        result = _run(folder, input_name)
        assert result.returncode == 2 and 'imports numexpr' in result.stderr + result.stdout
        (folder / 'user_defined_functions.py').unlink()
    result = _run(folder, input_name)
    assert result.returncode == 0, result.stdout + result.stderr
    ours = read_config_series(str(folder / config))
    published = read_config_series(str(reference_dir / PUBLISHED / 'examples' / name / config))
    for mine, theirs in zip(ours, published):  # locations (S, Nb, 3), then quaternions (S, Nb, 4)
        assert mine.shape == theirs.shape
        # the changes over the run against the published ones (measured: 1e-12 relative or better)
        moved, moved_published = mine[-1] - mine[0], theirs[-1] - theirs[0]
        scale = max(np.max(np.abs(moved_published)), 1e-6)
        assert np.max(np.abs(moved - moved_published)) < 1e-8 * scale + 1e-13, (moved, moved_published)
        np.testing.assert_array_equal(mine[0], theirs[0])
    for third in ('shell_N_42_Rg_0_8913_Rh_1.Laplace',) if name == 'Laplace_sphere' else ():
        assert (folder / ('run.' + third)).is_file()  # the copy of the third file, as published


def test_missing_published_files_get_a_clear_message(published_copy):
    folder = published_copy / 'examples' / 'Laplace_sphere'
    (published_copy / 'Structures' / 'shell_N_42_Rg_0_8913_Rh_1.Laplace').unlink()
    result = _run(folder, 'inputfile.dat')
    assert result.returncode == 2 and 'Traceback' not in result.stderr
    assert 'structure_generators janus-laplace --vertex ../../Structures/shell_N_42_Rg_0_8913_Rh_1.vertex' \
        in result.stderr, result.stderr
    (published_copy / 'Structures' / 'shell.clones').unlink()
    result = _run(folder, 'inputfile.dat')
    assert result.returncode == 2 and "clones file '../../Structures/shell.clones' not found" in result.stderr


def test_generators_write_the_published_files(reference_dir, tmp_path):
    """The Janus-sphere and slip-length generators give the files the published generators made (same numbers)."""
    structures = reference_dir / PUBLISHED / 'Structures'
    path = structure_generators.main(['janus-laplace', '--vertex', str(structures / 'shell_N_42_Rg_0_8913_Rh_1.vertex'),
                                      '--output', str(tmp_path)])
    np.testing.assert_array_equal(np.loadtxt(path), np.loadtxt(structures / 'shell_N_42_Rg_0_8913_Rh_1.Laplace'))
    path = structure_generators.main(['slip-length', '--vertex', str(structures / 'shell_N_162_Rg_1_Rh_1_0530.vertex'),
                                      '--slip-length', '1000', '--output', str(tmp_path)])
    np.testing.assert_array_equal(np.loadtxt(path),
                                  np.loadtxt(structures / 'shell_N_162_Rg_1_slip_length_1e+03.slip_length'))
    # a Janus sphere: the two hemispheres differ, the equator takes the average, and the name says what differs
    path = structure_generators.main(['janus-laplace', '--vertex', str(structures / 'shell_N_42_Rg_0_8913_Rh_1.vertex'),
                                      '--emitting-front', '1', '--emitting-back', '0', '--output', str(tmp_path)])
    assert path.endswith('_janus_alpha.Laplace')
    table, blobs = np.loadtxt(path), np.loadtxt(structures / 'shell_N_42_Rg_0_8913_Rh_1.vertex', skiprows=1)
    expected = np.where(blobs[:, 2] > 0, 1.0, np.where(blobs[:, 2] < 0, 0.0, 0.5))
    np.testing.assert_array_equal(table[:, 4], expected)


def test_concentration_and_vtk_outputs(reference_dir, published_copy):
    """``save_concentration`` writes the blob concentrations and slip of every saved step (step 0: the published
    probe's), ``save_vtk`` adds them to the blob files as point data; without .Laplace files the option is ignored,
    with a warning."""
    from multi_bodies.run.concentration_output import read_concentration_file
    folder = published_copy / 'examples' / 'chiral_phoretic_particle'
    text = (folder / 'inputfile_chiral_phoretic_particle.dat').read_text()
    (folder / 'in.dat').write_text(text + '\nsave_concentration True\nsave_vtk True\nn_steps 2\n')
    result = _run(folder, 'in.dat')
    assert result.returncode == 0, result.stderr
    blocks = read_concentration_file(str(folder / 'data/run_chiral_phoretic_particle.concentration'))
    assert blocks.shape == (3, 144, 7)
    probe = np.load(reference_dir / PUBLISHED / 'examples/chiral_phoretic_particle/data/'
                                                'run_chiral_phoretic_particle.probe.npz')
    np.testing.assert_array_equal(blocks[0, :, :3], probe['step0_r_vectors'])
    assert np.max(np.abs(blocks[0, :, 3] - probe['step0_c'])) < 1e-10 * np.max(np.abs(probe['step0_c']))
    assert np.max(np.abs(blocks[0, :, 4:] - probe['step0_slip'])) < 1e-10 * np.max(np.abs(probe['step0_slip']))
    assert not np.array_equal(blocks[2, :, :3], blocks[0, :, :3])  # the later blocks are at the later steps
    vtp = sorted((folder / 'data').glob('*blobs*.vtp'))
    assert vtp and 'Name="concentration"' in vtp[0].read_text(errors='replace')
    folder = published_copy / 'examples' / 'FreeSlip'
    (folder / 'in.dat').write_text((folder / 'inputfile.dat').read_text() + '\nsave_concentration True\n')
    result = _run(folder, 'in.dat')
    assert result.returncode == 0 and 'save_concentration is ignored' in result.stdout + result.stderr
    assert not (folder / 'run.concentration').exists()


def test_phoretic_restart_continues_exactly(published_copy):
    """4 steps in one run and 2 + 2 steps with initial_step 2 write the same .config byte for byte (the concentration
    warm start is in the restart record)."""
    folder = published_copy / 'examples' / 'chiral_phoretic_particle'
    text = (folder / 'inputfile_chiral_phoretic_particle.dat').read_text()
    full = re.sub(r'(?m)^dt .*$', 'dt 0.5', re.sub(r'(?m)^n_save .*$', 'n_save 2', re.sub(r'(?m)^n_steps .*$',
                                                                                        'n_steps 4', text)))
    runs = {'whole': full.replace('run_chiral', 'whole_chiral'),
            'first': re.sub(r'(?m)^n_steps .*$', 'n_steps 2', full.replace('run_chiral', 'part_chiral')),
            'rest': re.sub(r'(?m)^initial_step.*$', 'initial_step 2', full.replace('run_chiral', 'part_chiral'))}
    for name, content in runs.items():
        (folder / (name + '.dat')).write_text(content)
        result = _run(folder, name + '.dat')
        assert result.returncode == 0, result.stderr
    whole = (folder / 'data/whole_chiral_phoretic_particle.two_sprinklers.config').read_bytes()
    parts = (folder / 'data/part_chiral_phoretic_particle.two_sprinklers.config').read_bytes()
    assert whole == parts and len(whole.splitlines()) == 9


def test_static_mobility_problem_of_the_published_inputs(reference_dir, published_copy):
    """multi_bodies_utilities.py with scheme mobility on the FreeSlip and chiral inputs: the body velocities of the
    published probes (FreeSlip 1e-8, chiral 1e-10 relative); plot_velocity_field is refused with slip lengths.

    The chiral input's concentrations (144 blobs) are solved to its solver_tolerance 1e-10 unpreconditioned, as
    published (the default ``auto`` preconditions them from 400 blobs on), or preconditioned (``preconditioner
    neighbours``).  Two solves that meet the tolerance differ by up to cond(A) times it (measured 1.4e-10 through
    the slip), so the preconditioned solve is held to 1e-9 and the published one to 1e-10 (measured 2e-15)."""
    utilities = str(REPO_ROOT / 'multi_bodies' / 'multi_bodies_utilities.py')
    cases = (('FreeSlip', 'inputfile.dat', 'run', 'run.probe.npz', 1e-8),
             ('chiral_phoretic_particle', 'inputfile_chiral_phoretic_particle.dat', 'data/run_chiral_phoretic_particle',
              'data/run_chiral_phoretic_particle.probe.npz', 1e-10),
             ('chiral_phoretic_particle', 'inputfile_chiral_phoretic_particle.dat', 'data/run_chiral_phoretic_particle',
              'data/run_chiral_phoretic_particle.probe.npz', 1e-9, 'preconditioner neighbours\n'))
    for name, input_name, output, probe, tolerance, *extra in cases:
        folder = published_copy / 'examples' / name
        (folder / 'data').mkdir(exist_ok=True)
        text = re.sub(r'(?m)^scheme .*$', 'scheme mobility', (folder / input_name).read_text()) + ''.join(extra)
        (folder / 'static.dat').write_text(text)
        result = subprocess.run([sys.executable, utilities, '--input-file', 'static.dat'], cwd=folder,
                                capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr
        velocities = np.loadtxt(folder / (output + '.velocities.dat')).reshape(-1, 6)
        published = np.load(reference_dir / PUBLISHED / 'examples' / name / probe)['step0_velocities']
        assert np.max(np.abs(velocities - published)) < tolerance * np.max(np.abs(published)), name
    (folder.parent / 'FreeSlip' / 'field.dat').write_text(
        (folder.parent / 'FreeSlip' / 'static.dat').read_text() + '\nplot_velocity_field -2 2 3 -2 2 3 5 6 2\n')
    result = subprocess.run([sys.executable, utilities, '--input-file', 'field.dat'], cwd=folder.parent / 'FreeSlip',
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and 'plot_velocity_field is not available' in result.stderr
