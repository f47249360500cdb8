"""Small scenes of the data-safety, restart, hostile-input, crash and run-lock tests, the child-process
runners that start, stop and compare their runs, and a record forger.

Not a test module: ``tests/test_data_safety.py``, ``test_restart_checks.py``, ``test_hostile_inputs.py``,
``test_crash_safety.py``, ``test_run_locks.py``, ``test_resources_and_refusals.py`` and ``test_fuzz.py``
import it.  Each scene maker writes its files and ``input.dat`` into ``folder`` (created) and returns
``folder`` as a ``Path``; keyword options override the scene's input options (a value None removes one).
"""
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from multi_bodies.run import run_output
from run_scenes import REPO_ROOT, child_environment, set_options

DYNAMIC = str(REPO_ROOT / 'multi_bodies' / 'multi_bodies.py')
MCMC = str(REPO_ROOT / 'many_bodyMCMC' / 'many_body_MCMC.py')


# ------------------------------------------------------------------ scenes that read every kind of file (issue 27)
COMMON = dict(dt=0.01, n_steps=6, n_save=3, eta=1.0, blob_radius=0.25, g=1.0, solver_tolerance=1e-10,
              mobility_blobs_implementation='python', mobility_vector_prod_implementation='python',
              blob_blob_force_implementation='python', repulsion_strength_wall=1.0, debye_length_wall=0.2,
              output_name='data/run')


def articulated_scene(folder, **options):
    """Two one-blob bodies joined by one active joint (a .const with expressions of t), above the wall."""
    from run_scenes import set_options
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'chain.list_vertex').write_text('blob.vertex\nblob.vertex\n')
    (folder / 'chain.const').write_text('2\n1\n0 1 0.5 0 0 -0.5 0 0 0.5 0 0 -0.5 0 0.1*sin(t) 0 0 0 0 0 0.1*cos(t)\n')
    (folder / 'chain.clones').write_text('2\n0 0 3 1 0 0 0\n1 0 3 1 0 0 0\n')
    values = dict(COMMON, scheme='articulated_deterministic_forward_euler')
    values.update(options)
    (folder / 'input.dat').write_text(set_options('articulated chain.list_vertex chain.clones chain.const', **values))
    return folder


def driven_scene(folder, **options):
    """A free one-blob body with an active slip, a body of prescribed velocity, Brownian: slip and velocity files."""
    from run_scenes import set_options
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'a.slip').write_text('1\n0.1 0 0\n')
    (folder / 'a.clones').write_text('1\n0 0 2.0 1 0 0 0\n')
    (folder / 'b.clones').write_text('1\n2.5 0 2.5 1 0 0 0\n')
    (folder / 'b.velocity').write_text('0.2 0 0 0 0 0\n')
    values = dict(COMMON, scheme='stochastic_Slip_Trapz', kT=1.0, seed=3)
    values.update(options)
    (folder / 'input.dat').write_text(set_options('structure blob.vertex a.clones a.slip\n'
                                                  'structure blob.vertex b.clones None b.velocity', **values))
    return folder


def surface_scene(folder, kind, **options):
    """A 12-blob sphere in free space with a surface file: ``kind`` 'Laplace' (a Janus sphere in a background
    gradient, forward Euler) or 'slip_length' (slip length 0.5, sedimenting, forward Euler)."""
    from multi_bodies.files import structure_generators as gen
    from run_scenes import set_options
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    blobs, radius, _ = gen.calibrated_shell(12)
    np.savetxt(folder / 'shell.vertex', blobs, header=str(len(blobs)), comments='')
    (folder / 'a.clones').write_text('1\n0 0 5.0 1 0 0 0\n')
    if kind == 'Laplace':
        table = gen.janus_laplace_table(blobs, front=(1.0, 1.0, 1.0), back=(1.0, 0.0, 2.0))
        values = dict(background_Laplace='0 1 0 0', g=0.0)
    else:
        table = gen.slip_length_table(blobs, 0.5)
        values = {}
    gen.write_surface_table(folder / ('shell.' + kind), table, 'surface file of the fingerprint test')
    values = dict(COMMON, scheme='deterministic_forward_euler', blob_radius=radius,
                  mobility_blobs_implementation='python_no_wall', mobility_vector_prod_implementation='python_no_wall',
                  blob_blob_force_implementation='None', domain='no_wall', **values)
    values.update(options)
    (folder / 'input.dat').write_text(set_options('structure shell.vertex a.clones shell.%s' % kind, **values))
    return folder


def run_dynamic(folder):
    from run_scenes import run_in_process
    return run_in_process('dynamic', folder, 'input.dat')


def set_options_text(folder, **values):
    from run_scenes import set_options
    return set_options((Path(folder) / 'input.dat').read_text(), **values)


# ------------------------------------------------------------------ forged records (checksum recomputed)
def forge_record(output_name, step, change):
    """Rewrite the record of ``step`` in ``output_name.restart`` with ``change(record)`` and a valid checksum."""
    import hashlib
    from multi_bodies.run.run_state import state_from_bytes, state_to_bytes
    from multi_bodies.run.restart_records import RECORD_HEADER, RECORD_TAG, RESTART_MAGIC, restart_index
    path = output_name + '.restart'
    data = Path(path).read_bytes()
    out = bytearray(RESTART_MAGIC)
    for entry_step, start, end in restart_index(path):
        payload = data[start:end]
        if entry_step == step:
            record = state_from_bytes(payload)
            change(record)
            payload = state_to_bytes(record)
        out += RECORD_HEADER.pack(RECORD_TAG, entry_step, len(payload), hashlib.sha256(payload).digest()) + payload
    Path(path).write_bytes(bytes(out))


# ------------------------------------------------------------------ crash-test scenes; runners that start, stop, compare
def dynamic_scene(folder, n_steps=40, n_save=4, save_clones='one_file_per_step', **extra):
    """Two single-blob structures a and b (one body each), Brownian Adams-Bashforth: noise and history matter."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'a.clones').write_text('1\n0 0 2.0 1 0 0 0\n')
    (folder / 'b.clones').write_text('1\n2.5 0 2.5 1 0 0 0\n')
    options = dict(scheme='stochastic_adams_bashforth', dt=0.01, n_steps=n_steps, n_save=n_save, eta=1.0, g=0.5,
                   blob_radius=0.5, kT=1.0, seed=3, repulsion_strength_wall=1.0, debye_length_wall=0.2,
                   mobility_blobs_implementation='python', mobility_vector_prod_implementation='python',
                   blob_blob_force_implementation='python', solver_tolerance=1e-10, output_name='data/run',
                   save_clones=save_clones)
    options.update(extra)
    text = set_options('structure blob.vertex a.clones\nstructure blob.vertex b.clones', **options)
    (folder / 'input.dat').write_text(text)
    return folder


def mcmc_scene(folder, n_steps=400, n_save=40, save_clones='one_file_per_step', **extra):
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'a.clones').write_text('2\n0 0 2.0 1 0 0 0\n1.5 0 2.0 1 0 0 0\n')
    options = dict(n_steps=n_steps, n_save=n_save, kT=1.0, g=1.0, blob_radius=0.5, repulsion_strength_wall=1.0,
                   debye_length_wall=0.5, max_translation=0.1, seed=5, output_name='data/run',
                   save_clones=save_clones, mcmc_energy_implementation='python')
    options.update(extra)
    (folder / 'input.dat').write_text(set_options('structure blob.vertex a.clones', **options))
    return folder


def phoretic_scene(folder, n_steps=40, n_save=4, save_clones='one_file_per_step', **extra):
    """A Janus sphere (12 blobs, a .Laplace file) in a background gradient, Adams-Bashforth, writing
    ``.concentration``: the solute's warm start and the history matter."""
    values = dict(scheme='deterministic_adams_bashforth', n_steps=n_steps, n_save=n_save, save_clones=save_clones,
                  save_concentration=True, dt=0.05)
    values.update(extra)
    return surface_scene(folder, 'Laplace', **values)


def edit(folder, **values):
    path = Path(folder) / 'input.dat'
    path.write_text(set_options(path.read_text(), **values))


def start(script, folder, env=None):
    environment = child_environment()
    environment.update(env or {})
    return subprocess.Popen([sys.executable, script, '--input-file', 'input.dat'] if script == DYNAMIC
                            else [sys.executable, script, 'input.dat'], cwd=str(folder), env=environment,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def run(script, folder, env=None):
    process = start(script, folder, env)
    out, err = process.communicate(timeout=120)
    return process.returncode, out, err


def outputs(folder, mcmc=False):
    """{name: bytes} of the snapshots and counters of ``folder/data`` (the series only, nothing set aside)."""
    data = Path(folder) / 'data'
    found = {p.name: p.read_bytes() for p in data.iterdir()
             if p.is_file() and p.name.endswith(('.clones', '.config', '.concentration', '.vtp', '.pvd'))}
    info = data / ('run.MCMC_info' if mcmc else 'run.info')
    found['info'] = b'\n'.join(info.read_bytes().splitlines()[:3])
    return found


def last_pair_step(folder, save_clones, ids):
    record, _ = run_output.last_complete_pair(str(Path(folder) / 'data' / 'run'), save_clones,
                                              [(i, 0) for i in ids], report=lambda text: None)
    return None if record is None else record['step']


def wait_for_record(process, folder, step, timeout=60.0, path=None):
    """Wait until ``.restart`` holds the record of ``step`` (False when the child ended first)."""
    path = Path(folder) / 'data' / 'run.restart' if path is None else Path(path)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            return False
        if path.exists():
            try:
                if any(s >= step for s, _, _ in run_output.restart_index(str(path), report=lambda text: None)):
                    return True
            except run_output.RestartFileError:
                pass
        time.sleep(0.005)
    return False


def snapshot_tree(folder):
    return {p.name: p.read_bytes() for p in Path(folder).iterdir() if p.is_file() and not p.name.endswith('.lock')}
