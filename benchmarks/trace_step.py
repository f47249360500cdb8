"""Count how far one ``stochastic_Slip_Trapz`` step and one ``advise`` reach into the package (issue 43).

Not a timing: a call tracer (``sys.setprofile``) follows

* **one step**: a scene of a few boomerangs above a wall, set up from an input file as the dynamic script sets it
  up (``run_setup.prepare``), then one ``scheme.step`` traced.  Printed: the package files the step enters
  (distinct source files of this repository), the packages they belong to (their folders), and the calls into
  ``multi_bodies/solver/model.py`` made from other files (each call event whose callee is in ``model.py`` and
  whose caller is not);
* **the advisor**: ``advise(input_file, quick=True)`` on the same scene, traced from reading the input to the
  finished report.  Printed: the package files it enters ("stops") and their packages.

Only this repository's files count (the standard library, NumPy, SciPy and the tests do not); a package is a
file's folder relative to the repository (``multi_bodies/solver``, ``mobility``, ...; the top-level modules are
``.``).

    python benchmarks/trace_step.py [--bodies 4] [--backend python] [--no-advise] [--list]

``--list`` prints the files themselves.
"""
import argparse
import os
import sys
import tempfile
from collections import Counter

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

MODEL_FILE = os.path.join('multi_bodies', 'solver', 'model.py')
EXCLUDED = ('tests', 'benchmarks', 'build')


def repository_file(filename):
    """The path of ``filename`` relative to the repository, or None for a file outside it (or excluded)."""
    path = os.path.abspath(filename)
    if not path.startswith(REPO + os.sep) or not path.endswith('.py'):
        return None
    relative = os.path.relpath(path, REPO)
    if relative.split(os.sep)[0] in EXCLUDED:
        return None
    return relative


class Tracer:
    """A ``sys.setprofile`` hook counting the repository files entered and the calls into model.py."""

    def __init__(self):
        self.files = Counter()
        self.model_calls = Counter()
        self._names = {}

    def _file(self, code):
        name = self._names.get(code.co_filename, 0)
        if name == 0:
            name = self._names[code.co_filename] = repository_file(code.co_filename)
        return name

    def __call__(self, frame, event, arg):
        if event != 'call':
            return
        callee = self._file(frame.f_code)
        if callee is None:
            return
        self.files[callee] += 1
        if callee == MODEL_FILE:
            caller = frame.f_back
            if caller is not None and self._file(caller.f_code) != MODEL_FILE:
                self.model_calls['%s <- %s' % (frame.f_code.co_name, self._file(caller.f_code)
                                               or caller.f_code.co_filename)] += 1

    def run(self, function, *args, **kwargs):
        import threading
        threading.setprofile(self)  # the schemes pair products in a second thread
        sys.setprofile(self)
        try:
            return function(*args, **kwargs)
        finally:
            sys.setprofile(None)
            threading.setprofile(None)

    @property
    def packages(self):
        return sorted({os.path.dirname(name) or '.' for name in self.files})


def write_scene(folder, bodies, backend):
    """A Slip_Trapz input of ``bodies`` boomerangs (15 blobs, radius 0.25) on a grid of spacing 4 at z = 2.5."""
    from multi_bodies.files.snapshots import write_clones_file
    from multi_bodies.files.structure_files import write_vertex_file
    from multi_bodies.files.structure_generators import boomerang
    rng = np.random.default_rng(1)
    side = int(np.ceil(np.sqrt(bodies)))
    locations = np.array([[4.0 * (k % side), 4.0 * (k // side), 2.5] for k in range(bodies)])
    orientations = rng.normal(size=(bodies, 4))
    orientations /= np.linalg.norm(orientations, axis=1)[:, None]
    write_vertex_file(os.path.join(folder, 'boomerang.vertex'), boomerang())
    write_clones_file(os.path.join(folder, 'boomerang.clones'), locations, orientations)
    lines = ['scheme stochastic_Slip_Trapz', 'dt 0.01', 'n_steps 1', 'n_save 1', 'eta 1.0', 'g 1.0', 'kT 1.0',
             'blob_radius 0.25', 'solver_tolerance 1e-8', 'seed 1',
             'mobility_blobs_implementation %s' % backend, 'mobility_vector_prod_implementation %s' % backend,
             'blob_blob_force_implementation None', 'body_body_force_torque_implementation None',
             'repulsion_strength_wall 1.0', 'debye_length_wall 0.5', 'output_name out/run',
             'structure boomerang.vertex boomerang.clones']
    with open(os.path.join(folder, 'input.dat'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    os.makedirs(os.path.join(folder, 'out'), exist_ok=True)
    return 'input.dat'


def trace_step(input_file):
    """(Tracer of one Slip_Trapz step of the scene of ``input_file``, in the current directory)."""
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.run_setup import prepare
    from quaternion_integrator.schemes import make_scheme
    options = read_input_file(input_file)
    setup = prepare(options, 'dynamics', log=lambda *_: None)
    model = setup.system
    scheme = make_scheme(options.scheme, options.dt, options)
    state = scheme.init(model, model.start_configuration)
    scheme.step(model, state, np.random.default_rng(1))  # warm-up: first-use imports and caches are not counted
    tracer = Tracer()
    tracer.run(scheme.step, model, state, np.random.default_rng(2))
    return tracer


def trace_advise(input_file):
    from multi_bodies.advice.advisor import advise
    tracer = Tracer()
    tracer.run(advise, input_file, quick=True, log=lambda *_: None)
    return tracer


def report(title, tracer, show_files, model_calls=True):
    print('%s: %d package files in %d packages (%s)' % (title, len(tracer.files), len(tracer.packages),
                                                        ', '.join(tracer.packages)))
    if model_calls:
        print('  calls into %s from other files: %d (%d distinct caller/callee pairs)'
              % (MODEL_FILE, sum(tracer.model_calls.values()), len(tracer.model_calls)))
    if show_files:
        for name in sorted(tracer.files):
            print('    %s' % name)
        for pair, count in sorted(tracer.model_calls.items()):
            print('    %5d  %s' % (count, pair))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--bodies', type=int, default=4)
    parser.add_argument('--backend', default='python')
    parser.add_argument('--no-advise', action='store_true')
    parser.add_argument('--list', action='store_true')
    args = parser.parse_args(argv)
    here = os.getcwd()
    with tempfile.TemporaryDirectory() as folder:
        os.chdir(folder)
        try:
            input_file = write_scene(folder, args.bodies, args.backend)
            report('one stochastic_Slip_Trapz step', trace_step(input_file), args.list)
            if not args.no_advise:
                report('advise (quick)', trace_advise(input_file), args.list, model_calls=False)
        finally:
            os.chdir(here)


if __name__ == '__main__':
    main()
