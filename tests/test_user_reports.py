"""What users trying the package found (issue 47): published example folders and mistakes that got no clean
answer.  Each test says which report it answers; the scenes are copies of the shipped examples
(``tests/run_scenes.py``) with the one feature of the report.
"""

import numpy as np
import pytest

from run_scenes import SCRIPT_DIR, copy_scene, edit_input, run_in_process, snapshot_files


def error_lines(err):
    """The lines of stderr that are not warnings."""
    return [line for line in err.splitlines() if line.strip() and not line.startswith('warning:')]


# ---------------------------------------------------------------------------------------------- folder module copy
FOLDER_MODULE = '''
import numpy as np

def bodies_external_force_torque(bodies, r_vectors, *args, **kwargs):
    freq = kwargs.get('f')
    force_torque = np.zeros((2 * len(bodies), 3))
    for k in range(len(bodies)):
        force_torque[2 * k + 1] = 2 * np.pi * freq * np.array([0.0, 1.0, 0.0])
    return force_torque

def preprocess(bodies, *args, **kwargs):
    return
'''


@pytest.mark.parametrize('program', ['dynamic', 'static'])
def test_a_folder_copy_of_multi_bodies_functions_is_refused_by_name(tmp_path, program):
    """Published folders (Spectral_Multiblob_Roller, ...) ship a modified multi_bodies_functions.py that their copy
    of the published multi_bodies.py reads (with keywords it hard-codes, f = 9.0 there); this package read
    user_defined_functions.py only and ran without it (the rollers only sank).  Now: one line naming the file, the
    hooks it defines and what to do, and no output written."""
    folder = copy_scene(tmp_path / 'run')
    name = 'inputfile_dynamic.dat' if program == 'dynamic' else 'inputfile.dat'
    (folder / 'multi_bodies_functions.py').write_text(FOLDER_MODULE)
    before = snapshot_files(folder)
    status, out, err = run_in_process(program, folder, name)
    lines = error_lines(err)
    assert status == 2 and 'Traceback' not in out + err and len(lines) == 1, err
    assert str(folder / 'multi_bodies_functions.py') in lines[0] or 'multi_bodies_functions.py' in lines[0]
    assert 'bodies_external_force_torque, preprocess' in lines[0] and 'user_defined_functions.py' in lines[0]
    assert snapshot_files(folder) == before  # nothing written


def test_the_package_folder_with_its_own_module_is_not_refused():
    """Negative control: the scripts' own folder holds the package's multi_bodies_functions.py (the manual's
    examples run from there)."""
    from multi_bodies.solver.user_hooks import check_folder_module_copy
    assert (SCRIPT_DIR / 'multi_bodies_functions.py').is_file()
    check_folder_module_copy(str(SCRIPT_DIR))


# ---------------------------------------------------------------------------------------------- slip rows
def test_a_slip_file_longer_than_the_body_uses_its_first_rows_with_a_warning(tmp_path):
    """rollers_pillars gives a slip file of 1,536 rows to pillars of 120 blobs; the published code reads the rows
    it needs and ignores the rest, and this package refused the file.  Now the first rows are used with a warning
    naming the file and both counts: the run equals the run with the trimmed file (extra rows of slip 5 would move
    the squirmer if they were used), and a file with fewer rows than blobs is still an error."""
    from run_scenes import add_generated_inputs
    folder = add_generated_inputs(copy_scene(tmp_path / 'run'))
    slip = folder / 'Structures' / 'shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip'
    rows = [line for line in slip.read_text().splitlines() if line.strip() and not line.startswith('#')]
    assert int(rows[0].split()[0]) == 42 and len(rows) == 43
    (folder / 'Structures' / 'long.slip').write_text('%d\n' % 50 + '\n'.join(rows[1:]) + '\n' + '5 5 5\n' * 8)
    (folder / 'Structures' / 'short.slip').write_text('%d\n' % 40 + '\n'.join(rows[1:41]) + '\n')
    text = (folder / 'inputfile_squirmer.dat').read_text()
    runs = {}
    for name in ('shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1', 'long'):
        (folder / ('in_%s.dat' % name)).write_text(
            text.replace('shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip', name + '.slip')
            .replace('data/squirmer', 'data/%s' % name))
        status, out, err = run_in_process('dynamic', folder, 'in_%s.dat' % name)
        assert status == 0, err
        runs[name] = (err, sorted((folder / 'data').glob('%s.squirmer.*.clones' % name)))
    warning = [line for line in runs['long'][0].splitlines() if 'long.slip' in line]
    assert len(warning) == 1 and 'has 50 rows for the 42 blobs' in warning[0] and 'other 8 ignored' in warning[0]
    assert 'slip file' not in runs['shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1'][0]
    trimmed, long = runs['shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1'][1], runs['long'][1]
    assert len(trimmed) == len(long) == 3
    for a, b in zip(trimmed, long):
        assert a.read_text().split() == b.read_text().split()
    assert trimmed[0].read_text().split() != trimmed[-1].read_text().split()  # the squirmer moved
    (folder / 'in_short.dat').write_text(text.replace('shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip', 'short.slip'))
    status, out, err = run_in_process('dynamic', folder, 'in_short.dat')
    assert status == 2 and 'short.slip has 40 blobs but vertex file' in err, err


# ---------------------------------------------------------------------------------------------- later options
def test_domType_is_named_as_the_cRigid_cFibers_domain_not_lubrication():
    """cRigid_cFibers/Rigid_Rods/rods_input.dat (an input of the published Rigid_Object_Main.py) was refused on
    domType with a message that put it under lubrication; the refusal says what the option is and that fibres are
    not supported."""
    from multi_bodies.files.input_options import parse_input_text
    from utils import UserInputError
    for line in ('domType RPB', 'zmax 8.0'):
        with pytest.raises(UserInputError) as refusal:
            parse_input_text('dt 0.001\n%s\n' % line, 'rods_input.dat', 'dynamic')
        message = str(refusal.value)
        assert message.startswith('rods_input.dat, line 2: option') and 'cRigid_cFibers' in message
        assert 'geometry' in message and 'fibres' in message and 'Rigid_Object_Main.py' in message
        assert 'lubrication' not in message.lower()


def test_omega_one_roller_is_not_called_ignored_when_the_user_functions_read_it(tmp_path):
    """Multi_Blob_Two_Rollers sets omega_one_roller with a rigid scheme and its override turns it into the torque
    that rolls the shells; the warning said the value was ignored and should be removed (removing it stops the
    rollers).  Now the warning is given only when no function of user_defined_functions.py reads the option:
    here the shells roll (x grows) and nothing is said; the same scene with an override that does not read it
    gets the warning (negative control)."""
    from test_published_hooks import TWO_ROLLERS_OVERRIDE, two_shell_scene
    options = dict(scheme='deterministic_adams_bashforth', omega_one_roller='0 62.8 0', n_steps=2,
                   blob_blob_force_implementation='None', body_body_force_torque_implementation='None')
    folder = two_shell_scene(tmp_path / 'reads', TWO_ROLLERS_OVERRIDE, **options)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_rollers.dat')
    assert status == 0 and 'omega_one_roller' not in err, err
    lines = (folder / 'run_two_rollers' / 'data.two_rollers.config').read_text().split('\n')
    assert np.all(np.array([float(line.split()[0]) for line in lines[-3:-1]]) > np.array([-1.5, 1.5]))
    plain = TWO_ROLLERS_OVERRIDE.replace("kwargs['omega_one_roller']", 'np.zeros(3)')
    folder = two_shell_scene(tmp_path / 'ignores', plain, **options)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_rollers.dat')
    warning = [line for line in err.splitlines() if "option 'omega_one_roller' is ignored" in line]
    assert status == 0 and len(warning) == 1 and 'user_defined_functions.py that read it (none here)' in warning[0]


# ---------------------------------------------------------------------------------------------- mistakes
@pytest.mark.parametrize('program, scheme, name', [('dynamic', 'mobility', 'inputfile_dynamic.dat'),
                                                   ('static', 'deterministic_adams_bashforth', 'inputfile.dat')])
def test_a_scheme_of_the_other_script_gets_its_one_line_first(tmp_path, program, scheme, name):
    """`scheme mobility` given to multi_bodies.py printed three warnings about dt, n_steps and n_save (options a
    static problem ignores) before the real message; now the only line is the refusal naming the other script."""
    folder = copy_scene(tmp_path / 'run')
    edit_input(folder / name, scheme=scheme)
    status, out, err = run_in_process(program, folder, name)
    lines = [line for line in err.splitlines() if line.strip()]
    assert status == 2 and len(lines) == 1, err
    assert "scheme '%s' is not for this program" % scheme in lines[0]
    assert ('multi_bodies_utilities.py' if program == 'dynamic' else 'multi_bodies.py') in lines[0]


@pytest.mark.parametrize('given, words', [('nothere/missing.config', 'nothere/missing.config: no such file'),
                                          ('plain.config', 'plain.config: the name does not say the run')])
def test_analyse_names_the_config_file_it_was_given(tmp_path, monkeypatch, capsys, given, words):
    """analyse.py --config of a missing file said "snapshot file 'nothere/.missing.config' not found", a path the
    user never gave; now the message names the given path and the expected name form."""
    import importlib
    import utils
    analyse = importlib.import_module('multi_bodies.analyse')
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'plain.config').write_text('1\n0 0 1 1 0 0 0\n')
    with pytest.raises(SystemExit) as stop:
        utils.fail_cleanly(analyse.main, ['--config', given, '--gr', '--frame-interval', '1'])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and ('--config %s' % words) in err and '/.missing' not in err, err


@pytest.mark.parametrize('scheme', ['lubrication_trapezoidal', 'lubrication_trapezoidal_rollers'])
def test_a_lubrication_scheme_on_multiblob_bodies_writes_nothing(tmp_path, scheme):
    """A lubrication scheme on the manual's boomerang and shells was refused only after the step-0 files were
    written; now the refusal comes while the run is set up, and the run folder is left as it was."""
    folder = copy_scene(tmp_path / 'run')
    (folder / 'data').mkdir()
    edit_input(folder / 'inputfile_dynamic.dat', scheme=scheme)
    before = snapshot_files(folder)
    status, out, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    lines = error_lines(err)
    assert status == 2 and len(lines) == 1, err
    assert ('single-blob bodies' if 'rollers' in scheme else 'every body must be a single blob') in lines[0], err
    assert snapshot_files(folder) == before and not list((folder / 'data').iterdir())


def test_two_bodies_at_the_same_position_are_refused_or_named(tmp_path):
    """Two bodies at the same position ran silently (GMRES from 2-5 to 124 iterations a step).  Two shells with
    the same blobs at one position (a copied clones line): refused in one line naming both bodies and their
    file, nothing written; a boomerang moved onto a shell's centre (different blobs): a warning naming both, and
    the run goes on.  Negative control: the manual's scene as shipped gets neither."""
    folder = copy_scene(tmp_path / 'run')
    edit_input(folder / 'inputfile_dynamic.dat', n_steps=1)
    status, out, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0 and 'same position' not in err, err
    clones = folder / 'Structures' / 'shell_N_12_Rg_1.clones'
    clones.write_text('3\n5 0 5 1 0 0 0\n0 5 5 1 0 0 0\n5 0 5 1 0 0 0\n')
    status, out, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    lines = error_lines(err)
    assert status == 2 and len(lines) == 1, err
    assert 'body 0 of shell_N_12_Rg_1' in lines[0] and 'body 2 of shell_N_12_Rg_1' in lines[0]
    assert 'same position 5 0 5' in lines[0] and 'singular' in lines[0]
    clones.write_text('2\n5 0 5 1 0 0 0\n0 5 5 1 0 0 0\n')
    (folder / 'Structures' / 'boomerang_N_15.clones').write_text('1\n5 0 5 0.5 0.5 0.5 0.5\n')
    edit_input(folder / 'inputfile_dynamic.dat', output_name='data/second')
    status, out, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    warning = [line for line in err.splitlines() if 'same position' in line]
    assert status == 0 and len(warning) == 1 and warning[0].startswith('warning:'), err
    assert 'body 0 of boomerang_N_15' in warning[0] and 'body 0 of shell_N_12_Rg_1' in warning[0]


# ---------------------------------------------------------------------------------------------- charts
def overlapping_tick_labels(figure):
    """Pairs of visible tick labels (inside the axes' span) whose boxes overlap, on either axis."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    axes = figure.axes[0]
    count = 0
    for axis, (low, high) in ((axes.xaxis, axes.get_xlim()), (axes.yaxis, axes.get_ylim())):
        ticks = list(zip(axis.get_majorticklocs(), axis.get_ticklabels(which='major'))) + \
            list(zip(axis.get_minorticklocs(), axis.get_ticklabels(which='minor')))
        boxes = [label.get_window_extent(renderer) for where, label in ticks
                 if label.get_visible() and label.get_text() and min(low, high) <= where <= max(low, high)]
        count += sum(boxes[i].overlaps(boxes[j]) for i in range(len(boxes)) for j in range(i + 1, len(boxes)))
    return count


@pytest.mark.parametrize('span', [(0.016, 0.4), (0.05, 0.12), (1e-3, 30.0)])
def test_msd_and_fkt_charts_have_no_overlapping_tick_labels(span, monkeypatch):
    """The MSD and F(k, t) charts (log time axis) labelled the minor ticks of a span under a decade, and the
    labels ran into each other; now every visible label is clear of the others.  Negative control: without
    hide_overlapping_tick_labels the first span overlaps."""
    pytest.importorskip('matplotlib')
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from multi_bodies.analysis import tables
    t = np.geomspace(*span, 25)
    curves = [('x', t, 0.01 * t, None), ('y', t, 0.02 * t, 0.001 * t)]
    for title, y_label in (('mean-square displacement', 'MSD'), ('intermediate scattering function', 'F(k,t)')):
        figure = tables.build_chart(title, 'time', y_label, curves, log_x=True)
        assert overlapping_tick_labels(figure) == 0, (span, title)
        plt.close(figure)
    if span == (0.016, 0.4):
        monkeypatch.setattr(tables, 'hide_overlapping_tick_labels', lambda figure, axes: None)
        figure = tables.build_chart('mean-square displacement', 'time', 'MSD', curves, log_x=True)
        assert overlapping_tick_labels(figure) > 0
        plt.close(figure)


def test_a_velocity_file_may_start_with_the_number_of_bodies(tmp_path):
    """The published rollers_pillars gives its pillars' velocity file a first line '7' (the number of bodies); it
    was refused.  Now a leading line holding the number of bodies alone is skipped: the table equals the one
    without it, and a first line with another number is still an error naming the file."""
    from multi_bodies.files.structure_files import read_body_table
    from utils import UserInputError
    rows = '1 2 3 4 5 6\n0 0 0 0 0 0.5\n-1 0 0 0 0 0\n'
    (tmp_path / 'plain.dat').write_text(rows)
    (tmp_path / 'counted.dat').write_text('3\n' + rows)
    (tmp_path / 'wrong.dat').write_text('4\n' + rows)
    plain = read_body_table(str(tmp_path / 'plain.dat'), 3, 'velocity')
    np.testing.assert_array_equal(read_body_table(str(tmp_path / 'counted.dat'), 3, 'velocity'), plain)
    assert plain.shape == (3, 6) and plain[1, 5] == 0.5
    with pytest.raises(UserInputError, match='wrong.dat, line 1: expected six numbers'):
        read_body_table(str(tmp_path / 'wrong.dat'), 3, 'velocity')
