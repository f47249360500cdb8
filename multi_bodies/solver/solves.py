"""The one way into the package's one solve: settings, counts and what a solve that did not converge means (floor 4).

:func:`multi_bodies.solver.body_solver.solve` is the package's GMRES solve of any problem of the problem protocol
(doc/adding_a_problem.md).  Nothing of the package calls it but :meth:`Solver.solve` (``tests/test_layout.py``
checks it): the schemes through their step's context (``quaternion_integrator.scheme_state.StepContext.solve``),
the model's operations (``Model.solve``, the rollers' spin, the joints, the solute), the lubrication steps, the
static script, the advisor and the published ``Lub_Solver`` face.  A :class:`Solver` holds

* the settings of the solves of one model: ``solver_tolerance``, whether GMRES stops at the least true residual of
  its Krylov space and a kept preconditioner is turned with the bodies (``preconditioner auto`` and
  ``neighbours``; not under ``block_diagonal``, the published solves), whether every residual is printed, and the
  Lanczos iteration's limit: :meth:`Solver.noise` draws the blob noise ``factor M^{1/2} z`` (Lanczos, or exact where
  the product can), the other Krylov computation of a step;
* a :class:`multi_bodies.solver.counters.Tally` (or None) that counts each solve by its kind (deterministic, noise
  and random finite differences, roller torques, concentrations, lubrication);
* what a solve that stops at the iteration limit means: ``'stop'`` raises ``utils.SimulationStopped`` with one
  line (what was solved, the tolerance, the iterations and the residual reached) - the time-stepping schemes,
  lubrication included; ``'flag'`` returns the result with ``converged`` False for its caller to say so (the
  static script writes the velocities and exits 1; the advisor notes it; the published face returns the
  residual).
"""
import warnings

from multi_bodies.files.input_options import DEFAULTS
from multi_bodies.solver import body_solver, corotated_preconditioner
from stochastic_forcing import lanczos_square_root
from utils import SimulationStopped

NOT_CONVERGED_RULES = ('stop', 'flag')
# the relative tolerance of a solver made without one: the option table's default of solver_tolerance
SOLVER_TOLERANCE = DEFAULTS.solver_tolerance
LANCZOS_MAX_ITERATIONS = 1000  # Lanczos iterations of one noise at most (Model's lanczos_max_iterations)


class Solver:
    """The settings of a model's solves, their counts and their rule for solves that do not converge.

    Parameters
    ----------
    tolerance : float or None
        Relative tolerance of the solves that name none (the model's ``solver_tolerance``; None: the option
        table's default).
    minimal_residual : bool
        GMRES takes the point of least true residual of each Krylov space (``preconditioner auto`` and
        ``neighbours``); False: the published iterates.
    turn_with : body.body.BodyArrays or None
        A preconditioner built where the bodies were oriented otherwise is applied turned with them
        (:mod:`multi_bodies.solver.corotated_preconditioner`; None: as built, the published solves).
    print_residual : bool
        Print every GMRES residual.
    not_converged : 'stop' or 'flag' (see the module note).
    tally : multi_bodies.solver.counters.Tally or None
        Counts every solve by its ``kind``.
    lanczos_max_iterations : int
        The Lanczos iterations of one noise (:meth:`noise`) at most.

    ``max_iterations`` (class attribute): GMRES's limit on the inner iterations of a solve that names none.
    """
    max_iterations = body_solver.GMRES_MAXITER

    def __init__(self, tolerance=None, minimal_residual=False, turn_with=None, print_residual=False, not_converged='stop',
                 tally=None, lanczos_max_iterations=LANCZOS_MAX_ITERATIONS):
        if not_converged not in NOT_CONVERGED_RULES:
            raise ValueError('not_converged %r: one of %s' % (not_converged, ', '.join(NOT_CONVERGED_RULES)))
        self.tolerance = SOLVER_TOLERANCE if tolerance is None else float(tolerance)
        self.minimal_residual = bool(minimal_residual)
        self.turn_with = turn_with
        self.print_residual = bool(print_residual)
        self.not_converged = not_converged
        self.tally = tally
        self.lanczos_max_iterations = int(lanczos_max_iterations)

    @classmethod
    def of_model(cls, model, not_converged='stop', tally=None):
        """The solver of a ``multi_bodies.solver.model.Model``: its ``solver_tolerance``, its ``print_residual``, and
        under ``preconditioner auto`` and ``neighbours`` the least-residual iterate and the turned preconditioners."""
        published = model.published_solves
        return cls(model.tolerance, minimal_residual=not published, turn_with=None if published else model.arrays,
                   print_residual=model.print_residual, not_converged=not_converged, tally=tally,
                   lanczos_max_iterations=model.lanczos_max_iterations)

    def solve(self, problem, rhs, preconditioner, x0=None, tolerance=None, restart=body_solver.GMRES_RESTART,
              maxiter=None, kind='deterministic', what='the mobility problem'):
        """``body_solver.solve`` of ``problem`` (any problem of the protocol) with these settings: a SolveResult.

        rhs (problem.size,); preconditioner : as body_solver.solve (None: unpreconditioned); x0 : first guess of
        the normalised system (``SolveResult.normalised_solution`` of an earlier solve) or None; tolerance : None
        is this solver's; maxiter : GMRES's iteration limit (None: ``max_iterations``); kind : what the tally
        counts the solve as (``counters.SOLVE_KINDS``); what : the
        problem's name in the line of a solve that did not converge.  Under ``not_converged`` 'stop' such a
        solve raises SimulationStopped (its iterations are counted first).
        """
        tolerance = self.tolerance if tolerance is None else float(tolerance)
        if self.turn_with is not None:
            preconditioner = corotated_preconditioner.following(problem, preconditioner, self.turn_with)
        result = body_solver.solve(problem, rhs, preconditioner, x0=x0, tolerance=tolerance, restart=restart,
                                   maxiter=self.max_iterations if maxiter is None else int(maxiter),
                                   print_residual=self.print_residual,
                                   minimal_residual=self.minimal_residual)
        if self.tally is not None:
            self.tally.solved(kind, result.iterations)
        if not result.converged and self.not_converged == 'stop':
            raise SimulationStopped(not_converged_line(what, tolerance, result))
        return result

    def noise(self, problem, z, factor, preconditioner=None, tolerance=None):
        """``factor * M^{1/2} z`` at the configuration of ``problem``: a ``stochastic_forcing.LanczosResult``.

        ``noise`` (3N,), ``iterations``, ``converged`` (nothing is counted here: a step's context counts it).  With
        a preconditioner the Lanczos iteration runs on ``L^{-1} M L^{-T}`` and the result is multiplied by ``L``
        (covariance ``M``; SPEC decision 1): its ``noise_factor`` (the incomplete Cholesky factor of
        ``lanczos_preconditioner incomplete_cholesky``) or its own block-diagonal factors.  A product that draws
        its noise exactly (``noise_method`` 'fluctuating', the spectral product) does so, without Lanczos.  A call
        that does not converge is warned about.  tolerance : relative change at which Lanczos stops; None is this
        solver's.
        """
        tolerance = self.tolerance if tolerance is None else float(tolerance)
        mobility = getattr(problem, 'mobility', None)
        if getattr(mobility, 'noise_method', None) == 'fluctuating':  # exact: no Krylov space, no preconditioner
            return mobility.noise(problem.r_vectors, z, factor=factor)
        if preconditioner is None:
            matvec, L_mult = problem.M_dot, None
        else:
            # the factor L: the block-diagonal Cholesky factors, or the incomplete Cholesky factor of
            # lanczos_preconditioner incomplete_cholesky (any invertible L gives the covariance M)
            factor_of = getattr(preconditioner, 'noise_factor', None) or preconditioner

            def matvec(v):
                return factor_of.L_inv_dot(problem.M_dot(factor_of.L_inv_T_dot(v)))
            L_mult = factor_of.L_dot
        result = lanczos_square_root(matvec, z, tolerance, max_iterations=self.lanczos_max_iterations,
                                     factor=factor, L_mult=L_mult, print_residual=self.print_residual)
        warn_if_not_converged(result, tolerance)
        return result

    def replace(self, **changes):
        """A solver with these settings changed (``tolerance``, ``minimal_residual``, ``turn_with``,
        ``print_residual``, ``not_converged``, ``tally``, ``lanczos_max_iterations``)."""
        settings = dict(tolerance=self.tolerance, minimal_residual=self.minimal_residual, turn_with=self.turn_with,
                        print_residual=self.print_residual, not_converged=self.not_converged, tally=self.tally,
                        lanczos_max_iterations=self.lanczos_max_iterations)
        settings.update(changes)
        return type(self)(**settings)


def warn_if_not_converged(result, tolerance):
    """Warn (RuntimeWarning) when a Lanczos result (``stochastic_forcing.LanczosResult``) did not converge."""
    if not result.converged:
        warnings.warn('Lanczos did not converge to solver_tolerance %g in %d iterations (last relative change '
                      '%.3e); the noise is approximate (counted in .info as lanczos_not_converged_count)'
                      % (tolerance, result.iterations, result.relative_change), RuntimeWarning)


def not_converged_line(what, tolerance, result):
    """The one line that says a solve of ``what`` stopped at the iteration limit (``result`` a SolveResult)."""
    return ('GMRES of %s did not converge to solver_tolerance %g in %d iterations (relative residual %.3e); try a '
            'larger solver_tolerance or check the configuration' % (what, tolerance, result.iterations,
                                                                   result.residual))
