"""The spectral product against DoublyPeriodicStokes' own outputs (``../shared/reference/dpstokes``).

Every data file of the sets ``random``, ``pair`` and ``roller`` is found by globbing (held-back files of the
same sets dropped into those folders are checked the same way); everything a case needs (geometry, kernel
type, box, radius, viscosity, positions, inputs) is read from the file and its JSON twin.  Each output array
must match to 1e-10 relative (max |ours - ref| / max |ref|, the reference README's measure; round-off gives
about 1e-14).  The parameter selection is checked against the grid and kernel numbers the JSON records.
"""
import json

import numpy as np
import pytest

from conftest import REFERENCE_DIR
from mobility.spectral import SpectralStokes, dpstokes_parameters

DPSTOKES_DIR = REFERENCE_DIR / 'dpstokes'
SETS = ('random', 'pair', 'roller')
TOLERANCE = 1e-10


def _cases():
    """(set, json path) of every data file of the three sets, sorted."""
    found = []
    for name in SETS:
        for path in sorted((DPSTOKES_DIR / name).glob('*.json')):
            if path.with_suffix('.npz').exists():
                found.append((name, path))
    return found


CASES = _cases()
IDS = [path.stem for _, path in CASES]


def _runs(meta):
    """The run blocks of a JSON (random files: force-only and force-torque; pair and roller: one)."""
    return [meta[key] for key in ('force_only_run', 'force_torque_run', 'run') if key in meta]


def _parameters(run):
    """The discretisation of a run, with the arguments the library was given (its exact whole-cell rule)."""
    return dpstokes_parameters(run['radius'], run['geometry'], run['Lx_requested'], run['Ly_passed'], run['zmin'],
                               run['zmax_passed'], kernel=run['kernType'], has_torque=run['has_torque'],
                               whole_cells_tolerance=0.0)


def _relative_error(ours, ref):
    return np.max(np.abs(ours - ref)) / np.max(np.abs(ref))


def test_reference_folder_present():
    if not DPSTOKES_DIR.is_dir():
        pytest.skip('DoublyPeriodicStokes reference data not found at %s' % DPSTOKES_DIR)
    for name in SETS:
        assert any(s == name for s, _ in CASES), 'no data files in %s' % (DPSTOKES_DIR / name)


@pytest.mark.parametrize('case', CASES, ids=IDS)
def test_parameter_selection(case):
    """Nx, Ny, Nz, h, the lengths used, the z grid, widths, betas, alphas and norms of every run."""
    _, path = case
    meta = json.loads(path.read_text())
    for run in _runs(meta):
        p = _parameters(run)
        assert (p.Nx, p.Ny, p.Nz) == (run['Nx'], run['Ny'], run['Nz'])
        assert p.monopole.width[0] == run['w_m']
        expected = {'h': p.hx, 'Lx_used': p.Lx, 'Ly_used': p.Ly, 'Lz_grid': p.Lz, 'beta_m': p.monopole.beta[0],
                    'alpha_m': p.monopole.alpha[0], 'norm_m': p.monopole.norm[0]}
        if run['geometry'] != 'TP':
            expected['z0_grid'] = p.z0
        if run['has_torque']:
            assert p.dipole.width[0] == run['w_d']
            expected.update(beta_d=p.dipole.beta[0], alpha_d=p.dipole.alpha[0], norm_d=p.dipole.norm[0])
        for key, ours in expected.items():
            assert ours == pytest.approx(run[key], rel=1e-14, abs=1e-14), key
        assert p.hy == p.hx and p.x0 == 0.0 and p.y0 == 0.0


def _random_case(meta, data):
    out = []
    run = meta['force_only_run']
    stokes = SpectralStokes(_parameters(run), run['eta'])
    stokes.set_positions(data['positions'])
    U, W = stokes.product(data['forces'])
    assert W is None
    out.append(('U_F', U, data['U_F']))
    run = meta['force_torque_run']
    stokes = SpectralStokes(_parameters(run), run['eta'])
    stokes.set_positions(data['positions'])
    for suffix, F, T in (('FT', data['forces'], data['torques']), ('Fonly', data['forces'], None),
                         ('Tonly', None, data['torques'])):
        U, W = stokes.product(F, T)
        out += [('U_' + suffix, U, data['U_' + suffix]), ('W_' + suffix, W, data['W_' + suffix])]
    return out


def _pair_case(meta, data):
    run = meta['run']
    stokes = SpectralStokes(_parameters(run), run['eta'])
    M = data['M']
    columns = np.asarray(data['columns']).astype(int)
    out = []
    for i_s in range(M.shape[0]):
        for i_z in range(M.shape[1]):
            stokes.set_positions(data['positions'][i_s, i_z])
            ours = np.zeros_like(M[i_s, i_z])
            for j, column in enumerate(columns):
                unit = np.zeros(12)
                unit[column] = 1.0
                U, W = stokes.product(unit[:6].reshape(2, 3), unit[6:].reshape(2, 3) if run['has_torque'] else None)
                ours[:6, j] = U.ravel()
                if W is not None:
                    ours[6:, j] = W.ravel()
            out.append(('M[%d, %d]' % (i_s, i_z), ours, M[i_s, i_z]))
    return out


def _roller_case(meta, data):
    run = meta['run']
    stokes = SpectralStokes(_parameters(run), run['eta'])
    stokes.set_positions(data['positions'])
    U, W = stokes.product(data['forces'])
    return [('U_F', U, data['U_F'])]


@pytest.mark.parametrize('case', CASES, ids=IDS)
def test_reproduces_library(case):
    """Every output array of the file to 1e-10 relative, through the core with the JSON's parameters."""
    kind, path = case
    meta = json.loads(path.read_text())
    with np.load(path.with_suffix('.npz')) as archive:
        data = {key: archive[key] for key in archive.files}
    compare = {'random': _random_case, 'pair': _pair_case, 'roller': _roller_case}[kind]
    errors = {name: _relative_error(ours, ref) for name, ours, ref in compare(meta, data)}
    worst = max(errors, key=errors.get)
    assert errors[worst] < TOLERANCE, '%s: %s off by %.3g relative' % (path.stem, worst, errors[worst])
