"""A restart continues exactly or is refused, never silently wrong (issues 27 and 48).

Law: a deterministic program given the same state and inputs writes the same bytes, so a restart from
step 6 of a 12-step run either writes the uninterrupted run's step 12 exactly or is refused in one line
naming what changed.  Checked here:

* the fingerprint a record holds covers every option of the table and every kind of file a program reads
  (each one changed in turn between a run and its restart);
* a record rewritten with its checksum recomputed (forged) is checked field by field before anything is
  allocated or seeked, and every field against what the run needs before it is used.
"""
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from multi_bodies.run import run_output  # noqa: E402
from run_scenes import set_options  # noqa: E402
from safety_scenes import (articulated_scene, driven_scene, forge_record, run_dynamic, set_options_text,  # noqa: E402
                           surface_scene)


# ------------------------------------------------------------------ the fingerprint covers every option and file
# Law: a deterministic program given the same state and inputs writes the same bytes, so a restart from step 6 of a
# 12-step run either writes the uninterrupted run's step 12 exactly or is refused; an input that changes the
# trajectory must be refused with the change named.
NEUTRAL_REFUSED = {'output_name': 'other.a.00000006.clones, which does not exist',  # another name: no step 6
                   'call_HydroGrid': 'call_HydroGrid needs a periodic box'}  # refused as input: this scene has none


def changed_value(name, option, value):
    """Text of another valid value of option ``name`` (current ``value``); None: not changed by this test."""
    from multi_bodies.files.input_options import Choice
    special = {'initial_step': None, 'n_steps': '15', 'n_save': '6', 'output_name': 'data/other',
               'random_state': 'other.random_state', 'seed': '4', 'random_generator': 'default',
               'force_file': 'b.velocity', 'velocity_file': 'b.velocity', 'slip_file': 'a.slip',
               'structure_names': 'a', 'plot_velocity_field': '0 1 2 0 1 2 1 2 2', 'periodic_length': '40 40 0',
               'omega_one_roller': '1 0 0', 'cells': '2 2', 'green_particles': '0 1', 'tracer_radius': '0.5',
               'noise_solver_tolerance': '1e-6', 'scheme': 'stochastic_Slip_Mid', 'kT': '0.5',
               'background_Laplace': '1', 'spectral_z_bounds': '0 10'}
    if name in special:
        return special[name]
    if isinstance(option.rule, Choice):
        others = [choice for choice in option.rule.names if choice != value and choice not in ('auto', 'pycuda')
                  and 'gpu' not in choice.lower() and 'cuda' not in choice.lower()]
        return others[0]
    if option.kind == 'bool':
        return str(not value)
    if option.kind in ('int', 'optional_int'):
        return str((value or 0) + 1)
    if option.kind == 'float':
        return repr(value * 1.01 if value else 0.01)
    raise AssertionError('no changed value for option %s (kind %s): add one' % (name, option.kind))


@pytest.fixture(scope='module')
def twelve_steps(tmp_path_factory):
    """The driven scene run straight to step 12 (n_save 3), with a random_state file it started from."""
    folder = driven_scene(tmp_path_factory.mktemp('twelve') / 'run', n_steps=12)
    for seed, name in ((5, 'start.random_state'), (6, 'other.random_state')):
        run_output.save_random_state(str(folder / name), np.random.Generator(np.random.PCG64(seed)))
    (folder / 'input.dat').write_text(set_options_text(folder, random_state='start.random_state', seed=None))
    assert run_dynamic(folder)[0] == 0
    return folder


def restart_from_6(base, folder, edit=None, **values):
    """Copy of ``base`` restarted from step 6 with ``values`` (option texts) and ``edit(folder)`` applied."""
    shutil.copytree(base, folder)
    if edit is not None:
        edit(folder)
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6, **values))
    return run_dynamic(folder)


def assert_exact_or_refused(base, folder, status, out, err, named=None, refused=False):
    """Refused in one line (naming ``named``), or (not ``refused``) continued to the uninterrupted step 12."""
    assert 'Traceback' not in err + out, err
    if status == 2:  # one line of refusal (after the warnings about lines the scheme ignores)
        assert len([line for line in err.strip().splitlines() if not line.startswith('warning:')]) == 1, err
        assert named is None or named in err, (named, err)
        return 'refused'
    assert status == 0 and not refused, (status, err[-3000:])
    names = sorted(p.name for p in (base / 'data').glob('run.*.00000012.clones'))
    assert names, 'the uninterrupted run saved no step 12'
    for name in names:
        assert (folder / 'data' / name).read_bytes() == (base / 'data' / name).read_bytes(), name
    return 'exact'


def test_the_restart_fingerprint_covers_every_option_of_the_table(twelve_steps, tmp_path):
    """Walk OPTION_TABLE: a restart with an option of the dynamics column changed is refused naming it; with any
    other option changed it continues exactly (or is refused: output_name, which then holds no record)."""
    from multi_bodies.files.input_options import OPTION_TABLE, parse_input_text
    options = parse_input_text((twelve_steps / 'input.dat').read_text(), 'input.dat')
    outcomes = {}
    for name, option in OPTION_TABLE.items():
        value = changed_value(name, option, getattr(options, name))
        if value is None:
            continue
        status, out, err = restart_from_6(twelve_steps, tmp_path / name, **{name: value})
        outcomes[name] = assert_exact_or_refused(twelve_steps, tmp_path / name, status, out, err,
                                                 named=name if option.dynamics else NEUTRAL_REFUSED.get(name),
                                                 refused=option.dynamics)
        assert outcomes[name] == ('refused' if option.dynamics or name in NEUTRAL_REFUSED else 'exact'), \
            (name, err)
        shutil.rmtree(tmp_path / name)
    assert len(outcomes) == len(OPTION_TABLE) - 1  # every option but initial_step, the restart itself
    print('options covered: %d (%d refused, %d exact)' % (len(outcomes), list(outcomes.values()).count('refused'),
                                                          list(outcomes.values()).count('exact')))


def _edit(name, old, new):
    def edit(folder):
        path = folder / name
        text = path.read_text()
        assert old in text, (name, text)
        path.write_text(text.replace(old, new))
    return edit


def _override(folder):
    (folder / 'user_defined_functions.py').write_text('# an override source that overrides nothing\n')


DATA_FILES_OVERRIDE = '''"""Reads the strength of a constant force on every blob from parameters.dat."""
import numpy as np

data_files = ['parameters.dat']


def blob_external_forces(r_vectors, g=1.0, **kw):
    push = float(open('parameters.dat').read())
    forces = np.zeros_like(r_vectors)
    forces[:, 0] = push
    forces[:, 2] = -g
    return forces
'''


def _data_files_scene(folder, **options):
    """The driven scene with an override that declares the data file it reads."""
    folder = driven_scene(folder, **options)
    (folder / 'user_defined_functions.py').write_text(DATA_FILES_OVERRIDE)
    (folder / 'parameters.dat').write_text('0.5\n')
    return folder


FILE_EDITS = {  # kind -> (scene, edit before the restart)
    'vertex': ('driven', _edit('blob.vertex', '0 0 0', '0 0 0.0')),    # same numbers, other text: refused too
    'slip': ('driven', _edit('a.slip', '0.1 0 0', '0.2 0 0')),
    'velocity': ('driven', _edit('b.velocity', '0.2 0 0', '0.3 0 0')),
    'list_vertex': ('articulated', _edit('chain.list_vertex', 'blob.vertex\n', 'blob.vertex  # first\n')),
    'const': ('articulated', _edit('chain.const', '0.1*sin(t)', '0.2*sin(t)')),
    'override': ('driven', _override),
    'override data': ('data_files', _edit('parameters.dat', '0.5', '0.7')),
    'clones': ('driven', _edit('a.clones', '0 0 2.0', '0 0 2.2')),
    'force': ('driven', _edit('b.velocity', '0.2 0 0', '0.3 0 0')),  # placeholder, replaced below
    'random_state': ('driven', None),
    'Laplace': ('Laplace', _edit('shell.Laplace', 'surface file of the fingerprint test', 'an edited header')),
    'slip_length': ('slip_length', _edit('shell.slip_length', 'surface file of the fingerprint test',
                                         'an edited header')),
}


def test_the_restart_fingerprint_covers_every_file_kind(twelve_steps, tmp_path):
    """Every kind of file a program reads: edited before a restart, it is refused with the file named (kinds a
    restart reads) or the run continues exactly (kinds it does not read: FILE_KINDS says why)."""
    from multi_bodies.files.run_inputs import FILE_KINDS
    chain = articulated_scene(tmp_path / 'chain', n_steps=12)
    assert run_dynamic(chain)[0] == 0
    bases = {'driven': twelve_steps, 'articulated': chain,
             'data_files': _data_files_scene(tmp_path / 'data_files', n_steps=12)}
    assert run_dynamic(bases['data_files'])[0] == 0
    for kind in ('Laplace', 'slip_length'):
        bases[kind] = surface_scene(tmp_path / ('base_' + kind), kind, n_steps=12)
        assert run_dynamic(bases[kind])[0] == 0, kind
    edits = dict(FILE_EDITS)
    edits['force'] = ('driven', lambda folder: (folder / 'forces.dat').write_text('1 0 0 0 0 0\n2 0 0 0 0 0\n'))
    edits['random_state'] = ('driven', lambda folder: shutil.copy(folder / 'other.random_state',
                                                                  folder / 'start.random_state'))
    assert set(edits) == set(FILE_KINDS)
    for kind, (scene, edit) in edits.items():
        folder = tmp_path / kind
        values = {'force_file': 'forces.dat'} if kind == 'force' else {}
        if kind == 'force':  # the file named by the run that wrote the records, then edited
            shutil.copytree(bases[scene], tmp_path / 'with_forces')
            (tmp_path / 'with_forces' / 'forces.dat').write_text('0 0 0 0 0 0\n0 0 0 0 0 0\n')
            base = tmp_path / 'with_forces'
        else:
            base = bases[scene]
        status, out, err = restart_from_6(base, folder, edit, **values)
        reads = FILE_KINDS[kind] is True
        named = None
        if reads:
            named = '%s file ' % kind
        outcome = assert_exact_or_refused(base, folder, status, out, err, named=named, refused=reads)
        assert outcome == ('refused' if reads else 'exact'), (kind, err)
    print('file kinds covered: %d' % len(edits))


@pytest.mark.parametrize('line', ["data_files = 'parameters.dat'", 'data_files = [name for name in ("a",)]',
                                  'data_files = [1, 2]'])
def test_data_files_must_be_a_list_of_names_written_as_text(tmp_path, line):
    folder = _data_files_scene(tmp_path / 'run')
    path = folder / 'user_defined_functions.py'
    path.write_text(path.read_text().replace("data_files = ['parameters.dat']", line))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'user_defined_functions.py, line 4: data_files must be a list of file names' in err, err
    assert not (folder / 'data').exists()


def test_an_obstacle_made_a_structure_refuses_the_restart(tmp_path):
    """Changing the last obstacle line to structure between a run and its restart was not refused (4 of 15
    snapshots differed); the fingerprint now holds the kind of every line."""
    base = driven_scene(tmp_path / 'run', n_steps=12)
    text = (base / 'input.dat').read_text().replace('structure blob.vertex b.clones None b.velocity',
                                                    'obstacle blob.vertex b.clones')
    (base / 'input.dat').write_text(set_options(text, scheme='deterministic_adams_bashforth', kT=0))
    assert run_dynamic(base)[0] == 0
    status, out, err = restart_from_6(base, tmp_path / 'changed', _edit('input.dat', 'obstacle blob.vertex',
                                                                          'structure blob.vertex'))
    assert assert_exact_or_refused(base, tmp_path / 'changed', status, out, err, refused=True,
                                   named='structures: was a x 1, b x 1 (obstacle), now a x 1, b x 1') == 'refused'


def test_the_override_sources_covered_are_those_the_programs_import():
    from many_bodyMCMC import mcmc_energy
    from multi_bodies.files.run_inputs import OVERRIDE_FILES
    from multi_bodies.solver import physics
    assert OVERRIDE_FILES == (physics.USER_FILE, physics.USER_PYCUDA_FILE, mcmc_energy.USER_POTENTIAL_FILE,
                              mcmc_energy.GPU_POTENTIAL_FILE)


def test_a_changed_generator_kind_is_a_one_line_refusal(tmp_path):
    """Issue 27, row 4: random_generator published on a restart of a run of the default generator (seed 3)."""
    base = driven_scene(tmp_path / 'run', n_steps=12)
    assert run_dynamic(base)[0] == 0
    status, out, err = restart_from_6(base, tmp_path / 'published', random_generator='published')
    assert assert_exact_or_refused(base, tmp_path / 'published', status, out, err, refused=True,
                                   named='state.rng is the state of the default (PCG64) generator, but this run '
                                         'makes the published generator (random_generator published)') == 'refused'


# ------------------------------------------------------------------ forged records (checksum recomputed)
def _set(*keys_and_value):
    *keys, value = keys_and_value

    def change(record):
        target = record
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value(target[keys[-1]]) if callable(value) else value
    return change


FORGERIES = [  # (save_clones, change of the record of step 6, words of the refusal)
    ('one_file', _set('snapshots', 'a', lambda entry: [entry[0], 2 ** 40]), 'differs from the one its record'),
    ('one_file', _set('config_offsets', 'a', -5), 'config_offsets of a is -5'),
    ('one_file_per_step', _set('snapshots', 'a', lambda entry: [entry[0], str(entry[1])]), 'snapshots of a is'),
    ('one_file_per_step', _set('snapshots', lambda table: list(table.values())), 'snapshots is a list'),
    ('one_file_per_step', _set('state', 'rng', {'bit_generator': 'PCG64', 'state': 'x'}), 'holds no state table'),
    ('one_file_per_step', _set('state', 'rng', 'bit_generator', 'os.system'), 'not one of numpy'),
    ('one_file_per_step', _set('state', 'rng', 'state', 'state', 'seven'), 'does not fit the default (PCG64)'),
    ('one_file_per_step', _set('state', 'rng', {'bit_generator': 'MT19937', 'state': {
        'key': np.eye(1, 624, 0, np.uint32)[0], 'pos': 624}, 'has_gauss': 0, 'gauss': 0.0}),
     'every bit of the MT19937 state is 0'),
    ('one_file_per_step', _set('state', 'locations', np.zeros((3, 3))), 'state.locations holds 3 bodies'),
    ('one_file_per_step', _set('state', 'orientations', np.zeros((2, 5))), 'state.orientations has shape (2, 5)'),
    ('one_file_per_step', _set('state', 'counters', {'steps': -1}), 'state.counters'),
    ('one_file_per_step', _set('state', 'scheme', [[[[[[[[1]]]]]]]]), 'nested more than'),
    ('one_file_per_step', _set('step', 7), 'step is 7, the header says 6'),
    ('one_file_per_step', _set('stop_files', {'a': '../../../etc/passwd'}), 'not a file of the run folder'),
]


@pytest.mark.parametrize('save_clones, change, words', FORGERIES)
def test_a_forged_record_is_a_one_line_refusal_naming_it(tmp_path, save_clones, change, words):
    """Issue 27, row 6: a record rewritten with its checksum recomputed is checked field by field before anything
    is allocated or seeked (once: MemoryError, ValueError, TypeError, AttributeError tracebacks)."""
    folder = driven_scene(tmp_path / 'run', n_steps=12, save_clones=save_clones)
    assert run_dynamic(folder)[0] == 0
    forge_record(str(folder / 'data' / 'run'), 6, change)
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'step 6' in err and words in err, err


def test_an_output_name_with_a_nul_byte_is_a_one_line_refusal(tmp_path):
    """Found by the fuzzer (issue 27): a NUL byte in output_name made open() raise ValueError (a traceback)."""
    folder = driven_scene(tmp_path / 'run')
    (folder / 'input.dat').write_text(set_options_text(folder, output_name='data/r\x00un'))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and 'holds a NUL byte' in err, err
    assert not (folder / 'data').exists()


@pytest.mark.parametrize('offset', [2 ** 70, 2 ** 40, 10 ** 6])
def test_a_forged_config_offset_beyond_the_file_is_one_line(tmp_path, offset):
    """Found by the 30-minute fuzz run (issue 48): a record's config_offsets of 2**70 made the .config reader's
    seek raise ValueError (a traceback); an offset outside the file is now the reader's one-line refusal."""
    folder = driven_scene(tmp_path / 'run', n_steps=12, save_clones='one_file')
    assert run_dynamic(folder)[0] == 0
    forge_record(str(folder / 'data' / 'run'), 6, _set('config_offsets', 'a', offset))
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'run.a.config' in err, err


# ------------------------------------------------------------------ every field against the run (issue 48)
def _zero_first_quaternion(orientations):
    orientations = orientations.copy()
    orientations[0] = 0.0
    return orientations


RUN_FORGERIES = [  # (scene, change of the record of step 6, words of the refusal)
    ('adams_bashforth', _set('state', 'scheme', 'previous_velocities', np.zeros((2, 3))),
     'previous_velocities is a float64 array of shape (2, 3), not the body velocities (2, 6)'),
    ('adams_bashforth', _set('state', 'scheme', 'previous_velocities', np.zeros(12)),
     'previous_velocities is a float64 array of shape (12,)'),
    ('rollers', _set('state', 'scheme', 'previous_velocities', np.zeros((2, 6))), 'roller velocities (2, 3)'),
    ('adams_bashforth', _set('state', 'scheme', 'concentration_guess', {'a': 1}), 'concentration_guess'),
    ('adams_bashforth', _set('state', 'scheme', 'first_guess', np.zeros((3, 6))), 'first_guess is not a flat'),
    ('adams_bashforth', _set('state', 'orientations', _zero_first_quaternion),
     'state.orientations holds a quaternion of norm 0.0'),
    ('adams_bashforth', _set('state', 'scheme', 'preconditioner_configuration',
                             lambda saved: (saved[0], np.zeros_like(saved[1]))) , 'not a unit quaternion'),
    ('adams_bashforth', _set('state', 'locations', lambda locations: locations + 0.1),
     'state.locations are not the positions of the snapshot'),
    ('adams_bashforth', _set('state', 'rng', None), 'state.rng is absent'),
    ('adams_bashforth', _set('fingerprint', None), 'holds no fingerprint'),
    ('adams_bashforth', _set('snapshots', {}), 'snapshots holds no checksum of a, b'),
    ('adams_bashforth', _set('state', 'scheme', None), 'state.scheme is absent'),
]


@pytest.mark.parametrize('scene, change, words', RUN_FORGERIES)
def test_a_record_that_does_not_fit_the_run_is_a_one_line_refusal(tmp_path, scene, change, words):
    """Every field checked against what the run needs before it is used: Adams-Bashforth velocities of another
    shape (a ValueError traceback in every Adams-Bashforth scene), zero quaternions (once used, and written to the
    snapshots), a configuration that is not the snapshot's (once silently replaced by it), required fields
    absent (a record without fingerprint, state or checksums was taken as exact)."""
    from safety_scenes import dynamic_scene
    folder = dynamic_scene(tmp_path / 'run', n_steps=12, n_save=6,
                           **({'scheme': 'stochastic_adams_bashforth_rollers'} if scene == 'rollers' else {}))
    assert run_dynamic(folder)[0] == 0
    before = snapshot_tree(folder / 'data')
    forge_record(str(folder / 'data' / 'run'), 6, change)
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'step 6' in err and words in err, err
    after = snapshot_tree(folder / 'data')
    assert {k: v for k, v in after.items() if k != 'run.restart'} == {k: v for k, v in before.items()
                                                                      if k != 'run.restart'}


def snapshot_tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in Path(folder).rglob('*') if p.is_file()}
