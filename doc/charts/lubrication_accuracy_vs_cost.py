"""Accuracy against cost of sphere models near contact: 1 blob, 1 blob + lubrication, resolved shells.

Two geometries (radius a = 1): (a) two spheres approaching each other in free space, (b) one sphere
approaching the no-slip wall.  Models, scalars and error measures: ``multi_bodies.advice.lubrication_models``
(its docstring).  References: the exact answers (pair: the inverse of the resolved two-sphere
resistance, Jeffrey-Onishi tables and near-contact asymptotics; wall: the Brenner, O'Neill, Dean-O'Neill
and Jeffery series) and, where given, the published resolved-sphere tables of Sprinkle et al. 2020 (2562
blobs) read from ``--tables`` (the folder of ``mob_scalars_MB_2562.txt`` and
``mob_scalars_wall_MB_2562.txt``; skipped when absent).

Cost, measured here: a monolayer of 64 spheres (8 x 8 square lattice, gap 0.2 a, centres 1.2 a above the
wall), C++ backend, GMRES tolerance 1e-8: the time of one far-field ``M f`` of the scene and of one
mobility solve (1 blob: one grand ``M f``, no solve; 1 blob + lubrication: ``Delta_R`` assembled and one
preconditioned GMRES solve; shells: block-diagonal preconditioner built and one GMRES solve of the rigid
multiblob problem; the 642-blob solve is modelled as its measured ``M f`` times the iterations of the
162-blob solve plus its preconditioner, measured).

    python doc/charts/lubrication_accuracy_vs_cost.py                 # markdown tables + Python tables
    python doc/charts/lubrication_accuracy_vs_cost.py --png doc/charts/lubrication_accuracy_vs_cost.png

The last block printed is ``ERRORS`` and ``COSTS`` as shipped in ``multi_bodies/advice/lubrication_tables.py``
(the advisor reads them there; ``tests/test_advisor_lubrication.py`` recomputes some and compares).
"""
import argparse
import os
import time

import numpy as np

from multi_bodies.advice import lubrication_models as models

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_TABLES = os.path.join(HERE, '..', '..', '..', 'shared', 'reference', 'lubrication', 'tables')
SIDE, SPACING, HEIGHT, TOLERANCE = 8, 2.2, 1.2, 1e-8


def lattice():
    """Centres (64, 3) of the cost scene."""
    k = np.arange(SIDE * SIDE)
    return np.column_stack((SPACING * (k % SIDE), SPACING * (k // SIDE), np.full(k.size, HEIGHT)))


def _best(call, repeats=2):
    best, value = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        value = call()
        best = min(best, time.perf_counter() - start)
    return best, value


def cost_single_blob(centres):
    from lubrication import far_field_mobility, far_field_product
    product = far_field_product(centres, far_field_mobility(models.ETA, 1.0, wall=True, implementation='C++'))
    x = np.random.default_rng(0).standard_normal(6 * len(centres))
    seconds, _ = _best(lambda: product(x), 3)
    return seconds, seconds, 0


def cost_lubrication(centres):
    from lubrication import LubricationProblem
    from multi_bodies.solver.body_solver import solve
    force = np.zeros((len(centres), 6))
    force[:, 2] = -1.0
    force[:, 0] = 0.3

    def one_solve():
        problem = LubricationProblem(centres, 1.0, models.ETA, wall=True, implementation='C++')
        return solve(problem, problem.rhs(force), problem.preconditioner(TOLERANCE), tolerance=TOLERANCE)
    seconds, result = _best(one_solve)
    product_seconds = cost_single_blob(centres)[0]
    return product_seconds, seconds, result.iterations


def _shell_scene(num_blobs, centres):
    from body.body import Body, bodies_to_arrays
    from mobility.interface import Geometry, make_mobility
    blobs, blob_radius = models.calibrated_model_blobs(num_blobs)
    bodies = [Body(c, np.array([1.0, 0.0, 0.0, 0.0]), blobs, blob_radius) for c in centres]
    for body in bodies:
        body.ID = 'sphere'
    arrays = bodies_to_arrays(bodies)
    return arrays, make_mobility('C++', Geometry('single_wall'), models.ETA, blob_radius)


def cost_shell(num_blobs, centres, iterations=None):
    """(seconds of one M f, seconds of one solve, GMRES iterations); modelled solve when ``iterations`` given."""
    from multi_bodies.solver import body_solver
    arrays, blob_mobility = _shell_scene(num_blobs, centres)
    configuration = arrays.configuration
    problem = body_solver.MobilityProblem(arrays, configuration, blob_mobility)
    x = np.random.default_rng(0).standard_normal(problem.r_vectors.size)
    product_seconds, _ = _best(lambda: blob_mobility.velocities(problem.r_vectors, x), 1)
    force = np.zeros((len(centres), 6))
    force[:, 2] = -1.0
    force[:, 0] = 0.3

    def preconditioner():
        return body_solver.BlockDiagonalPreconditioner(arrays, configuration, blob_mobility)
    if iterations is not None:
        build_seconds, _ = _best(preconditioner, 1)
        return product_seconds, build_seconds + iterations * product_seconds, iterations

    def one_solve():
        return body_solver.solve(problem, problem.rhs(force_torque=force.reshape(-1)), preconditioner(),
                                 tolerance=TOLERANCE)
    seconds, result = _best(one_solve, 1)
    return product_seconds, seconds, result.iterations


def measure_costs():
    """{model: (M f seconds, solve seconds, iterations, 'measured' or 'modelled')} on the 64-sphere scene."""
    centres = lattice()
    costs = {'1 blob': cost_single_blob(centres) + ('measured',),
             '1 blob + lubrication': cost_lubrication(centres) + ('measured',)}
    for n in models.SHELLS[:-1]:
        costs['shell %d' % n] = cost_shell(n, centres) + ('measured',)
    iterations = costs['shell %d' % models.SHELLS[-2]][2]
    costs['shell %d' % models.SHELLS[-1]] = cost_shell(models.SHELLS[-1], centres, iterations) + ('modelled',)
    return costs


def measure_errors(tables):
    """{'pair'|'wall': {model: [(gap, error against exact, error against 2562 or None)]}}."""
    resolved = {}
    if tables and os.path.exists(os.path.join(tables, 'mob_scalars_MB_2562.txt')):
        resolved['pair'] = models.read_pair_table(os.path.join(tables, 'mob_scalars_MB_2562.txt'))
        resolved['wall'] = models.read_wall_table(os.path.join(tables, 'mob_scalars_wall_MB_2562.txt'))
    out = {'pair': {}, 'wall': {}}
    for kind, gaps, scalars, exact, error, contact in (
            ('pair', models.PAIR_GAPS, models.pair_scalars, models.exact_pair_scalars, models.pair_error, 2.0),
            ('wall', models.WALL_GAPS, models.wall_scalars, models.exact_wall_scalars, models.wall_error, 1.0)):
        for model in models.MODELS:
            rows = []
            for gap in gaps:
                values = scalars(model, gap)
                against_resolved = None
                if kind in resolved and contact + gap <= resolved[kind][0][-1]:
                    against_resolved = error(values, models.interpolate(*resolved[kind], contact + gap))
                rows.append((gap, error(values, exact(gap)), against_resolved))
            out[kind][model] = rows
        if kind in resolved:  # the published 2562-blob spheres themselves, against the exact answer
            out[kind][models.TABLE_MODEL] = [
                (gap, error(models.interpolate(*resolved[kind], contact + gap), exact(gap)), None)
                if contact + gap <= resolved[kind][0][-1] else (gap, None, None) for gap in gaps]
    return out


def _percent(value):
    return '-' if value is None else ('%.2g%%' % (100 * value) if value < 0.1 else '%.0f%%' % (100 * value))


def print_tables(errors, costs):
    for kind, title in (('pair', 'two spheres in free space'), ('wall', 'one sphere above the wall')):
        gaps = [row[0] for row in errors[kind][models.MODELS[0]]]
        print('\n%s: largest relative error against the exact answer (against the 2562-blob table)\n' % title)
        print('| model | ' + ' | '.join('gap %g a' % g for g in gaps) + ' |')
        print('|---|' + '---|' * len(gaps))
        for model in errors[kind]:
            print('| %s | ' % model + ' | '.join(
                '%s (%s)' % (_percent(e), _percent(r)) if r is not None else _percent(e)
                for _, e, r in errors[kind][model]) + ' |')
    print('\ncost on %d spheres (C++, GMRES tolerance %g)\n' % (SIDE * SIDE, TOLERANCE))
    print('| model | blobs | one M f | one solve | GMRES iterations |')
    print('|---|---|---|---|---|')
    for model in models.MODELS:
        product, solve, iterations, how = costs[model]
        blobs = 1 if not model.startswith('shell') else int(model.split()[1])
        print('| %s | %d | %.3g s | %.3g s%s | %s |' % (model, blobs * SIDE * SIDE, product, solve,
                                                      '' if how == 'measured' else ' (modelled)', iterations or '-'))
    print('\n# --- shipped in multi_bodies/advice/lubrication_tables.py ---')
    print('ERRORS = {')
    for kind in ('pair', 'wall'):
        print("    '%s': {" % kind)
        for model in errors[kind]:
            values = ', '.join('None' if e is None else '%.4g' % e for _, e, _ in errors[kind][model])
            print("        '%s':\n            (%s)," % (model, values))
        print('    },')
    print('}')
    print('COSTS = {')
    for model in models.MODELS:
        product, solve, iterations, how = costs[model]
        print("    '%s': (%.3g, %.3g, %d, '%s')," % (model, product, solve, iterations, how))
    print('}')


def draw(errors, costs, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    for ax, kind, title in ((axes[0], 'pair', 'two spheres (free space)'), (axes[1], 'wall', 'sphere above the wall')):
        for model in errors[kind]:
            rows = [r for r in errors[kind][model] if r[1] is not None]
            ax.loglog([r[0] for r in rows], [max(100 * r[1], 1e-4) for r in rows], 'o-' if model in models.MODELS
                      else 'k--', label=model)
        ax.set_xlabel('gap / a')
        ax.set_ylabel('largest relative error [%] (against exact)')
        ax.set_title(title)
        ax.grid(True, which='both', alpha=0.3)
    axes[0].legend(fontsize=8)
    ax = axes[2]
    for gap, marker in ((0.01, 'o'), (0.1, 's'), (0.5, '^')):
        points = []
        for model in models.MODELS:
            pair = [r[1] for r in errors['pair'][model] if r[0] == gap]
            wall = [r[1] for r in errors['wall'][model] if r[0] == gap]
            points.append((costs[model][1], 100 * max(pair + wall + [1e-6]), model))
        ax.loglog([p[0] for p in points], [p[1] for p in points], marker + '-', label='gap %g a' % gap)
        if gap == 0.1:
            for seconds, error, model in points:
                ax.annotate(model, (seconds, error), fontsize=7, textcoords='offset points', xytext=(3, 3))
    ax.set_xlabel('one mobility solve of 64 spheres, C++ on 2 cores [s]')
    ax.set_ylabel('worst of pair and wall error [%]')
    ax.set_title('accuracy against cost')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print('chart written to %s' % path)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--png', help='also draw the chart into this PNG file (needs matplotlib)')
    parser.add_argument('--tables', default=DEFAULT_TABLES, help='folder of the published resolved-sphere tables')
    parser.add_argument('--no-costs', action='store_true', help='errors only (costs from the shipped table)')
    args = parser.parse_args()
    start = time.perf_counter()
    errors = measure_errors(args.tables)
    if args.no_costs:
        from multi_bodies.advice.lubrication_tables import COSTS
        costs = dict(COSTS)
    else:
        costs = measure_costs()
    print_tables(errors, costs)
    if args.png:
        draw(errors, costs, args.png)
    print('# %.0f s' % (time.perf_counter() - start))


if __name__ == '__main__':
    main()
