"""The spectral product on an array namespace (``mobility.spectral.array_product``) and its GPU backend
(``spectral_gpu``, CuPy with raw CUDA kernels).

Without a GPU: the array product with NumPy and the NumPy stand-ins of the raw kernels equals the CPU product
(``SpectralStokes``, compiled or NumPy path: independent code for the spreading, interpolation and solves) to
round-off in the four geometries, force-only and with torques; the stand-ins equal the CPU product's spreading
and interpolation; and the same statements run in a strict stand-in namespace that, as CuPy does, refuses to mix
its arrays with NumPy's (so a host array left in the device path fails here, not only on a GPU).  With a GPU
(tests marked ``gpu``): the CUDA kernels equal the stand-ins and the ``spectral_gpu`` backend equals the
``spectral`` backend to 1e-12.
"""
import subprocess
import sys
import types
import warnings

import numpy as np
import pytest

from mobility.interface import (PERIODIC_GEOMETRIES, PREFERENCE, Geometry, make_mobility, registered_backends,
                                unusable_reason)
from mobility.spectral import SpectralStokes, dpstokes_parameters, grid_kernels, reference
from mobility.spectral.array_product import ArrayStokes
from mobility.spectral.stencil import make_stencil, wrap_positions
from utils import UserInputError

CASES = [(geometry, kernel, torque) for geometry in ('TP', 'DP', 'DPBW', 'DPSC')
         for kernel, torque in (('w6', False), ('w4', False), ('w6', True), ('w5w4', True))]
Z_RANGE = {'TP': (0.0, 20.0), 'DP': (2.0, 8.0), 'DPBW': (0.0, 8.0), 'DPSC': (0.0, 8.0)}


def discretisation(geometry, kernel, torque, Lx=20.0, Ly=24.0):
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        return dpstokes_parameters(1.0, geometry, Lx, Ly, *Z_RANGE[geometry], kernel=kernel, has_torque=torque)


def blobs(p, n=40, seed=0):
    """Positions (n, 3) inside the heights of ``p`` (x and y partly outside the box: wrapped), forces, torques."""
    rng = np.random.default_rng(seed)
    low, high = (-3.0, 25.0) if p.geometry == 'TP' else (p.z_range[0] + 0.3, p.z_range[1] - 0.3)
    r = np.column_stack([rng.uniform(-5.0, 25.0, n), rng.uniform(0.0, 24.0, n), rng.uniform(low, high, n)])
    return r, rng.standard_normal((n, 3)), (rng.standard_normal((n, 3)) if p.has_torque else None)


def relative(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


def cpu_product(p, r, F, T, eta=1.3):
    stokes = SpectralStokes(p, eta)
    stokes.set_positions(r)
    return stokes.product(F, T)


@pytest.mark.parametrize('geometry, kernel, torque', CASES)
def test_array_product_with_numpy_is_the_cpu_product(geometry, kernel, torque):
    p = discretisation(geometry, kernel, torque)
    r, F, T = blobs(p)
    U, W = cpu_product(p, r, F, T)
    array = ArrayStokes(p, 1.3)
    array.set_positions(r)
    U_array, W_array = array.product(F, T)
    assert relative(U_array, U) < 1e-12
    if torque:
        assert relative(W_array, W) < 1e-12
    else:
        assert W_array is None
    # flat vectors, forces alone and torques alone add up to the product of both
    U_f, _ = array.product(F.ravel(), None)
    if torque:
        U_t, W_t = array.product(None, T.ravel())
        assert relative(U_f + U_t, U) < 1e-12


def test_stand_in_kernels_are_the_cpu_spreading_and_interpolation():
    """The NumPy stand-ins of the raw kernels against the CPU product's spreading and interpolation
    (mobility.spectral.reference), on a slit grid with the torque kernels (derivative stencils included)."""
    p = discretisation('DPSC', 'w6', True)
    r, F, T = blobs(p, n=30, seed=4)
    rel = wrap_positions(p, r)
    monopole, dipole = make_stencil(p, p.monopole, rel), make_stencil(p, p.dipole, rel, derivative=True)
    st_m, st_d = grid_kernels.grid_stencil(p, monopole), grid_kernels.grid_stencil(p, dipole)
    expected = np.zeros((3, p.Nz, p.Ny, p.Nx))
    reference.spread_forces(p, monopole, F, expected)
    reference.spread_torques(p, dipole, T, expected)
    grid = np.zeros_like(expected)
    grid_kernels.spread_forces(grid, st_m, F)
    grid_kernels.spread_torques(grid, st_d, T)
    assert relative(grid, expected) < 1e-14
    velocity = np.random.default_rng(5).standard_normal(expected.shape)
    assert relative(grid_kernels.interpolate_velocities(velocity, st_m),
                    reference.interpolate_velocities(p, monopole, velocity)) < 1e-14
    assert relative(grid_kernels.interpolate_rotations(velocity, st_d),
                    reference.interpolate_rotations(p, dipole, velocity)) < 1e-14


# ------------------------------------------------------------------ a strict stand-in namespace
class Device(np.ndarray):
    """A NumPy array standing for a device array: operations that mix it with a host (NumPy) array of more than
    zero dimensions raise, as CuPy refuses implicit transfers."""

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        arrays = list(inputs) + list(kwargs.get('out', ()))
        if any(isinstance(x, np.ndarray) and not isinstance(x, Device) and x.ndim > 0 for x in arrays):
            raise TypeError('a host array mixed with a device array in %s.%s' % (ufunc.__name__, method))
        inputs = [x.view(np.ndarray) if isinstance(x, Device) else x for x in inputs]
        if 'out' in kwargs:
            kwargs['out'] = tuple(x.view(np.ndarray) if isinstance(x, Device) else x for x in kwargs['out'])
        result = getattr(ufunc, method)(*inputs, **kwargs)
        return _device(result)

    def __array_function__(self, func, types_, args, kwargs):
        def host(x):
            return isinstance(x, np.ndarray) and not isinstance(x, Device) and x.ndim > 0
        flat = list(args) + list(kwargs.values())
        flat += [y for x in flat if isinstance(x, (list, tuple)) for y in x]
        if any(host(x) for x in flat):
            raise TypeError('a host array mixed with a device array in %s' % func.__name__)
        return _device(func._implementation(*_host(args), **_host(kwargs)))


def _host(value):
    if isinstance(value, Device):
        return value.view(np.ndarray)
    if isinstance(value, (list, tuple)):
        return type(value)(_host(v) for v in value)
    if isinstance(value, dict):
        return {k: _host(v) for k, v in value.items()}
    return value


def _device(value):
    if isinstance(value, np.ndarray) and not isinstance(value, Device):
        return value.view(Device)
    if isinstance(value, tuple):
        return tuple(_device(v) for v in value)
    return value


def _wrap(function):
    def wrapped(*args, **kwargs):
        return _device(function(*_host(args), **_host(kwargs)))
    return wrapped


def strict_namespace():
    """A module standing for CuPy: NumPy's functions on Device arrays, asnumpy back to the host."""
    xp = types.ModuleType('strict_device')
    for name in ('zeros', 'zeros_like', 'empty', 'empty_like', 'asarray', 'ascontiguousarray', 'tensordot', 'stack',
                 'concatenate', 'exp', 'conj', 'einsum', 'all', 'isfinite'):
        setattr(xp, name, _wrap(getattr(np, name)))
    xp.float64 = np.float64
    xp.ndarray = Device
    xp.fft = types.SimpleNamespace(rfftn=_wrap(np.fft.rfftn), irfftn=_wrap(np.fft.irfftn))
    xp.linalg = types.SimpleNamespace(solve=_wrap(np.linalg.solve))
    xp.asnumpy = lambda a: np.array(a.view(np.ndarray))
    xp.cuda = types.SimpleNamespace(Stream=types.SimpleNamespace(null=types.SimpleNamespace(synchronize=lambda: None)))
    return xp


class DeviceKernels:
    """The stand-in kernels on Device arrays (views: the grid is written in place)."""

    @staticmethod
    def _st(st):
        return grid_kernels.GridStencil(*[_host(v) for v in st])

    def spread_forces(self, grid, st, forces):
        grid_kernels.spread_forces(grid.view(np.ndarray), self._st(st), _host(forces))

    def spread_torques(self, grid, st, torques):
        grid_kernels.spread_torques(grid.view(np.ndarray), self._st(st), _host(torques))

    def interpolate_velocities(self, grid, st):
        return _device(grid_kernels.interpolate_velocities(grid.view(np.ndarray), self._st(st)))

    def interpolate_rotations(self, grid, st):
        return _device(grid_kernels.interpolate_rotations(grid.view(np.ndarray), self._st(st)))


@pytest.mark.parametrize('geometry', ['TP', 'DP', 'DPBW', 'DPSC'])
def test_device_statements_never_mix_host_arrays(geometry):
    """The array product in a namespace that refuses host arrays (as CuPy does) runs and gives the CPU product:
    the branches taken off NumPy (transforms by the Chebyshev matrices, the namespace's FFT, the mean flow's
    constants, indices and wavenumbers moved to the device) are those a GPU runs."""
    xp = strict_namespace()
    p = discretisation(geometry, 'w6', True, Lx=16.0, Ly=16.0)
    r, F, T = blobs(p, n=25, seed=7)
    U, W = cpu_product(p, r, F, T)
    array = ArrayStokes(p, 1.3, xp=xp, kernels=DeviceKernels())
    array.set_positions(r)
    U_host, W_host = array.product(F, T)              # host inputs: host results
    assert type(U_host) is np.ndarray and relative(U_host, U) < 1e-12 and relative(W_host, W) < 1e-12
    U_device, _ = array.product(xp.asarray(F), xp.asarray(T))
    assert isinstance(U_device, Device) and relative(U_device.view(np.ndarray), U) < 1e-12
    with pytest.raises(TypeError, match='host array'):
        xp.asarray(F) + F                             # the namespace does refuse a mix


def test_libmobility_rules_are_refused():
    """UAMMD's rules (libMobility's face) are the CPU product's only: refused in one line, not computed wrongly."""
    import dataclasses
    p = dataclasses.replace(discretisation('DPBW', 'w6', False), rules='uammd')
    with pytest.raises(UserInputError, match='rules'):
        ArrayStokes(p, 1.0)


# ------------------------------------------------------------------ the registry
def test_the_gpu_backend_is_registered_and_lazy():
    """spectral_gpu serves the periodic geometries on the GPU, ahead of the CPU product in the one preference
    order; the package and the array product import without CuPy; where it cannot run, making it is one line."""
    assert set(registered_backends(device='gpu')) >= {'spectral_gpu'}
    assert all('spectral_gpu' in registered_backends(kind) for kind in PERIODIC_GEOMETRIES)
    assert PREFERENCE.index('spectral_gpu') < PREFERENCE.index('spectral')
    code = ('import sys, mobility, mobility.interface, mobility.spectral.array_product, mobility.spectral_gpu_mobility;'
            'print(any(m.split(".")[0] == "cupy" for m in sys.modules))')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout.strip() == 'False', run.stderr
    reason = unusable_reason('spectral_gpu')
    if reason is None:
        pytest.skip('a GPU is here: the gpu tests check the backend')
    with pytest.raises(UserInputError) as error:
        make_mobility('spectral_gpu', Geometry('triply_periodic', (16.0, 16.0, 16.0)), 1.0, 1.0)
    assert 'spectral_gpu' in str(error.value) and '\n' not in str(error.value)


# ------------------------------------------------------------------ on a GPU
def gpu_or_skip():
    reason = unusable_reason('spectral_gpu')
    if reason is not None:
        pytest.skip('spectral_gpu not usable here: %s' % reason)
    import cupy
    return cupy


@pytest.mark.gpu
def test_cuda_kernels_equal_the_stand_ins():
    cp = gpu_or_skip()
    from mobility.spectral import cuda_kernels
    p = discretisation('DPBW', 'w6', True)
    r, F, T = blobs(p, n=300, seed=8)
    rel = wrap_positions(p, r)
    monopole, dipole = make_stencil(p, p.monopole, rel), make_stencil(p, p.dipole, rel, derivative=True)
    host_m, host_d = grid_kernels.grid_stencil(p, monopole), grid_kernels.grid_stencil(p, dipole)
    dev_m, dev_d = grid_kernels.grid_stencil(p, monopole, cp), grid_kernels.grid_stencil(p, dipole, cp)
    expected = np.zeros((3, p.Nz, p.Ny, p.Nx))
    grid_kernels.spread_forces(expected, host_m, F)
    grid_kernels.spread_torques(expected, host_d, T)
    grid = cp.zeros(expected.shape)
    cuda_kernels.spread_forces(grid, dev_m, cp.asarray(F))
    cuda_kernels.spread_torques(grid, dev_d, cp.asarray(T))
    assert relative(cp.asnumpy(grid), expected) < 1e-13
    velocity = np.random.default_rng(9).standard_normal(expected.shape)
    device_velocity = cp.asarray(velocity)
    assert relative(cp.asnumpy(cuda_kernels.interpolate_velocities(device_velocity, dev_m)),
                    grid_kernels.interpolate_velocities(velocity, host_m)) < 1e-13
    assert relative(cp.asnumpy(cuda_kernels.interpolate_rotations(device_velocity, dev_d)),
                    grid_kernels.interpolate_rotations(velocity, host_d)) < 1e-13


@pytest.mark.gpu
@pytest.mark.parametrize('kind', PERIODIC_GEOMETRIES)
@pytest.mark.parametrize('rotation, kernel', [(False, 'w6'), (False, 'w4'), (True, 'w6'), (True, 'w6w5')])
def test_gpu_backend_equals_the_cpu_backend(kind, rotation, kernel):
    """The spectral_gpu backend against the spectral backend: 2000 blobs, one of them closer to the wall than its
    radius (the published near-wall rule), to 1e-12 of the largest output; device inputs stay on the device."""
    cp = gpu_or_skip()
    box = (40.0, 40.0, 40.0 if kind == 'triply_periodic' else 0.0)
    geometry = Geometry(kind, box, None if kind == 'triply_periodic' else (0.0, 8.0))
    options = dict(kernel=kernel, rotation=rotation, near_wall='published' if geometry.has_wall else None)
    cpu = make_mobility('spectral', geometry, 1.0, 1.0, **options)
    gpu = make_mobility('spectral_gpu', geometry, 1.0, 1.0, **options)
    rng = np.random.default_rng(10)
    n = 2000
    r = np.column_stack([rng.uniform(0, 40, n), rng.uniform(0, 40, n), rng.uniform(0.5, 7.5, n)])
    r[0, 2] = 0.6
    F, T = rng.standard_normal((2, 3 * n))
    U_cpu, W_cpu = cpu.product(r, F, T if rotation else None)
    U_gpu, W_gpu = gpu.product(r, F, T if rotation else None)
    assert relative(U_gpu, U_cpu) < 1e-12
    if rotation:
        assert relative(W_gpu, W_cpu) < 1e-12
    U_device = gpu.velocities(r, cp.asarray(F))
    assert isinstance(U_device, cp.ndarray) and relative(cp.asnumpy(U_device), cpu.velocities(r, F)) < 1e-12
