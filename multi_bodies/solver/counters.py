"""The run's counters as a value: what ``.info`` reports and the restart records carry.

Nothing in the solver counts: :func:`multi_bodies.solver.body_solver.solve`
returns its iterations, Lanczos returns its own, the joint restoration
returns its residual evaluations.  A scheme's step adds what its solves
returned to the counters of the state it started from and returns new
counters with the new state (``quaternion_integrator.scheme_state``); the
static script and the advisor read the counts from the results they get.

Published names (``.info``, SPEC 2.4) first: ``invalid_configuration_count``,
``deterministic_iterations_count`` (GMRES iterations of every solve),
``stochastic_iterations_count`` (Lanczos iterations); then this package's
split of the GMRES count and the solves per kind, and for articulated runs
the published ``nonlinear_iterations_count``.
"""
from dataclasses import dataclass, fields, replace


@dataclass(frozen=True)
class Counters:
    """Counts of a run so far (all ints >= 0)."""
    invalid_configurations: int = 0
    gmres_iterations: int = 0           # every GMRES iteration (the published deterministic_iterations_count)
    gmres_stochastic_iterations: int = 0  # of those: noise and random-finite-difference solves
    lanczos_iterations: int = 0
    lanczos_not_converged: int = 0
    deterministic_solves: int = 0
    stochastic_solves: int = 0
    nonlinear_iterations: int = 0       # residual evaluations of the joints' nonlinear correction
    laplace_iterations: int = 0         # GMRES iterations of the phoretic bodies' concentration solves

    def plus(self, **increments):
        """New counters with ``increments`` (field name -> int) added."""
        return replace(self, **{name: getattr(self, name) + int(value) for name, value in increments.items()})

    def info(self, articulated=False, phoretic=False):
        """Name -> int for ``.info`` and the restart records (``nonlinear_iterations_count`` with joints,
        ``laplace_iterations_count`` with phoretic bodies)."""
        counts = {'invalid_configuration_count': self.invalid_configurations,
                  'deterministic_iterations_count': self.gmres_iterations,
                  'stochastic_iterations_count': self.lanczos_iterations,
                  'gmres_iterations_deterministic_solves': self.gmres_iterations - self.gmres_stochastic_iterations,
                  'gmres_iterations_noise_and_rfd_solves': self.gmres_stochastic_iterations,
                  'deterministic_solves_count': self.deterministic_solves,
                  'noise_and_rfd_solves_count': self.stochastic_solves,
                  'lanczos_not_converged_count': self.lanczos_not_converged}
        if articulated:
            counts['nonlinear_iterations_count'] = self.nonlinear_iterations
        if phoretic:
            counts['laplace_iterations_count'] = self.laplace_iterations
        return counts

    @classmethod
    def from_info(cls, counts):
        """The counters of :meth:`info` (a restart record's ``counters``); missing names are 0."""
        counts = counts or {}

        def count(name):
            return int(counts.get(name, 0))
        return cls(invalid_configurations=count('invalid_configuration_count'),
                   gmres_iterations=count('deterministic_iterations_count'),
                   gmres_stochastic_iterations=count('gmres_iterations_noise_and_rfd_solves'),
                   lanczos_iterations=count('stochastic_iterations_count'),
                   lanczos_not_converged=count('lanczos_not_converged_count'),
                   deterministic_solves=count('deterministic_solves_count'),
                   stochastic_solves=count('noise_and_rfd_solves_count'),
                   nonlinear_iterations=count('nonlinear_iterations_count'),
                   laplace_iterations=count('laplace_iterations_count'))


COUNTER_NAMES = tuple(field.name for field in fields(Counters))


# What one solve of each kind adds to the counters: the fields its GMRES iterations go to, the field that counts
# the solve itself (or None), and whether its iterations are the progress line's "last iterations".
SOLVE_KINDS = {
    'deterministic': (('gmres_iterations',), 'deterministic_solves', True),
    'stochastic': (('gmres_iterations', 'gmres_stochastic_iterations'), 'stochastic_solves', False),
    'roller_torques': (('gmres_iterations',), None, True),   # rollers of prescribed spin (multi_bodies.solver.rollers)
    'concentration': (('laplace_iterations',), None, False),  # the phoretic bodies' solute (doc/phoretic.md)
    'lubrication': (('gmres_iterations',), None, False),      # the lubrication schemes' solves
}


class Tally:
    """The counts one step adds to the run's counters, as its solves and Lanczos calls return them.

    ``add(name=increment, ...)`` (Counters field names), ``solved(kind, iterations)`` (a solve of a kind of
    :data:`SOLVE_KINDS`), ``after(counters)``: the Counters ``counters`` plus these counts.  ``last_iterations``:
    the GMRES iterations of the last solve whose kind says so (None: none yet).  Safe to share between the two
    threads of the products the schemes run side by side.
    """

    def __init__(self):
        import threading
        self._lock = threading.Lock()
        self._counts = {}
        self.last_iterations = None

    def add(self, **increments):
        with self._lock:
            for name, value in increments.items():
                if name not in COUNTER_NAMES:
                    raise ValueError('no counter named %r' % name)
                self._counts[name] = self._counts.get(name, 0) + int(value)

    def solved(self, kind, iterations):
        """Count one solve of ``kind`` that took ``iterations`` GMRES iterations."""
        iteration_fields, solve_field, last = SOLVE_KINDS[kind]
        increments = dict.fromkeys(iteration_fields, iterations)
        if solve_field is not None:
            increments[solve_field] = 1
        self.add(**increments)
        if last:
            self.last_iterations = int(iterations)

    def count(self, name):
        """What this tally adds to counter ``name``."""
        with self._lock:
            return self._counts.get(name, 0)

    def after(self, counters):
        """``counters`` (Counters) plus these counts: a new Counters."""
        with self._lock:
            return counters.plus(**self._counts)
