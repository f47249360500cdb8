"""The soft-repulsion laws (SPEC sections 7 and 9) on every backend: force = -grad U, C++ = Python.

Laws (blob-wall, blob-blob, body-body) come from one source per language:
``multi_bodies/solver/physics.py`` (forces and energies beside each other) and
``mobility/cpp/pair_laws.h`` (host C++ and CUDA); the minimum image from
``mobility/periodic.py`` and the same header.

Finite differences.  The force is checked against the central difference
``-(U(x + h) - U(x - h)) / 2h`` of the energy of the same backend.  Its error
is at most ``h^2/6 max|U'''|`` (truncation) plus ``2 eps_mach |U| / h`` for
energies that carry at most a few units of round-off each; the tolerance of
every check is that bound (``fd_tolerance``), with |U'''| bounded from the law
(the derivative divides by the step actually taken, ``(x + h) - (x - h)``,
which is exact, not by 2h, whose rounding alone would be a relative 1e-10):

* soft exponential laws (wall, blob-blob): ``|U'''| <= eps/b^3`` (0 on the
  linear overlap branch);
* Yukawa ``eps exp(-r/b)/r``: ``|U'''| = eps e^(-r/b) (1/(b^3 r) + 3/(b^2 r^2) + 6/(b r^3) + 6/r^4)``;
* along a direction in 3D, ``U(|r|)`` has ``|d^3U/dt^3| <= |U'''| + 3|U''|/r + 3|U'|/r^2``.

The piecewise laws have a jump of U'' at contact (z = a, r = 2a), where the
truncation bound does not hold: samples are kept at least 1e-3 (> 100 h) away.
The samples include pairs across a periodic boundary, overlapping blobs
(r < 2a) and blobs below a from the wall.  A negative control shows that a
perturbed law (force off by 1e-4 relative, or the wrong overlap branch)
fails the same check.

C++ against Python: the same formulas in a different order of operations
(x/b against x (1/b)); the exponential's argument differs by an ulp of up to
|x/b| <= 30, so energies and forces agree to a relative 1e-13.
"""
import numpy as np
import pytest

from many_bodyMCMC import mcmc_energy
from mobility.periodic import minimum_image, wall_regularisation
from multi_bodies.solver import physics

EPS_MACH = np.finfo(float).eps
LAW = dict(repulsion_strength=1.7, debye_length=0.3, blob_radius=0.25)
WALL = dict(g=0.7, repulsion_strength_wall=2.3, debye_length_wall=0.2, blob_radius=0.25, blob_mass=1.0)
BOX = np.array([3.0, 2.5, 0.0])          # periodic in x and y, wall below
H = 1e-6                                 # finite-difference step (lengths of order 0.1 - 1)
KINK_CLEARANCE = 1e-3
CPP_RTOL = 1e-13


def cpp_modules():
    try:
        from multi_bodies.solver import _forces_cpp
        from many_bodyMCMC import _energy_cpp
    except ImportError as err:
        pytest.skip('C++ extensions not built: %s' % err)
    return _forces_cpp, _energy_cpp


def fd_tolerance(h, third_derivative_bound, energy_scale):
    """Bound on |central difference - derivative|: h^2/6 |U'''| + 2 eps_mach |U| / h (see module docstring)."""
    return h * h / 6.0 * third_derivative_bound + 2.0 * EPS_MACH * energy_scale / h


def yukawa_third_derivative(r, eps, b):
    return eps * np.exp(-r / b) * (1 / (b ** 3 * r) + 3 / (b ** 2 * r ** 2) + 6 / (b * r ** 3) + 6 / r ** 4)


def away_from(x, kink):
    return x[np.abs(x - kink) > KINK_CLEARANCE]


# ------------------------------------------------------------------------------------ sample points
def heights():
    """Blob heights below and above a (the wall's contact), kink excluded."""
    a = WALL['blob_radius']
    return away_from(np.concatenate((np.linspace(0.01, a, 23), np.linspace(a, a + 12 * WALL['debye_length_wall'], 57))), a)


def blob_distances():
    """Pair distances of overlapping (r < 2a) and separated blobs, kink excluded."""
    d = 2 * LAW['blob_radius']
    return away_from(np.concatenate((np.linspace(0.05, d, 19), np.linspace(d, d + 10 * LAW['debye_length'], 61))), d)


def body_distances():
    return np.linspace(0.5, 5.0, 50)


def scalar_law_bounds(law, x):
    """(|U'''| bound, |U| scale) of the 1D law at the samples x (bound taken at x - h: laws decay)."""
    if law == 'wall':
        return WALL['repulsion_strength_wall'] / WALL['debye_length_wall'] ** 3, 2 * WALL['repulsion_strength_wall']
    if law == 'blob_blob':
        return LAW['repulsion_strength'] / LAW['debye_length'] ** 3, 2 * LAW['repulsion_strength']
    eps, b = LAW['repulsion_strength'], LAW['debye_length']
    return yukawa_third_derivative(x - H, eps, b), eps * np.exp(-(x - H) / b) / (x - H)


# ------------------------------------------------------------------------------------ 1D laws, both backends
def python_law(law, x):
    """(energy, force) of the Python law: the wall force f_z at heights x (gravity off), or for the
    pair laws the force on i along r = (x, 0, 0) from i to j, as a signed number along +x."""
    if law == 'wall':
        keywords = dict(WALL, g=0.0)
        r = np.zeros((x.size, 3))
        r[:, 2] = x
        return physics.blob_external_potential(r, **keywords), physics.blob_external_forces(r, **keywords)[:, 2]
    r = np.zeros((x.size, 3))
    r[:, 0] = x
    if law == 'blob_blob':
        return physics.blob_blob_potential(r, **LAW), physics.blob_blob_force(r, **LAW)[:, 0]
    return physics.body_body_potential(r, **LAW), physics.body_body_force_torque(r, **LAW)[0][:, 0]


def cpp_law(law, x):
    """The header's law through _forces_cpp.pair_laws, in python_law's convention."""
    forces_cpp, _ = cpp_modules()
    if law == 'wall':
        energy, force = forces_cpp.pair_laws('wall', x, WALL['repulsion_strength_wall'], WALL['debye_length_wall'],
                                             WALL['blob_radius'])
        return energy, force
    energy, factor = forces_cpp.pair_laws(law, x, LAW['repulsion_strength'], LAW['debye_length'], LAW['blob_radius'])
    return energy, -factor * x      # force on i is -m r, r = (x, 0, 0)


SAMPLES = {'wall': heights, 'blob_blob': blob_distances, 'body_body': body_distances}
BACKENDS = {'python': python_law, 'C++': cpp_law}


def check_force_is_minus_gradient(law, x, evaluate):
    """Assert force = -dU/dx at the samples x, within fd_tolerance; evaluate(law, x) -> (energy, force).

    For the wall x is the height and the force f_z; for the pair laws x is the
    distance and the force on i is along -x (r = (x, 0, 0) points from i to j):
    its component along +x equals +dU/dx.
    """
    plus, minus = x + H, x - H          # the step actually taken is plus - minus (exact), not 2H
    energy_plus, _ = evaluate(law, plus)
    energy_minus, _ = evaluate(law, minus)
    _, force = evaluate(law, x)
    derivative = (energy_plus - energy_minus) / (plus - minus)
    expected = -derivative if law == 'wall' else derivative
    third, scale = scalar_law_bounds(law, x)
    tolerance = fd_tolerance(H, third, scale)
    np.testing.assert_array_less(np.abs(force - expected), tolerance)


@pytest.mark.parametrize('backend', sorted(BACKENDS))
@pytest.mark.parametrize('law', sorted(SAMPLES))
def test_force_is_minus_gradient_of_energy(law, backend):
    check_force_is_minus_gradient(law, SAMPLES[law](), BACKENDS[backend])


@pytest.mark.parametrize('law', sorted(SAMPLES))
def test_cpp_law_equals_python_law(law):
    x = SAMPLES[law]()
    for cpp, python in zip(cpp_law(law, x), python_law(law, x)):
        np.testing.assert_allclose(cpp, python, rtol=CPP_RTOL, atol=0)


@pytest.mark.parametrize('perturbation', ['scaled force', 'wrong overlap branch'])
def test_negative_control_perturbed_law_fails(perturbation):
    """The check above is sensitive: a force 1e-4 off, or the far branch continued into the overlap, fails it."""
    def perturbed(law, x):
        energy, force = python_law(law, x)
        if perturbation == 'scaled force':
            return energy, force * (1 + 1e-4)
        eps, b, d = LAW['repulsion_strength'], LAW['debye_length'], 2 * LAW['blob_radius']
        return energy, np.where(x < d, -(eps / b) * np.exp(-(x - d) / b), force)
    for law in (['blob_blob'] if perturbation == 'wrong overlap branch' else sorted(SAMPLES)):
        with pytest.raises(AssertionError):
            check_force_is_minus_gradient(law, SAMPLES[law](), perturbed)


# ------------------------------------------------------------------------------------ minimum image
def test_minimum_image_rounds_half_away_from_zero_on_every_backend():
    """SPEC section 8: d - round_half_away(d/L) L on axes with L > 0, unchanged where L <= 0."""
    L = np.array([2.0, 0.0, -1.0])
    d = np.array([[1.0, 5.0, 7.0], [-1.0, -5.0, -7.0], [3.0, 0.5, 0.5], [-2.9, 1.0, 1.0], [0.99, 0.0, 0.0]])
    expected = np.array([[-1.0, 5.0, 7.0], [1.0, -5.0, -7.0], [-1.0, 0.5, 0.5], [-0.9, 1.0, 1.0], [0.99, 0.0, 0.0]])
    np.testing.assert_allclose(minimum_image(d, L), expected, rtol=0, atol=1e-15)
    assert physics.minimum_image is minimum_image and mcmc_energy.minimum_image is minimum_image
    forces_cpp, _ = cpp_modules()
    rng = np.random.default_rng(5)
    many = rng.uniform(-7, 7, size=(400, 3))
    many[:6] = [[1.0, 1.25, 0.0], [-1.0, -1.25, 0.0], [3.0, 3.75, 0.0], [-3.0, -3.75, 0.0], [0.0, 0.0, 0.0],
                [2.0, 2.5, 1.0]]
    box = np.array([2.0, 2.5, 0.0])
    np.testing.assert_array_equal(forces_cpp.minimum_images(many, box), minimum_image(many, box))


def test_wall_regularisation_one_formula():
    """z_eff = max(z, radius), damping min(z/radius, 1), 0 for a point blob below the wall."""
    z = np.array([-0.1, 0.0, 0.1, 0.5, 0.7])
    z_eff, damping = wall_regularisation(z, 0.5)
    np.testing.assert_array_equal(z_eff, [0.5, 0.5, 0.5, 0.5, 0.7])
    np.testing.assert_allclose(damping, [-0.2, 0.0, 0.2, 1.0, 1.0], rtol=1e-15)
    z_eff, damping = wall_regularisation(np.array([-0.1, 0.2]), np.array([0.0, 0.0]))
    np.testing.assert_array_equal(damping, [0.0, 1.0])


# ------------------------------------------------------------------------------------ all-pairs sums
def configuration():
    """12 blobs in the box BOX: pairs across the x and y boundaries, overlapping pairs, blobs below a."""
    rng = np.random.default_rng(11)
    r = np.column_stack((rng.uniform(0, BOX[0], 12), rng.uniform(0, BOX[1], 12), rng.uniform(0.6, 2.0, 12)))
    r[0], r[1] = [0.05, 1.0, 0.4], [BOX[0] - 0.15, 1.1, 0.45]         # overlap across x = 0 (distance ~0.21)
    r[2], r[3] = [1.5, 0.1, 1.2], [1.6, BOX[1] - 0.3, 1.0]           # overlap across y = 0 (distance ~0.46)
    r[4], r[5] = [2.0, 1.8, 0.1], [2.2, 1.9, 0.2]                    # both below a from the wall, overlapping (~0.24)
    r[6] = [0.9, 1.6, 0.15]                                          # below a
    return r


def pair_distances(r):
    d = minimum_image(r[None, :, :] - r[:, None, :], BOX)
    dist = np.linalg.norm(d, axis=-1)
    return dist[np.triu_indices(len(r), k=1)]


def all_pairs_tolerance(r, energy_terms):
    """fd_tolerance of a derivative of a sum over pairs (the 3D bound of the module docstring, summed)."""
    eps, b = LAW['repulsion_strength'], LAW['debye_length']
    r_min = pair_distances(r).min() - H
    per_pair = eps / b ** 3 + 3 * eps / (b ** 2 * r_min) + 3 * eps / (b * r_min ** 2)
    # each energy is a sum of `energy_terms` terms of size <= 2 eps: round-off up to energy_terms ulp of that
    return fd_tolerance(H, (len(r) - 1) * per_pair, energy_terms * 2 * eps)


def gradient(energy, r):
    """Central differences of energy(r (N, 3)) -> (N, 3)."""
    grad = np.zeros_like(r)
    for index in np.ndindex(r.shape):
        plus, minus = r.copy(), r.copy()
        plus[index] += H
        minus[index] -= H
        grad[index] = (energy(plus) - energy(minus)) / (plus[index] - minus[index])
    return grad


def blob_blob_backends():
    """(name, forces(r), energy(r)) of the blob-blob sums that run here."""
    keywords = dict(LAW, periodic_length=BOX)
    backends = [('python', lambda r: physics.calc_blob_blob_forces(r, **keywords),
                 mcmc_energy.PythonPairSums(keywords).total)]
    try:
        forces_cpp, energy_cpp = cpp_modules()
    except pytest.skip.Exception:
        return backends
    args = (BOX, LAW['repulsion_strength'], LAW['debye_length'], LAW['blob_radius'])
    backends.append(('C++', lambda r: forces_cpp.blob_blob_forces(r, *args),
                     lambda r: energy_cpp.pair_energy_total(r, *args)))
    return backends


def test_configuration_covers_the_cases():
    r = configuration()
    dist = pair_distances(r)
    assert np.any(dist < 2 * LAW['blob_radius'])                   # overlapping
    assert np.sum(r[:, 2] < LAW['blob_radius']) >= 3               # below a
    raw = np.linalg.norm(r[1] - r[0])
    assert raw > BOX[0] / 2 and np.linalg.norm(minimum_image(r[1] - r[0], BOX)) < 2 * LAW['blob_radius']
    assert np.all(np.abs(dist - 2 * LAW['blob_radius']) > KINK_CLEARANCE)


@pytest.mark.parametrize('name', [b[0] for b in blob_blob_backends()])
def test_all_pairs_forces_are_minus_gradient(name):
    _, forces, energy = dict((b[0], b) for b in blob_blob_backends())[name]
    r = configuration()
    n = len(r)
    np.testing.assert_array_less(np.abs(forces(r) + gradient(energy, r)), all_pairs_tolerance(r, n * (n - 1) // 2))


def test_all_pairs_cpp_equals_python():
    backends = blob_blob_backends()
    if len(backends) < 2:
        pytest.skip('C++ extensions not built')
    r = configuration()
    (_, f_py, e_py), (_, f_cpp, e_cpp) = backends
    np.testing.assert_allclose(f_cpp(r), f_py(r), rtol=CPP_RTOL, atol=CPP_RTOL * np.abs(f_py(r)).max())
    assert e_cpp(r) == pytest.approx(e_py(r), rel=CPP_RTOL)


def test_wall_and_gravity_forces_are_minus_gradient():
    r = configuration()

    def energy(x):
        return float(np.sum(physics.blob_external_potential(x, **WALL)))

    bound = WALL['repulsion_strength_wall'] / WALL['debye_length_wall'] ** 3
    scale = len(r) * (2 * WALL['repulsion_strength_wall'] + WALL['g'] * 2.0)
    np.testing.assert_array_less(np.abs(physics.blob_external_forces(r, **WALL) + gradient(energy, r)),
                                 fd_tolerance(H, bound, scale))


def test_body_body_forces_are_minus_gradient_across_the_boundary():
    locations = np.array([[0.2, 1.0, 1.0], [BOX[0] - 0.5, 1.2, 1.3], [1.5, 0.3, 1.1], [1.4, BOX[1] - 0.4, 1.6]])
    keywords = dict(LAW, periodic_length=BOX)

    def energy(x):
        i, j = np.triu_indices(len(x), k=1)
        return float(np.sum(physics.body_body_potential(minimum_image(x[j] - x[i], BOX), **keywords)))

    force_torque = physics.calc_body_body_forces_torques(locations, **keywords).reshape(-1, 2, 3)
    eps, b = LAW['repulsion_strength'], LAW['debye_length']
    i, j = np.triu_indices(len(locations), k=1)
    r_min = np.linalg.norm(minimum_image(locations[j] - locations[i], BOX), axis=-1).min() - H
    u1 = eps * np.exp(-r_min / b) * (1 / (b * r_min) + 1 / r_min ** 2)
    u2 = eps * np.exp(-r_min / b) * (1 / (b ** 2 * r_min) + 2 / (b * r_min ** 2) + 2 / r_min ** 3)
    per_pair = yukawa_third_derivative(r_min, eps, b) + 3 * u2 / r_min + 3 * u1 / r_min ** 2
    tolerance = fd_tolerance(H, (len(locations) - 1) * per_pair, len(i) * eps / r_min)
    np.testing.assert_array_less(np.abs(force_torque[:, 0] + gradient(energy, locations)), tolerance)
    np.testing.assert_array_equal(force_torque[:, 1], 0.0)


# ------------------------------------------------------------------------------------ CUDA
def cuda_or_skip():
    try:
        from multi_bodies.solver import forces_pycuda
        from many_bodyMCMC import mcmc_cuda
        forces_pycuda.check_usable()
        mcmc_cuda.check_usable()
    except Exception as err:   # no CuPy, no device, compiler failure
        pytest.skip('CUDA backends cannot run here (%s: %s)' % (type(err).__name__, err))
    return forces_pycuda, mcmc_cuda


def test_cuda_forces_and_energies_equal_python():
    """On a GPU: the kernels built from pair_laws.h agree with Python to round-off and F = -grad U."""
    forces_pycuda, mcmc_cuda = cuda_or_skip()
    keywords = dict(LAW, periodic_length=BOX)
    r = configuration()
    f_gpu = forces_pycuda.calc_blob_blob_forces_pycuda(r, **keywords)
    f_py = physics.calc_blob_blob_forces(r, **keywords)
    np.testing.assert_allclose(f_gpu, f_py, rtol=CPP_RTOL, atol=CPP_RTOL * np.abs(f_py).max())
    sums = mcmc_cuda.CudaPairSums(keywords)
    assert sums.total(r) == pytest.approx(mcmc_energy.PythonPairSums(keywords).total(r), rel=CPP_RTOL)
    n = len(r)
    np.testing.assert_array_less(np.abs(f_gpu + gradient(sums.total, r)), all_pairs_tolerance(r, n * (n - 1) // 2))
