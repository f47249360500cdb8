"""The surface data of a run: phoretic (``.Laplace``) and slip-length (``.slip_length``) blobs (floor 3).

:func:`read_surface` reads the third files of the structure lines into one
:class:`Surface` (per-blob arrays in the body frame, in the blob order of the
run), checks that the run can use them, and the model (``Model.surface``)
asks it for the active slip of the solute field and for the slip-length
problem and its preconditioner.  See doc/phoretic.md.

Which runs are refused, and why:

* surface files with the roller schemes (single blobs have no surface);
* phoretic data on some structure lines but not all (every blob is a node of
  the solute's boundary integral; the published code crashes), or on
  ``articulated`` lines (not read by the published code either);
* slip lengths with a wall seen by the hydrodynamics (the published
  double layer has no wall images), with obstacles or bodies of prescribed
  velocity, joints, or any scheme but the deterministic iterative ones
  (``deterministic_forward_euler``, ``deterministic_adams_bashforth``,
  ``deterministic_midpoint``) and the static ``mobility`` problem: the
  dense schemes have no dense form of this operator, and the stochastic
  schemes' noise ``M^{1/2} W`` has the covariance of the no-slip mobility,
  not of the slip-length one (whose discrete operator is not symmetric).
"""
import numpy as np

from multi_bodies.files.scheme_table import moves_rollers, scheme_names
from multi_bodies.files.surface_files import read_laplace_file, read_slip_length_file
from multi_bodies.solver import laplace_preconditioner, phoretic, slip_length
from utils import UserInputError, warn_user

SLIP_LENGTH_SCHEMES = scheme_names(slip_length=True)  # the scheme registry's


class Surface:
    """Per-blob surface data of a run (body frame, fixed).

    phoretic : phoretic.PhoreticSurface or None
    slip_normals, slip_lengths, slip_weights : (N, 3), (N,), (N,) or None (no slip-length data)
    """

    def __init__(self, phoretic_surface=None, slip_normals=None, slip_lengths=None, slip_weights=None):
        self.phoretic = phoretic_surface
        self.slip_normals, self.slip_lengths, self.slip_weights = slip_normals, slip_lengths, slip_weights

    @property
    def has_slip_length(self):
        return self.slip_lengths is not None

    def laplace_problem(self, model, configuration):
        """The concentration problem (phoretic.LaplaceProblem) at ``configuration``."""
        return self.phoretic.problem(model.arrays, configuration)

    @staticmethod
    def preconditions_concentrations(model, num_blobs):
        """True when the concentration solves of ``num_blobs`` blobs are preconditioned: the model's
        ``preconditioner`` ``neighbours``, or ``auto`` from ``AUTO_MIN_BLOBS`` blobs on (``block_diagonal``:
        unpreconditioned, as published)."""
        return model.preconditioner == 'neighbours' or (model.preconditioner == 'auto'
                                                        and num_blobs >= laplace_preconditioner.AUTO_MIN_BLOBS)

    def concentration_preconditioner(self, model, configuration, problem=None):
        """The :class:`laplace_preconditioner.LaplacePreconditioner` of the concentration problem at
        ``configuration`` (``problem``: that problem, if built), or None where the solves are unpreconditioned."""
        problem = self.laplace_problem(model, configuration) if problem is None else problem
        if not self.preconditions_concentrations(model, problem.size):
            return None
        return laplace_preconditioner.LaplacePreconditioner(problem, model.arrays.blob_offsets)

    def solve_concentrations(self, model, configuration, x0=None, preconditioner=None, solver=None):
        """(LaplaceProblem, SolveResult) at ``configuration``: the blob concentrations in ``constraint_force_torque``.

        GMRES(200) of the model's ``solver_tolerance`` through ``solver`` (a ``solves.Solver``; None: the model's,
        ``model.solver()``), preconditioned by
        :meth:`concentration_preconditioner` (every body alone plus the coarse modes of all bodies, where the
        solves are preconditioned); x0 : normalised first guess (N,) or None (zeros, as published);
        preconditioner : one built elsewhere (kept by a run between solves), or None: built here.
        """
        problem = self.laplace_problem(model, configuration)
        if preconditioner is None:
            preconditioner = self.concentration_preconditioner(model, configuration, problem)
        solver = model.solver() if solver is None else solver
        result = solver.solve(problem, problem.rhs(), preconditioner, x0=x0, restart=phoretic.LAPLACE_RESTART,
                              kind='concentration', what='the concentration (Laplace) problem')
        return problem, result

    def phoretic_slip(self, model, configuration, solved=None):
        """Active slip (N, 3) of the solute field at ``configuration``; ``solved``: the (problem, SolveResult) of
        :meth:`solve_concentrations` there (None: solved here from zero)."""
        problem, result = self.solve_concentrations(model, configuration) if solved is None else solved
        return self.phoretic.slip(problem, result.constraint_force_torque)

    def slip_length_problem(self, model, configuration):
        return slip_length.slip_length_problem(model.arrays, configuration, model.vector_mobility,
                                               reference_normals=self.slip_normals, slip_lengths=self.slip_lengths,
                                               weights=self.slip_weights)

    def slip_length_preconditioner(self, model, configuration):
        """The slip-length problem's preconditioner at ``configuration``: every body's own system inverted
        (:class:`slip_length.SlipLengthPreconditioner`, alone under ``preconditioner block_diagonal``, as
        published), corrected for the couplings of neighbouring bodies under ``neighbours`` and under ``auto``
        where the near pairs hold at most ``slip_length.AUTO_MAX_COST_RATIO`` of the blob pairs
        (:class:`slip_length.SlipLengthNeighbourPreconditioner`)."""
        base = slip_length.SlipLengthPreconditioner(model.arrays, configuration, model.blobs_mobility,
                                                    normals=self.slip_normals, slip_lengths=self.slip_lengths,
                                                    weights=self.slip_weights)
        if model.published_solves or model.num_bodies < 2:
            return base
        return slip_length.SlipLengthNeighbourPreconditioner(
            base, model.blobs_mobility, periodic_length=model.periodic_length, body_lengths=model.body_lengths,
            max_cost_ratio=slip_length.AUTO_MAX_COST_RATIO if model.preconditioner == 'auto' else None)


def warm_solute(model, configuration, guess, preconditioner=None, solver=None):
    """(solved, next guess) of a step: ``solved`` the (problem, SolveResult) of the concentrations at
    ``configuration`` started from the normalised ``guess`` (N,) or None, or None when the model has no phoretic
    bodies (then the guess is returned unchanged); preconditioner : a kept one, or None (built here); solver : the
    step's ``solves.Solver`` (None: the model's)."""
    surface = model.surface
    if surface is None or surface.phoretic is None:
        return None, guess
    problem, result = surface.solve_concentrations(model, configuration, x0=guess, preconditioner=preconditioner,
                                                   solver=solver)
    return (problem, result), (guess if result.normalised_solution is None else result.normalised_solution)


def read_surface(options, specs, types, vertex_blobs, laplace_wall, hydrodynamic_wall):
    """The run's :class:`Surface` of the structure lines, or None when no line has a third surface file.

    specs : StructureSpec of every structure and obstacle line (body order); types : (ID, count) per line;
    vertex_blobs : blobs per body of each line; laplace_wall : bool, the Laplace kernels add the images of
    the wall ``z = 0`` (``domain single_wall``, as published); hydrodynamic_wall : bool, the mobility sees it.
    """
    laplace = [s.laplace_file for s in specs]
    lengths = [s.slip_length_file for s in specs]
    if options.save_concentration and not any(laplace):
        warn_user('%s: save_concentration is ignored: it writes the solute of phoretic bodies, but no structure line '
                  'has a .Laplace file; remove the option or add the files' % options.where('save_concentration'))
    if not any(laplace) and not any(lengths):
        return None
    if options.articulated:
        raise UserInputError('%s: .Laplace and .slip_length files are not read on articulated bodies; remove the '
                             "'articulated' line or the surface files" % options.articulated[0].where)
    if moves_rollers(options.scheme):
        raise UserInputError('%s: scheme %s moves single-blob rollers, which have no surface; remove the .Laplace and '
                             '.slip_length files or use a rigid-body scheme'
                             % (options.where('scheme'), options.scheme))
    surface = Surface()
    if any(laplace):
        missing = [s for s in specs if s.laplace_file is None]
        if missing:
            raise UserInputError('%s: this line has no .Laplace file, but another structure line has one; every '
                                 'blob is a node of the solute field, so give every structure line a .Laplace file '
                                 '(zero rates for inert bodies)' % missing[0].where)
        tables = [np.tile(read_laplace_file(s.laplace_file, n, s.vertex_file, s.where), (count, 1))
                  for s, (_, count), n in zip(specs, types, vertex_blobs)]
        table = np.concatenate(tables)
        surface.phoretic = phoretic.PhoreticSurface(table[:, :3], table[:, 3], table[:, 4], table[:, 5], table[:, 6],
                                                    options.background_Laplace, options.diffusion_coefficient,
                                                    laplace_wall)
    if any(lengths):
        missing = [s for s in specs if s.slip_length_file is None]
        if missing:
            raise UserInputError('%s: this line has no .slip_length file, but another structure line has one; give '
                                 'every structure line one (slip length 0 for no slip)' % missing[0].where)
        fixed = [s for s in specs if s.obstacle or s.velocity_file is not None]
        if fixed:
            raise UserInputError('%s: slip lengths are not supported with obstacles or bodies of prescribed velocity '
                                 '(the published formulation of these is inconsistent); remove the .slip_length file '
                                 'or the prescribed motion' % fixed[0].where)
        if options.scheme not in SLIP_LENGTH_SCHEMES:
            raise UserInputError('%s: scheme %s cannot move slip-length bodies; use one of %s (doc/phoretic.md)'
                                 % (options.where('scheme'), options.scheme, ', '.join(SLIP_LENGTH_SCHEMES)))
        if getattr(options, 'plot_velocity_field', None) is not None:
            raise UserInputError('%s: plot_velocity_field is not available with slip-length bodies (the flow of their '
                                 'surface slip, a double layer, is not in it); remove the option'
                                 % options.where('plot_velocity_field'))
        if hydrodynamic_wall:
            raise UserInputError('%s: slip-length bodies need a no-wall mobility (the double layer of the slip-length '
                                 'problem has no wall images); use mobility_vector_prod_implementation and '
                                 'mobility_blobs_implementation ..._no_wall' % specs[lengths.index(next(
                                     f for f in lengths if f))].where)
        tables = [np.tile(read_slip_length_file(s.slip_length_file, n, s.vertex_file, s.where), (count, 1))
                  for s, (_, count), n in zip(specs, types, vertex_blobs)]
        table = np.concatenate(tables)
        surface.slip_normals, surface.slip_lengths, surface.slip_weights = table[:, :3], table[:, 3], table[:, 4]
    return surface
