"""Sphere models near contact: 1 blob, 1 blob + lubrication, resolved shells; their mobility scalars and errors.

One source for the chart of ``doc/lubrication_accuracy.md`` (``doc/charts/lubrication_accuracy_vs_cost.py``
computes with these functions and prints the numbers shipped in
``multi_bodies.advice.lubrication_tables``) and for the advisor (``advisor_lubrication``), which reads
the shipped numbers.

Two geometries, spheres of radius a = 1, viscosity eta = 1 / (6 pi) (so ``6 pi eta a^n = 1``):

* **pair**: two spheres in free space along x, centre distance ``r = 2 + gap``; the ten scalars of the
  published two-sphere tables (self "11" then pair "12"; each X^A, Y^A, Y^B, X^C, Y^C), normalised by
  ``1/(6 pi eta a)``, ``1/(6 pi eta a^2)``, ``1/(6 pi eta a^3)`` for the A, B, C parts;
* **wall**: one sphere at height ``h = 1 + gap`` above the no-slip wall; the five scalars
  X^a (normal), Y^a (parallel), Y^b (coupling, rolling sense), X^c (rotation about the normal),
  Y^c (rotation about a parallel axis), same normalisation.

Models (labels of ``MODELS``): ``'1 blob'`` (the single-blob RPY/RPB mobility), ``'1 blob + lubrication'``
(the package's ``M_lub = (M^-1 + Delta_R)^-1``, ``lubrication.LubricationProblem``, default
``firm_delta`` and ``Lub_Cut``), ``'shell N'`` (N = 12, 42, 162, 642: the package's calibrated
icosahedral shells, ``structure_generators.calibrated_shell``, rigid multiblob mobility by dense
algebra).

Error measure (``pair_error``, ``wall_error``): the largest relative error of the scalars that move the
spheres.  Pair: of the collective and relative modes ``s11 + s12`` and ``s11 - s12`` of X^A, Y^A, X^C,
Y^C (the relative mode ``X^A_11 - X^A_12`` is the approach mobility, which vanishes like the gap at
contact); the coupling modes ``Y^B_11 +- Y^B_12`` relative to the geometric mean of the reference
``Y^A`` and ``Y^C`` modes they couple.  Wall: relative errors of X^a, Y^a, X^c, Y^c; the coupling Y^b
relative to ``sqrt(Y^a Y^c)`` of the reference.
"""
import numpy as np

PAIR_SCALARS = ('XA11', 'YA11', 'YB11', 'XC11', 'YC11', 'XA12', 'YA12', 'YB12', 'XC12', 'YC12')
WALL_SCALARS = ('Xa', 'Ya', 'Yb', 'Xc', 'Yc')
SHELLS = (12, 42, 162, 642)
MODELS = ('1 blob', '1 blob + lubrication') + tuple('shell %d' % n for n in SHELLS)
TABLE_MODEL = 'shell 2562 (published)'   # the published resolved spheres: their tables, not computed here
ETA = 1.0 / (6.0 * np.pi)
# The wall gaps are heights of the exact sphere-wall table (sphere_tables.EXACT_SPHERE_WALL, h = 1 + gap).
PAIR_GAPS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 2.9)
WALL_GAPS = (0.01, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 4.0)


# ------------------------------------------------------------------ reference tables (development only)
def read_pair_table(path):
    """Published two-sphere table: (r (m,), scalars (m, 10)) in the order of ``PAIR_SCALARS``."""
    data = np.loadtxt(path)
    self_rows, pair_rows = data[0::2], data[1::2]
    return self_rows[:, 0], np.hstack([self_rows[:, 1:], pair_rows[:, 1:]])


def read_wall_table(path):
    """Published sphere-wall table: (h (m,) ascending, scalars (m, 5)) in the order of ``WALL_SCALARS``."""
    data = np.loadtxt(path)
    order = np.argsort(data[:, 0])
    return data[order, 0], data[order, 1:]


def interpolate(x_table, values, x):
    """Values (5 or 10,) at x, linear in log(x - lowest contact) between tabulated rows (pair r or wall h)."""
    contact = 2.0 if x_table[0] > 1.9 else 1.0
    t = np.log(np.asarray(x_table) - contact + 1e-12)
    return np.array([np.interp(np.log(x - contact), t, values[:, k]) for k in range(values.shape[1])])


# ------------------------------------------------------------------ mobility scalars of each model
def _pair_scalars_from(M):
    """Ten pair scalars from the (12, 12) mobility [U1 W1 U2 W2] of two spheres along x (normalised units)."""
    return np.array([M[0, 0], M[1, 1], M[5, 1], M[3, 3], M[4, 4],
                     M[0, 6], M[1, 7], -M[11, 1], M[3, 9], M[4, 10]])


def _wall_scalars_from(M):
    """Five wall scalars from the (6, 6) mobility [U W] of one sphere above the wall (normalised units)."""
    return np.array([M[2, 2], M[0, 0], M[4, 0], M[5, 5], M[3, 3]])


def calibrated_model_blobs(num_blobs):
    """Calibrated shell of hydrodynamic radius 1: (blobs (n, 3) about 0, blob radius)."""
    from multi_bodies.advice.advisor_models import calibrated_model
    return calibrated_model(num_blobs, 1.0)


def model_mobility(model, centres, wall, backend='C++'):
    """Body mobility (6 nb, 6 nb) of spheres of radius 1 at ``centres`` (nb, 3), eta = 1/(6 pi), by ``model``."""
    centres = np.asarray(centres, dtype=float)
    if model == '1 blob':
        from multi_bodies.advice.advisor_models import roller_grand_mobility
        return roller_grand_mobility(centres, 1.0, ETA, wall, backend)
    if model == '1 blob + lubrication':
        from lubrication import LubricationProblem, dense_lubricated_mobility
        return dense_lubricated_mobility(LubricationProblem(centres, 1.0, ETA, wall=wall,
                                                            implementation=backend))
    if model.startswith('shell '):
        from multi_bodies.advice.advisor_models import bodies_mobility, calibrated_model
        blobs, blob_radius = calibrated_model(int(model.split()[1]), 1.0)
        return bodies_mobility([blobs + c for c in centres], centres, blob_radius, ETA, wall, backend)
    raise ValueError('unknown sphere model %r (one of %s)' % (model, ', '.join(MODELS)))


def exact_pair_scalars(gap):
    """The ten exact two-sphere scalars (10,) at ``gap``: the inverse of the resolved resistance ``R_sup``.

    ``R_sup`` of the package (``lubrication.resistance_matrices``, free space): near-contact asymptotics
    (Townsend 2018) below r = 2.006, the two-sphere mobility table 2.006 < r <= 2.1, the Jeffrey-Onishi
    resistance table above (it ends at r = 5.001, so gaps up to 3; the cutoff is set to 5.05 here).
    """
    from lubrication import resistance_matrices
    centres = np.array([[0.0, 0.0, 0.0], [2.0 + gap, 0.0, 0.0]])
    R_sup = resistance_matrices(centres, 1.0, ETA, cutoff=5.05, wall=False).R_sup.toarray()
    return _pair_scalars_from(np.linalg.inv(R_sup))


def exact_wall_scalars(gap):
    """The five exact sphere-wall scalars (5,) at a gap of ``WALL_GAPS`` (Brenner, O'Neill, Dean-O'Neill,
    Jeffery series: ``sphere_tables.EXACT_SPHERE_WALL``), in the normalisation of this module."""
    from multi_bodies.advice.sphere_tables import EXACT_SPHERE_WALL
    par, perp, rot_par, rot_perp, coupling = EXACT_SPHERE_WALL[round(1.0 + gap, 6)]
    return np.array([perp, par, coupling, 0.75 * rot_perp, 0.75 * rot_par])


def pair_scalars(model, gap, backend='C++'):
    """The ten normalised pair scalars (10,) of two spheres in free space at surface gap ``gap`` (units of a)."""
    centres = np.array([[0.0, 0.0, 0.0], [2.0 + gap, 0.0, 0.0]])
    return _pair_scalars_from(model_mobility(model, centres, False, backend))


def wall_scalars(model, gap, backend='C++'):
    """The five normalised wall scalars (5,) of one sphere at wall gap ``gap`` (h = 1 + gap, units of a)."""
    return _wall_scalars_from(model_mobility(model, np.array([[0.0, 0.0, 1.0 + gap]]), True, backend))


# ------------------------------------------------------------------ error measures
def pair_modes(scalars):
    """(plus (5,), minus (5,)): s11 + s12 and s11 - s12 of X^A, Y^A, Y^B, X^C, Y^C."""
    scalars = np.asarray(scalars, dtype=float)
    return scalars[:5] + scalars[5:], scalars[:5] - scalars[5:]


def pair_error(scalars, reference):
    """Largest relative error of the pair modes (see the module docstring); scalars, reference (10,)."""
    errors = []
    for model_mode, ref_mode in zip(pair_modes(scalars), pair_modes(reference)):
        diagonal = [0, 1, 3, 4]
        errors += list(np.abs(model_mode[diagonal] / ref_mode[diagonal] - 1.0))
        errors.append(abs(model_mode[2] - ref_mode[2]) / np.sqrt(abs(ref_mode[1] * ref_mode[4])))
    return float(max(errors))


def wall_error(scalars, reference):
    """Largest relative error of the wall scalars (see the module docstring); scalars, reference (5,)."""
    scalars, reference = np.asarray(scalars, dtype=float), np.asarray(reference, dtype=float)
    diagonal = [0, 1, 3, 4]
    errors = list(np.abs(scalars[diagonal] / reference[diagonal] - 1.0))
    errors.append(abs(scalars[2] - reference[2]) / np.sqrt(reference[1] * reference[4]))
    return float(max(errors))
