"""Deterministic integrators: error, cost and stability against the time step.

Runs the manual's dynamic scene (one boomerang and two 12-blob spheres
sedimenting under gravity onto the wall, soft blob-blob and blob-wall
repulsions, C++ backends) with ``deterministic_forward_euler`` and
``deterministic_adams_bashforth`` for time steps from 0.8 to 0.025, up to
t = 20 (the bodies land on the wall near t = 10 and then rest on the soft
wall repulsion, a stiff problem).  Each run is compared with an
Adams-Bashforth run at dt = 0.00625:

* error during the fall, at t = 4 (smooth regime: shows the order), and
* error at t = 20 (resting on the wall: shows stability),

as the largest distance between a body location and its reference.  A run
that puts a blob below the wall stops and is marked as
failed.  The script runs ``multi_bodies.py`` itself, as a user would.

    python doc/charts/integrators_accuracy_vs_dt.py [--debye-length 0.1] [--png chart.png]
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))  # the repository
from multi_bodies.files import snapshots  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SCRIPT = os.path.join(REPO, 'multi_bodies', 'multi_bodies.py')
STRUCTURES = os.path.join(REPO, 'multi_bodies', 'Structures')
T_FALL, T_END = 4.0, 20.0
IDS = ('boomerang_N_15', 'shell_N_12_Rg_1')

INPUT = """scheme {scheme}
mobility_blobs_implementation C++
mobility_vector_prod_implementation C++
blob_blob_force_implementation C++
dt {dt!r}
n_steps {n_steps}
n_save {n_save}
eta 1.0
g 1.0
blob_radius 0.25
repulsion_strength 1.0
debye_length {debye!r}
repulsion_strength_wall 1.0
debye_length_wall {debye!r}
solver_tolerance 1e-10
output_name {output}
structure {structures}/boomerang_N_15.vertex {structures}/boomerang_N_15.clones
structure {structures}/shell_N_12_Rg_1.vertex {structures}/shell_N_12_Rg_1.clones
"""


def run(scheme, dt, folder, debye=1.0):
    """Run the scene; returns (locations at T_FALL, locations at T_END, wall seconds) or None on failure."""
    n_save = int(round(T_FALL / dt))
    n_steps = int(round(T_END / dt))
    output = os.path.join(folder, '%s_%g' % (scheme, dt))
    path = output + '.dat'
    with open(path, 'w') as f:
        f.write(INPUT.format(scheme=scheme, dt=dt, n_steps=n_steps, n_save=n_save, output=output,
                             structures=STRUCTURES, debye=debye))
    result = subprocess.run([sys.executable, SCRIPT, '--input-file', path], capture_output=True, text=True)
    if result.returncode != 0:
        return None, result.stderr.strip().splitlines()[-1] if result.stderr.strip() else 'failed'

    def locations(step):
        return np.concatenate([snapshots.read_clones_file(snapshots.clones_name(output, structure_id, step))[0]
                               for structure_id in IDS])

    with open(output + '.time') as f:
        seconds = float(f.read())
    return (locations(n_save), locations(n_steps), seconds), None


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--png', help='also draw the chart into this PNG file (needs matplotlib)')
    parser.add_argument('--debye-length', type=float, default=1.0,
                        help='range of the blob-blob and blob-wall repulsions (the manual: 1; 0.1 is stiffer)')
    args = parser.parse_args()
    debye = args.debye_length
    print('# debye_length and debye_length_wall = %g' % debye)
    steps = [0.8, 0.4, 0.2, 0.1, 0.05, 0.025]
    schemes = ['deterministic_forward_euler', 'deterministic_adams_bashforth']
    with tempfile.TemporaryDirectory() as folder:
        reference, why = run('deterministic_adams_bashforth', 0.00625, folder, debye)
        if reference is None:
            sys.exit('reference run failed: %s' % why)
        table = []
        print('| scheme | dt | run time | error at t = %g (falling) | error at t = %g (on the wall) |' % (T_FALL, T_END))
        print('|---|---|---|---|---|')
        for scheme in schemes:
            for dt in steps:
                outcome, why = run(scheme, dt, folder, debye)
                if outcome is None:
                    table.append((scheme, dt, None, None, None))
                    print('| %s | %g | - | failed: %s | |' % (scheme, dt, why))
                    continue
                fall = np.max(np.linalg.norm(outcome[0] - reference[0], axis=1))
                end = np.max(np.linalg.norm(outcome[1] - reference[1], axis=1))
                table.append((scheme, dt, outcome[2], fall, end))
                print('| %s | %g | %.2f s | %.2e | %.2e |' % (scheme, dt, outcome[2], fall, end))
    for scheme in schemes:
        rows = [r for r in table if r[0] == scheme and r[3] is not None]
        if len(rows) >= 3:
            dts = np.array([r[1] for r in rows])
            errors = np.array([r[3] for r in rows])
            slope = np.polyfit(np.log(dts[-3:]), np.log(errors[-3:]), 1)[0]
            print('# %s: observed order during the fall (three smallest dt) %.2f' % (scheme, slope))
    if args.png:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
        import matplotlib.ticker
        fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
        for scheme, marker in zip(schemes, ('o', 's')):
            rows = [r for r in table if r[0] == scheme and r[3] is not None]
            label = scheme.replace('deterministic_', '')
            axes[0].loglog([r[1] for r in rows], [r[3] for r in rows], marker + '-', label=label)
            axes[1].loglog([r[2] for r in rows], [r[4] for r in rows], marker + '-', label=label)
            for r in table:
                if r[0] == scheme and r[3] is None:
                    axes[0].axvline(r[1], color='gray', ls=':', lw=1)
        axes[0].set_xticks(steps)
        axes[0].xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter('%g'))
        axes[0].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        axes[0].set_xlabel('dt (dotted: the run crossed the wall)')
        axes[0].set_ylabel('error of body locations at t = %g' % T_FALL)
        axes[0].set_title('falling: order of accuracy (debye length %g)' % debye)
        axes[1].set_xlabel('run time to t = %g [s]' % T_END)
        axes[1].set_ylabel('error at t = %g' % T_END)
        axes[1].set_title('resting on the wall: cost of accuracy')
        for ax in axes:
            ax.grid(True, which='both', alpha=0.3)
            ax.legend()
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        print('chart written to %s' % args.png)


if __name__ == '__main__':
    main()
