"""The published ``Lub_Solver`` class (RigidMultiblobsWall ``Lubrication/Lub_Solver.py``) as a thin face over
the package's :mod:`lubrication` room, so that the published lubrication examples run unchanged with their
own ``main_*.py`` drivers and ``multi_bodies_functions.py`` force files::

    from Lub_Solver import Lub_Solver as LS
    LSolv = LS(bodies, a, eta, cutoff, L, debye_length=firm_delta)
    LSolv.dt, LSolv.kT, LSolv.tolerance = dt, kT, solver_tolerance
    LSolv.Set_R_Mats()
    reject_wall, reject_jump = LSolv.Update_Bodies_Trap(FT_calc)

Spheres of one radius ``a`` (one blob each, ``Body`` objects of ``body.body``) above a no-slip wall at
z = 0.  ``FT_calc(bodies, r_vectors)`` returns forces and torques of shape (2N, 3) rows
``[f_1, t_1, f_2, t_2, ...]`` (the published layout); it is called with the bodies moved to the
configuration being evaluated.  The steps update ``bodies[k].location`` and ``bodies[k].orientation`` in
place (the old ones are kept when a step is rejected) and count rejections in ``num_rejections_wall``
and ``num_rejections_jump``.  Random numbers come from ``numpy.random`` (the drivers seed it).

Differences from the published class (see ``doc/lubrication.md``): the pair vector is divided by ``a`` in
every direction (the published code does so only along periodic axes, which makes its pair lubrication
wrong for ``a != 1``); no CHOLMOD (SciPy's sparse LU), so stochastic runs match the published ones only in
distribution; ``Update_Bodies`` (Euler-Maruyama) works; nothing is printed.  The steps keep their preconditioners
(sparse LUs) from solve to solve and step to step and start their solves from first guesses
(:class:`lubrication.integrators.KeptSolves`, what the schemes of ``multi_bodies.py`` do under ``preconditioner
auto``): the same velocities within ``tolerance``, fewer factorisations.  ``published_solves = True`` gives the
published solves instead (a fresh LU at every solve, the corrector starting from the predictor's velocities).

Floor: a published face on the top floor, never imported by the package itself.
"""
import numpy as np

from body.geometry import Quaternion
from lubrication import brownian, integrators
from multi_bodies.files.input_options import DEFAULTS
from multi_bodies.solver.solves import Solver



def in_periodic_box(locations, periodic_length):
    """The published ``put_r_vecs_in_periodic_box``: (N, 3) positions moved by whole periods along each periodic
    axis into [0, L] (a coordinate below 0 by whole periods up to [0, L); one above L down to (0, L]); a copy."""
    r = np.array(locations, dtype=float).reshape(-1, 3)
    for axis, L in enumerate(np.asarray(periodic_length, dtype=float).reshape(3)):
        if L > 0:
            x = r[:, axis]
            x += L * np.where(x < 0, np.ceil(-x / L), np.where(x > L, -np.ceil((x - L) / L), 0.0))
    return r

class Lub_Solver:
    """Lubrication-corrected hydrodynamics of spheres of radius ``a`` above a wall (the published driver API).

    Parameters
    ----------
    bodies : sequence of ``body.body.Body`` (one blob each), moved in place by the steps.
    a : sphere radius (length); eta : viscosity.
    cutoff : pair cutoff, centre distance in units of a (the input option ``Lub_Cut``, 4.5 by default).
    periodic_length : (3,) box lengths, 0 for non-periodic axes.
    debye_length : the gap clamp in units of a (the input option ``firm_delta``; None: its default, the published
        1e-4).

    Attributes set by the drivers: ``kT`` (energy), ``dt`` (time), ``tolerance`` (GMRES and Lanczos).
    After ``Set_R_Mats()``: ``Delta_R``, ``R_Sup``, ``R_MB`` (scipy.sparse, 6N x 6N, force per velocity,
    layout ``[F1 T1 F2 T2 ...]``).  Counters: ``num_rejections_wall``, ``num_rejections_jump``, and
    ``counts`` (work of the last step: far-field products, GMRES and Lanczos iterations, factorisations).
    ``published_solves`` (False): True makes the steps' solves as published (see the module note).
    """

    def __init__(self, bodies, a, eta, cutoff, periodic_length, debye_length=None):
        self.bodies = bodies
        self.a, self.eta, self.cutoff = float(a), float(eta), float(cutoff)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3)
        self.debye_cut = float(DEFAULTS.firm_delta if debye_length is None else debye_length)
        self.kT = 0.0
        self.dt = 0.0
        self.tolerance = DEFAULTS.solver_tolerance
        self.num_rejections_wall = 0
        self.num_rejections_jump = 0
        self.Delta_R = self.R_Sup = self.R_MB = None
        self.counts = integrators.new_counts()
        self.near_field_root = 'lanczos'
        self.implementation = None
        self.published_solves = False
        self._kept = None

    # -- configuration ---------------------------------------------------------------------------------------
    def settings(self):
        """The :class:`lubrication.brownian.LubricationSettings` of this solver (read at every call)."""
        return brownian.lubrication_settings(self.a, self.eta, True, self.cutoff, self.periodic_length,
                                             self.debye_cut, self.implementation, 'published', self.near_field_root)

    def kept_solves(self):
        """The :class:`lubrication.integrators.KeptSolves` of the steps (None with ``published_solves``); a new one
        when the settings or the tolerance changed since the last step."""
        if self.published_solves:
            self._kept = None
            return None
        settings = self.settings()
        if self._kept is None or self._kept.settings != settings or self._kept.tolerance != float(self.tolerance):
            self._kept = integrators.KeptSolves(settings, self.tolerance)
        return self._kept

    def locations(self):
        """Sphere centres (N, 3)."""
        return np.array([b.location for b in self.bodies], dtype=float).reshape(-1, 3)

    def orientations(self):
        """Orientations (N, 4), scalar-first quaternions."""
        return np.array([b.orientation.entries for b in self.bodies], dtype=float).reshape(-1, 4)

    def _place(self, locations, orientations):
        """Move the bodies to locations (N, 3) and orientations (N, 4): one copy of each array, whose rows the bodies
        get (each body its own row, shared with no other body and not with the caller's arrays)."""
        locations = np.array(locations, dtype=float).reshape(-1, 3)
        entries = np.array(orientations, dtype=float).reshape(-1, 4)
        new = Quaternion.__new__  # each body's Quaternion holds its row itself: no constructor's checks and copy
        for b, location, quaternion in zip(self.bodies, locations, entries):
            b.location = location
            b.orientation = new(Quaternion)
            b.orientation.entries = quaternion

    def Set_R_Mats(self, r_vecs_np=None):
        """Build ``Delta_R``, ``R_Sup``, ``R_MB`` at the bodies' locations (or at r_vecs_np (N, 3))."""
        locations = self.locations() if r_vecs_np is None else np.asarray(r_vecs_np, dtype=float).reshape(-1, 3)
        self._matrices = self.settings().matrices(locations)
        self._matrices_at = locations.copy()
        self.R_Sup, self.R_MB, self.Delta_R = self._matrices.R_sup, self._matrices.R_MB, self._matrices.Delta_R

    def _current_matrices(self, locations=None):
        """The near-field matrices at the bodies' locations (N, 3) (``locations``: read from them already)."""
        locations = self.locations() if locations is None else locations
        if self.Delta_R is None or not np.array_equal(self._matrices_at, locations):
            self.Set_R_Mats()
        return self._matrices

    def _problem(self):
        return self.settings().problem(self.locations(), matrices=self._current_matrices())

    # -- products and solves ---------------------------------------------------------------------------------
    def Wall_Mobility_Mult(self, X, r_vecs_np=None):
        """``M X`` (6N,): the far-field RPB mobility of single blobs times forces and torques X (6N,)."""
        locations = self.locations() if r_vecs_np is None else np.asarray(r_vecs_np, dtype=float).reshape(-1, 3)
        return self.settings().problem(locations, matrices=self._current_matrices()).mobility_product(
            np.asarray(X, dtype=float).reshape(-1))

    def Lubrucation_solve(self, X, Xm, X0=None, print_residual=False, its_out=1000, PC_flag=True):
        """``U = (I + M Delta_R)^-1 (X + M Xm)`` (6N,) by preconditioned GMRES; returns ``(U, residuals)``.

        X : velocities (6N,) or None; Xm : forces and torques (6N,) or None.  ``residuals`` is a list with
        the final relative residual (the published code returned GMRES's residual history): a solve stopped at
        ``its_out`` iterations is returned as it stands, its residual above ``tolerance``, as published.  (The
        steps below stop with ``utils.SimulationStopped`` at a solve that does not converge.)
        """
        problem = self._problem()
        rhs = problem.rhs(force_torque=None if Xm is None else np.asarray(Xm, dtype=float).reshape(-1),
                          velocity=None if X is None else np.asarray(X, dtype=float).reshape(-1))
        preconditioner = problem.preconditioner(self.tolerance) if PC_flag else None
        solver = Solver(self.tolerance, print_residual=print_residual, not_converged='flag')
        result = solver.solve(problem, rhs, preconditioner, x0=X0, maxiter=its_out, kind='lubrication',
                              what='the lubrication problem')
        return result.velocities.reshape(-1), [result.residual]

    def Torque_from_Omega(self, Om, F):
        """Torques (N, 3) that make every sphere turn at ``Om`` (a number: ``Om * y_hat``; or (N, 3)) under the
        forces F ((N, 3) forces, or the (2N, 3) force-torque array of ``FT_calc``: its forces are used)."""
        F = np.asarray(F, dtype=float)
        n = len(self.bodies)
        forces = F.reshape(-1, 3)[0::2] if F.size == 6 * n else F.reshape(n, 3)
        return integrators.torque_from_omega(self._problem(), forces, Om, self.tolerance, None, self.counts)

    # -- time steps ------------------------------------------------------------------------------------------
    def _force_torque_at(self, FT_calc, start_locations, start_orientations):
        """The steps' force function: FT_calc with the bodies moved to the configuration asked, unless they are at
        it already (the step's start, ``start_locations`` (N, 3) and ``start_orientations`` (N, 4), read from them)."""
        def force_torque_at(locations, orientations):
            if not (np.array_equal(locations, start_locations) and np.array_equal(orientations, start_orientations)):
                self._place(locations, orientations)
            # as published: FT_calc gets the sphere centres put in the periodic box (put_r_vecs_in_periodic_box)
            r_vectors = in_periodic_box(locations, self.periodic_length)
            return np.asarray(FT_calc(self.bodies, r_vectors), dtype=float).reshape(-1, 6)
        return force_torque_at

    def _finish(self, step, old_locations, old_orientations):
        self.counts = step.counts
        self.num_rejections_wall += step.rejected_wall
        self.num_rejections_jump += step.rejected_jump
        if step.rejected_wall or step.rejected_jump:
            locations, orientations = old_locations, old_orientations
        else:
            locations, orientations = step.locations, step.orientations
        self._place(locations, orientations)
        self.Set_R_Mats(locations)  # where the bodies now are
        return step.rejected_wall, step.rejected_jump

    def Update_Bodies_Trap(self, FT_calc, Omega=None, Out_Torque=False, Cut_Torque=None):
        """One step of the stochastic trapezoidal scheme (:func:`lubrication.integrators.trapezoidal_step`).

        FT_calc(bodies, r_vectors) -> (2N, 3); Omega : prescribed rotation rate (rollers; torques from
        ``Torque_from_Omega``), Cut_Torque : per-sphere torque cap.  Returns ``(reject_wall, reject_jump)``,
        and the torques used (3N,) as a third value when ``Out_Torque``.
        """
        locations, orientations = self.locations(), self.orientations()
        force_torque_at = self._force_torque_at(FT_calc, locations, orientations)
        step = integrators.trapezoidal_step(self.settings(), locations, orientations, force_torque_at, self.kT, self.dt,
                                            np.random, self.tolerance, Omega, Cut_Torque,
                                            self._current_matrices(locations), kept=self.kept_solves())
        rejected = self._finish(step, locations, orientations)
        if Out_Torque:
            torques = np.zeros((len(self.bodies), 3)) if step.torques is None else step.torques
            return rejected + (torques.reshape(-1),)
        return rejected

    def Update_Bodies(self, FT_calc):
        """One Euler-Maruyama step with the RFD drift of M_lub; returns ``(reject_wall, reject_jump)``."""
        locations, orientations = self.locations(), self.orientations()
        step = integrators.euler_maruyama_step(self.settings(), locations, orientations,
                                               self._force_torque_at(FT_calc, locations, orientations), self.kT,
                                               self.dt, np.random, self.tolerance,
                                               matrices=self._current_matrices(locations), kept=self.kept_solves())
        return self._finish(step, locations, orientations)

    def Update_Bodies_no_lub(self, FT_calc):
        """One Euler-Maruyama step of the plain RPB model (no lubrication); returns ``(reject_wall, reject_jump)``."""
        locations, orientations = self.locations(), self.orientations()
        step = integrators.rpb_step(self.settings(), locations, orientations,
                                    self._force_torque_at(FT_calc, locations, orientations), self.kT, self.dt,
                                    np.random, self.tolerance)
        return self._finish(step, locations, orientations)
