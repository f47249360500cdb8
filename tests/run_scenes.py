"""Helpers of the robustness and fuzz tests: copies of the shipped example scenes, and the scripts run
in-process (as ``sys.exit(utils.fail_cleanly(main))`` runs them) or as child processes.

Not a test module: ``tests/test_robustness.py`` and ``tests/test_fuzz.py`` import it.
"""
import contextlib
import importlib
import io
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import utils

REPO_ROOT = Path(__file__).resolve().parents[1]
SCRIPT_DIR = REPO_ROOT / 'multi_bodies'
DYNAMIC_SCRIPT = SCRIPT_DIR / 'multi_bodies.py'
STATIC_SCRIPT = SCRIPT_DIR / 'multi_bodies_utilities.py'

# Shipped files of the example scenes, relative to multi_bodies/ (the scripts run from there).
SCENE_FILES = ('inputfile_dynamic.dat', 'inputfile.dat', 'inputfile_body_mobility.dat', 'inputfile_rollers.dat',
               'Structures/boomerang_N_15.vertex', 'Structures/boomerang_N_15.clones',
               'Structures/shell_N_12_Rg_1.vertex', 'Structures/shell_N_12_Rg_1.clones',
               'Structures/force.dat', 'Structures/blob.vertex', 'Structures/four_rollers.clones',
               'Structures/shell_N_42_Rg_0_8912_Rh_1.vertex',
               'Structures/shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip')


def copy_scene(folder):
    """Copy the shipped example files into ``folder`` (same layout as multi_bodies/); returns ``folder``."""
    folder = Path(folder)
    for name in SCENE_FILES:
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SCRIPT_DIR / name, target)
    return folder


def add_generated_inputs(folder):
    """Inputs made from the shipped ones for the other readers and schemes; returns ``folder``.

    * ``inputfile_resistance.dat``: the resistance problem of ``inputfile.dat``'s bodies with ``velocity.dat``;
    * ``inputfile_squirmer.dat`` (dynamic, 2 steps) and ``inputfile_squirmer_mobility.dat`` (static): the
      squirmer of ``examples/squirmer`` (a 42-blob shell with a ``.slip`` file);
    * ``inputfile_rollers_mobility.dat``: the mobility problem of the four rollers of ``inputfile_rollers.dat``.
    """
    folder = Path(folder)
    static = (folder / 'inputfile.dat').read_text()
    (folder / 'velocity.dat').write_text('0 0 0 0 0 0\n0 0 0 0 0 1\n1 0 0 0 0 0\n')
    (folder / 'inputfile_resistance.dat').write_text(set_options(
        static, scheme='resistance', force_file=None, velocity_file='velocity.dat', output_name='data/resistance'))
    (folder / 'Structures' / 'squirmer.clones').write_text('1\n0 0 3 1 0 0 0\n')
    squirmer = ('structure Structures/shell_N_42_Rg_0_8912_Rh_1.vertex Structures/squirmer.clones '
                'Structures/shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip')
    common = dict(blob_radius=0.243548261566, eta=1.0, g=0.5, repulsion_strength_wall=1.0, debye_length_wall=0.2)
    (folder / 'inputfile_squirmer.dat').write_text(set_options(
        squirmer, scheme='deterministic_adams_bashforth', mobility_vector_prod_implementation='C++', dt=0.05,
        n_steps=2, n_save=1, output_name='data/squirmer', **common))
    (folder / 'inputfile_squirmer_mobility.dat').write_text(set_options(
        squirmer, scheme='mobility', output_name='data/squirmer_static', **common))
    rollers = [line for line in (folder / 'inputfile_rollers.dat').read_text().splitlines()
               if line.startswith('structure')]
    (folder / 'inputfile_rollers_mobility.dat').write_text(set_options(
        '\n'.join(rollers), scheme='mobility', blob_radius=0.656, eta=1e-3, g=0.0024892,
        output_name='data/rollers_static'))
    return folder


def set_options(text, **values):
    """Input-file text with option lines replaced (or appended); a value None removes the option."""
    lines = text.splitlines()
    for name, value in values.items():
        pattern = re.compile(r'^\s*%s(\s|$)' % re.escape(name))
        kept = [line for line in lines if not pattern.match(line)]
        if value is not None:
            kept.append('%s %s' % (name, value))
        lines = kept
    return '\n'.join(lines) + '\n'


def edit_input(path, **values):
    path = Path(path)
    path.write_text(set_options(path.read_text(), **values))
    return path


_MODULES = {}


def script_module(kind):
    """The imported script module: kind 'dynamic' (multi_bodies.py) or 'static' (multi_bodies_utilities.py)."""
    if kind not in _MODULES:
        name = 'multi_bodies.multi_bodies' if kind == 'dynamic' else 'multi_bodies.multi_bodies_utilities'
        _MODULES[kind] = importlib.import_module(name)
    return _MODULES[kind]


def run_in_process(kind, folder, input_name):
    """Run a script's ``main`` from ``folder`` as its ``__main__`` block does.

    Returns (exit status, stdout text, stderr text).  Any exception other
    than SystemExit propagates: it is the traceback a user would have seen.
    """
    main = script_module(kind).main
    out, err = io.StringIO(), io.StringIO()
    previous = os.getcwd()
    os.chdir(str(folder))
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = utils.fail_cleanly(main, ['--input-file', input_name])
            except SystemExit as stop:
                status = stop.code
    finally:
        os.chdir(previous)
    return (0 if status is None else status), out.getvalue(), err.getvalue()


def child_environment():
    env = dict(os.environ)
    env['PYTHONPATH'] = str(REPO_ROOT) + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH') else '')
    env['PYTHONUNBUFFERED'] = '1'
    return env


def start_child(kind, folder, input_name):
    """Start a script as a child process in ``folder``; returns the ``subprocess.Popen``."""
    script = DYNAMIC_SCRIPT if kind == 'dynamic' else STATIC_SCRIPT
    return subprocess.Popen([sys.executable, str(script), '--input-file', input_name], cwd=str(folder),
                            env=child_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def snapshot_files(folder):
    """{relative path: bytes} of every file under ``folder`` (to check that nothing was changed)."""
    folder = Path(folder)
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob('*')) if p.is_file()}
