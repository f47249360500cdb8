"""Writers as one protocol (issue 43): a user's writer plugs into the dynamic run and Monte Carlo alike.

The protocol (``multi_bodies.run.writers``): ``open(run)``, ``write(frame)`` when ``trigger(frame)``,
``flush()`` after every save, ``close()``.  Checked here:

* a writer of our own (the centre of mass every n steps, written against the protocol only) runs in a dynamic run,
  a Monte Carlo chain and an ensemble replica: it is written at exactly the multiples of n (the trigger's law),
  opened and closed once, flushed at every save, and the centre of mass it records at a saved step is the mean of
  the locations in that step's snapshot (read back with the package's snapshot reader, another writer's file);
* a new run moves the user writer's file of an earlier run with the same ``output_name`` aside (issue 48);
* the writer set checks the lock before any writer writes a save, and the writers that feed the record take their
  bytes back when the record cannot be written (and only then);
* Monte Carlo's step is a scheme-like step: the state it is given is left unchanged, the same state gives the same
  next state, and the chain through the run loop is the sampler's own chain driven by hand with one generator.
"""
import os
from pathlib import Path

import numpy as np
import pytest

from multi_bodies.files.input_options import read_input_file
from multi_bodies.files.snapshots import read_clones_file
from multi_bodies.run import run_output, writers


class CentreOfMass(writers.Writer):
    """A user's writer: ``output_name.com.dat``, one line ``step x y z`` every ``period`` steps."""
    suffixes = ('com.dat',)

    def __init__(self, period):
        self.trigger = writers.Periodic(period)
        self.rows, self.calls, self.file = [], [], None

    def open(self, run):
        self.path = run.output_name + '.com.dat'
        self.file = open(self.path, 'a' if run.restart else 'w')
        self.calls.append('open')

    def write(self, frame):
        centre = np.mean(frame.locations, axis=0)
        self.file.write('%d %r %r %r\n' % ((frame.step,) + tuple(float(v) for v in centre)))
        self.rows.append((frame.step, centre))

    def flush(self):
        self.file.flush()
        self.calls.append('flush')

    def close(self):
        self.file.close()
        self.calls.append('close')


class Ending(writers.Writer):
    """Counts the frames of an AtEnd trigger."""
    trigger = writers.AtEnd()

    def __init__(self):
        self.steps = []

    def write(self, frame):
        self.steps.append(frame.step)


def dynamic_folder(folder, n_steps=10, n_save=4):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'a.clones').write_text('2\n0 0 2.0 1 0 0 0\n2.5 0 2.5 1 0 0 0\n')
    (folder / 'input.dat').write_text(
        'scheme stochastic_adams_bashforth\ndt 0.01\nn_steps %d\nn_save %d\neta 1.0\ng 0.5\nblob_radius 0.5\n'
        'kT 1.0\nseed 3\nrepulsion_strength_wall 1.0\ndebye_length_wall 0.2\nmobility_blobs_implementation python\n'
        'mobility_vector_prod_implementation python\nblob_blob_force_implementation python\n'
        'solver_tolerance 1e-10\noutput_name data/run\nstructure blob.vertex a.clones\n' % (n_steps, n_save))
    return folder


def mcmc_folder(folder, n_steps=10, n_save=4, move='one_body'):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'a.clones').write_text('2\n0 0 2.0 1 0 0 0\n1.5 0 2.0 1 0 0 0\n')
    (folder / 'input.dat').write_text(
        'n_steps %d\nn_save %d\nkT 1.0\ng 1.0\nblob_radius 0.5\nrepulsion_strength_wall 1.0\ndebye_length_wall 0.5\n'
        'max_translation 0.1\nseed 5\noutput_name data/run\nmcmc_move %s\nmcmc_energy_implementation python\n'
        'structure blob.vertex a.clones\n' % (n_steps, n_save, move))
    return folder


def run_program(program, folder, monkeypatch, *user_writers):
    monkeypatch.chdir(folder)
    if program == 'dynamic':
        from multi_bodies.run.dynamic_run import run_dynamics
        return run_dynamics(read_input_file('input.dat'), log=lambda text: None, writers=user_writers)
    from many_bodyMCMC.mcmc_run import run_mcmc
    return run_mcmc(read_input_file('input.dat', program='mcmc'), log=lambda text: None, writers=user_writers)


def check_centre_of_mass(writer, folder, period, n_steps, n_save):
    steps = [row[0] for row in writer.rows]
    assert steps == list(range(0, n_steps + 1, period))  # the trigger's law: every multiple of the period
    saves = list(range(0, n_steps + 1, n_save))
    assert writer.calls == ['open'] + ['flush'] * len(saves) + ['close']
    table = np.loadtxt(str(folder / 'data' / 'run.com.dat'), ndmin=2)
    assert table[:, 0].astype(int).tolist() == steps
    centres = dict(writer.rows)
    compared = 0
    for step in saves:  # at a saved step: the mean of the snapshot's locations, read back from its file
        if step in centres:
            locations, _ = read_clones_file(str(folder / 'data' / ('run.a.%08d.clones' % step)))
            assert np.allclose(centres[step], np.mean(locations, axis=0), rtol=0, atol=1e-12)
            compared += 1
    assert compared >= 2
    assert np.ptp(table[:, 3]) > 0  # the bodies moved: the frames are not one configuration written again


@pytest.mark.parametrize('program', ['dynamic', 'mcmc'])
def test_a_users_writer_plugs_into_the_run(tmp_path, monkeypatch, program):
    folder = (dynamic_folder if program == 'dynamic' else mcmc_folder)(tmp_path / 'run')
    writer, ending = CentreOfMass(2), Ending()
    assert run_program(program, folder, monkeypatch, writer, ending) == 0
    check_centre_of_mass(writer, folder, 2, 10, 4)
    assert ending.steps == [10]  # once, after the last step


def test_a_users_writer_plugs_into_an_ensemble_replica(tmp_path, monkeypatch):
    from multi_bodies.ensembles import ensemble_runner as runner
    folder = dynamic_folder(tmp_path / 'scene')
    made = []

    def make_writers(options):
        made.append(CentreOfMass(3))
        return made[-1:]

    plan = runner.build_plan(str(folder / 'input.dat'), 1, output_dir=str(tmp_path / 'ensemble'), master_seed=7)
    runner.write_plan(plan)
    spec = runner.replica_specs(plan)[0]
    result = runner.run_replica(spec, make_writers=make_writers)
    assert result['status'] == 'done', result
    assert len(made) == 1 and [row[0] for row in made[0].rows] == [0, 3, 6, 9]
    assert made[0].calls[0] == 'open' and made[0].calls[-1] == 'close'
    path = Path(os.path.abspath(os.path.join(spec['run_directory'], made[0].path)))
    assert path.is_file() and Path(spec['path']).resolve() in path.resolve().parents  # beside the replica's outputs


def test_a_new_run_sets_the_users_earlier_file_aside(tmp_path, monkeypatch):
    folder = mcmc_folder(tmp_path / 'run')
    first = CentreOfMass(5)
    assert run_program('mcmc', folder, monkeypatch, first) == 0
    earlier = (folder / 'data' / 'run.com.dat').read_text()
    second = CentreOfMass(5)
    assert run_program('mcmc', folder, monkeypatch, second) == 0
    aside = list((folder / 'data' / ('run' + run_output.ASIDE_SUFFIX)).rglob('run.com.dat'))
    assert len(aside) == 1 and aside[0].read_text() == earlier
    assert (folder / 'data' / 'run.com.dat').read_text().count('\n') == 3  # steps 0, 5, 10 of the new run only


def test_periodic_trigger_law_and_refusal():
    run = type('Run', (), {'dt': 0.5})()
    fired = [k for k in range(12) if writers.Periodic(3, phase=1)(writers.Frame(k, 'step', None, None, None, run))]
    assert fired == [1, 4, 7, 10]
    assert not writers.Periodic(1)(writers.Frame(4, 'stop', None, None, None, run))
    assert writers.OnSave(stops=True)(writers.Frame(5, 'stop', None, None, None, run))
    assert not writers.OnSave()(writers.Frame(5, 'stop', None, None, None, run))
    assert writers.Frame(4, 'save', None, None, None, run).time == 2.0
    with pytest.raises(ValueError):
        writers.Periodic(0)


class Recording(writers.Writer):
    def __init__(self, log, name, feeds=False, fails=False):
        self.log, self.name, self.feeds_record, self.fails = log, name, feeds, fails

    def write(self, frame):
        if self.fails:
            raise OSError(28, 'No space left on device', self.name)
        self.log.append('write ' + self.name)
        if self.feeds_record:
            frame.side_files[self.name] = [0, 1]

    def take_back(self, frame):
        self.log.append('take back ' + self.name)


class Lock:
    def __init__(self, log, lost=False):
        self.log, self.lost = log, lost

    def check(self):
        self.log.append('lock')
        if self.lost:
            raise run_output.LockLost(16, 'taken', 'run.lock')


def save_frame(writer_set):
    run = type('Run', (), {'dt': 1.0})()
    writer_set.run = run
    return writers.Frame(4, 'save', np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), None, run)


def test_the_set_checks_the_lock_first_and_takes_back_an_unsaved_step():
    log = []
    side = Recording(log, 'side', feeds=True)
    ok = writers.WriterSet(Recording(log, 'record'), [Recording(log, 'after'), side], lock=Lock(log))
    frame = save_frame(ok)
    ok.write(frame)
    assert log == ['lock', 'write side', 'write record', 'write after'] and frame.side_files == {'side': [0, 1]}

    log.clear()  # the record cannot be written: the side file's bytes are taken back, the error raised
    failing = writers.WriterSet(Recording(log, 'record', fails=True), [Recording(log, 'after'), side], lock=None)
    with pytest.raises(OSError):
        failing.write(save_frame(failing))
    assert log == ['write side', 'take back side']

    log.clear()  # a writer after the record fails: the step is saved, nothing is taken back
    late = writers.WriterSet(Recording(log, 'record'), [Recording(log, 'after', fails=True), side])
    with pytest.raises(OSError):
        late.write(save_frame(late))
    assert log == ['write side', 'write record']

    log.clear()  # the lock was taken: no writer writes
    lost = writers.WriterSet(Recording(log, 'record'), [side], lock=Lock(log, lost=True))
    with pytest.raises(run_output.LockLost):
        lost.write(save_frame(lost))
    assert log == ['lock']


@pytest.mark.parametrize('move', ['one_body', 'all_bodies'])
def test_the_monte_carlo_step_is_a_scheme_step(tmp_path, monkeypatch, move):
    """State in, state out: the given state is left as it was and the same state gives the same next state; the
    chain of the run loop is the sampler's chain driven by hand with the run's generator."""
    from many_bodyMCMC.mcmc_run import MCMCRun
    from many_bodyMCMC.sampler import MetropolisSampler
    folder = mcmc_folder(tmp_path / 'run', n_steps=12, n_save=12, move=move)
    monkeypatch.chdir(folder)
    options = read_input_file('input.dat', program='mcmc')
    chain = MCMCRun(options, log=lambda text: None)
    state = chain.scheme.init(0, chain.rng.bit_generator.state)
    before = (state.locations.copy(), state.orientations.copy(), state.r_vectors.copy(), dict(state.rng_state))
    one = chain.scheme.step(chain.model, state)
    assert np.array_equal(state.locations, before[0]) and np.array_equal(state.orientations, before[1])
    assert np.array_equal(state.r_vectors, before[2]) and state.rng_state == before[3]
    again = chain.scheme.step(chain.model, state)
    assert one.step == again.step == 1 and np.array_equal(one.locations, again.locations)
    assert one.counters == again.counters and one.rng_state == again.rng_state
    two = chain.scheme.step(chain.model, again)  # continues the generator the last step left
    two_again = chain.scheme.step(chain.model, again)  # from the same state again: the same numbers
    assert np.array_equal(two.locations, two_again.locations) and two.rng_state == two_again.rng_state
    assert two.rng_state != again.rng_state and two.counters[0] > again.counters[0]  # a step was made

    assert chain.run() == 0  # the run starts from the state made when it was set up, whatever was stepped since
    saved, _ = read_clones_file(str(folder / 'data' / 'run.a.00000012.clones'))
    start = read_clones_file(str(folder / 'a.clones'))
    longest = max(body.body_length for body in chain.bodies)
    by_hand = MetropolisSampler(chain.energy, start[0], start[1], options.kT, 0.1, 0.1 / longest, move,
                                options.n_burn_in, options.target_acceptance)
    rng = run_output.make_generator(options)
    for step in range(12):
        by_hand.step(step, rng)
    assert np.array_equal(saved, by_hand.locations)


def test_the_writer_example_of_the_manual_runs_as_written(tmp_path, monkeypatch, capsys):
    """doc/dynamics.md's centre-of-mass writer, run as written from a copy of ``multi_bodies/``'s input and
    structures: a line every 5 steps, and the first is the mean of the starting locations."""
    import re
    import shutil
    repo = Path(__file__).resolve().parents[1]
    text = (repo / 'doc' / 'dynamics.md').read_text()
    section = text[text.index('## Adding a writer'):]
    block = re.search(r'```python\n(.*?)```', section, flags=re.S).group(1)
    shutil.copy(str(repo / 'multi_bodies' / 'inputfile_brownian.dat'), str(tmp_path))
    (tmp_path / 'Structures').mkdir()
    for name in ('boomerang_N_15.vertex', 'boomerang_N_15.clones', 'shell_N_12_Rg_1.vertex',
                 'shell_N_12_Rg_1.clones'):
        shutil.copy(str(repo / 'multi_bodies' / 'Structures' / name), str(tmp_path / 'Structures'))
    monkeypatch.chdir(tmp_path)
    exec(compile(block, 'doc/dynamics.md', 'exec'), {'__name__': 'doc_example'})
    table = np.loadtxt('data/com_example.com.dat', ndmin=2)
    assert table[:, 0].astype(int).tolist() == [0, 5, 10, 15, 20]
    assert np.allclose(table[:, 1], 0.01 * table[:, 0], rtol=0, atol=1e-15)  # time = step * dt
    starts = np.concatenate([read_clones_file('Structures/%s.clones' % name)[0]
                             for name in ('boomerang_N_15', 'shell_N_12_Rg_1')])
    assert np.allclose(table[0, 2:], starts.mean(axis=0), rtol=0, atol=1e-12)
    assert any(line.startswith('0 0 0 ') for line in capsys.readouterr().out.splitlines())  # status 0, step 0
