"""Each articulated body solved exactly as if alone in the fluid: a preconditioner of the articulated problem.

The published preconditioner of the articulated problem (``articulated.ArticulatedPreconditioner``) treats
every rigid body as alone and couples the bodies of an articulated body through the Schur complement
``C N C^T`` of their self mobilities ``N``.  The bodies of an articulated body touch at their joints (a
bacterium's head and its flagellum, the links of a chain), so their hydrodynamic coupling is as strong as
any in a suspension, and it is left to GMRES.  Here every articulated body is one block: the saddle-point
system of all its blobs, bodies and reduced joint multipliers,

    [ M_g    -K_g      0       ] [lambda_g]   [s_g]
    [-K_g^T   0     -(Q^T C)^T ] [   U_g  ] = [f_g]
    [ 0    -(Q^T C)    0       ] [  psi_g ]   [b_g]

(``M_g`` the dense blob mobility of its blobs, wall included), factored once (LU) and solved exactly.
Bodies outside the articulated bodies keep the body preconditioner.  Measured on 4 bacteria
(doc/preconditioners.md): 16 GMRES iterations per solve -> 5.

It applies when every body has a full-rank ``K`` and the articulated bodies are no larger than
``MAX_GROUP_BLOBS`` blobs (a dense LU of ``(3n)^3 / 3`` flops each), and under ``preconditioner auto`` when the
LUs cost at most ``AUTO_MAX_PRODUCTS`` ``M f`` products; otherwise :func:`build` returns None and the published
preconditioner is used.
"""
import numpy as np
import scipy.linalg

from body.body import K_matrices
from multi_bodies.solver.body_solver import MobilityProblem, blob_mobility, radius_of_blobs
from multi_bodies.solver.linear_map import LinearMap

MAX_GROUP_BLOBS = 600  # a (1,800 + 6k + r)-square LU, about 2e9 flops, per articulated body and build
# preconditioner auto: the groups are built when their LUs, sum of (3n)^3 / 3 flops, cost at most this many times
# the flops of one M f product (about 40 per blob pair, N^2 pairs); a solve saves about 10 products (4 bacteria of
# 82 blobs: 4.6, 16 -> 5 iterations, built; ten articulated bodies of 600 blobs among 6,000: 13.5, not built)
AUTO_MAX_PRODUCTS = 10.0


def build(problem, model, configuration):
    """A :class:`GroupPreconditioner` of an ``articulated.ArticulatedProblem`` built by ``model`` at
    ``configuration``, or None where it does not apply (the caller then builds the published one)."""
    arrays = model.arrays
    sizes = np.diff(arrays.blob_offsets)
    groups = problem.articulated.groups
    group_blobs = np.array([sizes[group.body_indices].sum() for group in groups], dtype=float)
    eligible = (problem.projectors is None and type(problem.problem) is MobilityProblem  # no obstacles, no slip
                and np.all(group_blobs <= MAX_GROUP_BLOBS))
    if model.preconditioner == 'auto':
        eligible = eligible and lu_cost_in_products(group_blobs, problem.num_blobs) <= AUTO_MAX_PRODUCTS
    if not eligible:
        return None
    grouped = np.zeros(problem.num_bodies, dtype=bool)
    for group in groups:
        grouped[group.body_indices] = True
    body = None if np.all(grouped) else model.build_preconditioner(configuration)
    return GroupPreconditioner(problem, arrays, body, model.blobs_mobility)


def lu_cost_in_products(group_blobs, num_blobs):
    """The flops of the groups' LUs, ``sum (3n)^3 / 3``, in M f products of ``num_blobs`` blobs (40 per pair)."""
    return float(np.sum((3.0 * np.asarray(group_blobs, dtype=float)) ** 3) / 3.0) / (40.0 * float(num_blobs) ** 2)


class GroupPreconditioner(LinearMap):
    """``P ~ A^{-1}`` of an articulated problem: every articulated body's saddle-point system solved exactly.

    problem : articulated.ArticulatedProblem; arrays : body.body.BodyArrays; body_preconditioner : the model's,
    for the bodies outside the articulated bodies (None when there are none); mobility : the BlobMobility of the
    dense blocks (the model's blobs mobility), or a function of the published form ``(r (k, n, 3), eta, radius)
    -> (k, 3n, 3n)`` with eta and blob_radius.
    ``apply(x)`` on ``[lambda (3N); U (6Nb); psi]``; ``operator`` is it as a LinearOperator.
    """

    def __init__(self, problem, arrays, body_preconditioner, mobility, eta=None, blob_radius=None):
        self.problem, self.body = problem, body_preconditioner
        mobility = blob_mobility(arrays, mobility, eta, blob_radius, role='stacked_dense_matrix')
        r_vectors, locations = problem.problem.r_vectors, problem.problem.locations
        offsets = arrays.blob_offsets
        n3, n6 = 3 * problem.num_blobs, 3 * problem.num_blobs + 6 * problem.num_bodies
        members = []  # (bodies, blobs, multiplier range, QC) of every articulated body
        for group, (_, QC), start, stop in zip(problem.articulated.groups, problem.reduced, problem.offsets[:-1],
                                                problem.offsets[1:]):
            bodies = np.asarray(group.body_indices)
            blobs = np.concatenate([np.arange(offsets[b], offsets[b + 1]) for b in bodies])
            members.append((bodies, blobs, start, stop, QC))
        # the dense blob mobilities, one stacked call per articulated-body size
        mobilities = [None] * len(members)
        counts = np.array([m[1].size for m in members])
        for n in np.unique(counts):
            chosen = np.flatnonzero(counts == n)
            blobs = np.stack([members[c][1] for c in chosen])
            stack = mobility.replace(blob_radius=radius_of_blobs(mobility, blobs.reshape(-1), blobs.shape))
            for c, M in zip(chosen, stack.dense_matrix(r_vectors[blobs])):
                mobilities[c] = M
        self.groups = []  # (rows (m,), LU of the articulated body's matrix)
        for (bodies, blobs, start, stop, QC), M in zip(members, mobilities):
            n, k, r = blobs.size, bodies.size, stop - start
            G = np.zeros((3 * n + 6 * k + r, 3 * n + 6 * k + r))
            G[:3 * n, :3 * n] = M
            first = 0
            for j, b in enumerate(bodies):
                count = offsets[b + 1] - offsets[b]
                K = K_matrices(r_vectors[offsets[b]:offsets[b + 1]][None], locations[b][None])[0]
                G[3 * first:3 * (first + count), 3 * n + 6 * j:3 * n + 6 * j + 6] = -K
                G[3 * n + 6 * j:3 * n + 6 * j + 6, 3 * first:3 * (first + count)] = -K.T
                first += count
            G[3 * n:3 * n + 6 * k, 3 * n + 6 * k:] = -QC.T
            G[3 * n + 6 * k:, 3 * n:3 * n + 6 * k] = -QC
            rows = np.concatenate(((3 * blobs[:, None] + np.arange(3)).reshape(-1),
                                   (n3 + 6 * bodies[:, None] + np.arange(6)).reshape(-1), n6 + np.arange(start, stop)))
            self.groups.append((rows, scipy.linalg.lu_factor(G, check_finite=False)))
        self.size = problem.size

    def apply(self, x):
        """The preconditioner applied to ``x = [s (3N); f (6Nb); b]`` (the articulated problem's layout)."""
        x = np.asarray(x, dtype=float).reshape(-1)
        z = np.zeros_like(x)
        if self.body is not None:  # the bodies outside the articulated bodies (their rows are overwritten below)
            n6 = 3 * self.problem.num_blobs + 6 * self.problem.num_bodies
            z[:n6] = self.body.apply(x[:n6])
        for rows, lu in self.groups:
            z[rows] = scipy.linalg.lu_solve(lu, x[rows], check_finite=False)
        return z
