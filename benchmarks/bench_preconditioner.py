"""GMRES iterations, passes over the blob pairs and seconds per step with each GMRES preconditioner.

For every scene and scheme, the same steps (same seed) are taken with each ``preconditioner``:
``block_diagonal`` (every body alone, the published preconditioner), ``neighbours`` (the block-diagonal one
corrected for the couplings of neighbouring bodies, doc/preconditioners.md) and ``auto`` (the default: the
correction where it is cheap to build), their steps alternating so that a drift of the machine's speed
touches all alike.  Printed per run: GMRES iterations per solve (from the run's counters), ``M f`` passes
per step (counted as in bench_dynamics.py), seconds per step (median), each with its ratio to
block_diagonal (no ratio to the published code: ``bench_published_steps.py`` times its steps side by side).

Scenes (C++ backends, solver_tolerance 1e-8):

* ``dilute``: 100 boomerangs (15 blobs, a = 0.25) on a square grid of spacing 4 at z = 2.5, random
  orientations (bench_dynamics.py's scene);
* ``packed``: 100 boomerangs at half that spacing (2); their heights are drawn in [1.5, 6] and orientations
  redrawn until no two blobs of different bodies overlap (at z = 2.5 they cannot all fit);
* ``boomerangs_1000``: 1,000 boomerangs as in ``dilute``;
* ``rollers_1000``: 1,000 single-blob bodies of radius 0.5 at z = 1.5 on a grid of spacing 2 (the rigid
  problem: a single blob has three unknown velocities, its torque-free rotation is undetermined);
* ``pillars``: 16 fixed pillars (48-blob cylinders of radius 0.6, height 4, prescribed zero velocity: the
  obstacle problem) among 84 12-blob spheres of radius 0.5, no two blobs overlapping;
* ``articulated``: 4 bacteria of benchmarks/bench_articulated.py (42-blob shells) joined to their
  flagella, ``articulated_deterministic_midpoint``.

    python benchmarks/bench_preconditioner.py [--scenes dilute packed ...] [--steps 3]

``--near-field`` (scenes: the six above and ``shells``, 25 icosahedral shells of 162 blobs 0.6 apart)
compares the neighbour correction's near field computed from the blob positions at every
application (the default with the C++ blob mobility) with stored pair blocks, under ``preconditioner
neighbours``: GMRES iterations and seconds per step.

``--lanczos`` compares instead the two Lanczos factors (option ``lanczos_preconditioner``) under
``preconditioner auto``: Lanczos iterations, passes and seconds per step of ``stochastic_Slip_Trapz`` in the
dilute, packed and 1,000-boomerang scenes, and of ``stochastic_adams_bashforth_rollers`` for 4,000 rollers
placed at random at area fraction 0.4 (``rollers_dense``).
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_dynamics import boomerang_system, count_products  # noqa: E402
from body.body import Body, bodies_to_arrays  # noqa: E402
from body.geometry import rotation_matrices  # noqa: E402
from multi_bodies.files.input_options import options_with  # noqa: E402
from multi_bodies.files.structure_generators import boomerang, icosahedral_shell  # noqa: E402
from multi_bodies.solver import user_hooks  # noqa: E402
from multi_bodies.solver.model import Model  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

PRECONDITIONERS = ('block_diagonal', 'neighbours', 'auto')
PHYSICS = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
               debye_length=1.0, periodic_length=np.zeros(3), blob_mass=1.0)


def model_of(bodies, blob_radius):
    physics = dict(PHYSICS, blob_radius=blob_radius)
    return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0,
                 blob_radius, 1e-8, vector_product_name='C++', blobs_name='C++', blob_blob_name='C++')


def packed_boomerangs(num=100, spacing=2.0, seed=1, heights=(1.5, 6.0), tries=20000):
    """Boomerangs on a grid of ``spacing``, no two blobs of different bodies closer than two radii."""
    from scipy.spatial.distance import cdist
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(num)))
    reference = boomerang()
    placed, bodies = [], []
    for k in range(num):
        for _ in range(tries):
            centre = np.array([spacing * (k % side), spacing * (k // side), rng.uniform(*heights)])
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            r = centre + reference @ rotation_matrices(q[None])[0].T
            if r[:, 2].min() >= 0.5 and (not placed or cdist(r, np.concatenate(placed)).min() >= 0.5):
                break
        else:
            raise RuntimeError('could not place boomerang %d' % k)
        placed.append(r)
        body = Body(centre, q, reference, 0.25)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    return model_of(bodies, 0.25)


def rollers(num=1000, spacing=2.0):
    side = int(np.ceil(np.sqrt(num)))
    bodies = []
    for k in range(num):
        body = Body([spacing * (k % side), spacing * (k // side), 1.5], [1.0, 0, 0, 0], np.zeros((1, 3)), 0.5)
        body.ID = 'roller'
        body.body_length = 1.0
        bodies.append(body)
    return model_of(bodies, 0.5)


def dense_rollers(num=4000, area_fraction=0.4, radius=0.5, seed=0):
    """Rollers of ``radius`` placed at random (no two closer than 2.05 radii) in a square at ``area_fraction``,
    at heights 1.5-1.65 radii, spinning about y (the roller schemes' model: free_kinematics False)."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(num * np.pi * radius ** 2 / area_fraction)
    placed = np.zeros((num, 2))
    count = 0
    while count < num:  # random sequential adsorption
        point = rng.uniform(0.0, side, 2)
        if count == 0 or np.min(np.sum((placed[:count] - point) ** 2, axis=1)) > (2.05 * radius) ** 2:
            placed[count] = point
            count += 1
    bodies = []
    for point in placed:
        body = Body([point[0], point[1], radius * (1.5 + 0.15 * rng.random())], [1.0, 0, 0, 0], np.zeros((1, 3)),
                    radius)
        body.ID = 'roller'
        body.body_length = 1.0
        bodies.append(body)
    physics = dict(PHYSICS, blob_radius=radius, debye_length_wall=0.1, debye_length=0.1)
    return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, radius,
                 1e-8, vector_product_name='C++', blobs_name='C++', blob_blob_name='C++',
                 omega_one_roller=np.array([0.0, 1.0, 0.0]), free_kinematics=False)


def pillars(num_pillars=16, num_spheres=84, seed=3):
    rng = np.random.default_rng(seed)
    angles = 2 * np.pi * np.arange(6) / 6
    cylinder = np.array([[0.6 * np.cos(t + 0.5 * (z % 2)), 0.6 * np.sin(t + 0.5 * (z % 2)), 0.5 * z - 1.75]
                         for z in range(8) for t in angles])
    sphere = icosahedral_shell(12)
    sphere = 0.5 * sphere / np.max(np.linalg.norm(sphere, axis=1))
    bodies = []
    side = int(np.sqrt(num_pillars))
    for k in range(num_pillars):
        body = Body([4.0 * (k % side), 4.0 * (k // side), 2.5], [1.0, 0, 0, 0], cylinder, 0.25)
        body.ID = 'pillar'
        body.body_length = body.calc_body_length()
        body.prescribed_velocity = np.zeros(6)
        bodies.append(body)
    placed = 0
    while placed < num_spheres:
        centre = np.array([rng.uniform(-1.5, 4.0 * side - 2.5), rng.uniform(-1.5, 4.0 * side - 2.5),
                           rng.uniform(1.0, 4.0)])
        # no blob overlaps: a sphere's blobs reach 0.75 from its centre, a pillar's 0.85 from its axis
        if any(np.linalg.norm(b.location[:2] - centre[:2]) < 0.85 + 0.75 + 0.1 if b.ID == 'pillar'
               else np.linalg.norm(b.location - centre) < 1.5 + 0.1 for b in bodies):
            continue
        body = Body(centre, [1.0, 0, 0, 0], sphere, 0.25)
        body.ID = 'sphere'
        body.body_length = body.calc_body_length()
        bodies.append(body)
        placed += 1
    return model_of(bodies, 0.25)


def shells(num=25, blobs=162, spacing=2.6, seed=0):
    """``num`` icosahedral shells of ``blobs`` blobs (unit radius, blob radius half the smallest blob distance) on a
    square grid of ``spacing`` (0.6 apart surface to surface) at height 1 + 2a + 0.3, random orientations."""
    from multi_bodies.files.structure_generators import smallest_distance
    shell = icosahedral_shell(blobs)
    a = 0.5 * smallest_distance(shell)
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(num)))
    bodies = []
    for k in range(num):
        q = rng.normal(size=4)
        body = Body([spacing * (k % side), spacing * (k // side), 1.3 + 2 * a], q / np.linalg.norm(q), shell, a)
        body.ID = 'shell'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    return model_of(bodies, a)


def articulated(folder):
    from bench_articulated import COMMON, write_files
    from multi_bodies.files.input_options import parse_input_text
    from multi_bodies.run.run_setup import prepare
    write_files(folder, 4, 42)
    here = os.getcwd()
    os.chdir(folder)
    try:
        text = ('scheme articulated_deterministic_midpoint\n%s\narticulated bacteria.list_vertex bacteria.clones '
                'bacteria.const\n' % COMMON)
        options = parse_input_text(text, 'bench.dat', 'dynamic')
        return prepare(options, 'dynamics', log=lambda *a: None).system, options
    finally:
        os.chdir(here)


SCENES = {
    'dilute': (lambda: boomerang_system(100, 'C++'), ('deterministic_adams_bashforth', 'stochastic_Slip_Trapz')),
    'packed': (packed_boomerangs, ('deterministic_adams_bashforth', 'stochastic_Slip_Trapz')),
    'boomerangs_1000': (lambda: boomerang_system(1000, 'C++'), ('deterministic_adams_bashforth',)),
    'rollers_1000': (rollers, ('deterministic_adams_bashforth',)),
    'pillars': (pillars, ('deterministic_adams_bashforth',)),
    'articulated': (None, ('articulated_deterministic_midpoint',)),
}


def run(model, scheme_name, steps, options=None, variants=None, before_step=None):
    """{variant: (iterations per solve, passes per step, seconds per step, Lanczos iterations per step)} for
    ``steps`` steps; variants: {name: Model.replace keywords} (None: every GMRES preconditioner);
    before_step: {name: callable()} called before each step of that variant (None: nothing)."""
    before_step = before_step or {}
    options = options if options is not None else options_with(kT=1.0, rf_delta=1e-3, update_PC=1)
    dt = float(options.dt) if options.dt else 0.01
    if variants is None:
        variants = {name: dict(preconditioner=name) for name in PRECONDITIONERS}
    results = {}
    runs = {}
    for name, changes in variants.items():
        timed = model.replace(**changes)
        counted, counter = count_products(timed)
        scheme = make_scheme(scheme_name, dt, options)
        runs[name] = [timed, scheme, scheme.init(timed, timed.start_configuration), np.random.default_rng(3),
                      counted, scheme.init(counted, counted.start_configuration), np.random.default_rng(3), counter]
    seconds = {name: [] for name in runs}
    for step in range(steps + 1):
        for name, r in runs.items():
            timed, scheme, state, rng = r[:4]
            before_step.get(name, lambda: None)()
            start = time.perf_counter()
            r[2] = scheme.step(timed, state, rng)
            if step:  # the first step is a warm-up (and the Euler start of multistep schemes)
                seconds[name].append(time.perf_counter() - start)
    for name, r in runs.items():
        counted, state, rng, counter = r[4], r[5], r[6], r[7]
        scheme = r[1]
        before_step.get(name, lambda: None)()
        state = scheme.step(counted, state, rng)
        first, passes_before = state.counters, sum(counter.counts.values())
        for _ in range(steps):
            state = scheme.step(counted, state, rng)
        counts = state.counters
        solves = (counts.deterministic_solves + counts.stochastic_solves
                  - first.deterministic_solves - first.stochastic_solves)
        iterations = counts.gmres_iterations - first.gmres_iterations
        passes = (sum(counter.counts.values()) - passes_before) / steps
        lanczos = (counts.lanczos_iterations - first.lanczos_iterations) / steps
        results[name] = (iterations / max(solves, 1), passes, float(np.median(seconds[name])), lanczos)
    return results


# the scenes of --near-field: the six above and 25 shells of 162 blobs 0.6 apart (pair blocks of 486 x 486)
NEAR_FIELD_SCENES = dict(SCENES, shells=(shells, ('deterministic_adams_bashforth', 'stochastic_Slip_Trapz')))

# the scenes of --lanczos: (model maker, scheme)
LANCZOS_SCENES = {
    'dilute': (SCENES['dilute'][0], 'stochastic_Slip_Trapz'),
    'packed': (packed_boomerangs, 'stochastic_Slip_Trapz'),
    'boomerangs_1000': (SCENES['boomerangs_1000'][0], 'stochastic_Slip_Trapz'),
    'rollers_dense': (dense_rollers, 'stochastic_adams_bashforth_rollers'),
}


def lanczos_main(scenes, steps):
    """The Lanczos factors side by side under ``preconditioner auto`` with ``lanczos_preconditioner``
    block_diagonal (the published noise) and incomplete_cholesky: stochastic_Slip_Trapz of the boomerang scenes,
    stochastic_adams_bashforth_rollers of 4,000 rollers at area fraction 0.4 (``rollers_dense``)."""
    variants = {name: dict(preconditioner='auto', lanczos_preconditioner=name)
                for name in ('block_diagonal', 'incomplete_cholesky')}
    print('%-16s %-22s %9s %7s %9s %7s %9s %7s' % (
        'scene', 'lanczos_preconditioner', 'lanczos', 'ratio', 'passes', 'ratio', 's/step', 'ratio'))
    for scene in scenes:
        make, scheme_name = LANCZOS_SCENES[scene]
        r = run(make(), scheme_name, 1 if scene == 'boomerangs_1000' else steps, variants=variants)
        _, pb, sb, lb = r['block_diagonal']
        for name in variants:
            _, passes, seconds, lanczos = r[name]
            print('%-16s %-22s %9.1f %7.2f %9.1f %7.2f %9.4f %7.2f' % (
                scene, name, lanczos, lanczos / lb, passes, passes / pb, seconds, seconds / sb), flush=True)
    return 0


def scene_model(scene, folder, table):
    """(model, options or None, scheme names) of ``scene`` in ``table`` (the articulated scene writes its
    files into ``folder``)."""
    make, schemes = table[scene]
    if scene == 'articulated':
        model, options = articulated(folder)
        return model, options, schemes
    return make(), None, schemes


def without_compiled_near_field(blob_mobility):
    """The same blob mobility whose neighbour preconditioner stores the near field's pair blocks (its
    ``near_field_domain`` None: the compiled loop from the positions is not used)."""
    import copy
    stored = copy.copy(blob_mobility)
    stored.near_field_domain = None
    return stored


def near_field_main(scenes, steps):
    """The neighbour correction's near field from the positions (the compiled loop, the default with the C++
    blob mobility) against stored pair blocks (a blobs mobility without ``near_field_domain``), under
    ``preconditioner neighbours``, their steps alternating."""
    print('%-16s %-36s %-15s %9s %9s %7s' % ('scene', 'scheme', 'near field', 'it/solve', 's/step', 'ratio'))
    for scene in scenes:
        with tempfile.TemporaryDirectory() as folder:
            model, options, schemes = scene_model(scene, folder, NEAR_FIELD_SCENES)
            variants = {'positions': dict(preconditioner='neighbours'),
                        'stored_blocks': dict(preconditioner='neighbours',
                                              blobs_mobility=without_compiled_near_field(model.blobs_mobility))}
            for scheme_name in schemes:
                r = run(model, scheme_name, 1 if scene == 'boomerangs_1000' else steps, options, variants)
                stored = r['stored_blocks'][2]
                for name in variants:
                    it, _, seconds, _ = r[name]
                    print('%-16s %-36s %-15s %9.1f %9.4f %7.2f' % (scene, scheme_name, name, it, seconds,
                                                                  seconds / stored), flush=True)
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenes', nargs='+', default=None,
                        choices=sorted(set(NEAR_FIELD_SCENES) | set(LANCZOS_SCENES)))
    parser.add_argument('--steps', type=int, default=3)
    parser.add_argument('--lanczos', action='store_true',
                        help='compare the Lanczos factors (lanczos_preconditioner) under stochastic_Slip_Trapz '
                             'instead, in the scenes %s' % ', '.join(LANCZOS_SCENES))
    parser.add_argument('--near-field', action='store_true',
                        help='compare the neighbour correction\'s near field from the positions with stored pair '
                             'blocks, under preconditioner neighbours')
    args = parser.parse_args(argv)
    if args.near_field:
        return near_field_main([scene for scene in (args.scenes or NEAR_FIELD_SCENES) if scene in NEAR_FIELD_SCENES],
                               args.steps)
    if args.lanczos:
        return lanczos_main([scene for scene in (args.scenes or LANCZOS_SCENES) if scene in LANCZOS_SCENES],
                            args.steps)
    args.scenes = [scene for scene in (args.scenes or SCENES) if scene in SCENES]
    print('%-16s %-36s %-15s %9s %7s %9s %7s %9s %7s' % (
        'scene', 'scheme', 'preconditioner', 'it/solve', 'ratio', 'passes', 'ratio', 's/step', 'ratio'))
    for scene in args.scenes:
        with tempfile.TemporaryDirectory() as folder:
            model, options, schemes = scene_model(scene, folder, SCENES)
            for scheme_name in schemes:
                steps = 1 if scene == 'boomerangs_1000' else args.steps
                r = run(model, scheme_name, steps, options)
                ib, pb, sb, _ = r['block_diagonal']
                for name in PRECONDITIONERS:
                    it, passes, seconds, _ = r[name]
                    print('%-16s %-36s %-15s %9.1f %7.2f %9.1f %7.2f %9.4f %7.2f' % (
                        scene, scheme_name, name, it, it / ib, passes, passes / pb, seconds, seconds / sb),
                          flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
