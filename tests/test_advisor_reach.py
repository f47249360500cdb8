"""The advisor follows only the features an input uses (issue 43: the options followed through ``advise`` cross
fewer modules).

``benchmarks/trace_step.py`` counts the package files that ``advise(quick=True)`` enters on a scene of boomerangs
above a wall (no periodic box, no spectral product, no obstacle, no surface files, no GPU).  The files of those
features have nothing to do for that input: each is asked for only where its option says the feature is on.  The
law checked here: none of them is entered for the plain scene, and each is entered (the tracer sees it) for a scene
that turns its feature on, so the check cannot pass by not looking.
"""
import importlib.util
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'benchmarks'))
import trace_step  # noqa: E402

from multi_bodies.files.input_options import read_input_file  # noqa: E402
from multi_bodies.files.snapshots import write_clones_file  # noqa: E402
from multi_bodies.run.run_setup import prepare  # noqa: E402

# The files of features the plain scene does not use, and the input line that turns each on.
UNUSED_FEATURE_FILES = {
    os.path.join('multi_bodies', 'run', 'run_output.py'): 'periodic_length 30 30 0',   # the box's lengths checked
    os.path.join('multi_bodies', 'solver', 'obstacles.py'): 'obstacle',                 # bodies held in place
    os.path.join('multi_bodies', 'solver', 'surface.py'): 'save_concentration True',    # the solute (warned about)
}
# Entered only with the spectral product (its published reading, a slit's top wall, its options' check).
SPECTRAL_FILES = (os.path.join('multi_bodies', 'solver', 'published_spectral.py'),
                  os.path.join('multi_bodies', 'solver', 'periodic.py'))
CUDA_BACKEND = os.path.join('mobility', 'cuda_backend.py')
# The lubrication topic compares models of spheres: entered only when every body is one.
ADVISOR_LUBRICATION = os.path.join('multi_bodies', 'advice', 'advisor_lubrication.py')


def plain_scene(folder):
    """The counter's scene, two boomerangs; returns the input file name (in ``folder``, the current directory)."""
    return trace_step.write_scene(str(folder), 2, 'C++')


def test_quick_advice_enters_no_file_of_an_unused_feature(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    input_file = plain_scene(tmp_path)
    from multi_bodies.advice.advisor import advise
    tracer = trace_step.Tracer()
    result = tracer.run(advise, input_file, quick=True, log=lambda *_: None)
    assert result.choices  # the advisor measured something
    entered = set(tracer.files)
    assert os.path.join('multi_bodies', 'advice', 'advisor.py') in entered  # the tracer sees the package
    unused = set(UNUSED_FEATURE_FILES) | set(SPECTRAL_FILES) | {ADVISOR_LUBRICATION}
    if importlib.util.find_spec('cupy') is None:  # no CuPy: the GPU backend is refused without running its module
        unused.add(CUDA_BACKEND)
    assert not entered & unused, 'files of features the input does not use: %s' % sorted(entered & unused)


def traced_set_up(folder, extra_line):
    """Files entered by ``prepare`` (the dynamic run's set-up) of the plain scene with ``extra_line`` (or None)."""
    input_file = plain_scene(folder)
    path = os.path.join(str(folder), input_file)
    lines = open(path).read().splitlines()
    if extra_line == 'obstacle':  # one boomerang held in place, away from the others
        write_clones_file(os.path.join(str(folder), 'held.clones'), [[20.0, 20.0, 2.5]], [[1.0, 0.0, 0.0, 0.0]])
        lines.append('obstacle boomerang.vertex held.clones')
    elif extra_line is not None:
        lines.append(extra_line)
    with open(path, 'w') as f:
        f.write('\n'.join(lines) + '\n')
    options = read_input_file(input_file)
    tracer = trace_step.Tracer()
    tracer.run(prepare, options, 'dynamics', log=lambda *_: None)
    return set(tracer.files)


@pytest.mark.parametrize('name', sorted(UNUSED_FEATURE_FILES))
def test_the_feature_turned_on_enters_its_file(tmp_path, monkeypatch, name):
    """Control: with the feature's line in the input, the set-up enters the file (the tracer would see it)."""
    monkeypatch.chdir(tmp_path)
    assert name not in traced_set_up(tmp_path, None)
    assert name in traced_set_up(tmp_path, UNUSED_FEATURE_FILES[name])


def test_gpu_backend_refused_without_cupy_with_the_import_error_text():
    """Without CuPy the GPU backend is refused before its module runs, with the words its import would give."""
    try:
        import cupy  # noqa: F401
    except ModuleNotFoundError as err:
        expected = '%s: %s' % (type(err).__name__, err)
    else:
        pytest.skip('CuPy is installed here: the GPU backend module is imported and checked')
    from mobility.interface import unusable_reason
    assert unusable_reason('pycuda') == expected


def test_lubrication_topic_is_entered_for_spheres(tmp_path, monkeypatch):
    """Control: the same scene with every body a single blob (a sphere) enters the lubrication topic's file."""
    monkeypatch.chdir(tmp_path)
    input_file = plain_scene(tmp_path)
    with open(os.path.join(str(tmp_path), 'blob.vertex'), 'w') as f:
        f.write('1\n0.0 0.0 0.0\n')
    path = os.path.join(str(tmp_path), input_file)
    lines = [line for line in open(path).read().splitlines() if not line.startswith('structure')]
    with open(path, 'w') as f:
        f.write('\n'.join(lines + ['structure blob.vertex boomerang.clones']) + '\n')
    from multi_bodies.advice.advisor import advise
    tracer = trace_step.Tracer()
    result = tracer.run(advise, input_file, quick=True, log=lambda *_: None)
    assert ADVISOR_LUBRICATION in tracer.files
    assert any(choice[0] == 'lubrication' for choice in result.choices), 'the topic reported no row for spheres'
