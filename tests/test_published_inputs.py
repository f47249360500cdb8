"""Inputs of the published examples and scripts that were refused: a velocity-field plane, the boomerang
analysis flags (-n_runs, --data-name, --profile True).

Numbers asserted come from the same computation reached another way: the plane's velocities equal those
of a box whose cell centres are the same points, the published file naming reads the same trajectories as
the explicit file list.
"""
import numpy as np
import pytest

from run_scenes import copy_scene, edit_input, run_in_process

import mobility
from multi_bodies.files.input_options import parse_input_text
from utils import UserInputError

BACKEND = 'C++' if mobility.backends.is_usable('C++') else 'python'


# ------------------------------------------------------------------ plot_velocity_field with one point in z
def velocity_cells(folder, grid):
    pyvista = pytest.importorskip('pyvista')
    edit_input(folder / 'inputfile.dat', plot_velocity_field=grid)
    status, _, err = run_in_process('static', folder, 'inputfile.dat')
    assert status == 0, err
    mesh = pyvista.read(str(folder / 'data' / 'run.velocity_field.vtk'))
    return np.asarray(mesh.cell_data['velocity']), mesh


def test_velocity_field_plane_equals_the_same_points_of_a_box(tmp_path):
    """``... 3 3 1`` with z0 = z1: a 12 x 16 plane at z = 2; the same points as the centres of a box
    1.5 < z < 2.5 with one cell in z, so both velocities agree to round-off."""
    plane, mesh = velocity_cells(copy_scene(tmp_path / 'plane'), '-6 6 12 -6 10 16 2 2 1')
    box, _ = velocity_cells(copy_scene(tmp_path / 'box'), '-6 6 12 -6 10 16 1.5 2.5 1')
    assert plane.shape == (12 * 16, 3) and mesh.n_cells == 12 * 16
    np.testing.assert_allclose(plane, box, rtol=0, atol=1e-12 * np.max(np.abs(box)))
    assert np.max(np.abs(plane)) > 0


def test_degenerate_axis_needs_one_point():
    assert parse_input_text('plot_velocity_field 0 1 2 0 1 2 3 3 1\n', 'in.dat').plot_velocity_field[2] == (3.0, 3.0, 1)
    with pytest.raises(UserInputError, match='in.dat, line 1.*one point'):
        parse_input_text('plot_velocity_field 0 1 2 0 1 2 3 3 2\n', 'in.dat')


# ------------------------------------------------------------------ boomerang analysis flags of the published code
def test_published_boomerang_analysis_flags(tmp_path, monkeypatch, capsys):
    """``-dt -N -scheme -gfactor -n_runs 2 --data-name ex -end`` reads the runs made with --data-name ex-1 and
    ex-2: the same MSD as the explicit file list; ``--profile True`` prints the cProfile table, ``False`` not."""
    from boomerang import boomerang as script
    from boomerang import calculate_boomerang_msd_from_trajectories as msd_script
    monkeypatch.chdir(tmp_path)
    for k in (1, 2):
        assert script.main(['-dt', '0.01', '-N', '30', '--data-name', 'ex-%d' % k, '--seed', str(k),
                            '--data-dir', str(tmp_path), '--implementation', BACKEND, '--profile', 'False']) in (0, None)
    assert 'function calls' not in capsys.readouterr().out
    files = sorted(str(p) for p in (tmp_path / 'boomerang').glob('*ex-*.txt'))
    assert len(files) == 2
    assert msd_script.main(files + ['--end', '0.1', '--output', str(tmp_path / 'listed')]) == 0
    assert msd_script.main(['-dt', '0.01', '-N', '30', '-scheme', 'RFD', '-gfactor', '1.0', '-n_runs', '2',
                            '--data-name', 'ex', '-end', '0.1', '--data-dir', str(tmp_path),
                            '--output', str(tmp_path / 'named'), '--profile', 'True']) == 0
    assert 'function calls' in capsys.readouterr().out
    np.testing.assert_array_equal(np.loadtxt(tmp_path / 'named.txt'), np.loadtxt(tmp_path / 'listed.txt'))
    with pytest.raises(UserInputError, match='-n_runs'):
        msd_script.main(['-dt', '0.01', '-N', '30', '--data-dir', str(tmp_path)])
    with pytest.raises(SystemExit):
        msd_script.main(files + ['--profile', 'maybe'])


# ------------------------------------------------------------------ later published force names
def roller_snapshot(folder, forces):
    edit_input(folder / 'inputfile_rollers.dat', blob_blob_force_implementation=forces, n_steps=10, n_save=10,
               periodic_length='20 20 0')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_rollers.dat')
    assert status == 0, err
    return np.loadtxt(folder / 'data' / 'rollers.four_rollers.00000010.clones', skiprows=1)


def test_rollers_example_with_the_later_published_force_names(tmp_path):
    """The rollers example (Rollers_Small_Example style) with ``numba`` and ``tree_numba`` runs and gives the
    trajectory of the python all-pairs forces (the cell list neglects pairs whose force is below exp(-30) of
    contact; the rest agrees to round-off), in a box periodic in x and y."""
    python = roller_snapshot(copy_scene(tmp_path / 'python'), 'python')
    for name in ('numba', 'tree_numba'):
        np.testing.assert_allclose(roller_snapshot(copy_scene(tmp_path / name), name), python, rtol=0, atol=1e-10)
