"""Laws of the spectral product that need no reference data.

* the compiled path equals the NumPy path (round-off), in every geometry, with torques, blobs on a wall;
* the adapter (backend ``spectral`` of ``mobility.interface``) gives the core's numbers and never a stale
  stencil;
* triply periodic self-mobility against Hasimoto's finite-size series;
* far from the walls in a large box: DP -> free-space RPY, DPBW -> Rotne-Prager-Blake with periodic images;
* symmetry (TP to round-off, Chebyshev geometries to the library's discretisation level) and positive
  definiteness; translation by a period; linearity (F, T) = (F, 0) + (0, T);
* the one-line errors.

Each law test fails for a wrong factor (a factor 2 in the viscosity, the kernel normalisation or the torque
coupling moves the numbers far beyond the stated tolerances).
"""
import numpy as np
import pytest

from mobility import interface
from mobility.spectral import SpectralStokes, compiled_available, dpstokes_parameters
from utils import UserInputError

RADIUS = 1.0155
ETA = 0.957e-3
needs_compiled = pytest.mark.skipif(not compiled_available(), reason='mobility._spectral_cpp not built')


def _box(geometry, kernel='w6', torque=False, L=(24.0, 20.0), z=(0.0, 8.0)):
    return dpstokes_parameters(RADIUS, geometry, L[0], L[1], z[0], z[1], kernel=kernel, has_torque=torque, warn=False)


def _blobs(p, n, rng, z=None):
    lo, hi = (0.0, p.Lz) if p.z_range is None else p.z_range
    r = np.column_stack([rng.uniform(0, p.Lx, n), rng.uniform(0, p.Ly, n), rng.uniform(lo, hi, n)])
    if z is not None:
        r[:len(z), 2] = z
    return r


def _relative(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


# ------------------------------------------------------------------ the two paths
@needs_compiled
@pytest.mark.parametrize('geometry', ['TP', 'DP', 'DPBW', 'DPSC'])
@pytest.mark.parametrize('kernel, torque', [('w6', False), ('w4', False), ('w6', True), ('w5w4', True)])
def test_compiled_equals_numpy(geometry, kernel, torque):
    """Same numbers to round-off; blobs on the walls, at the ends of the height range, on grid nodes."""
    p = _box(geometry, kernel, torque, L=(18.0, 15.0))
    rng = np.random.default_rng(7)
    special = [p.z_range[0], p.z_range[1], 1.0] if p.z_range else [0.0, 3.0]
    r = _blobs(p, 60, rng, z=special)
    r[3, :2] = (4 * p.hx, 6 * p.hy)                # exactly on a node (the kernel's edge nodes)
    F = rng.standard_normal((60, 3))
    T = rng.standard_normal((60, 3)) if torque else None
    out = []
    for path in ('numpy', 'compiled'):
        stokes = SpectralStokes(p, ETA, path=path)
        stokes.set_positions(r)
        out.append(stokes.product(F, T))
    assert _relative(out[1][0], out[0][0]) < 1e-13
    if torque:
        assert _relative(out[1][1], out[0][1]) < 1e-13
    else:
        assert out[0][1] is None and out[1][1] is None


@needs_compiled
@pytest.mark.parametrize('geometry', ['DP', 'DPBW', 'DPSC'])
def test_compiled_skips_untouched_planes_exactly(geometry):
    """The compiled transforms skip the z planes no blob's kernel touches (doc/spectral.md): with the blobs in a
    thin layer, then moved to another one (the planes left with spectral values by the first product must not
    leak into the second), the products equal the NumPy path's (which transforms every plane) to round-off, and
    the skipped band is really narrower than the grid (the test exercises the skip)."""
    p = _box(geometry, 'w6', True, L=(18.0, 15.0))
    low, high = p.z_range
    rng = np.random.default_rng(11)
    F = rng.standard_normal((40, 3))
    T = rng.standard_normal((40, 3))
    compiled = SpectralStokes(p, ETA, path='compiled')
    for layer in ((low + 1.0, low + 1.6), (high - 2.0, high - 1.5)):
        r = _blobs(p, 40, rng)
        r[:, 2] = rng.uniform(*layer, 40)
        compiled.set_positions(r)
        band = compiled._engine._planes
        assert 0 < band.stop - band.start < p.Nz
        U, W = compiled.product(F, T)
        reference = SpectralStokes(p, ETA, path='numpy')
        reference.set_positions(r)
        U0, W0 = reference.product(F, T)
        assert _relative(U, U0) < 1e-13 and _relative(W, W0) < 1e-13


# ------------------------------------------------------------------ the adapter
def _geometry(kind, L=(24.0, 20.0, 16.0), z=(0.0, 8.0)):
    return interface.Geometry(kind, periodic_length=L, z_bounds=None if kind == 'triply_periodic' else z)


def test_adapter_matches_core_and_refreshes_stencils():
    geometry = _geometry('doubly_periodic_wall')
    mob = interface.make_mobility('spectral', geometry, ETA, RADIUS, rotation=True)
    assert mob.has_rotation and mob.backend == 'spectral'
    rng = np.random.default_rng(3)
    r = _blobs(mob.parameters, 12, rng)
    F, T = rng.standard_normal(36), rng.standard_normal(36)
    core = SpectralStokes(mob.parameters, ETA)
    core.set_positions(r)
    U_ref, W_ref = core.product(F, T)
    U, W = mob.product(r, F, T)
    assert np.array_equal(U, U_ref.ravel()) and np.array_equal(W, W_ref.ravel())
    # the couplings add up to the grand product
    parts = [mob.coupling(kind, r, F if kind.endswith('force') else T)
             for kind in ('trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque')]
    assert _relative(parts[0] + parts[1], U) < 1e-13 and _relative(parts[2] + parts[3], W) < 1e-13
    # moving one blob in place (same array object) must not reuse the old stencils
    moved = r.copy()
    moved[0, 0] += 0.37
    fresh = SpectralStokes(mob.parameters, ETA)
    fresh.set_positions(moved)
    r[0, 0] += 0.37
    assert np.array_equal(mob.product(r, F, T)[0], fresh.product(F, T)[0].ravel())


def test_adapter_geometries_registered():
    assert 'spectral' in interface.registered_backends('doubly_periodic_slit')
    for kind in interface.PERIODIC_GEOMETRIES:
        mob = interface.make_mobility('spectral', _geometry(kind), ETA, RADIUS)
        assert mob.parameters.geometry == {'triply_periodic': 'TP', 'doubly_periodic_open': 'DP',
                                           'doubly_periodic_wall': 'DPBW', 'doubly_periodic_slit': 'DPSC'}[kind]
        r = _blobs(mob.parameters, 5, np.random.default_rng(1))
        assert mob.velocities(r, np.ones(15)).shape == (15,)
    with pytest.raises(UserInputError):
        interface.make_mobility('spectral', _geometry('doubly_periodic_wall'), ETA, RADIUS).product(
            np.array([[1.0, 1.0, 2.0]]), np.zeros(3), np.ones(3))


# ------------------------------------------------------------------ physics
def _dense(p, r, torque=False, path=None):
    """The (grand) mobility matrix at r by products with unit vectors: (3N, 3N) or with torques (6N, 6N)
    ordered [U; W] x [F; T]."""
    stokes = SpectralStokes(p, ETA, path=path)
    stokes.set_positions(r)
    n = 3 * len(r)
    size = 2 * n if torque else n
    M = np.zeros((size, size))
    for j in range(size):
        x = np.zeros(size)
        x[j] = 1.0
        U, W = stokes.product(x[:n], x[n:] if torque else None)
        M[:n, j] = U.ravel()
        if torque:
            M[n:, j] = W.ravel()
    return M


def _hasimoto(R, L):
    x = R / L
    return (1 - 2.837297 * x + 4.19 * x ** 3 - 27.4 * x ** 6) / (6 * np.pi * ETA * R)


@pytest.mark.parametrize('kernel, tolerance', [('w6', 4e-4), ('w4', 7e-3)])
@pytest.mark.parametrize('L', [16.0, 32.0])
def test_triply_periodic_self_mobility_hasimoto(kernel, tolerance, L):
    """One blob in a cubic box: trace/3 of its self-mobility against Hasimoto's series (Hasimoto, J. Fluid Mech.
    5, 317, 1959, with the higher terms of Zick and Homsy, J. Fluid Mech. 115, 13, 1982), at positions on a
    node, mid-cell and in between.  The tolerance is the kernel's accuracy: the radius fit (DoublyPeriodicStokes
    reaches 2.4e-4 with w6 and 2.1e-3 with w4) plus the kernel's dependence on the position within a cell
    (measured up to 6e-3 for w4, 1.2e-4 for w6)."""
    p = dpstokes_parameters(RADIUS, 'TP', L, L, 0.0, L, kernel=kernel, warn=False)
    h = p.hx
    for position in ([L / 2, L / 2, L / 2], [0.5 * h, 0.5 * h, 0.5 * h], [0.25 * h, 0.3 * h, 0.77 * h]):
        M = _dense(p, np.array([position]))
        assert np.trace(M) / 3 == pytest.approx(_hasimoto(RADIUS, L), rel=tolerance)
        assert np.max(np.abs(M - np.diag(np.diag(M)))) < 1e-10 * M[0, 0]


def test_open_doubly_periodic_tends_to_free_space():
    """DP (open z) in growing boxes: the difference from the free-space RPY mobility falls as 1/L (periodic
    images, zero mean flow), and the Richardson extrapolation in 1/L meets RPY to the kernel's accuracy."""
    import mobility
    errors, matrices = [], []
    for L in (32.0, 64.0, 128.0):
        r = np.array([[L / 2 + 0.3, L / 2 + 0.1, 0.2], [L / 2 - 3.7, L / 2 + 2.2, 1.5]])
        M = _dense(dpstokes_parameters(RADIUS, 'DP', L, L, -4.0, 4.0, warn=False), r)
        rpy = mobility.rotne_prager_tensor(r, ETA, RADIUS)
        errors.append(np.max(np.abs(M - rpy)) / np.max(np.abs(rpy)))
        matrices.append(M)
    assert 1.8 < errors[0] / errors[1] < 2.2 and 1.8 < errors[1] / errors[2] < 2.2   # first order in 1/L
    extrapolated = 2 * matrices[2] - matrices[1]
    assert np.max(np.abs(extrapolated - rpy)) / np.max(np.abs(rpy)) < 3e-3             # measured 1.8e-3


def test_bottom_wall_tends_to_blake_with_images():
    """DPBW in growing boxes against the Rotne-Prager-Blake mobility with the periodic images of the first ring
    (this package's pseudo-periodic wall product): 2.3e-3 at L = 64, 6.8e-4 at L = 128 (measured), closer
    than without the images."""
    import mobility
    for L, tolerance in ((64.0, 4e-3), (128.0, 1.2e-3)):
        r = np.array([[L / 2 + 0.3, L / 2 + 0.1, 4.0], [L / 2 - 3.7, L / 2 + 2.2, 6.0]])
        M = _dense(dpstokes_parameters(RADIUS, 'DPBW', L, L, 0.0, 10.0, warn=False), r)
        blake = mobility.single_wall_fluid_mobility(r, ETA, RADIUS, periodic_length=(L, L, 0.0))
        lone = mobility.single_wall_fluid_mobility(r, ETA, RADIUS)
        error = np.max(np.abs(M - blake)) / np.max(np.abs(blake))
        assert error < tolerance
        assert error < np.max(np.abs(M - lone)) / np.max(np.abs(lone))


# Symmetry: round-off in TP; in the Chebyshev geometries the discretisation is not symmetric (spreading by
# collocation at the Chebyshev nodes, interpolation with Clenshaw-Curtis weights): DoublyPeriodicStokes'
# own asymmetry reaches 2.4e-5 of sqrt(x1.M x1 x2.M x2) (reference checks/symmetry.json, heights >= R);
# measured here up to 3e-4 of the largest entry with a blob 1.2 R above the wall and torques.
SYMMETRY = {'TP': 1e-12, 'DP': 5e-4, 'DPBW': 5e-4, 'DPSC': 5e-4}


@pytest.mark.parametrize('geometry', ['TP', 'DP', 'DPBW', 'DPSC'])
@pytest.mark.parametrize('kernel, torque', [('w6', False), ('w6', True), ('w5w4', True)])
def test_symmetric_positive_definite(geometry, kernel, torque):
    p = _box(geometry, kernel, torque, L=(14.0, 12.0), z=(0.0, 7.0))
    rng = np.random.default_rng(11)
    r = _blobs(p, 4, rng, z=[p.z_range[0] + 1.2, p.z_range[1] - 1.1] if p.z_range else None)
    M = _dense(p, r, torque)
    asymmetry = np.max(np.abs(M - M.T)) / np.max(np.abs(M))
    assert asymmetry < SYMMETRY[geometry]
    eigenvalues = np.linalg.eigvalsh(0.5 * (M + M.T))
    assert eigenvalues.min() > 0.0
    # a coupling with the wrong factor breaks the symmetry between M_UT and M_WF^T
    if torque:
        wrong = M.copy()
        n = 3 * len(r)
        wrong[n:, :n] *= 2.0
        assert np.max(np.abs(wrong - wrong.T)) / np.max(np.abs(wrong)) > 100 * SYMMETRY[geometry]


@pytest.mark.parametrize('geometry', ['TP', 'DP', 'DPBW', 'DPSC'])
def test_translation_by_a_period_and_linearity(geometry):
    p = _box(geometry, 'w6', True, L=(14.0, 12.0), z=(0.0, 7.0))
    rng = np.random.default_rng(5)
    r = _blobs(p, 20, rng)
    F, T = rng.standard_normal((20, 3)), rng.standard_normal((20, 3))
    stokes = SpectralStokes(p, ETA)
    stokes.set_positions(r)
    U, W = stokes.product(F, T)
    U_F, W_F = stokes.product(F, None)
    U_T, W_T = stokes.product(None, T)
    assert _relative(U_F + U_T, U) < 1e-13 and _relative(W_F + W_T, W) < 1e-13
    shift = np.array([p.Lx, -2 * p.Ly, p.Lz if geometry == 'TP' else 0.0])
    moved = r + shift * rng.integers(0, 2, (20, 1))
    stokes.set_positions(moved)
    U2, W2 = stokes.product(F, T)
    assert _relative(U2, U) < 1e-11 and _relative(W2, W) < 1e-11


# ------------------------------------------------------------------ errors
def test_one_line_errors():
    p = _box('DPSC', 'w6', False, L=(14.0, 12.0), z=(0.0, 7.0))
    stokes = SpectralStokes(p, ETA)
    cases = [(np.array([[1.0, 1.0, -0.1]]), 'below the wall'), (np.array([[1.0, 1.0, 7.5]]), 'above the top wall'),
             (np.array([[np.nan, 1.0, 1.0]]), 'not finite'), (np.ones((2, 2)), 'shape')]
    for r, words in cases:
        with pytest.raises(UserInputError, match=words) as error:
            stokes.set_positions(r)
        assert '\n' not in str(error.value)
    open_box = _box('DP', 'w6', False, L=(14.0, 12.0), z=(0.0, 7.0))
    with pytest.raises(UserInputError, match='heights'):
        SpectralStokes(open_box, ETA).set_positions(np.array([[1.0, 1.0, 9.0]]))
    stokes.set_positions(np.array([[1.0, 1.0, 3.0]]))
    with pytest.raises(UserInputError, match='forces'):
        stokes.product(np.ones(4))
    with pytest.raises(UserInputError, match='not finite'):
        stokes.product(np.array([[np.inf, 0.0, 0.0]]))
    with pytest.raises(UserInputError, match='torques'):
        stokes.product(np.ones(3), np.ones(3))
    with pytest.raises(UserInputError, match='smaller than the kernel'):
        dpstokes_parameters(RADIUS, 'DPBW', 3.0, 20.0, 0.0, 5.0)
    with pytest.raises(UserInputError, match='beta'):
        dpstokes_parameters(RADIUS, 'TP', 1.0, 1.0, 0.0, 1.0)
    with pytest.raises(UserInputError, match='viscosity'):
        SpectralStokes(p, -1.0)


def test_doc_examples_run():
    """The worked examples of doc/spectral.md run as written."""
    import re
    from pathlib import Path
    text = (Path(__file__).resolve().parents[1] / 'doc' / 'spectral.md').read_text()
    blocks = re.findall(r'```python\n(.*?)```', text, re.S)
    assert len(blocks) >= 2
    for block in blocks:
        exec(compile(block, 'doc/spectral.md', 'exec'), {})


def test_stencils_made_in_blocks_give_the_same_product(monkeypatch):
    """Stencils are made in blocks of blobs (bounded temporaries); block boundaries change nothing."""
    from mobility.spectral import stencil
    p = _box('DPBW', 'w6', True, L=(18.0, 15.0))
    rng = np.random.default_rng(2)
    r = _blobs(p, 50, rng, z=[0.0, 0.05, 8.0])
    F, T = rng.standard_normal((50, 3)), rng.standard_normal((50, 3))
    whole = SpectralStokes(p, ETA)
    whole.set_positions(r)
    monkeypatch.setattr(stencil, 'STENCIL_CHUNK', 7)
    blocks = SpectralStokes(p, ETA)
    blocks.set_positions(r)
    for a, b in zip(whole.product(F, T), blocks.product(F, T)):
        assert _relative(b, a) < 1e-14


def test_whole_cells_rule():
    """Ly/h = 49.000000000000007: DoublyPeriodicStokes adds a cell (whole_cells_tolerance=0); by default the
    ratio counts as 49 cells, with a warning that says so."""
    radius = (32.0 / 49.5) / 0.6439997821994082     # h0 = 32/49.5: Nx = 49, h = 32/49
    with pytest.warns(UserWarning, match='whole number of cells'):
        p = dpstokes_parameters(radius, 'DPBW', 32.0, 32.0, 0.0, 8.0)
    assert (p.Nx, p.Ny) == (49, 49) and p.Ly == pytest.approx(32.0, rel=1e-15)
    library = dpstokes_parameters(radius, 'DPBW', 32.0, 32.0, 0.0, 8.0, whole_cells_tolerance=0.0)
    assert library.Ny == 50 and library.Ly == pytest.approx(50 * 32.0 / 49, rel=1e-15)
    genuine = dpstokes_parameters(radius, 'DPBW', 32.0, 30.3, 0.0, 8.0, warn=False)
    assert genuine.Ny == 47 and genuine.Ly == pytest.approx(47 * 32.0 / 49, rel=1e-15)


@needs_compiled
@pytest.mark.parametrize('geometry', ['DPBW', 'DPSC'])
def test_uammd_solve_rules_same_in_both_paths(geometry):
    """The two solve rules of UAMMD (p' by the Chebyshev recurrence; unpaired wall corrections not averaged
    with their partner) give the same numbers in the compiled and the NumPy solve, and other numbers than
    DoublyPeriodicStokes' rules where the grid has an unpaired y mode (the x-halved real inverse transform
    averages unpaired x modes by itself; the two forms of p' agree to rounding)."""
    import dataclasses
    from mobility.spectral import reference
    from mobility.spectral.compiled import CompiledEngine
    base = _box(geometry, 'w6', False, L=(12.0, 12.0), z=(0.0, 6.0))
    assert base.Ny % 2 == 0                      # an unpaired y mode: there the two rules differ
    rng = np.random.default_rng(4)
    force = rng.standard_normal((3, base.Nz, base.Ny, base.Nx))
    force -= force.mean(axis=(2, 3), keepdims=True)   # no mean flow, which would dwarf the difference
    results = {}
    for rules in ('dpstokes', 'uammd'):
        p = dataclasses.replace(base, rules=rules)
        engine = CompiledEngine(p, ETA)
        grid = engine._zeroed_grid()
        grid[..., :p.Nx] = force
        engine.solve(engine.forward())
        engine.backward()
        ours = grid[..., :p.Nx].copy()
        expected = reference.solve(p, ETA, force.copy())
        assert _relative(ours, expected) < 1e-12
        results[rules] = expected
    assert _relative(results['uammd'], results['dpstokes']) > 1e-10
