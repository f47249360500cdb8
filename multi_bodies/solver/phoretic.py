"""The solute field of phoretic bodies and the active slip it drives (floor 3; doc/phoretic.md).

Each blob of a phoretic body is a quadrature node of the body surface with a
lab-frame normal ``n_i`` (the body-frame normal of its ``.Laplace`` file
turned with the body), a reaction rate ``k_i`` ([L]/[T]), an emitting rate
``alpha_i`` ([c][L]/[T]), a surface (phoretic) mobility ``mu_i``
([L]^2/([T][c])) and a weight ``w_i`` ([L]^2).  The solute obeys Laplace's
equation in the fluid, ``c -> c_bg`` far away, and the flux condition
``-D n.grad c = alpha - k c`` on the surfaces.  The on-surface limit of the
exterior representation gives, at every blob (the published discretisation,
``multi_bodies.solver.laplace_kernels``)::

    (1/2) c_i - D[c]_i + S[k c / D]_i = c_bg(x_i) + S[alpha / D]_i

(the problem :class:`LaplaceProblem`, N unknowns, solved by the package's
one GMRES without a preconditioner, restart 200).  The surface gradient and
the active slip are then, with ``q = (alpha - k c) / D``::

    g_i = 2 (G + 2 H x_i) + 2 dD[c]_i - 2 Dip[q]_i,
    u_i = mu_i (g_i - n_i (n_i . g_i)).

The background ``c_bg(x) = b0 + G.x + x^T H x`` comes from the nine numbers
of ``background_Laplace``: ``G = (b1, b2, b3)`` and
``H = [[b4, b5, b6], [b5, b7, b8], [b6, b8, -(b4 + b7)]]`` (traceless, so
``c_bg`` is harmonic); ``x`` is the lab position.
"""
import numpy as np

from multi_bodies.solver import laplace_kernels
from multi_bodies.solver.body_solver import SolutionParts
from multi_bodies.solver.linear_map import LinearProblem

LAPLACE_RESTART = 200  # the published GMRES(200) of the concentration


def background_matrices(background):
    """(b0, G (3,), H (3, 3)) of the up to nine numbers of ``background_Laplace`` (padded with zeros)."""
    b = np.zeros(9)
    values = np.asarray(background if background is not None else (), dtype=float).reshape(-1)
    b[:values.size] = values
    H = np.array([[b[4], b[5], b[6]], [b[5], b[7], b[8]], [b[6], b[8], -(b[4] + b[7])]])
    return b[0], b[1:4].copy(), H


def background_field(background, x):
    """``(c_bg (N,), grad c_bg (N, 3))`` at lab positions x (N, 3)."""
    b0, G, H = background_matrices(background)
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    Hx = x @ H.T
    return b0 + x @ G + np.einsum('ij,ij->i', x, Hx), G[None, :] + 2.0 * Hx


class LaplaceProblem(LinearProblem):
    """The concentration on the blobs at one configuration: ``A c = b`` of size N (the problem protocol).

    Parameters
    ----------
    r_vectors : (N, 3) lab-frame blob positions; normals : (N, 3) lab-frame normals (not renormalised)
    reaction, emitting, weights : (N,) ``k``, ``alpha``, ``w``
    diffusion_coefficient : float ``D``; background : up to 9 numbers; wall : bool (images of ``z = 0``)

    ``solution(x)`` gives ``SolutionParts(None, None, c (N,))``: the concentrations are the problem's
    only unknowns and are returned in the ``constraint`` slot.
    """

    def __init__(self, r_vectors, normals, reaction, emitting, weights, diffusion_coefficient, background, wall):
        self.r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
        self.normals = np.asarray(normals, dtype=float).reshape(-1, 3)
        self.reaction = np.asarray(reaction, dtype=float).reshape(-1)
        self.emitting = np.asarray(emitting, dtype=float).reshape(-1)
        self.weights = np.asarray(weights, dtype=float).reshape(-1)
        self.diffusion_coefficient = float(diffusion_coefficient)
        self.background = background
        self.wall = bool(wall)
        self.size = self.r_vectors.shape[0]

    def _layers(self, **densities):
        return laplace_kernels.layers(self.r_vectors, self.normals, self.weights, self.wall, **densities)

    def matvec(self, c):
        """``A c = c/2 - D[c] + S[k c / D]`` (N,)."""
        c = np.asarray(c, dtype=float).reshape(-1)
        out = self._layers(single=self.reaction * c / self.diffusion_coefficient, double=c)
        return 0.5 * c - out['double'] + out['single']

    def rhs(self):
        """``b = c_bg(x_i) + S[alpha / D]_i`` (N,)."""
        c_background, _ = background_field(self.background, self.r_vectors)
        if not np.any(self.emitting):
            return c_background
        return c_background + self._layers(single=self.emitting / self.diffusion_coefficient)['single']

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, x):
        return SolutionParts(None, None, np.asarray(x, dtype=float).reshape(-1))

    def surface_gradient(self, c):
        """``g`` (N, 3) of the concentrations c (N,): the published on-surface gradient, normal part included."""
        q = (self.emitting - self.reaction * np.asarray(c, dtype=float).reshape(-1)) / self.diffusion_coefficient
        out = self._layers(grad_double=c, dipole=q)
        _, grad_background = background_field(self.background, self.r_vectors)
        return 2.0 * grad_background + 2.0 * out['grad_double'] - 2.0 * out['dipole']

    def tangential(self, g):
        """``g - n (n . g)`` (N, 3) with the normals as given."""
        return g - self.normals * np.einsum('ij,ij->i', self.normals, g)[:, None]


class PhoreticSurface:
    """The phoretic data of every blob of a run, in the body frame (fixed for the run), and the slip it drives.

    normals : (N, 3) body-frame normals; reaction, emitting, surface_mobility, weights : (N,);
    blob_body_index : (N,) body of each blob; background : up to 9 numbers; diffusion_coefficient : float;
    wall : bool (the Laplace kernels add the images of the wall ``z = 0``).
    """

    def __init__(self, normals, reaction, emitting, surface_mobility, weights, background, diffusion_coefficient,
                 wall):
        self.normals = np.asarray(normals, dtype=float).reshape(-1, 3)
        self.reaction = np.asarray(reaction, dtype=float).reshape(-1)
        self.emitting = np.asarray(emitting, dtype=float).reshape(-1)
        self.surface_mobility = np.asarray(surface_mobility, dtype=float).reshape(-1)
        self.weights = np.asarray(weights, dtype=float).reshape(-1)
        self.background = np.asarray(background if background is not None else (), dtype=float).reshape(-1)
        self.diffusion_coefficient = float(diffusion_coefficient)
        self.wall = bool(wall)

    def problem(self, body_arrays, configuration):
        """The :class:`LaplaceProblem` at ``configuration`` (body.body.Configuration)."""
        r_vectors = body_arrays.blob_positions(configuration)
        normals = lab_normals(body_arrays, configuration, self.normals)
        return LaplaceProblem(r_vectors, normals, self.reaction, self.emitting, self.weights,
                              self.diffusion_coefficient, self.background, self.wall)

    def slip(self, problem, concentrations):
        """Active slip ``mu (g - n (n.g))`` (N, 3) of the concentrations (N,) of ``problem``."""
        g = problem.surface_gradient(concentrations)
        return self.surface_mobility[:, None] * problem.tangential(g)


def lab_normals(body_arrays, configuration, reference_normals):
    """Body-frame vectors (N, 3) turned with each blob's body at ``configuration`` (N, 3)."""
    R = body_arrays.rotation_matrices(configuration)[body_arrays.blob_body_index]
    return np.einsum('nij,nj->ni', R, reference_normals)
