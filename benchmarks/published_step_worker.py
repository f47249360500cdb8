"""One side of ``bench_published_steps.py``: a process that runs one input file of rigid bodies with one code and
takes its time steps when asked, timing each.

    python published_step_worker.py --code package --input-file DIR/inputfile.dat
    /path/to/published/python published_step_worker.py --code published --published-tree TREE \
        --input-file DIR/inputfile.dat

Run it in a folder of its own (the run's output files, named by the input's ``output_name``, go there).

``--code package`` sets the run up as this package's ``multi_bodies.py`` does (``read_input_file`` and
``multi_bodies.run.dynamic_run.DynamicRun``) and steps with ``scheme.step(model, state)``.  ``--code published``
runs the published script ``TREE/multi_bodies/multi_bodies.py`` itself, unchanged, as its ``__main__`` (``TREE``
is a checkout of the published RigidMultiblobsWall, put on the path as its README says), and wraps the method its
time loop calls once a step, ``QuaternionIntegrator.advance_time_step``, so that each step waits for the order
to go and is timed; everything else (reading the input, building bodies and integrator, saving step 0) is the
published code's own.  This file imports nothing of the package on the published side.

Protocol (one JSON object per line on stdout; the codes' own prints go to /dev/null): after setting up and one
warm-up step (numba compiles its kernels there, the package fills its caches) it writes
``{"ready": code, "bodies": n, "blobs": n, "threads": text, "kernels": text}``; then for each line read from
stdin: ``step`` -> ``{"cpu": s, "wall": s}`` (CPU seconds of the whole process, all its threads, and wall seconds
of one step), ``untimed`` -> ``{"untimed": true}`` (one step, not timed: the lead-in of a timed one),
``configuration`` -> ``{"locations": (n, 3), "orientations": (n, 4)}``, ``quit`` -> exits.
"""
import argparse
import contextlib
import json
import os
import runpy
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class Protocol:
    """The JSON lines to the controller, on the stdout the process started with."""

    def __init__(self, stream):
        self.stream = stream

    def send(self, **record):
        self.stream.write(json.dumps(record) + '\n')
        self.stream.flush()

    @staticmethod
    def order():
        """The next order of the controller ('quit' at the end of stdin)."""
        line = sys.stdin.readline()
        return line.strip() or 'quit'


def timed(step):
    """(CPU seconds of the process, wall seconds) of ``step()``."""
    cpu, wall = time.process_time(), time.perf_counter()
    step()
    return time.process_time() - cpu, time.perf_counter() - wall


def serve(protocol, step, configuration):
    """Answer the controller's orders until 'quit' (then exit at once: nothing of a code runs after it)."""
    while True:
        order = protocol.order()
        if order == 'step':
            cpu, wall = timed(step)
            protocol.send(cpu=cpu, wall=wall)
        elif order == 'untimed':
            step()
            protocol.send(untimed=True)
        elif order == 'configuration':
            locations, orientations = configuration()
            protocol.send(locations=locations, orientations=orientations)
        else:
            sys.stdout.flush()
            os._exit(0)


def run_published(tree, input_file, protocol, quiet):
    """Run the published script on ``input_file``, serving the controller between its steps (does not return)."""
    sys.path[:0] = [tree, os.path.join(tree, 'multi_bodies')]
    from quaternion_integrator import quaternion_integrator_multi_bodies as published_integrator
    import numba
    published_step = published_integrator.QuaternionIntegrator.advance_time_step

    def configuration_of(integrator):
        return ([[float(x) for x in b.location] for b in integrator.bodies],
                [[float(x) for x in b.orientation.entries] for b in integrator.bodies])

    def advance_time_step(integrator, dt, *args, **kwargs):
        """The published step, taken when the controller says so (the first one, the warm-up, at once)."""
        if not getattr(integrator, 'bench_warmed_up', False):
            published_step(integrator, dt, *args, **kwargs)
            integrator.bench_warmed_up = True
            protocol.send(ready='published', bodies=len(integrator.bodies), blobs=int(integrator.Nblobs),
                          threads='numba %s, %d threads' % (numba.__version__, numba.get_num_threads()),
                          kernels='numba (published mobility_numba.py, forces_numba.py)')
            return None
        while True:
            order = protocol.order()
            if order == 'step':
                with contextlib.redirect_stdout(quiet):
                    cpu, wall = timed(lambda: published_step(integrator, dt, *args, **kwargs))
                protocol.send(cpu=cpu, wall=wall)
                return None
            if order == 'untimed':
                with contextlib.redirect_stdout(quiet):
                    published_step(integrator, dt, *args, **kwargs)
                protocol.send(untimed=True)
                return None
            if order == 'configuration':
                locations, orientations = configuration_of(integrator)
                protocol.send(locations=locations, orientations=orientations)
                continue
            os._exit(0)

    published_integrator.QuaternionIntegrator.advance_time_step = advance_time_step
    sys.argv = [os.path.join(tree, 'multi_bodies', 'multi_bodies.py'), '--input-file', input_file]
    with contextlib.redirect_stdout(quiet):
        runpy.run_path(sys.argv[0], run_name='__main__')
    # The published time loop ended (n_steps reached) before the controller said quit.
    protocol.send(error='the published run ended after its n_steps; give the input file more steps')
    os._exit(1)


def run_package(input_file, protocol, quiet):
    """Set up this package's run of ``input_file`` and serve the controller (does not return)."""
    sys.path.insert(0, ROOT)
    import mobility.simd
    import mobility.threads
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.dynamic_run import DynamicRun
    with contextlib.redirect_stdout(quiet):
        options = read_input_file(input_file, program='dynamic')
        run = DynamicRun(options, log=lambda text: print(text, file=sys.stderr))
        model, scheme = run.system, run.scheme
        state = scheme.step(model, run.start_state)  # warm-up
    holder = {'state': state}

    def step():
        with contextlib.redirect_stdout(quiet):
            holder['state'] = scheme.step(model, holder['state'])

    def configuration():
        locations, orientations = holder['state'].configuration.copy_arrays()
        return locations.tolist(), orientations.tolist()

    protocol.send(ready='package', bodies=int(len(run.bodies)), blobs=int(model.num_blobs),
                  threads=mobility.threads.describe(), kernels=mobility.simd.describe())
    serve(protocol, step, configuration)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--code', choices=('package', 'published'), required=True)
    parser.add_argument('--published-tree', default=None, help='the published checkout (with --code published)')
    parser.add_argument('--input-file', required=True)
    args = parser.parse_args()
    protocol = Protocol(sys.stdout)
    quiet = open(os.devnull, 'w')
    input_file = os.path.abspath(args.input_file)
    if args.code == 'published':
        if args.published_tree is None:
            parser.error('--code published needs --published-tree')
        run_published(os.path.abspath(args.published_tree), input_file, protocol, quiet)
    else:
        run_package(input_file, protocol, quiet)


if __name__ == '__main__':
    main()
