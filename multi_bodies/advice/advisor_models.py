"""What the advisor measures with: scheme tables, dense mobilities of small sets of bodies, sphere models.

Helpers of ``multi_bodies/advice/advisor.py`` (floor 7): the shipped scheme tables
(deterministic stability limits, the measured weak-error table of the
stochastic schemes) and the cost ranking over them; dense body mobilities of
one body, a pair of bodies or single-blob rollers, with and without the
wall; the error measures (normalised self-mobility diagonals against the
exact sphere-wall values, Richardson extrapolation over shell
resolutions); and the sphere models (calibrated shells, shells of a fixed
blob radius, recognising a shell from its blobs); and the scene of an input
file, read as the scripts read it.  Shapes (6, 6) per body,
torques about the body centre, lengths and times in the user's units.
"""
import os
from collections import namedtuple

import numpy as np
import scipy.linalg

from body.body import K_matrices, bodies_to_arrays
from mobility.interface import Geometry, make_mobility, preferred_backend
from multi_bodies.solver.body_solver import body_mobility_from_resistance
from multi_bodies.solver import user_hooks
from multi_bodies.advice import sphere_tables
from multi_bodies.files.input_options import read_input_file
from multi_bodies.files.scheme_table import dense_variants, moves_rollers, roller_variants, scheme_names
from multi_bodies.run.run_setup import read_bodies
from body.geometry import smallest_distance
from multi_bodies.files.structure_generators import calibrated_shell, icosahedral_shell

SHELL_SIZES = (12, 42, 162, 642)
RICHARDSON_LEVELS = (42, 162, 642)
GMRES_WARNING_ITERATIONS = 100
NO_WALL = '_no_wall'
DENSE_BLOB_LIMIT = 3000           # blobs above which one dense solve is modelled, not measured
MEASURE_BUDGET_S = 1.0            # a single timing predicted to take longer is modelled instead
# The roller and dense counterparts of a scheme and the static schemes: the scheme registry's
ROLLER_SCHEMES = roller_variants()
DENSE_SCHEMES = dense_variants()
STATIC_SCHEMES = scheme_names(kind='static')

# Scheme cost/accuracy tables shipped with the package, by scheme name: a dict with 'order',
# 'solves_per_step', 'stability' (dt * mu * k limit) and 'source'.  The deterministic rows are the
# textbook stability limits of the schemes on the negative real axis, confirmed by the chart of
# doc/integrators_accuracy_vs_dt.md.  The weak-error table of the stochastic schemes follows.
SCHEME_TABLE = {
    'deterministic_forward_euler': {'order': 1, 'solves_per_step': 1, 'stability': 2.0,
                                    'source': 'forward Euler: |1 + z| <= 1'},
    'deterministic_adams_bashforth': {'order': 2, 'solves_per_step': 1, 'stability': 1.0,
                                      'source': 'AB2: real stability interval [-1, 0]'},
}
# One row per stochastic scheme, from the weak-order study of doc/brownian_validation.md
# (python doc/charts/brownian_weak_order.py): the relative bias of the equilibrium variance of blobs held in a
# stiff harmonic trap at z = 1.5 a above the wall is C (dt/tau)^p, tau = 1/(mu_perp k) the trap's relaxation
# time (stochastic_EM: in free space, tau = 1/(mu0 k)); C and p fitted at the three smallest time steps whose
# bias was resolved (4 standard errors).  The sign of C is that of the bias.  'solves_per_step' counts GMRES
# solves plus Lanczos calls (rollers: Lanczos calls); None for the dense schemes, which are not ranked by it.
_WEAK_SOURCE = 'doc/brownian_validation.md, weak-order study (blobs in a trap near the wall), 2026-12-01'


def _weak_row(solves, constant, order):
    return {'solves_per_step': solves, 'weak_error': (constant, order),
            'time_unit': 'tau = 1/(mu k)', 'source': _WEAK_SOURCE}


STOCHASTIC_SCHEME_TABLE = {
    'stochastic_first_order_RFD': _weak_row(4, 0.665, 1.11),
    'stochastic_traction_EM': _weak_row(3, 0.665, 1.11),
    'stochastic_adams_bashforth': _weak_row(5, 0.855, 2.24),
    'stochastic_traction_AB': _weak_row(4, 0.873, 2.25),
    'stochastic_Slip_Trapz': _weak_row(4, -0.305, 2.27),
    'stochastic_Slip_Mid': _weak_row(5, 0.311, 3.20),
    'stochastic_GDC_RFD': _weak_row(4, -0.307, 1.09),
    'stochastic_EM': _weak_row(2, 0.627, 1.08),
    'stochastic_first_order_RFD_dense_algebra': _weak_row(None, 0.621, 1.10),
    'Fixman': _weak_row(None, 0.346, 3.73),
    'stochastic_Slip_Mid_DLA': _weak_row(None, 0.275, 3.00),
    'stochastic_first_order_rollers': _weak_row(1, 0.547, 0.96),
    'stochastic_adams_bashforth_rollers': _weak_row(1, 0.506, 1.82),
    'stochastic_mid_point_rollers': _weak_row(2, 0.259, 3.07),
    'stochastic_trapezoidal_rollers': _weak_row(1, -0.32, 2.21),
}


def cheapest_scheme(table, accuracy, solve_seconds, time_unit=1.0):
    """The scheme of a weak-error table that reaches ``accuracy`` at the smallest cost per unit time.

    For each row, the time step that gives the target is ``dt* = (accuracy / |C|)^(1/p) * time_unit``
    (``time_unit``: the scene's relaxation time tau = 1/(mu k) for the shipped table, whose dt are in
    units of tau) and the cost per unit of simulated time is ``solves_per_step * solve_seconds / dt*``.
    Rows without ``solves_per_step`` (the dense schemes, whose cost is not a number of solves) are not
    ranked.  Returns a list of (cost per unit time, scheme, dt*) sorted cheapest first (empty for an
    empty table).
    """
    ranked = []
    for scheme, row in table.items():
        if row.get('solves_per_step') is None:
            continue
        constant, order = row['weak_error']
        dt_target = (accuracy / abs(constant)) ** (1.0 / order) * time_unit
        ranked.append((row['solves_per_step'] * solve_seconds / dt_target, scheme, dt_target))
    return sorted(ranked)

Choice = namedtuple('Choice', ['topic', 'structure', 'candidate', 'blobs', 'estimated_error', 'cost_s',
                               'meets_target', 'note'])
Choice.__doc__ = """One row of a choice table (the JSON rows of ``.advice.json``, plus a free-text note)."""


# ------------------------------------------------------------------ dense mobilities of small sets of bodies
def blob_mobility(backend, eta, blob_radius, wall=True, periodic_length=(0.0, 0.0, 0.0)):
    """The ``BlobMobility`` of ``backend`` above the wall (``wall``) or in free space (the advisor's products)."""
    return make_mobility(backend, Geometry('single_wall' if wall else 'free_space', periodic_length), eta,
                         blob_radius)


def bodies_mobility(blob_sets, centres, blob_radius, eta, wall=True, backend='python'):
    """Body mobility (6 nb, 6 nb) of rigid bodies made of the given blobs, torques about ``centres``.

    blob_sets: list of (n_k, 3) lab-frame blob positions; centres (nb, 3).
    A body of one blob is a roller: its 6x6 block is the blob's grand
    mobility (translation and rotation couplings, Rotne-Prager(-Blake)).
    """
    if all(len(b) == 1 for b in blob_sets):
        return roller_grand_mobility(np.concatenate(blob_sets), blob_radius, eta, wall, backend)
    r = np.concatenate(blob_sets)
    M = blob_mobility(backend, eta, blob_radius, wall).dense_matrix(r)
    K = np.zeros((3 * r.shape[0], 6 * len(blob_sets)))
    row = 0
    for k, (blobs, centre) in enumerate(zip(blob_sets, centres)):
        n = len(blobs)
        K[row:row + 3 * n, 6 * k:6 * k + 6] = K_matrices(np.asarray(blobs)[None], np.asarray(centre)[None])[0]
        row += 3 * n
    factor = scipy.linalg.cho_factor(M)
    # pinv (the package's one body mobility): a straight rod has no resistance to spinning about its axis
    return body_mobility_from_resistance(K.T @ scipy.linalg.cho_solve(factor, K))


def roller_grand_mobility(positions, blob_radius, eta, wall=True, backend='python'):
    """Grand mobility (6n, 6n) of single blobs ``positions`` (n, 3), ordered ``[v_k, w_k]`` per blob."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    n = positions.shape[0]
    mobility = blob_mobility(backend, eta, blob_radius, wall)
    G = np.zeros((6 * n, 6 * n))
    for col in range(6 * n):
        body, component = divmod(col, 6)
        e = np.zeros(3 * n)
        e[3 * body + component % 3] = 1.0
        if component < 3:
            v = mobility.coupling('trans_times_force', positions, e)
            w = mobility.coupling('rot_times_force', positions, e)
        else:
            v = mobility.coupling('trans_times_torque', positions, e)
            w = mobility.coupling('rot_times_torque', positions, e)
        G[:, col] = np.concatenate((np.reshape(v, (n, 3)), np.reshape(w, (n, 3))), axis=1).reshape(-1)
    return G


def normalised_diagonal(body_mobility, sphere_radius, eta):
    """The six self-mobility diagonal entries of body 0 in units of the bulk sphere values, shape (6,)."""
    d = np.diag(body_mobility)[:6]
    bulk = np.array([1.0 / (6 * np.pi * eta * sphere_radius)] * 3 + [1.0 / (8 * np.pi * eta * sphere_radius ** 3)] * 3)
    return d / bulk


def exact_diagonal(h_over_R):
    """Exact normalised diagonal (xx, yy, zz, rxx, ryy, rzz) of a sphere at h/R, or None below the table."""
    exact = sphere_tables.exact_self_mobilities(h_over_R)
    if exact is None:
        return None
    par, perp, rot_par, rot_perp = exact
    return np.array([par, par, perp, rot_par, rot_par, rot_perp])


def worst_error(values, reference):
    """Largest relative error ``max |values / reference - 1|`` (the advisor's error measure).

    Entries whose reference vanishes (the spin of a straight rod about its axis) are left out.
    """
    values, reference = np.asarray(values, dtype=float), np.asarray(reference, dtype=float)
    keep = np.abs(reference) > 1e-12 * np.max(np.abs(reference))
    return float(np.max(np.abs(values[keep] / reference[keep] - 1.0)))


def richardson(levels, smallest_rate=2.0):
    """Extrapolate a sequence of values (each (6,)) of three successive shell levels.

    With differences ``d1 = v2 - v1``, ``d2 = v3 - v2`` and ``q = d1 / d2``,
    entries that converge at a clear geometric rate (``q >= smallest_rate``:
    the difference at least halves per fourfold refinement) are extrapolated
    as ``v3 + d2 / (q - 1)``; other entries (no clear rate, or a change of
    sign) keep ``v3 + d2``, the last difference taken as the remaining error.
    Returns the extrapolated values (6,).
    """
    v1, v2, v3 = (np.asarray(v, dtype=float) for v in levels)
    d1, d2 = v2 - v1, v3 - v2
    with np.errstate(divide='ignore', invalid='ignore'):
        q = d1 / d2
    geometric = np.isfinite(q) & (q >= smallest_rate)
    extrapolated = np.where(geometric, v3 + d2 / np.where(geometric, q - 1.0, 1.0), v3 + d2)
    return np.where(d2 == 0.0, v3, extrapolated)


def distance_to_other_bodies(r_vectors, owner):
    """Distance from every blob to the closest blob of another body, shape (N,) (inf with one body).

    r_vectors (N, 3); owner (N,) body index of each blob.  A k-d tree query of
    as many neighbours as the largest body has blobs (plus one) must contain
    a blob of another body, so the search costs O(N n log N), not O(N^2).
    """
    from scipy.spatial import cKDTree
    owner = np.asarray(owner)
    if len(np.unique(owner)) < 2:
        return np.full(len(owner), np.inf)
    k = min(len(owner), int(np.max(np.bincount(owner))) + 1)
    distance, index = cKDTree(r_vectors).query(r_vectors, k=k)
    return np.min(np.where(owner[index] != owner[:, None], distance, np.inf), axis=1)


# ------------------------------------------------------------------ sphere models
_CALIBRATED = {}


def calibrated_model(num_blobs, sphere_radius):
    """Calibrated shell of hydrodynamic radius ``sphere_radius``: (blobs (n, 3) about 0, blob radius)."""
    if num_blobs not in _CALIBRATED:
        _CALIBRATED[num_blobs] = calibrated_shell(num_blobs)[:2]
    blobs, a = _CALIBRATED[num_blobs]
    return blobs * sphere_radius, a * sphere_radius


def bulk_radius(blobs, blob_radius):
    """Hydrodynamic radius (translation, far from walls) of a rigid body of RPY blobs (n, 3)."""
    centre = np.mean(blobs, axis=0)
    arms = np.asarray(blobs, dtype=float) - centre
    backend = preferred_backend(Geometry('free_space'), dense_matrices=True)  # the registry's fastest CPU one
    M = blob_mobility(backend, 1.0, blob_radius, wall=False).dense_matrix(arms)
    K = K_matrices(arms[None], np.zeros((1, 3)))[0]
    N = body_mobility_from_resistance(K.T @ scipy.linalg.cho_solve(scipy.linalg.cho_factor(M), K))
    return 1.0 / (6 * np.pi * np.trace(N[:3, :3]) / 3.0)


def fixed_radius_model(num_blobs, sphere_radius, blob_radius):
    """Shell of ``num_blobs`` blobs of the given blob radius with hydrodynamic radius ``sphere_radius``.

    The shell radius solves ``R_h(shell radius) = sphere_radius`` by secant
    steps (R_h grows about one for one with the shell radius).  Returns
    (blobs (n, 3), blob_radius), or None when the blobs would overlap by more
    than their radius (spacing < a) or no shell radius fits.
    """
    unit = icosahedral_shell(num_blobs)
    unit_spacing = smallest_distance(unit)
    if unit_spacing * sphere_radius < blob_radius:  # the shell radius is below R: spacing < a for sure
        return None

    def excess(radius):
        return bulk_radius(unit * radius, blob_radius) - sphere_radius
    x0 = max(sphere_radius - blob_radius, 0.5 * sphere_radius)
    x1 = x0 + 0.05 * sphere_radius
    f0, f1 = excess(x0), excess(x1)
    for _ in range(20):
        if f1 == f0:
            break
        x0, x1, f0 = x1, x1 - f1 * (x1 - x0) / (f1 - f0), f1
        if not x1 > 0:
            return None
        f1 = excess(x1)
        if abs(f1) < 1e-9 * sphere_radius:
            break
    if abs(f1) > 1e-6 * sphere_radius or unit_spacing * x1 < blob_radius:
        return None
    return unit * x1, blob_radius


def recognise_sphere(reference, blob_radius):
    """Sphere model of a structure, or None: dict(kind 'blob' or 'shell', blobs, radius R, offset (3,)).

    A single blob is a sphere of radius ``a``.  A shell is recognised when its
    blobs lie on a sphere about their centroid (radii equal to 1e-3) and their
    count and smallest spacing are those of an icosahedral shell; its radius
    is the hydrodynamic radius of the model (bulk translational mobility).
    """
    reference = np.asarray(reference, dtype=float).reshape(-1, 3)
    n = reference.shape[0]
    if n == 1:
        return dict(kind='blob', blobs=n, radius=blob_radius, offset=reference[0].copy())
    sizes = [12]
    while sizes[-1] < n:
        sizes.append(4 * sizes[-1] - 6)
    if sizes[-1] != n:
        return None
    centroid = reference.mean(axis=0)
    radii = np.linalg.norm(reference - centroid, axis=1)
    if np.std(radii) > 1e-3 * np.mean(radii):
        return None
    unit_spacing = smallest_distance(icosahedral_shell(n))
    if abs(smallest_distance(reference) / np.mean(radii) - unit_spacing) > 1e-3 * unit_spacing:
        return None
    return dict(kind='shell', blobs=n, radius=bulk_radius(reference, blob_radius), offset=centroid)


# ------------------------------------------------------------------ the scene
class Scene:
    """The scene of an input file, read as the scripts read it.

    Attributes: ``options``, ``bodies``, ``types`` (list of (ID, count)),
    ``arrays`` (BodyArrays), ``r_vectors`` (N, 3), ``hooks`` (the user's
    physics hooks of the run directory), ``structures`` (list of dicts per
    type: ID, spec, reference (n, 3), bodies slice, sphere model or None,
    centres (nb, 3) of the bodies (blob centroids), lowest (index in the type),
    nearest_pair ((i, j) in the type or None), nearest_gap (centre distance)).
    """

    def __init__(self, input_file, directory=None):
        self.directory = os.path.dirname(os.path.abspath(input_file)) if directory is None else directory
        import contextlib
        import io
        from multi_bodies.advice.advisor_physics import program_of
        with contextlib.redirect_stderr(io.StringIO()):  # warnings once, for the program that reads the file
            probe = read_input_file(input_file)
        self.program = program_of(probe)
        self.options = read_input_file(input_file, 'mcmc' if self.program == 'mcmc' else None)
        self.hooks = user_hooks.load_user_hooks(os.getcwd(), load_pycuda=False)
        self.bodies, self.types, _ = read_bodies(self.options, self.hooks.set_slip_by_ID,
                                              single_blob_bodies=moves_rollers(self.options.scheme))
        self.arrays = bodies_to_arrays(self.bodies, [count for _, count in self.types])
        slips = [np.zeros((b.Nblobs, 3)) if b.slip_reference is None else b.slip_reference for b in self.bodies]
        self.arrays.reference_slip = np.concatenate(slips).reshape(-1, 3)
        self.r_vectors = self.arrays.blob_positions(self.arrays.configuration)
        self.a = self.options.blob_radius
        self.eta = self.options.eta
        if not (self.a > 0 and self.eta > 0):
            from utils import UserInputError
            raise UserInputError('%s: blob_radius and eta must be positive' % self.options.input_file)
        self.structures = []
        offsets = self.arrays.blob_offsets
        for (structure_id, count), spec, (bodies, blobs), n in zip(
                self.types, self.options.structures, self.arrays.type_slices, self.arrays.type_blobs):
            reference = self.arrays.reference_blobs[offsets[bodies.start]:offsets[bodies.start] + n]
            r_type = self.r_vectors[blobs].reshape(count, n, 3)
            centres = r_type.mean(axis=1)
            lowest = int(np.argmin(centres[:, 2])) if count else 0
            info = dict(ID=structure_id, spec=spec, reference=reference, bodies=bodies, blobs=blobs,
                        num_blobs=n, count=count, centres=centres, lowest=lowest, r_type=r_type,
                        sphere=recognise_sphere(reference, self.a), nearest_pair=None, nearest_gap=None)
            if count > 1:
                distance = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
                distance[np.diag_indices(count)] = np.inf
                i, j = np.unravel_index(np.argmin(distance), distance.shape)
                info['nearest_pair'], info['nearest_gap'] = (int(i), int(j)), float(distance[i, j])
            self.structures.append(info)

    @property
    def num_blobs(self):
        return self.arrays.num_blobs

    @property
    def wall(self):
        names = (self.options.mobility_vector_prod_implementation, self.options.mobility_blobs_implementation)
        if moves_rollers(self.options.scheme):
            return self.options.domain != 'no_wall'
        return not all(name.endswith(NO_WALL) for name in names)

    def physics(self):
        o = self.options
        return dict(g=o.g, repulsion_strength_wall=o.repulsion_strength_wall, debye_length_wall=o.debye_length_wall,
                    repulsion_strength=o.repulsion_strength, debye_length=o.debye_length,
                    periodic_length=np.array(o.periodic_length), blob_radius=o.blob_radius, blob_mass=1.0)
