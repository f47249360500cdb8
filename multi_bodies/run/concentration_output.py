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
from multi_bodies.run.writers import OnSave, Writer


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


SIDE_FILE = 'concentration'  # the key of this file's bytes in a restart record's ``side_files``


class ConcentrationWriter(Writer):
    """``output_name.concentration`` (``save_concentration True``): at every save, the block of that
    configuration is appended and its bytes ``[start, end]`` go into the step's restart record
    (``frame.side_files``; a writer of ``multi_bodies.run.writers`` that feeds the record).

    A new run starts the file empty (the earlier run's was set aside before).  A restart from step k keeps the
    blocks before step k (``keep`` bytes, :func:`kept_bytes` of the record of k, checked before the run starts)
    and, at its first save, moves the rest (the abandoned continuation's blocks, and block k, which the restart
    writes again) to ``output_name.set_aside/`` (``RunInfo.set_aside_tail``), so the file holds one block per
    saved step, as the uninterrupted run's.  At the step a signal stopped the run at (off the grid) no block is
    written and the record gets ``[end, end]``.  Runs without phoretic bodies write nothing (the option is
    ignored, with a warning).
    """
    trigger = OnSave(stops=True)
    feeds_record = True
    suffixes = (SIDE_FILE,)

    def __init__(self, options, model, keep=None, log=print):
        self.model, self.log = model, log
        self.output_name = options.output_name
        self.path = options.output_name + '.concentration'
        self.phoretic = is_phoretic(model)
        self.keep = keep  # bytes of the file a restart keeps (:func:`kept_bytes`; None: nothing to cut)
        self._begun = False
        self.run = None
        self._start = None

    def open(self, run):
        self.run = run
        if not run.restart and self.phoretic:
            open(self.path, 'w').close()
            self._begun = True

    def _begin(self):
        """A restart's first save: cut the file where the record of the restart step says (the tail set aside)."""
        self._begun = True
        folder = self.run.set_aside_tail(self.path, self.keep, 'after_step_concentration')
        if folder is not None:
            self.log('restart: the blocks of %s after byte %d (the continuation that is replaced) moved to %s'
                     % (self.path, self.keep, folder))

    def _size(self):
        import os
        return os.path.getsize(self.path) if os.path.isfile(self.path) else 0

    def write(self, frame):
        if not self.phoretic:
            return
        if not self._begun:
            self._begin()
        start = self._size()
        if frame.kind == 'stop':  # off the grid: no block, the record says where the blocks end
            self._start = None
            frame.side_files[SIDE_FILE] = [start, start]
            return
        from multi_bodies.run import run_output
        block = concentration_block(self.model, Configuration(frame.locations, frame.orientations)).encode()
        run_output._append_or_take_back(self.path, block)
        self._start = start
        frame.side_files[SIDE_FILE] = [start, start + len(block)]

    def take_back(self, frame):
        """The step is not saved: neither is its block."""
        if self._start is not None:
            _cut_quietly(self.path, self._start)
            self._start = None


def is_phoretic(model):
    """True when the model has phoretic bodies (a ``.concentration`` file is written)."""
    surface = getattr(model, 'surface', None)
    return surface is not None and surface.phoretic is not None


def _cut_quietly(path, size):
    try:
        with open(path, 'r+b') as f:
            f.truncate(size)
    except OSError:
        pass


def kept_bytes(options, record):
    """The bytes of ``output_name.concentration`` a restart from ``record`` keeps (the blocks before its step).

    Raises UserInputError when the file is shorter than the record says (cut or replaced: the blocks before the
    restart step are not those of the run); None when the record names no block (a record of a run without
    ``save_concentration``: the file, if any, is continued as it is)."""
    import os
    from utils import UserInputError
    side = (record or {}).get('side_files') or {}
    if SIDE_FILE not in side:
        return None
    keep = int(side[SIDE_FILE][0])
    path = options.output_name + '.concentration'
    size = os.path.getsize(path) if os.path.isfile(path) else None
    if size is None:
        return None  # removed by the user: the restart writes its blocks into a new file
    if size < keep:
        raise UserInputError('%s: initial_step %d: %s holds %d bytes, but the restart record of step %d says the '
                             'blocks before that step end at byte %d (the file was cut or replaced); restore it, or '
                             'move it away to start a new one' % (options.where('initial_step'), options.initial_step,
                                                                  path, size, options.initial_step, keep))
    return keep
