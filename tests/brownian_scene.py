"""The scene of the Brownian tests and its exact Gibbs-Boltzmann equilibrium.

Single-blob bodies of radius ``A`` above a no-slip wall, with gravity and a soft wall repulsion (the
numbers below); the height density is computed by quadrature on a fine grid, so that tests compare
simulated averages with exact ones; ``run_heights`` runs a scheme from an exact equilibrium sample.

Not a test module: ``tests/test_stochastic.py``, ``test_boomerang_equilibrium.py``,
``test_stochastic_reproducibility.py``, ``test_new_schemes.py`` and ``test_noise_factor.py`` import it.
"""
import functools

import numpy as np

import mobility
from body.body import Body, bodies_to_arrays
from multi_bodies import multi_bodies_functions as mbf
from multi_bodies.files.input_options import options_with
from multi_bodies.solver.model import Model
from quaternion_integrator.schemes import make_scheme


CPP = 'C++' if mobility.backends.is_usable('C++') else 'python'
RIGID_ITERATIVE = ['stochastic_first_order_RFD', 'stochastic_adams_bashforth', 'stochastic_traction_EM',
                   'stochastic_traction_AB', 'stochastic_Slip_Trapz', 'stochastic_Slip_Mid']
RIGID_DENSE = ['stochastic_first_order_RFD_dense_algebra', 'Fixman', 'stochastic_Slip_Mid_DLA']
ROLLERS = ['stochastic_first_order_rollers', 'stochastic_adams_bashforth_rollers', 'stochastic_mid_point_rollers',
           'stochastic_trapezoidal_rollers']

# Scene of the Gibbs-Boltzmann tests: a = 1, eta = 1/(6 pi) (so mu0 = 1), kT = 1, weight g = 2 per blob,
# wall eps = 2, b = 0.25.  Then <z> = 1.639, std 0.57, relaxation time (kT/g)^2/(kT <mu_perp>) ~ 0.6, and
# without the thermal drift the stationary mean would be 0.40 (density exp(-U/kT)/mu_perp).
A, ETA, KT, G, EPS_WALL, B_WALL = 1.0, 1.0 / (6.0 * np.pi), 1.0, 2.0, 2.0, 0.25


def Opts(kT=KT, rf_delta=1e-3, update_PC=1):
    """Options of the table's defaults with the few a stochastic scheme reads set."""
    return options_with(kT=kT, rf_delta=rf_delta, update_PC=update_PC)


def physics(**extra):
    values = dict(g=G, repulsion_strength_wall=EPS_WALL, debye_length_wall=B_WALL, repulsion_strength=1.0,
                  debye_length=1.0, periodic_length=np.zeros(3), blob_radius=A, blob_mass=1.0)
    values.update(extra)
    return values


def make_system(bodies, types, vector_product=CPP, blobs='python', tolerance=1e-6, domain='single_wall'):
    arrays = bodies_to_arrays(bodies, types)
    system = Model(bodies, arrays, mbf.load_user_hooks('/nonexistent'), physics(), ETA, A, tolerance,
                   vector_product_name=vector_product, blobs_name=blobs, domain=domain)
    return system


def height_density(z):
    """Unnormalised Gibbs-Boltzmann density of a single blob's height (gravity + soft wall)."""
    U = G * z + np.where(z < A, EPS_WALL + EPS_WALL * (A - z) / B_WALL, EPS_WALL * np.exp(-(z - A) / B_WALL))
    return np.exp(-U / KT)


GRID = np.linspace(0.0, 25.0, 200001)
CDF = np.cumsum(height_density(GRID))
CDF /= CDF[-1]
EXACT_MEAN = np.trapezoid(GRID * height_density(GRID), GRID) / np.trapezoid(height_density(GRID), GRID)
HIST_EDGES = np.concatenate(([0.0], np.interp(np.arange(1, 8) / 8.0, CDF, GRID), [25.0]))  # 8 bins of 1/8 each
EXACT_BINS = np.diff(np.interp(HIST_EDGES, GRID, CDF))
CHI2_LIMIT = 24.0  # sum of squared bin z-scores: about chi^2 with 7 degrees of freedom, p = 0.001


MSD_WINDOW = 10  # steps per window of the in-plane displacements recorded by run_heights


@functools.lru_cache(maxsize=None)
def mean_parallel_mobility():
    """<mu_par> of one blob over the exact height density (quadrature; units mu0 = 1/(6 pi eta a))."""
    M = mobility.blob_mobility_matrix('python')
    z = np.linspace(1e-3, 20, 4000)
    mu_par = np.array([M(np.array([[0, 0, h]]), ETA, A)[0, 0] for h in z])
    density = height_density(z)
    return np.trapezoid(mu_par * density, z) / np.trapezoid(density, z)


def equilibrium_blobs(n_bodies, seed, spacing=25.0):
    """Single-blob bodies on a square lattice (far apart), heights drawn from the exact density."""
    rng = np.random.default_rng(seed)
    heights = np.interp(rng.random(n_bodies), CDF, GRID)
    side = int(np.ceil(np.sqrt(n_bodies)))
    ij = np.array([(i, j) for i in range(side) for j in range(side)][:n_bodies], dtype=float)
    reference = np.zeros((1, 3))
    bodies = []
    for (i, j), h in zip(ij, heights):
        body = Body(np.array([spacing * i, spacing * j, h]), np.array([1.0, 0, 0, 0]), reference, A)
        body.ID = 'blob'
        body.body_length = 2 * A
        bodies.append(body)
    return bodies


def run_heights(scheme_name, n_bodies, n_steps, dt, seed, disable_drift=False, vector_product=CPP, kT=KT):
    """Per-body time averages of z and of the histogram bins, the in-plane displacements over the run, the
    scheme, and the in-plane displacements over consecutive windows of MSD_WINDOW steps (windows, n_bodies, 2)."""
    bodies = equilibrium_blobs(n_bodies, seed)
    system = make_system(bodies, [n_bodies], vector_product=vector_product)
    scheme = make_scheme(scheme_name, dt, Opts(kT=kT))
    if disable_drift:
        scheme.thermal_drift = False
    rng = np.random.default_rng(seed + 1)
    state = scheme.init(system, system.start_configuration)
    start = state.configuration.locations.copy()
    window_start = start[:, :2].copy()
    increments = []  # in-plane displacements over consecutive windows of MSD_WINDOW steps
    z_sum = np.zeros(n_bodies)
    bins = np.zeros((n_bodies, len(HIST_EDGES) - 1))
    for step in range(n_steps):
        state = scheme.step(system, state, rng)
        locations = state.configuration.locations
        z = locations[:, 2]
        z_sum += z
        bins[np.arange(n_bodies), np.clip(np.searchsorted(HIST_EDGES, z) - 1, 0, len(HIST_EDGES) - 2)] += 1
        if (step + 1) % MSD_WINDOW == 0:
            increments.append(locations[:, :2] - window_start)
            window_start = locations[:, :2].copy()
    displacement = state.configuration.locations[:, :2] - start[:, :2]
    return z_sum / n_steps, bins / n_steps, displacement, state, np.array(increments)


def z_score(per_body, exact):
    """(mean - exact) / standard error, the standard error from the spread of per-body values."""
    per_body = np.asarray(per_body)
    return (per_body.mean(axis=0) - exact) / (per_body.std(axis=0, ddof=1) / np.sqrt(per_body.shape[0]))
