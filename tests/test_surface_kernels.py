"""The compiled surface kernels (Laplace layers, Stokes double layer) against the NumPy references, with and without
the wall, including blobs near the wall; and the layers against closed forms on a sphere."""
import numpy as np
import pytest

from multi_bodies.files.structure_generators import icosahedral_shell
from multi_bodies.solver import laplace_kernels


@pytest.mark.parametrize('wall', [False, True])
def test_compiled_equals_numpy(wall):
    if laplace_kernels._surface_cpp is None:
        pytest.skip('the C++ Laplace kernels are not built (pip install -e . builds them)')
    rng = np.random.default_rng(3)
    x = rng.uniform(-3, 3, size=(300, 3))
    x[:, 2] = np.abs(x[:, 2]) + 0.05
    n = rng.normal(size=(300, 3))
    w = rng.uniform(0.1, 1, size=300)
    densities = {k: rng.normal(size=300) for k in ('single', 'double', 'grad_double', 'dipole')}
    ours = laplace_kernels.layers(x, n, w, wall, backend='C++', **densities)
    reference = laplace_kernels.layers(x, n, w, wall, backend='python', **densities)
    for key in densities:
        scale = np.max(np.abs(reference[key]))
        assert np.max(np.abs(ours[key] - reference[key])) < 1e-12 * scale, key
    only = laplace_kernels.layers(x, n, w, wall, backend='C++', single=densities['single'])
    assert set(only) == {'single'}


def test_layers_on_a_sphere():
    """Unit sphere of 2562 points, w = 4 pi / n, outward normals: S[1] = 1 and D[1] = -1/2 on the surface
    (Gauss: the exterior limit of the double layer of a constant density), within the point rule's error."""
    x = icosahedral_shell(2562)
    w = np.full(2562, 4 * np.pi / 2562)
    out = laplace_kernels.layers(x, x, w, False, single=np.ones(2562), double=np.ones(2562))
    assert abs(np.mean(out['single']) - 1.0) < 0.03   # measured 0.978: the dropped self term
    assert abs(np.mean(out['double']) + 0.5) < 0.02
    # negative control: the inward normals flip the double layer's sign
    assert abs(np.mean(laplace_kernels.layers(x, -x, w, False, double=np.ones(2562))['double']) - 0.5) < 0.02


def test_compiled_stokes_double_layer_equals_numpy():
    from multi_bodies.solver import slip_length
    if slip_length._surface_cpp is None:
        pytest.skip('the C++ surface kernels are not built (pip install -e . builds them)')
    rng = np.random.default_rng(4)
    x = rng.uniform(-3, 3, size=(300, 3))
    x[7] = x[3]  # two blobs at one point: skipped as a self pair by both
    n, v, w = rng.normal(size=(300, 3)), rng.normal(size=(300, 3)), rng.uniform(0.1, 1, size=300)
    ours = slip_length.double_layer(x, n, w, 0.3, v, backend='C++')
    reference = slip_length.double_layer(x, n, w, 0.3, v, backend='python')
    assert np.max(np.abs(ours - reference)) < 1e-12 * np.max(np.abs(reference))
