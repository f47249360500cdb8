"""The published HydroGrid options, computed by the package instead of the external HydroGrid library.

The published code passes the blob positions to HydroGrid
(https://github.com/stochasticHydroTools/HydroGrid) every ``sample_HydroGrid``
steps, which bins them on ``cells`` cells of the periodic xy box and computes
structure factors of the concentration fields named in ``hydroGridOptions.nml``
(a Fortran namelist in the run folder).  Here the same options select the
package's analyses, computed from the particle positions themselves (no
binning on cells):

* ``cells nx ny``: the wavevectors of that grid, ``k = 2 pi n / L`` with
  ``|n_x| <= nx/2``, ``|n_y| <= ny/2`` (the grid's Nyquist range);
* ``green_particles i0 i1``: the species ``green`` (index i0 <= i < i1) and ``red``;
* ``structureFactorPairs`` of the first namelist group: variables 1 (rho), 5
  (rho_green), 6 (rho_red) map onto the columns ``S``, ``S_green_green``,
  ``S_red_red``, ``S_green_red`` of the S(k) table (all four are written when
  green particles are set); pairs of variables 2-4 (velocities, temperature:
  none in a particle simulation) do not map;
* ``nWavenumbers``, ``selectedWavenumbers``, ``nSavedSnapshots`` (the dynamic
  structure factor S(k, w) of HydroGrid): the intermediate scattering function
  F(k, t) (self and collective) at those wavevectors, lags up to
  ``nSavedSnapshots`` samples; S(k, w) is its time Fourier transform, which is
  not computed;
* the second group (the projection along y, a 1-d grid): its static structure
  factor is the ``n_y = 0`` row of the 2-d table (no separate file);
* ``save_HydroGrid s``: every s steps a copy of the tables with the step in its
  name, and the averages restart (0: one average over the whole run);
* not mapped (said in the log): the VTK snapshots and spectra
  (``writeSnapshotVTK``, ``writeSpectrumVTK``, ``writeMeansVTK``,
  ``writeVariancesVTK``, ``writeAbsValue``), variances (``nVariances``,
  ``variancePairs``), ``subtractMeanFT``, ``storeConserved``, ``axisToPrint``,
  ``periodic``, ``outputFolder`` and ``filePrefix`` (the tables are named
  after ``output_name``).

The particles are the body locations (for rollers, one blob per body, the
blobs of the published code; for multiblob bodies HydroGrid saw the blobs).
"""
import math
import os
import re
import time

import numpy as np

from multi_bodies.analysis import tables
from multi_bodies.analysis.structure_factor import StructureFactor, half_space, structure_factor_memory
from multi_bodies.analysis.time_correlations import TimeCorrelations
from multi_bodies.run.writers import Writer
from utils import UserInputError, refuse_if_too_big

NAMELIST_NAME = 'hydroGridOptions.nml'
VARIABLES = {1: 'all', 5: 'green', 6: 'red'}
MAPPED = {'nstructurefactors', 'structurefactorpairs', 'nwavenumbers', 'selectedwavenumbers', 'nsavedsnapshots'}


# ------------------------------------------------------------------ the namelist
def _value(text):
    text = text.strip().rstrip(',').strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in '"\'':
        return text[1:-1]
    if text.upper() in ('T', '.TRUE.', 'TRUE'):
        return True
    if text.upper() in ('F', '.FALSE.', 'FALSE'):
        return False
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text.replace('d', 'e').replace('D', 'e'))
    except ValueError:
        return text


def read_namelist(path):
    """Groups of a Fortran namelist file: list of (group name, {lower-case key: value}).

    ``&name ... /`` groups, ``key = value`` entries (several per line allowed),
    ``!`` comments; values: quoted strings, logicals (T, F, .true., .false.),
    integers, reals, otherwise the text.  Raises UserInputError naming the line.
    """
    try:
        with open(path) as f:
            raw_lines = f.readlines()
    except OSError as err:
        raise UserInputError('cannot read %s (%s)' % (path, err.strerror))
    groups, current = [], None
    for number, raw in enumerate(raw_lines, start=1):
        line = re.sub(r'!(?=(?:[^"\']*["\'][^"\']*["\'])*[^"\']*$).*', '', raw).strip()
        if not line:
            continue
        if line.startswith('&'):
            if line.lower().startswith('&end'):
                current = None
                continue
            current = {}
            groups.append((line[1:].split()[0], current, number))
            line = line[1:].split(None, 1)[1] if len(line[1:].split(None, 1)) > 1 else ''
        if current is None:
            raise UserInputError('%s, line %d: text outside a namelist group (&name ... /)' % (path, number))
        closing = line.endswith('/')
        if closing:
            line = line[:-1]
        keys = list(re.finditer(r'(\w+)\s*=', line))
        for i, key in enumerate(keys):
            end = keys[i + 1].start() if i + 1 < len(keys) else len(line)
            current[key.group(1).lower()] = _value(line[key.end():end])
        if closing:
            current = None
    return [(name, values) for name, values, _ in groups]


def _index_pairs(text, what):
    """'a b, c d, ...' -> list of (a, b) ints."""
    pairs = []
    for item in str(text).split(','):
        words = item.split()
        if len(words) != 2:
            raise UserInputError('%s: expected pairs of integers "a b, c d, ...", got %r' % (what, text))
        pairs.append((int(words[0]), int(words[1])))
    return pairs


def selected_wavevector_indices(group, what):
    """Index vectors (n, 2) of ``selectedWavenumbers`` (nWavenumbers < 0: 'kx0 kx1, ky0 ky1' ranges;
    > 0: that many 'kx ky' pairs), half space, k = 0 left out."""
    count = int(group.get('nwavenumbers', 0) or 0)
    if count == 0:
        return np.zeros((0, 2), dtype=int)
    pairs = _index_pairs(group.get('selectedwavenumbers', ''), what + ' selectedWavenumbers')
    if count < 0:
        (x0, x1), (y0, y1) = pairs[:2]
        refuse_if_too_big(8.0 * 6 * max(x1 - x0 + 1, 0) * max(y1 - y0 + 1, 0), 'the wavevector ranges %d..%d, '
                          '%d..%d' % (x0, x1, y0, y1), what + ' selectedWavenumbers', 'select fewer wavevectors')
        grid = np.stack(np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1), indexing='ij'), -1).reshape(-1, 2)
    else:
        grid = np.array(pairs[:count], dtype=int).reshape(-1, 2)
    grid = np.where(half_space(grid)[:, None], grid, -grid)  # S(k) = S(-k): one of each pair
    return np.unique(grid[np.any(grid != 0, axis=1)], axis=0)


class HydroGridPlan:
    """What a HydroGrid input asks for, in the package's terms (see module docstring).

    Attributes: n_max (2,) wavevector indices, green (i0, i1) or None, fkt_indices (n, 2), max_lag (samples),
    sample_every, save_every (steps), notes (list of str: what maps and what does not, for the log).
    """

    def __init__(self, options, folder=None, log=print):
        if not all(v > 0 for v in options.periodic_length[:2]):
            raise UserInputError('%s: call_HydroGrid needs a periodic box in the xy plane (periodic_length Lx Ly '
                                 '0 with Lx, Ly > 0)' % options.where('periodic_length'))
        if min(options.cells) < 1:
            raise UserInputError('%s: cells must be two integers >= 1, got %d %d' % ((options.where('cells'),)
                                                                                  + tuple(options.cells)))
        if not 0 <= options.green_particles[0] <= options.green_particles[1]:
            raise UserInputError('%s: green_particles i0 i1 needs 0 <= i0 <= i1, got %d %d'
                                 % ((options.where('green_particles'),) + tuple(options.green_particles)))
        self.n_max = np.maximum(np.asarray(options.cells, dtype=np.int64) // 2, 1)
        # S(k) of the cells' wavevectors: refused here, before the run writes anything, when it cannot fit
        refuse_if_too_big(structure_factor_memory(self.n_max), 'S(k) on the wavevectors of %d x %d cells'
                          % tuple(options.cells), '%s: cells %d %d' % ((options.where('cells'),) + tuple(options.cells)),
                          'give fewer cells (the wavevectors |n_x| <= cells_x / 2, |n_y| <= cells_y / 2)')
        self.green = tuple(options.green_particles) if options.green_particles[1] > options.green_particles[0] \
            else None
        self.sample_every, self.save_every = int(options.sample_HydroGrid), int(options.save_HydroGrid)
        self.notes, self.fkt_indices, self.max_lag = [], np.zeros((0, 2), dtype=int), 0
        candidates = [os.getcwd()] + ([folder] if folder else []) + [os.path.dirname(os.path.abspath(
            options.input_file))]
        path = next((os.path.join(c, NAMELIST_NAME) for c in candidates
                     if os.path.isfile(os.path.join(c, NAMELIST_NAME))), None)
        self.notes.append('HydroGrid options computed by the package (doc/analysis.md): S(k) on the wavevectors of '
                          'the %d x %d cells (|n_x| <= %d, |n_y| <= %d)%s' % (
                              options.cells[0], options.cells[1], self.n_max[0], self.n_max[1],
                              ', green particles %d <= i < %d' % self.green if self.green else ''))
        if path is None:
            self.notes.append('no %s in %s: only the static structure factor is computed' % (
                NAMELIST_NAME, ' or '.join(dict.fromkeys(candidates))))
            return
        groups = read_namelist(path)
        for number, (name, group) in enumerate(groups):
            what = '%s group %d (&%s)' % (path, number + 1, name)
            pairs = _pairs_of_variables(group.get('structurefactorpairs', '0 1 0 1'))
            for a, b in _index_pairs(pairs, what) if int(group.get('nstructurefactors', 1) or 0) else ():
                if a not in VARIABLES or b not in VARIABLES:
                    self.notes.append('%s: structure factor of variables %d-%d does not map (only 1 rho, 5 green, '
                                      '6 red exist for particles)' % (what, a, b))
            indices = selected_wavevector_indices(group, what)
            if len(indices):
                self.fkt_indices = np.unique(np.concatenate([self.fkt_indices, indices]), axis=0)
                self.max_lag = max(self.max_lag, int(group.get('nsavedsnapshots', 100) or 100) - 1)
            unmapped = sorted(k for k, v in group.items() if k not in MAPPED)
            if number == 1:
                self.notes.append('%s (the projection along y): its static structure factor is the n_y = 0 rows of '
                                  'the 2-d table' % what)
            if unmapped:
                self.notes.append('%s: not mapped (no effect here): %s' % (what, ', '.join(unmapped)))
        if len(self.fkt_indices):
            self.notes.append('dynamic structure factors: F(k,t) (self and collective) at %d selected wavevectors, '
                              'lags up to %d samples (HydroGrid gives S(k,w), its Fourier transform in time)'
                              % (len(self.fkt_indices), self.max_lag))
        for note in self.notes:
            log(note)

    def accumulators(self, options, time_step):
        """(StructureFactor, TimeCorrelations or None) for samples ``time_step`` apart."""
        structure = StructureFactor(options.periodic_length, self.n_max, 2, green=self.green,
                                    where='%s: cells' % options.where('cells'))
        correlations = None
        if len(self.fkt_indices) and self.max_lag >= 1:
            box = np.asarray(options.periodic_length[:2], dtype=float)
            wavevectors = 2.0 * np.pi * self.fkt_indices / box
            correlations = TimeCorrelations(time_step, np.arange(self.max_lag + 1), options.periodic_length,
                                            wavevectors, np.arange(len(wavevectors)), 2, msd=False)
            correlations.indices = self.fkt_indices
        return structure, correlations


def _pairs_of_variables(text):
    """'0 1 0 1, 0 5 0 6' (HydroGrid: species variable species variable) -> '1 1, 5 6'."""
    items = []
    for item in str(text).split(','):
        words = item.split()
        if len(words) == 4:
            items.append('%s %s' % (words[1], words[3]))
        elif words:
            items.append(' '.join(words))
    return ', '.join(items)


def output_paths(output_name, step=None):
    """Names of the HydroGrid tables: ``output_name.hydrogrid[.<step>].{sk,sk_radial,fkt}.dat``."""
    stem = '%s.hydrogrid%s' % (output_name, '' if step is None else '.' + str(step).zfill(8))
    return {'sk': stem + '.sk.dat', 'sk_radial': stem + '.sk_radial.dat', 'fkt': stem + '.fkt.dat'}


def write_hydrogrid_tables(output_name, structure, correlations, step=None):
    """Write the S(k) tables (and F(k,t)) of the accumulators; returns the paths written."""
    paths = output_paths(output_name, step)
    written = list(tables.write_structure_factor(paths['sk'], paths['sk_radial'], structure.result()))
    if correlations is not None and correlations.n_particles is not None:
        result = correlations.result()
        labels = ['n = %s' % ' '.join('%d' % v for v in n) for n in getattr(correlations, 'indices', [])] or None
        tables.write_fkt(paths['fkt'], result, np.linalg.norm(correlations.wavevectors, axis=1), labels)
        written.append(paths['fkt'])
    return written


class StructureFactorWriter(Writer):
    """The HydroGrid analyses of a dynamic run (``call_HydroGrid True``), sampled at its saves; a writer of
    ``multi_bodies.run.writers``.

    At a save of ``step`` a multiple of ``sample_HydroGrid``, the body locations (Nb, 3) are added to S(k) (and
    F(k, t)); the tables are rewritten at most every 30 s and at the last save, and with ``save_HydroGrid``
    s > 0 a copy named with the step is written every s steps and the averages restart.  Samples are taken when
    the run saves (every ``n_save`` steps): the sampling interval is ``lcm(n_save, sample_HydroGrid)`` steps
    (said in the log when it differs).
    """
    suffixes = ('hydrogrid.sk.dat', 'hydrogrid.sk_radial.dat', 'hydrogrid.fkt.dat')

    def __init__(self, options, log=print, plan=None):
        self.options, self.log = options, log
        self.plan = HydroGridPlan(options, log=log) if plan is None else plan  # a run makes it with its checks
        interval = options.n_save * self.plan.sample_every // math.gcd(options.n_save, self.plan.sample_every)
        if interval != self.plan.sample_every:
            log('sample_HydroGrid %d: samples are taken when the run saves (n_save %d), so every %d steps'
                % (self.plan.sample_every, options.n_save, interval))
        self.interval = interval
        self.structure, self.correlations = self.plan.accumulators(options, interval * options.dt)
        expected = max(1, (options.n_steps - options.initial_step) // interval + 1)
        self.block_length = max(1, -(-expected // 10))  # ten blocks (the last may be shorter)
        self.samples, self.last_write = 0, time.monotonic()

    def write(self, frame):
        """The HydroGrid sample of ``frame.step`` (a save)."""
        step = frame.step
        if step % self.interval != 0:
            return
        positions = np.asarray(frame.locations, dtype=float)[None, :, :]  # (1, Nb, 3)
        sample, block = np.array([self.samples]), np.array([self.samples // self.block_length])
        self.structure.add(positions, sample, block)
        if self.correlations is not None:
            self.correlations.add(positions, sample, block)
        self.samples += 1
        last = step + self.options.n_save > self.options.n_steps
        if last or time.monotonic() - self.last_write > 30.0:
            write_hydrogrid_tables(self.options.output_name, self.structure, self.correlations)
            self.last_write = time.monotonic()
        if self.plan.save_every > 0 and step % self.plan.save_every == 0 and step > self.options.initial_step:
            write_hydrogrid_tables(self.options.output_name, self.structure, self.correlations, step=step)
            self.structure.reset()
            self.samples = 0
            if self.correlations is not None:
                self.correlations = self.plan.accumulators(self.options, self.interval * self.options.dt)[1]
                self.correlations.start_source()
