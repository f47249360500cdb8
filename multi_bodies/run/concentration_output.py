"""Outputs of phoretic runs: ``output_name.concentration`` and the VTK point data (floor 5; doc/phoretic.md).

``.concentration`` (option ``save_concentration True``) holds one block per
saved step, in the blob order of the run (structure lines in input order,
clones, vertex order)::

    N
    x y z c u_x u_y u_z      (one line per blob)

with the lab-frame blob position, the blob concentration ``c`` of the solute
and the total active slip ``u`` (solute slip plus any prescribed slip) at the
saved configuration, numbers with round-trip precision.  The blob files of
``save_vtk True`` get the same ``concentration`` (and the slip ``slip``) as
point data.  Both are computed at the saved configuration by one concentration
solve from zero (so they do not depend on the run's warm starts).
"""
import numpy as np

from body.body import Configuration


def surface_point_data(model, configuration):
    """(blob slip (N, 3) or None, [('concentration', c (N,))] or []) of a model at ``configuration``."""
    surface = getattr(model, 'surface', None)
    if surface is None or surface.phoretic is None:
        return None, []
    solved = surface.solve_concentrations(model, configuration)
    return model.slip(configuration, solved), [('concentration', solved[1].constraint_force_torque)]


def concentration_block(model, configuration):
    """The text of one ``.concentration`` block at ``configuration`` (see the module docstring)."""
    slip, arrays = surface_point_data(model, configuration)
    r_vectors = model.blob_positions(configuration)
    table = np.column_stack((r_vectors, arrays[0][1], slip))
    lines = ['%d' % table.shape[0]] + [' '.join(repr(float(v)) for v in row) for row in table]
    return '\n'.join(lines) + '\n'


def read_concentration_file(path):
    """The blocks of a ``.concentration`` file: array (steps, N, 7) of ``x y z c u_x u_y u_z``."""
    with open(path) as f:
        words = f.read().split()
    blocks, i = [], 0
    while i < len(words):
        n = int(words[i])
        blocks.append(np.array(words[i + 1:i + 1 + 7 * n], dtype=float).reshape(n, 7))
        i += 1 + 7 * n
    return np.array(blocks)


class AlsoWriteConcentration:
    """Wraps the snapshot writer of a running script: each ``save(step, locations, orientations, ...)`` also
    appends the block of that configuration to ``output_name.concentration`` (a new file unless restarting)."""

    def __init__(self, snapshot_writer, options, model):
        self.snapshot_writer, self.model = snapshot_writer, model
        self.path = options.output_name + '.concentration'
        phoretic = model.surface is not None and model.surface.phoretic is not None
        if options.initial_step == 0 and phoretic:  # without phoretic bodies the option is ignored (warned)
            open(self.path, 'w').close()

    def save(self, step, locations, orientations, *args, **kwargs):
        result = self.snapshot_writer.save(step, locations, orientations, *args, **kwargs)
        if not kwargs.get('stop') and self.model.surface is not None and self.model.surface.phoretic is not None:
            with open(self.path, 'a') as f:
                f.write(concentration_block(self.model, Configuration(locations, orientations)))
        return result

    def __getattr__(self, name):
        return getattr(self.snapshot_writer, name)
