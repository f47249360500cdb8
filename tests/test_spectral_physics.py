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
    return dpstokes_parameters(RADIUS, geometry, L[0], L[1], z[0], z[1], kernel=kernel, has_torque=torque)


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
