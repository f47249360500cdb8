"""libMobility's DPStokes on the CPU (``mobility.libmobility.DPStokes``) under its two parameter selections.

What the numbers are checked against (never the face's own output):

* DoublyPeriodicStokes' selection (``parameter_selection='dpstokes'``): every reference file of
  ``../shared/reference/dpstokes`` (outputs of the published DoublyPeriodicStokes code) to 1e-10 relative,
  through its README's call sequence; constructor, wall and net-force checks against the conventions of
  libMobility's interface (``../shared/manual/libmobility_interface.md``);
* libMobility's own selection (the default): the wall matrices libMobility's tests ship
  (``../shared/reference/libmobility``, a bottom wall and a slit) to 100 machine epsilons, as libMobility's
  test compares them (every height with ``RMB_LIBMOBILITY_FULL=1``, a spread subset by default); the
  numbers of the selection from the interface note; with torques, laws (symmetry, positive definiteness,
  the Rotne-Prager-Blake rotational self-mobility of Swan and Brady 2007);
* the compiled spectral path against the NumPy path, to round-off.
"""
import json
import os

import numpy as np
import pytest

from conftest import REFERENCE_DIR
from libmobility_helpers import ETA, RADIUS, _wall_self_mobility
from mobility.libmobility import DPStokes


# ------------------------------------------------------------------ DPStokes: DoublyPeriodicStokes' selection
DPSTOKES_DIR = REFERENCE_DIR / 'dpstokes'
Z_OF_GEOMETRY = {'TP': 'periodic', 'DP': 'open', 'DPBW': 'single_wall', 'DPSC': 'two_walls'}
KERNEL_OF_TYPE = {False: {0: 'w6', 1: 'w5', 2: 'w4'}, True: {0: 'w6', 1: 'w5', 3: 'w6w5', 4: 'w6w4', 5: 'w5w4'}}


def _dpstokes_cases():
    found = []
    for name in ('random', 'pair', 'roller'):
        for path in sorted((DPSTOKES_DIR / name).glob('*.json')):
            if path.with_suffix('.npz').exists():
                found.append((name, path))
    return found


DPSTOKES_CASES = _dpstokes_cases()


def _dpstokes_solver(run):
    """The README's call sequence of ``DPStokes`` for one run block of a reference JSON."""
    solver = DPStokes('periodic', 'periodic', Z_OF_GEOMETRY[run['geometry']])
    solver.setParameters(Lx=run['Lx_requested'], Ly=run['Ly_requested'], zmin=run['zmin'], zmax=run['zmax_requested'],
                         allowChangingBoxSize=True, allowUnsafeForces=True, parameter_selection='dpstokes',
                         kernel=KERNEL_OF_TYPE[run['has_torque']][run['kernType']])
    solver.initialize(viscosity=run['eta'], hydrodynamicRadius=run['radius'], includeAngular=run['has_torque'])
    return solver


def test_dpstokes_reference_folder_present():
    if not DPSTOKES_DIR.is_dir():
        pytest.skip('DoublyPeriodicStokes reference data not found at %s' % DPSTOKES_DIR)
    assert DPSTOKES_CASES, 'no reference files under %s' % DPSTOKES_DIR


@pytest.mark.parametrize('case', DPSTOKES_CASES, ids=[path.stem for _, path in DPSTOKES_CASES])
def test_dpstokes_selection_reproduces_every_reference_file(case):
    """Every file of ../shared/reference/dpstokes (held-back files dropped there too) through the face, by the
    README's call sequence; every output array to 1e-10 relative (max |ours - ref| / max |ref|)."""
    kind, path = case
    meta = json.loads(path.read_text())
    with np.load(path.with_suffix('.npz')) as archive:
        data = {key: archive[key] for key in archive.files}
    compared = []
    if kind in ('random', 'roller'):
        run = meta['force_only_run' if kind == 'random' else 'run']
        solver = _dpstokes_solver(run)
        solver.setPositions(data['positions'])
        U, W = solver.Mdot(data['forces'])
        assert W is None and U.shape == data['positions'].shape
        compared.append(('U_F', U, data['U_F']))
    if kind == 'random':
        solver = _dpstokes_solver(meta['force_torque_run'])
        solver.setPositions(data['positions'])
        for suffix, (U, W) in (('FT', solver.Mdot(data['forces'], data['torques'])),
                               ('Fonly', solver.Mdot(data['forces'])),
                               ('Tonly', solver.Mdot(torques=data['torques']))):
            compared += [('U_' + suffix, U, data['U_' + suffix]), ('W_' + suffix, W, data['W_' + suffix])]
    if kind == 'pair':
        run = meta['run']
        solver = _dpstokes_solver(run)
        M = data['M']
        columns = np.asarray(data['columns']).astype(int)
        for i_s in range(M.shape[0]):
            for i_z in range(M.shape[1]):
                solver.setPositions(data['positions'][i_s, i_z])
                ours = np.zeros_like(M[i_s, i_z])
                for j, column in enumerate(columns):
                    unit = np.zeros(12)
                    unit[column] = 1.0
                    if run['has_torque']:
                        U, W = solver.Mdot(unit[:6].reshape(2, 3), unit[6:].reshape(2, 3))
                        ours[:, j] = np.concatenate((U.ravel(), W.ravel()))
                    else:
                        U, _ = solver.Mdot(unit[:6].reshape(2, 3))
                        ours[:, j] = U.ravel()
                compared.append(('M[%d, %d]' % (i_s, i_z), ours, M[i_s, i_z]))
    errors = {name: np.max(np.abs(ours - ref)) / np.max(np.abs(ref)) for name, ours, ref in compared}
    worst = max(errors, key=errors.get)
    assert errors[worst] < 1e-10, '%s: %s off by %.3g relative' % (path.stem, worst, errors[worst])


def _small_dpstokes(z='single_wall', include_angular=False, selection='dpstokes', seed=3, **options):
    solver = DPStokes('periodic', 'periodic', z)
    parameters = dict(Lx=16.0, Ly=16.0, zmin=0.0, zmax=6.0)
    if selection == 'dpstokes':
        parameters.update(parameter_selection='dpstokes')
    parameters.update(options)
    solver.setParameters(**parameters)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, includeAngular=include_angular, seed=seed)
    return solver


def test_dpstokes_constructor_and_parameters():
    for periodicity in [('open', 'periodic', 'open'), ('periodic', 'periodic', 'unspecified'),
                        ('periodic', 'open', 'single_wall')]:
        with pytest.raises(RuntimeError, match='doubly periodic solver'):
            DPStokes(*periodicity)
    with pytest.raises(RuntimeError, match='doubly periodic solver'):       # the extension needs the dpstokes tables
        DPStokes('periodic', 'periodic', 'periodic').setParameters(16.0, 16.0, 0.0, 8.0)
    with pytest.raises(RuntimeError, match='kernel'):
        DPStokes('periodic', 'periodic', 'open').setParameters(16.0, 16.0, 0.0, 8.0, kernel='w6')
    with pytest.raises(RuntimeError, match='parameter_selection'):
        DPStokes('periodic', 'periodic', 'open').setParameters(16.0, 16.0, 0.0, 8.0, parameter_selection='uammd')
    with pytest.raises(RuntimeError, match='setParameters'):
        DPStokes('periodic', 'periodic', 'open').initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    with pytest.raises(RuntimeError, match='kernel'):
        _small_dpstokes(include_angular=True, kernel='w4')                 # w4 has no torque pair
    with pytest.raises(RuntimeError, match='whole number of cells'):     # 16.3 is not whole cells of the w6 grid
        _small_dpstokes(Ly=16.3)
    assert DPStokes.precision == 'double'


def test_dpstokes_wall_checks():
    bottom = _small_dpstokes('single_wall')
    bottom.setPositions([[1.0, 2.0, 0.0]])                  # on the wall: accepted
    with pytest.raises(RuntimeError, match='passed through a wall'):
        bottom.setPositions([[1.0, 2.0, 3.0], [0.0, 0.0, -1e-9]])
    slit = _small_dpstokes('two_walls')
    with pytest.raises(RuntimeError, match='passed through a wall'):
        slit.setPositions([[1.0, 2.0, 6.0 + 1e-9]])
    with pytest.raises(RuntimeError, match='passed through a wall'):
        slit.setPositions([[1.0, 2.0, -0.1]])


def test_dpstokes_open_net_force_check():
    solver = _small_dpstokes('open')
    solver.setPositions([[1.0, 2.0, 3.0], [5.0, 1.0, 2.0]])
    with pytest.raises(RuntimeError, match='DPStokes'):
        solver.Mdot([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    U, _ = solver.Mdot([[1.0, 0.5, 0.0], [-1.0, -0.5, 0.0]])          # zero net force: fine
    assert U.shape == (2, 3)
    with pytest.raises(RuntimeError, match='DPStokes'):                 # the Lanczos vectors have a net force
        solver.sqrtMdotW()
    unsafe = _small_dpstokes('open', allowUnsafeForces=True)
    unsafe.setPositions([[1.0, 2.0, 3.0], [5.0, 1.0, 2.0]])
    unsafe.Mdot([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert unsafe.sqrtMdotW()[0].shape == (2, 3)


@pytest.mark.parametrize('selection', ['dpstokes', 'libmobility'])
def test_dpstokes_langevin_at_zero_temperature_and_seeds(selection):
    positions = [[1.0, 2.0, 3.0], [5.0, 1.0, 2.0]]
    F = np.array([[0.3, -1.0, 0.2], [1.0, 0.4, -0.7]])
    T = np.array([[0.1, 0.2, -0.3], [0.0, 0.5, 0.1]])

    def run(seed):
        solver = _small_dpstokes('single_wall', include_angular=True, selection=selection, seed=seed)
        solver.setPositions(positions)
        U, W = solver.LangevinVelocities(0.1, 0.0, F, T)
        U_ref, W_ref = solver.Mdot(F, T)
        np.testing.assert_array_equal(U, U_ref)
        np.testing.assert_array_equal(W, W_ref)
        return solver.sqrtMdotW(0.7) + solver.divM(0.5)

    first, again, other = run(11), run(11), run(12)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], other[0])


# ------------------------------------------------------------------ DPStokes: libMobility's own selection
LIBMOBILITY_DIR = REFERENCE_DIR / 'libmobility'
EPS_100 = 100 * np.finfo(np.float64).eps          # libMobility's tolerance for a module declaring "double"
WALL_ETA = 1 / 4 / np.sqrt(np.pi)                 # libMobility's test_wall_mobility: eta, a = 1, box 76.8
# Heights checked: every one with RMB_LIBMOBILITY_FULL=1 (3,888 products, many minutes; all passed
# when written); by default a spread subset near the wall and in the bulk (about 300 products).
FULL_SWEEP = bool(os.environ.get('RMB_LIBMOBILITY_FULL'))
SUBSET = {('self', True): [1, 5, 10, 17, 25, 35, 47, 59], ('self', False): [2, 20, 59],
          ('pair', True): [1, 6, 13, 25], ('pair', False): [3, 25]}


def _wall_solver(z_mode, shift, include_angular=False):
    """libMobility's test_wall_mobility set-up: DPStokes over [0, 19.2] + shift in a 76.8 box, default selection."""
    solver = DPStokes('periodic', 'periodic', z_mode)
    solver.setParameters(Lx=76.8, Ly=76.8, zmin=0 + shift, zmax=19.2 + shift, allowChangingBoxSize=False)
    solver.initialize(viscosity=WALL_ETA, hydrodynamicRadius=1.0, includeAngular=include_angular)
    return solver


def _compute_M(solver, n):
    """Column i = Mdot(e_i), forces only (libMobility's tests/utils compute_M)."""
    M = np.zeros((3 * n, 3 * n))
    for i in range(3 * n):
        unit = np.zeros(3 * n)
        unit[i] = 1.0
        M[:, i] = solver.Mdot(unit.reshape(n, 3))[0].reshape(-1)
    return M


def _load_libmobility(name):
    path = LIBMOBILITY_DIR / (name + '.npz')
    if not path.exists():
        pytest.skip('libMobility reference matrices not found at %s' % LIBMOBILITY_DIR)
    with np.load(path) as archive:
        return archive['M'], archive['heights'].ravel()


def _indices(kind, count, shift):
    return list(range(count)) if FULL_SWEEP else SUBSET[(kind, shift == 0)]


@pytest.mark.parametrize('shift', [0, 5.4, -10])
@pytest.mark.parametrize('z_mode, tag', [('single_wall', 'bw'), ('two_walls', 'sc')])
def test_libmobility_self_mobility_linear(z_mode, tag, shift):
    """libMobility's self-mobility files (w = 4, bottom wall / slit) at 100 eps, as its test compares them: the
    diagonal of M / (1/(6 pi eta a)) with rtol = atol = 100 eps.  (The xy entries of the stored matrices, 1e-8
    to 1e-7, which libMobility's test does not compare, differ from ours by a factor 0.376; see
    doc/libmobility.md.)"""
    M_ref, heights = _load_libmobility('self_mobility_%s_w4' % tag)
    solver = _wall_solver(z_mode, shift)
    for i in _indices('self', heights.size, shift):
        solver.setPositions(np.array([[76.8 / 2, 76.8 / 2, heights[i] + shift]]))
        M = _compute_M(solver, 1) / (1 / (6 * np.pi * WALL_ETA * 1.0))
        assert np.allclose(np.diag(M), np.diag(M_ref[i]), rtol=EPS_100, atol=EPS_100), \
            (i, heights[i], np.abs(np.diag(M) - np.diag(M_ref[i])).max())


@pytest.mark.parametrize('shift', [0, 5.4, -10])
@pytest.mark.parametrize('z_mode, tag', [('single_wall', 'bw'), ('two_walls', 'sc')])
def test_libmobility_pair_mobility_linear(z_mode, tag, shift):
    """libMobility's pair-mobility files: every entry of M / (1/(6 pi eta)) within 100 eps (absolute)."""
    M_ref, heights = _load_libmobility('pair_mobility_%s_w4' % tag)
    solver = _wall_solver(z_mode, shift)
    separations = [3.0, 4.0, 8.0] if (FULL_SWEEP or shift == 0) else [4.0]
    for d in separations:
        i = [3.0, 4.0, 8.0].index(d)
        for k in _indices('pair', heights.size, shift):
            x = 76.8 / 2
            solver.setPositions(np.array([[x + d / 2, x, heights[k] + shift], [x - d / 2, x, heights[k] + shift]]))
            M = _compute_M(solver, 2) / (1 / (6 * np.pi * WALL_ETA))
            difference = np.abs(M - M_ref[i, k][0:6, 0:6])
            assert np.all(difference < EPS_100), (d, k, heights[k], difference.max())


def test_libmobility_selection_check_values():
    """The numbers of libMobility's selection for a = 1 (interface note, section 4)."""
    from mobility.spectral.libmobility_parameters import libmobility_parameters
    p, _ = libmobility_parameters(1.0, 'single_wall', 16.0, 16.0, -6.0, 6.0)
    assert (p.Nx, p.Ny) == (20, 20) and p.hx == pytest.approx(0.8, rel=1e-15)
    assert p.monopole.beta == pytest.approx((6.4875,) * 3, abs=1e-4)
    p, _ = libmobility_parameters(1.0, 'single_wall', 76.8, 76.8, 0.0, 19.2)
    assert (p.Nx, p.Ny) == (92, 92) and p.hx == pytest.approx(0.834783, abs=1e-6)
    assert p.monopole.beta[0] == pytest.approx(7.2377, abs=1e-4)
    p, _ = libmobility_parameters(1.0, 'single_wall', 76.8, 76.8, 0.0, 19.2, include_angular=True)
    assert (p.Nx, p.Ny) == (132, 132) and p.hx == pytest.approx(0.581818, abs=1e-6)
    assert p.monopole.beta[0] == pytest.approx(8.0822, abs=1e-4)
    assert p.dipole.beta[0] == pytest.approx(13.5060, abs=1e-4)
    assert p.monopole.width[0] == 6 and p.dipole.width[0] == 6
    # the z extents and Nz of the 16 x 16, z in [-6, 6] example (force only)
    for z_mode, extent, nz in (('open', (-8.4, 8.4), 33), ('single_wall', (-6.0, 8.4), 29),
                               ('two_walls', (-6.0, 6.0), None)):
        p, stored = libmobility_parameters(1.0, z_mode, 16.0, 16.0, -6.0, 6.0)
        assert (p.z0, p.z0 + p.Lz) == pytest.approx(extent, abs=1e-12)
        assert (stored['zmin'], stored['zmax']) == pytest.approx(extent, abs=1e-12)
        if nz is not None:
            assert p.Nz == nz
        assert p.Nz % 2 == 1
    # allowChangingBoxSize: the box becomes whole nominal cells and the nominal beta stays
    p, stored = libmobility_parameters(1.0, 'single_wall', 16.0, 15.0, 0.0, 6.0, allow_changing_box_size=True)
    h = 1.0 / 1.205
    assert (p.Nx, p.Ny) == (20, 18) and (stored['Lx'], stored['Ly']) == pytest.approx((20 * h, 18 * h), rel=1e-15)
    assert p.monopole.beta == pytest.approx((1.785 * 4,) * 3, rel=1e-15)
    # the grid is centred on x = y = 0
    assert (p.x0, p.y0) == pytest.approx((-10 * h, -9 * h), rel=1e-15)


def test_libmobility_selection_non_square_refits_per_direction():
    from mobility.spectral.libmobility_parameters import libmobility_parameters
    p, _ = libmobility_parameters(1.0, 'two_walls', 16.0, 19.0, 0.0, 8.0)
    assert p.hx != p.hy
    assert p.monopole.beta[0] != p.monopole.beta[1]
    assert p.monopole.beta[2] == min(p.monopole.beta[:2])
    assert p.monopole.alpha[2] == pytest.approx(2.0 * min(p.hx, p.hy), rel=1e-15)
    with pytest.raises(RuntimeError, match='Could not find'):
        solver = DPStokes('periodic', 'periodic', 'single_wall')
        solver.setParameters(Lx=16.0, Ly=2.68, zmin=0.0, zmax=8.0)      # Ny = 4: hy = 0.67, beta(a/(4 hy)) < 4
        solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    with pytest.raises(RuntimeError, match='DPStokes.*too small'):
        solver = DPStokes('periodic', 'periodic', 'two_walls')
        solver.setParameters(Lx=16.0, Ly=16.0, zmin=0.0, zmax=1.5)
        solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)


def test_libmobility_initialize_keeps_the_widened_extent():
    """libMobility stores the widened z extent: a second initialize without setParameters widens it again."""
    solver = DPStokes('periodic', 'periodic', 'single_wall')
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=-6.0, zmax=6.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    first = solver.parameters.z0 + solver.parameters.Lz
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    assert first == pytest.approx(8.4, abs=1e-12)
    assert solver.parameters.z0 + solver.parameters.Lz == pytest.approx(8.4 + 2.4, abs=1e-12)
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=-6.0, zmax=6.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    assert solver.parameters.z0 + solver.parameters.Lz == pytest.approx(8.4, abs=1e-12)


def test_libmobility_single_wall_accepts_blobs_above_zmax():
    """libMobility's DPStokes with one wall refuses only z < zmin (its test passes z = 5.5 with zmax = 5)."""
    solver = DPStokes('periodic', 'periodic', 'single_wall')
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=0.0, zmax=5.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    solver.setPositions([[0.0, 0.0, 5.5]])
    assert np.all(np.isfinite(solver.Mdot([[1.0, 0.0, 0.0]])[0]))
    with pytest.raises(RuntimeError, match='passed through a wall'):
        solver.setPositions([[0.0, 0.0, -0.01]])


def _grand_M(solver, n):
    size = 6 * n
    M = np.zeros((size, size))
    for c in range(size):
        unit = np.zeros(size)
        unit[c] = 1.0
        U, W = solver.Mdot(unit[:3 * n].reshape(n, 3), unit[3 * n:].reshape(n, 3))
        M[:, c] = np.concatenate((U.ravel(), W.ravel()))
    return M


def test_libmobility_angular_path_by_laws():
    """With torques (w = 6 kernels, spectral curl; libMobility's angular files are not shipped): the grand
    mobility is symmetric to the discretisation's level (measured 1e-7 to 5e-6 relative; the Chebyshev
    geometries' spreading and Clenshaw-Curtis-weighted interpolation are not exact adjoints) and positive
    definite, and the rotational self-mobility far from the box's periodic images agrees with the
    Rotne-Prager-Blake one (Swan and Brady 2007) to the kernel's accuracy (measured <= 0.32% in a 16 box at
    heights 1.5 to 5; periodic images of a torque enter at O((a/L)^3)).  A wrong factor 2 in the curl, a
    lost image or a transposed coupling fails one of these."""
    solver = DPStokes('periodic', 'periodic', 'single_wall')
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=0.0, zmax=10.0)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, includeAngular=True)
    for h in (1.5, 3.0, 5.0):
        solver.setPositions([[0.3, -0.2, h]])
        M = _grand_M(solver, 1)
        scale = np.abs(M).max()
        assert np.abs(M - M.T).max() < 2e-5 * scale
        assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0
        np.testing.assert_allclose(np.diag(M)[3:], _wall_self_mobility(h)[3:], rtol=1e-2)
        assert np.abs(np.diag(M)[3:] / _wall_self_mobility(h)[3:] - 1).max() > 1e-5   # not the wall product itself
    solver.setPositions([[0.3, -0.2, 2.0], [2.9, 1.1, 3.1]])
    M = _grand_M(solver, 2)
    assert np.abs(M - M.T).max() < 2e-5 * np.abs(M).max()
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0
    # forces and torques superpose, and W has the shape of the torques
    F = np.array([[0.2, -1.0, 0.5], [0.1, 0.3, -0.2]])
    T = np.array([[1.0, 0.4, -0.3], [-0.5, 0.2, 0.7]])
    U, W = solver.Mdot(F, T)
    U_F, W_F = solver.Mdot(F)
    U_T, W_T = solver.Mdot(torques=T.reshape(-1))
    assert W_T.shape == (6,)
    np.testing.assert_allclose(U, U_F + U_T.reshape(2, 3), rtol=1e-12, atol=1e-15 * np.abs(U).max())
    np.testing.assert_allclose(W, W_F + W_T.reshape(2, 3), rtol=1e-12, atol=1e-15 * np.abs(W).max())


def test_dpstokes_selection_whole_cells_up_to_round_off():
    """DoublyPeriodicStokes' selection with a box of whole cells up to round-off (radius 0.9, L = 26: h = 26/45
    and 26 / h = 45.00000000000001, where the library adds a cell): no extra cell, even with
    allowChangingBoxSize=False; a genuine fraction is enlarged with allowChangingBoxSize=True only."""
    from mobility.spectral import dpstokes_parameters
    exact = dpstokes_parameters(RADIUS, 'DPBW', 26.0, 26.0, 0.0, 6.0, whole_cells_tolerance=0.0, warn=False)
    assert (exact.Nx, exact.Ny) == (45, 46)                      # the library's own rule adds a cell here
    solver = _small_dpstokes(Lx=26.0, Ly=26.0)
    assert (solver.parameters.Nx, solver.parameters.Ny) == (45, 45)
    assert solver.parameters.Ly == pytest.approx(26.0, rel=1e-15)
    enlarged = _small_dpstokes(Lx=32.0, Ly=31.5, allowChangingBoxSize=True)
    h = enlarged.parameters.hx
    assert enlarged.parameters.Ny == int(np.ceil(31.5 / h)) and enlarged.parameters.Ly == pytest.approx(
        enlarged.parameters.Ny * h, rel=1e-15)
    with pytest.raises(RuntimeError, match='allowChangingBoxSize'):
        _small_dpstokes(Lx=32.0, Ly=31.5)
    with pytest.raises(RuntimeError, match='kernel'):
        _small_dpstokes(kernel='w3')


@pytest.mark.parametrize('z_mode', ['open', 'single_wall', 'two_walls'])
def test_libmobility_selection_compiled_path_equals_numpy_path(z_mode):
    """Force-only products of libMobility's selection run on the core's compiled engine with this package's
    UAMMD stencils; the NumPy path (mobility.spectral.uammd) gives the same numbers to round-off."""
    from mobility.spectral import SpectralStokes, compiled_available
    from mobility.spectral.libmobility_parameters import libmobility_parameters
    if not compiled_available():
        pytest.skip('the compiled spectral extension is not built')
    p, _ = libmobility_parameters(RADIUS, z_mode, 16.0, 19.0, 0.0, 7.0)
    rng = np.random.default_rng(5)
    r = np.column_stack((rng.uniform(-20, 20, 12), rng.uniform(-20, 20, 12), rng.uniform(0.0, 7.0, 12)))
    F = rng.standard_normal((12, 3))
    F -= F.mean(axis=0)
    results = []
    for path in ('compiled', 'numpy'):
        stokes = SpectralStokes(p, ETA, path=path)
        assert stokes.path == path
        stokes.set_positions(r)
        results.append(stokes.product(F)[0])
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-13 * np.abs(results[1]).max())
