"""The stochastic schemes repeat themselves and restart exactly (issue: Brownian dynamics).

Law: a program given the same seed, or the same saved generator state, draws the same numbers and writes
the same bytes; so the same seed gives bit-identical snapshots (another seed does not), the
``.random_state`` a run saved reproduces it, and 4 steps plus 6 restarted steps equal 10 steps bit for bit
(the restart needs the preconditioner configuration, the solver guess, the generator and the
Adams-Bashforth history).  Every stochastic scheme name of the manual runs.
"""
import os

import numpy as np
import pytest

from brownian_scene import A, CPP, ETA, RIGID_DENSE, RIGID_ITERATIVE, ROLLERS, equilibrium_blobs
from multi_bodies.files import structure_generators as gen


# ====================================================================== reproducibility and exact restart
def write_scene(tmp_path, scheme, n_steps, extra=None, initial_step=0):
    bodies = equilibrium_blobs(6, 300) if 'rollers' in scheme else None
    from multi_bodies.files.snapshots import write_clones_file
    from multi_bodies.files.structure_files import write_vertex_file
    if 'rollers' in scheme:
        write_vertex_file(tmp_path / 'blob.vertex', np.zeros((1, 3)))
        write_clones_file(tmp_path / 'blobs.clones', np.array([b.location for b in bodies]),
                          np.tile([1.0, 0, 0, 0], (len(bodies), 1)))
        structure = 'structure blob.vertex blobs.clones'
        radius = A
    else:
        reference = gen.boomerang()
        write_vertex_file(tmp_path / 'boomerang.vertex', reference)
        write_clones_file(tmp_path / 'boomerang.clones', np.array([[0, 0, 2.0], [3.0, 0.5, 2.5]]),
                          np.array([[1.0, 0, 0, 0], [0.9, 0.1, 0.3, 0.2]]) / np.linalg.norm([0.9, 0.1, 0.3, 0.2]))
        structure = 'structure boomerang.vertex boomerang.clones'
        radius = 0.3
    options = {'scheme': scheme, 'dt': 0.01, 'n_steps': n_steps, 'n_save': 2, 'eta': ETA, 'g': 0.2,
               'blob_radius': radius, 'kT': 0.5, 'repulsion_strength_wall': 2.0, 'debye_length_wall': 0.25,
               'mobility_vector_prod_implementation': CPP, 'mobility_blobs_implementation': 'python',
               'solver_tolerance': 1e-6, 'output_name': 'run', 'update_PC': 3}
    if initial_step:
        options['initial_step'] = initial_step
    options.update(extra or {})
    text = '\n'.join('%s %s' % item for item in options.items()) + '\n' + structure + '\n'
    (tmp_path / 'input.dat').write_text(text)


def run_in(tmp_path, monkeypatch):
    import importlib
    script = importlib.import_module('multi_bodies.multi_bodies')
    monkeypatch.chdir(tmp_path)
    return script.main(['--input-file', 'input.dat'])


def snapshots(folder, save_clones='one_file_per_step'):
    if save_clones == 'one_file':
        return {name: (folder / name).read_bytes() for name in sorted(os.listdir(folder)) if name.endswith('.config')}
    return {name: (folder / name).read_bytes() for name in sorted(os.listdir(folder)) if name.endswith('.clones')
            and name.startswith('run.')}


@pytest.mark.parametrize('scheme', ['stochastic_Slip_Trapz', 'stochastic_adams_bashforth_rollers'])
def test_same_seed_is_bit_identical_and_random_state_reproduces(scheme, tmp_path, monkeypatch):
    runs = []
    for k, extra in enumerate([{'seed': 5}, {'seed': 5}, None]):
        folder = tmp_path / str(k)
        folder.mkdir()
        if extra is None:  # the state saved by the first run, and no seed
            (folder / 'state.pickle').write_bytes((tmp_path / '0' / 'run.random_state').read_bytes())
            extra = {'random_state': 'state.pickle'}
        write_scene(folder, scheme, 6, extra)
        assert run_in(folder, monkeypatch) == 0
        runs.append(snapshots(folder))
    assert len(runs[0]) == 4 and runs[0] == runs[1] == runs[2]
    other = tmp_path / 'other'
    other.mkdir()
    write_scene(other, scheme, 6, {'seed': 6})
    assert run_in(other, monkeypatch) == 0
    assert snapshots(other) != runs[0]


@pytest.mark.parametrize('save_clones', ['one_file_per_step', 'one_file'])
@pytest.mark.parametrize('scheme', ['stochastic_Slip_Trapz', 'stochastic_adams_bashforth_rollers'])
def test_restart_continues_bit_for_bit(scheme, save_clones, tmp_path, monkeypatch):
    """10 steps in one run equal 4 + 6 steps with initial_step 4 (update_PC 3, so the restart needs the
    saved preconditioner configuration, the solver guess, the generator and the Adams-Bashforth history)."""
    whole, split = tmp_path / 'whole', tmp_path / 'split'
    whole.mkdir()
    split.mkdir()
    extra = {'seed': 9, 'save_clones': save_clones}
    write_scene(whole, scheme, 10, extra)
    assert run_in(whole, monkeypatch) == 0
    write_scene(split, scheme, 4, extra)
    assert run_in(split, monkeypatch) == 0
    write_scene(split, scheme, 10, extra, initial_step=4)
    assert run_in(split, monkeypatch) == 0
    assert snapshots(whole, save_clones) == snapshots(split, save_clones)
    info_whole = (whole / 'run.info').read_text().splitlines()[:3]
    info_split = (split / 'run.info').read_text().splitlines()[:3]
    assert info_whole == info_split
    assert len((split / 'run.time').read_text().splitlines()) == 2


def test_every_manual_scheme_name_runs(tmp_path, monkeypatch):
    """Every stochastic scheme name of the manual runs two steps of a boomerang pair (rollers: blobs)."""
    for scheme in RIGID_ITERATIVE + RIGID_DENSE + ROLLERS:
        folder = tmp_path / scheme
        folder.mkdir()
        write_scene(folder, scheme, 2, {'seed': 1})
        assert run_in(folder, monkeypatch) == 0, scheme
        info = (folder / 'run.info').read_text()
        assert 'stochastic_iterations_count' in info
