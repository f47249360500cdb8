"""libMobility's Python interface on the CPU: ``SelfMobility``, ``NBody`` and ``DPStokes``.

libMobility (github stochasticHydroTools/libMobility; GPU only) gives each hydrodynamic solver one small
interface.  This module offers the same classes, methods, keywords, return shapes and errors on top of the
package's mobility interface (:mod:`mobility.interface`), so that a script written for libMobility runs here
after changing only its import line::

    from mobility.libmobility import NBody          # instead of: from libMobility import NBody

    solver = NBody("open", "open", "single_wall")
    solver.setParameters(wallHeight=0.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0, includeAngular=True)
    solver.setPositions(positions)                   # (N, 3) or (3N,)
    U, W = solver.Mdot(forces, torques)              # shapes follow the inputs; W is None without angular
    dU, dW = solver.sqrtMdotW(prefactor=1.0)         # prefactor * M^{1/2} z, z ~ N(0, I), seeded
    dU, dW = solver.divM(prefactor=1.0)              # prefactor * div M (zero, or one RFD sample at a wall)
    U, W = solver.LangevinVelocities(dt, kbt, forces, torques)

What each class is:

* ``SelfMobility("open", "open", "open")``: no hydrodynamic interactions, ``U = F / (6 pi eta a)``,
  ``W = T / (8 pi eta a^3)`` (the self terms of the package's free-space Rotne-Prager-Yamakawa product).
* ``NBody(X, Y, Z)``: X, Y ``open``; Z ``open`` (free-space RPY) or ``single_wall`` (Rotne-Prager-Blake with
  the package's regularisation of blobs that overlap each other or the wall; the wall is the plane
  ``z = wallHeight``).  The package's direct products (``C++``, else ``python``; ``pycuda`` first where it
  runs), independent batches of particles.
* ``DPStokes("periodic", "periodic", Z)``: the spectral (force-coupling, ES kernel) product periodic in x and
  y, Z ``open``, ``single_wall`` (wall at ``zmin``) or ``two_walls`` (walls at ``zmin`` and ``zmax``), and as
  an extension ``periodic`` (triply periodic).  By default libMobility's own grid and kernel selection;
  ``setParameters(..., parameter_selection="dpstokes", kernel="w6")`` takes the DoublyPeriodicStokes CPU
  code's selection instead (``doc/libmobility.md``).

Conventions (those of libMobility's interface, version "1.1"):

* arrays: positions, forces, torques of shape (N, 3) or (3N,), any real dtype (converted to float64),
  contiguous or not; outputs are float64 NumPy arrays whose shapes follow the inputs (the last positions'
  shape where there is no input).  Other array types (torch, ...) are read through ``numpy.asarray`` and
  answered with NumPy arrays (this module runs on the CPU).
* ``precision`` is the class attribute ``"double"``.
* ``setParameters`` is per class and takes effect at the next ``initialize``;
  ``initialize(viscosity, hydrodynamicRadius, includeAngular=False, tolerance=1e-4, seed=None,
  lanczos_callback=None)`` may be called again (it cleans first); ``setPositions`` after it.
* noise: Lanczos on the grand operator ``[F; T] -> [U; W]`` (torques after forces), tolerance ``tolerance``;
  drift: one random-finite-difference sample per ``divM`` call at a wall, zero otherwise.  Equal seeds and
  equal call sequences give equal numbers; the noise and the drift draw from separate streams of the seed.
* every error is a :class:`LibMobilityError`, a ``RuntimeError`` (as libMobility's) and a
  ``utils.UserInputError`` (so the package's scripts print it without a traceback).

Top floor of the mobility room (a face, like ``mobility.mobility``): the package never imports it.
"""
import numpy as np

from utils import UserInputError

from mobility.interface import Geometry, make_mobility, registered_backends

__all__ = ['LibMobilityError', 'SelfMobility', 'NBody', 'DPStokes', 'PERIODICITIES', 'PARAMETER_SELECTIONS']

# The periodicity strings of libMobility's constructors.
PERIODICITIES = ('open', 'unspecified', 'single_wall', 'two_walls', 'periodic')


class LibMobilityError(UserInputError, RuntimeError):
    """A libMobility call that cannot be done as asked (bad periodicity, shape, parameter, position...).

    A ``RuntimeError``, as libMobility's errors are (scripts catch that), and a ``utils.UserInputError``, so
    the package's scripts print the one-line message and stop without a traceback.
    """


def _periodicity(value, axis):
    if not isinstance(value, str) or value not in PERIODICITIES:
        raise LibMobilityError('[libMobility] Invalid periodicity %r for %s; one of %s'
                               % (value, axis, ', '.join(PERIODICITIES)))
    return value


def _real_array(values, what):
    """``values`` as a float64 array, refusing complex, boolean, object and string data."""
    array = np.asarray(values)
    if array.dtype.kind not in 'fiu':
        raise LibMobilityError('[libMobility] %s must hold real numbers, got dtype %s' % (what, array.dtype))
    return array


def _vectors(values, what):
    """(N, 3) float64 copy of positions, forces or torques given as (N, 3) or (3N,); and the input's shape."""
    array = _real_array(values, what)
    if array.size % 3 != 0:
        raise LibMobilityError('[libMobility] The input arrays for positions, forces, and torques must each have '
                               'total size 3*N; %s has size %d' % (what, array.size))
    if not (array.ndim == 1 or (array.ndim == 2 and array.shape[1] == 3)):
        raise LibMobilityError('[libMobility] The input arrays for positions, forces, and torques must each have '
                               'shape (N, 3) or (3*N); %s has shape %s' % (what, array.shape))
    vectors = np.array(array, dtype=np.float64, order='C').reshape(-1, 3)
    if not np.all(np.isfinite(vectors)):
        raise LibMobilityError('[libMobility] %s contain NaN or infinite values' % what)
    return vectors, tuple(array.shape)


def _given(values):
    """None for an omitted input (None or an empty array, as libMobility's default), else the values."""
    if values is None:
        return None
    if np.size(values) == 0:
        return None
    return values


class _Solver:
    """What every libMobility solver shares (constructor, initialize, positions, noise, Langevin velocities).

    Subclasses set ``_solver_name``, check their periodicities in ``_check_periodicity``, keep their
    ``setParameters`` values in ``self._requested``, build their product in ``_configure`` and give the
    grand product ``_grand_product(positions (N, 3), forces (N, 3) or None, torques (N, 3) or None) ->
    (U (N, 3), W (N, 3) or None)``.
    """
    precision = 'double'
    version = '1.1'
    _solver_name = 'libMobility'
    _needs_positions = True

    def __init__(self, periodicityX, periodicityY, periodicityZ):
        self.periodicity = (_periodicity(periodicityX, 'periodicityX'), _periodicity(periodicityY, 'periodicityY'),
                            _periodicity(periodicityZ, 'periodicityZ'))
        self._check_periodicity(*self.periodicity)
        self._requested = self._default_parameters()
        self._initialized = False
        self._positions = None
        self._positions_shape = None

    # -------------------------------------------------------------- per solver
    def _check_periodicity(self, x, y, z):
        raise NotImplementedError

    def _default_parameters(self):
        return {}

    def _configure(self):
        """Build the product from ``self._requested`` and the initialize arguments."""
        raise NotImplementedError

    def _check_positions(self, positions):
        """Refuse positions the solver cannot take (walls); positions (N, 3)."""

    def _grand_product(self, positions, forces, torques):
        raise NotImplementedError

    def _drift(self, positions, prefactor):
        """``prefactor * div M`` as (N, 3) linear and (N, 3) or None angular parts; zero by default."""
        n = positions.shape[0]
        return np.zeros((n, 3)), (np.zeros((n, 3)) if self._include_angular else None)

    # -------------------------------------------------------------- the interface
    def initialize(self, viscosity, hydrodynamicRadius, includeAngular=False, tolerance=1e-4, seed=None,
                   lanczos_callback=None):
        """Make the solver ready for ``setPositions`` (cleans first when called again).

        viscosity : float > 0; hydrodynamicRadius : float > 0, one radius for every particle (a length);
        includeAngular : bool, whether torques are taken and angular velocities returned;
        tolerance : float, the Lanczos tolerance of ``sqrtMdotW``;
        seed : int or None; None or 0 draws a seed from the operating system; equal seeds and equal call
        sequences give equal noise and drift;
        lanczos_callback : None or a callable, called as ``lanczos_callback(iterations, relative_change)``
        after each Lanczos square root (this module's form: a way to watch the convergence).
        """
        if self._initialized:
            self.clean()
        eta = self._positive(viscosity, 'viscosity')
        radius = np.asarray(hydrodynamicRadius, dtype=float)
        if radius.size != 1:
            raise LibMobilityError('[libMobility] hydrodynamicRadius must be one number (one radius for all '
                                   'particles), got %d values' % radius.size)
        radius = self._positive(radius.reshape(()), 'hydrodynamicRadius')
        tolerance = self._positive(tolerance, 'tolerance')
        if lanczos_callback is not None and not callable(lanczos_callback):
            raise LibMobilityError('[libMobility] lanczos_callback must be callable or None')
        if seed is None or int(seed) == 0:
            sequence = np.random.SeedSequence()
        else:
            if int(seed) < 0:
                raise LibMobilityError('[libMobility] seed must be a non-negative integer, got %r' % (seed,))
            sequence = np.random.SeedSequence(int(seed))
        noise_sequence, drift_sequence = sequence.spawn(2)
        self._noise_rng = np.random.Generator(np.random.MT19937(noise_sequence))
        self._drift_rng = np.random.Generator(np.random.MT19937(drift_sequence))
        self._eta = eta
        self._radius = radius
        self._include_angular = bool(includeAngular)
        self._tolerance = tolerance
        self._lanczos_callback = lanczos_callback
        self._configure()
        self._initialized = True

    def setPositions(self, positions):
        """The positions (N, 3) or (3N,) the mobility is computed at (the shape is remembered for outputs)."""
        self._require_initialized()
        vectors, shape = _vectors(positions, 'positions')
        self._check_positions(vectors)
        self._positions = vectors
        self._positions_shape = shape

    def Mdot(self, forces=None, torques=None):
        """``(U, W)`` = the grand mobility times ``[forces; torques]`` (a missing input counts as zero).

        forces, torques : (N, 3) or (3N,), or None; torques only with ``includeAngular``.
        U has the shape of forces (of torques when forces are omitted); W is None without angular, else it has
        the shape of torques (of forces when torques are omitted).
        """
        self._require_initialized()
        forces, torques = _given(forces), _given(torques)
        if torques is not None and not self._include_angular:
            raise LibMobilityError('[libMobility] The solver was configured without including angular velocities. '
                                   'Set includeAngular to true when initializing if you want to use torques')
        F, F_shape = (None, None) if forces is None else _vectors(forces, 'forces')
        T, T_shape = (None, None) if torques is None else _vectors(torques, 'torques')
        positions = self._current_positions(F if F is not None else T)
        n = positions.shape[0]
        for values, name in ((F, 'forces'), (T, 'torques')):
            if values is not None and values.shape[0] != n:
                raise LibMobilityError('[libMobility] The %s array must have size 3*N = %d (N = %d particles from '
                                       'setPositions), got size %d' % (name, 3 * n, n, 3 * values.shape[0]))
        shape = F_shape or T_shape or self._positions_shape or (n, 3)
        if F is None and T is None:
            U, W = np.zeros((n, 3)), (np.zeros((n, 3)) if self._include_angular else None)
        else:
            U, W = self._grand_product(positions, F, T)
        return U.reshape(shape), (None if W is None else W.reshape(T_shape or shape))

    def sqrtMdotW(self, prefactor=1.0):
        """``(prefactor * M^{1/2} z, angular part or None)`` for a fresh z ~ N(0, I) of length 3N (6N with
        angular; torques after forces), shapes those of the last positions.  Lanczos to ``tolerance``."""
        self._require_initialized()
        positions = self._require_positions()
        n = positions.shape[0]
        prefactor = float(prefactor)
        size = 6 * n if self._include_angular else 3 * n
        if prefactor == 0.0 or n == 0:
            noise = np.zeros(size)
        else:
            noise = self._root(positions, self._noise_rng.standard_normal(size), prefactor)
        return self._split(noise, n)

    def divM(self, prefactor=1.0):
        """``(prefactor * div_q M, angular part or None)``, shapes those of the last positions: zero where the
        divergence vanishes (open and periodic domains), one random-finite-difference sample at walls."""
        self._require_initialized()
        positions = self._require_positions()
        linear, angular = self._drift(positions, float(prefactor))
        return self._shaped(linear, angular)

    def LangevinVelocities(self, dt, kbt, forces=None, torques=None):
        """``M [F; T] + sqrt(2 kbt / dt) M^{1/2} z + kbt div M`` (Euler-Maruyama velocities with the drift).

        The deterministic part is skipped when both inputs are absent; noise and drift when ``kbt == 0``, so
        ``LangevinVelocities(dt, 0, F) == Mdot(F)``.  U like forces (else like the positions), W like torques
        (else like the positions), None without angular.
        """
        self._require_initialized()
        forces, torques = _given(forces), _given(torques)
        kbt = float(kbt)
        if forces is not None or torques is not None:
            U, W = self.Mdot(forces, torques)
        else:
            positions = self._require_positions()
            U, W = self._shaped(np.zeros_like(positions), np.zeros_like(positions) if self._include_angular
                                else None)
        if kbt != 0.0:
            dt = self._positive(dt, 'dt')
            noise_U, noise_W = self.sqrtMdotW(np.sqrt(2.0 * kbt / dt))
            drift_U, drift_W = self.divM(kbt)
            U = U + (noise_U + drift_U).reshape(U.shape)
            if W is not None:
                W = W + (noise_W + drift_W).reshape(W.shape)
        return U, W

    def clean(self):
        """Free what the solver holds; it needs ``initialize`` (and ``setPositions``) again."""
        self._initialized = False
        self._positions = None
        self._positions_shape = None
        self._release()

    def _release(self):
        pass

    # -------------------------------------------------------------- helpers
    @staticmethod
    def _positive(value, name):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise LibMobilityError('[libMobility] %s must be a number, got %r' % (name, value)) from None
        if not np.isfinite(value) or value <= 0:
            raise LibMobilityError('[libMobility] %s must be positive and finite, got %r' % (name, value))
        return value

    def _require_initialized(self):
        if not self._initialized:
            raise LibMobilityError('[%s] The solver is not initialized: call setParameters (where needed) and '
                                   'initialize first' % self._solver_name)

    def _require_positions(self):
        if self._positions is None or self._positions.shape[0] == 0:
            raise LibMobilityError('[libMobility] Positions are not set. Did you forget to call setPositions?')
        return self._positions

    def _current_positions(self, values):
        return self._require_positions()

    def _shaped(self, linear, angular):
        shape = self._positions_shape
        return linear.reshape(shape), (None if angular is None else angular.reshape(shape))

    def _split(self, stacked, n):
        linear = stacked[:3 * n].reshape(n, 3)
        angular = stacked[3 * n:].reshape(n, 3) if self._include_angular else None
        return self._shaped(linear, angular)

    def _grand_matvec(self, positions):
        """The grand operator as a flat matvec: (3N,) or (6N,) with torques after forces."""
        n = positions.shape[0]

        def matvec(vector):
            vector = np.asarray(vector, dtype=float)
            F = vector[:3 * n].reshape(n, 3)
            T = vector[3 * n:].reshape(n, 3) if self._include_angular else None
            U, W = self._grand_product(positions, F, T)
            return U.reshape(-1) if W is None else np.concatenate((U.reshape(-1), W.reshape(-1)))
        return matvec

    def _root(self, positions, z, prefactor):
        """``prefactor * M^{1/2} z`` (flat) by Lanczos on the grand operator (through the package interface)."""
        result = self._lanczos_mobility().noise(positions, z, tolerance=self._tolerance, factor=prefactor,
                                                matvec=self._grand_matvec(positions))
        if self._lanczos_callback is not None:
            self._lanczos_callback(result.iterations, result.relative_change)
        if not result.converged:
            raise LibMobilityError('[libMobility] Lanczos did not reach tolerance %g in %d iterations (last relative '
                                   'change %.3g): raise the tolerance in initialize'
                                   % (self._tolerance, result.iterations, result.relative_change))
        return result.noise

    def _lanczos_mobility(self):
        """The package mobility object whose ``noise`` (Lanczos by default) takes the grand matvec."""
        return self._mobility


# ------------------------------------------------------------------ the direct products
def _direct_mobility(geometry, eta, radius):
    """The first backend of the registry's preference order that serves ``geometry`` and runs here."""
    reasons = []
    for backend in registered_backends(geometry):
        try:
            return make_mobility(backend, geometry, eta, radius)
        except UserInputError as err:
            reasons.append(str(err))
    raise LibMobilityError('[libMobility] no mobility backend runs geometry %s here: %s'
                           % (geometry.kind, '; '.join(reasons)))


def _interface_product(mobility, positions, forces, torques, include_angular):
    """(U (n, 3), W (n, 3) or None) of a package mobility object at ``positions`` (n, 3)."""
    F = None if forces is None else forces.reshape(-1)
    T = None if torques is None else torques.reshape(-1)
    n = positions.shape[0]
    if not include_angular:
        return mobility.velocities(positions, F).reshape(n, 3), None
    if F is None and T is None:
        F = np.zeros(3 * n)
    U, W = mobility.product(positions, F, T)
    return U.reshape(n, 3), W.reshape(n, 3)


class SelfMobility(_Solver):
    """No hydrodynamic interactions: ``U = F / (6 pi eta a)``, ``W = T / (8 pi eta a^3)``.

    ``SelfMobility("open", "open", "open")`` only.  ``setParameters(parameter)`` takes one number that is
    ignored (libMobility's form).  The two mobilities are the self terms of the package's free-space
    Rotne-Prager-Yamakawa product (one blob alone), so they follow its formula.  Mdot needs no positions
    (N from the inputs); the noise is exact (``prefactor * sqrt(mobility) * z`` per component); divM is zero.
    """
    _solver_name = 'SelfMobility'
    _needs_positions = False

    def _check_periodicity(self, x, y, z):
        if (x, y, z) != ('open', 'open', 'open'):
            raise LibMobilityError('[SelfMobility] This is an open boundary solver: use ("open", "open", "open"), '
                                   'got (%r, %r, %r)' % (x, y, z))

    def setParameters(self, parameter):
        """libMobility's SelfMobility takes one number and ignores it; so does this one."""
        self._requested = {'parameter': float(parameter)}

    def _configure(self):
        alone = np.zeros((1, 3))
        self._mobility = _direct_mobility(Geometry('free_space'), self._eta, self._radius)
        unit = np.array([1.0, 0.0, 0.0])
        U, _ = self._mobility.product(alone, unit, None)
        _, W = self._mobility.product(alone, None, unit)
        self._translational = float(U[0])   # 1 / (6 pi eta a)
        self._rotational = float(W[0])      # 1 / (8 pi eta a^3)

    def _current_positions(self, values):
        if self._positions is not None:
            return self._positions
        return np.zeros((values.shape[0], 3))  # Mdot before setPositions is allowed: N from the inputs

    def _grand_product(self, positions, forces, torques):
        n = positions.shape[0]
        U = np.zeros((n, 3)) if forces is None else self._translational * forces
        if not self._include_angular:
            return U, None
        W = np.zeros((n, 3)) if torques is None else self._rotational * torques
        return U, W

    def _root(self, positions, z, prefactor):
        n = positions.shape[0]
        scale = np.full(z.size, np.sqrt(self._translational))
        scale[3 * n:] = np.sqrt(self._rotational)
        return prefactor * scale * z


_NBODY_ALGORITHMS = ('naive', 'block', 'fast', 'advise')
# batches of at most this many particles are applied as one stack of dense blocks (force-only products)
_DENSE_BATCH_SIZE = 32


class NBody(_Solver):
    """Direct sums of the blob mobility: free-space Rotne-Prager-Yamakawa or Rotne-Prager-Blake above a wall.

    ``NBody("open", "open", Z)`` with Z ``open`` or ``single_wall``.  The package's direct products through
    :mod:`mobility.interface` (the registry's first usable backend: ``C++``, else ``python``), with the wall
    at ``z = wallHeight`` (positions shifted by ``-wallHeight``), blobs overlapping each other or the wall
    regularised as in the package (Usabiaga et al. 2016, Sprinkle et al. 2017).  Prefactors
    ``1/(6 pi eta a)``, ``1/(8 pi eta a^2)``, ``1/(8 pi eta a^3)``.
    """
    _solver_name = 'NBody'

    def _check_periodicity(self, x, y, z):
        if x != 'open' or y != 'open':
            raise LibMobilityError('[NBody] NBody must be open in the plane: periodicityX and periodicityY "open", '
                                   'got (%r, %r)' % (x, y))
        if z not in ('open', 'single_wall'):
            raise LibMobilityError('[NBody] Invalid periodicity %r in z: NBody takes "open" or "single_wall"' % z)
        self._wall = z == 'single_wall'

    def _default_parameters(self):
        return {'algorithm': 'advise', 'Nbatch': -1, 'NperBatch': -1, 'wallHeight': None, 'delta': 1e-3,
                'set': False}

    def setParameters(self, algorithm='advise', Nbatch=-1, NperBatch=-1, wallHeight=None, delta=1e-3):
        """NBody's parameters (libMobility's keywords and defaults).

        algorithm : 'naive', 'block', 'fast' or 'advise' (GPU strategies in libMobility, the same numbers;
            here all give the package's direct product);
        Nbatch, NperBatch : independent batches of particles (``Nbatch * NperBatch`` must be N at setPositions;
            -1: one batch of all); particles of different batches do not interact;
        wallHeight : the wall plane ``z = wallHeight``; required with ``single_wall``, refused with ``open``;
        delta : the random-finite-difference step of divM in units of the hydrodynamic radius.
        """
        if algorithm not in _NBODY_ALGORITHMS:
            raise LibMobilityError('[NBody] Invalid algorithm %r; one of %s'
                                   % (algorithm, ', '.join(_NBODY_ALGORITHMS)))
        Nbatch, NperBatch = int(Nbatch), int(NperBatch)
        for value, name in ((Nbatch, 'Nbatch'), (NperBatch, 'NperBatch')):
            if value == 0 or value < -1:
                raise LibMobilityError('[NBody] %s must be a positive integer or -1 (automatic), got %d'
                                       % (name, value))
        if self._wall and wallHeight is None:
            raise LibMobilityError('[NBody] single_wall needs the wall position: setParameters(wallHeight=...)')
        if not self._wall and wallHeight is not None:
            raise LibMobilityError('[NBody] wallHeight is only valid with periodicityZ "single_wall" (this solver '
                                   'is open in z): leave wallHeight out')
        if wallHeight is not None:
            wallHeight = float(wallHeight)
            if not np.isfinite(wallHeight):
                raise LibMobilityError('[NBody] wallHeight must be finite, got %r' % wallHeight)
        self._requested = {'algorithm': algorithm, 'Nbatch': Nbatch, 'NperBatch': NperBatch,
                           'wallHeight': wallHeight, 'delta': self._positive(delta, 'delta'), 'set': True}

    def _configure(self):
        requested = self._requested
        if self._wall and requested['wallHeight'] is None:
            raise LibMobilityError('[NBody] single_wall needs the wall position: call setParameters(wallHeight=...) '
                                   'before initialize')
        self._wall_height = requested['wallHeight'] if self._wall else 0.0
        self._batches = (requested['Nbatch'], requested['NperBatch'])
        self._delta = requested['delta']
        self._mobility = _direct_mobility(Geometry('single_wall' if self._wall else 'free_space'), self._eta,
                                          self._radius)

    def _check_positions(self, positions):
        n = positions.shape[0]
        Nbatch, NperBatch = self._batches
        Nbatch = 1 if Nbatch < 0 else Nbatch            # libMobility's defaults: one batch of all particles
        NperBatch = n if NperBatch < 0 else NperBatch
        if Nbatch * NperBatch != n:
            raise LibMobilityError('[NBody] Invalid batch parameters for NBody: Nbatch * NperBatch = %d x %d must '
                                   'equal the number of particles %d. If in doubt, use the defaults.'
                                   % (Nbatch, NperBatch, n))
        self._batch_size = NperBatch
        if self._wall and n:
            lowest = int(np.argmin(positions[:, 2]))
            if positions[lowest, 2] < self._wall_height:
                raise LibMobilityError('[NBody] Particle %d has fallen below the wall: z = %.17g < wallHeight = %.17g'
                                       % (lowest, positions[lowest, 2], self._wall_height))

    def _grand_product(self, positions, forces, torques):
        shifted = positions - np.array([0.0, 0.0, self._wall_height])
        n = positions.shape[0]
        size = self._batch_size
        if size == n:
            return _interface_product(self._mobility, shifted, forces, torques, self._include_angular)
        if (not self._include_angular and forces is not None and size <= _DENSE_BATCH_SIZE
                and self._mobility.backend in registered_backends(dense_matrices=True)):
            # many small batches: the dense blocks of every batch at once, one stacked matrix-vector product
            stack = self._mobility.dense_matrix(shifted.reshape(n // size, size, 3))
            return np.einsum('bij,bj->bi', stack, forces.reshape(n // size, 3 * size)).reshape(n, 3), None
        U = np.empty((n, 3))
        W = np.empty((n, 3)) if self._include_angular else None
        for start in range(0, n, size):
            part = slice(start, start + size)
            u, w = _interface_product(self._mobility, shifted[part], None if forces is None else forces[part],
                                      None if torques is None else torques[part], self._include_angular)
            U[part] = u
            if W is not None:
                W[part] = w
        return U, W

    def _drift(self, positions, prefactor):
        n = positions.shape[0]
        if not self._wall or prefactor == 0.0:
            return _Solver._drift(self, positions, prefactor)
        return _rfd_drift(self, positions, prefactor, self._delta * self._radius)


def _rfd_drift(solver, positions, prefactor, step):
    """One random-finite-difference sample of ``prefactor * div M`` (libMobility's form).

    W ~ N(0, I) of length 3N from the solver's drift stream; ``(prefactor / step) [M(q + step/2 W) W -
    M(q - step/2 W) W]`` with forces-only products (the angular part is the rotation-from-force block's
    difference).  The stored positions are not touched.  Returns (N, 3) and (N, 3) or None.
    """
    n = positions.shape[0]
    W = solver._drift_rng.standard_normal((n, 3))
    plus_U, plus_W = solver._grand_product(positions + 0.5 * step * W, W, None)
    minus_U, minus_W = solver._grand_product(positions - 0.5 * step * W, W, None)
    scale = prefactor / step
    linear = scale * (plus_U - minus_U)
    angular = None if plus_W is None else scale * (plus_W - minus_W)
    return linear, angular


# ------------------------------------------------------------------ the spectral product
_DP_GEOMETRY = {'open': 'doubly_periodic_open', 'single_wall': 'doubly_periodic_wall',
                'two_walls': 'doubly_periodic_slit', 'periodic': 'triply_periodic'}
_DP_KIND = {'open': 'DP', 'single_wall': 'DPBW', 'two_walls': 'DPSC', 'periodic': 'TP'}
PARAMETER_SELECTIONS = ('libmobility', 'dpstokes')
# libMobility's open-z check: |sum_i F_ic| / sum_i (|F_ix| + |F_iy| + |F_iz|) above this is refused
NET_FORCE_TOLERANCE = 1e-6


class DPStokes(_Solver):
    """The spectral (force-coupling) product, periodic in x and y (``mobility.spectral``).

    ``DPStokes("periodic", "periodic", Z)``, Z ``open``, ``single_wall`` (wall at zmin), ``two_walls`` (walls
    at zmin and zmax), or ``periodic`` (triply periodic; this package's extension, with
    ``parameter_selection="dpstokes"``).  By default libMobility's own grid and kernel selection and UAMMD's
    discretisation rules (``mobility.spectral.libmobility_parameters``, ``mobility.spectral.uammd``), which
    give libMobility's numbers; ``parameter_selection="dpstokes"`` takes the DoublyPeriodicStokes CPU code's
    selection (``mobility.spectral.dpstokes_parameters``) with the kernel named by ``kernel``.  Through the
    package's mobility interface (backend ``spectral``).
    """
    _solver_name = 'DPStokes'

    def _check_periodicity(self, x, y, z):
        if x != 'periodic' or y != 'periodic' or z not in _DP_GEOMETRY:
            raise LibMobilityError("[DPStokes] This is a doubly periodic solver: periodicityX and periodicityY must be "
                                   "'periodic' and periodicityZ one of 'open', 'single_wall', 'two_walls' (or "
                                   "'periodic', this package's triply periodic extension), got (%r, %r, %r)"
                                   % (x, y, z))
        self._z_mode = z

    def _default_parameters(self):
        return None

    def setParameters(self, Lx, Ly, zmin, zmax, allowChangingBoxSize=False, delta=1e-3, allowUnsafeForces=False,
                      parameter_selection='libmobility', kernel=None):
        """DPStokes' parameters (libMobility's keywords and defaults, and two extension keywords).

        Lx, Ly : the periods (lengths); zmin, zmax : the z extent (walls at zmin, and zmax with two_walls; the
            heights of the blobs with open z; the z period zmax - zmin with ``periodic``);
        allowChangingBoxSize : whether Lx, Ly may change to fit the grid (libMobility's selection: whole
            numbers of its nominal cell; DoublyPeriodicStokes' selection: Ly, and the TP z period, enlarged to
            whole cells, a length already whole up to round-off unchanged);
        delta : random-finite-difference step of divM in units of the hydrodynamic radius;
        allowUnsafeForces : skip the open-z (and triply periodic) net-force check;
        parameter_selection : 'libmobility' (default: libMobility's grid, kernel and discretisation, its
            numbers) or 'dpstokes' (the DoublyPeriodicStokes CPU code's grid and kernel tables);
        kernel : with 'dpstokes' only: 'w6' (default), 'w5', 'w4' force only; 'w6', 'w5', 'w6w5', 'w6w4',
            'w5w4' with includeAngular (monopole, then dipole width).
        """
        values = {}
        for name, value in (('Lx', Lx), ('Ly', Ly), ('zmin', zmin), ('zmax', zmax)):
            try:
                values[name] = float(value)
            except (TypeError, ValueError):
                raise LibMobilityError('[DPStokes] %s must be a number, got %r' % (name, value)) from None
            if not np.isfinite(values[name]):
                raise LibMobilityError('[DPStokes] %s must be finite, got %r' % (name, value))
        if values['Lx'] <= 0 or values['Ly'] <= 0:
            raise LibMobilityError('[DPStokes] Lx and Ly must be positive, got %g and %g'
                                   % (values['Lx'], values['Ly']))
        if not values['zmax'] > values['zmin']:
            raise LibMobilityError('[DPStokes] zmax (%g) must exceed zmin (%g)' % (values['zmax'], values['zmin']))
        if parameter_selection not in PARAMETER_SELECTIONS:
            raise LibMobilityError('[DPStokes] parameter_selection must be one of %s, got %r'
                                   % (', '.join(PARAMETER_SELECTIONS), parameter_selection))
        if parameter_selection == 'libmobility':
            if kernel is not None:
                raise LibMobilityError("[DPStokes] kernel= goes with parameter_selection='dpstokes'; libMobility's "
                                       'selection takes w = 4 force-only and w = 6 with includeAngular')
            if self._z_mode == 'periodic':
                raise LibMobilityError("[DPStokes] This is a doubly periodic solver: periodicityZ 'periodic' (this "
                                       "package's triply periodic extension) needs parameter_selection='dpstokes'")
        values.update(allowChangingBoxSize=bool(allowChangingBoxSize), delta=self._positive(delta, 'delta'),
                      allowUnsafeForces=bool(allowUnsafeForces), parameter_selection=parameter_selection,
                      kernel='w6' if kernel is None else kernel)
        self._requested = values

    def _configure(self):
        from mobility.spectral import dpstokes_parameters
        from mobility.spectral.libmobility_parameters import libmobility_parameters
        requested = self._requested
        if requested is None:
            raise LibMobilityError('[DPStokes] call setParameters(Lx, Ly, zmin, zmax) before initialize')
        self._delta = requested['delta']
        self._allow_unsafe = requested['allowUnsafeForces']
        self._wall_bounds = (requested['zmin'], requested['zmax'])
        try:
            if requested['parameter_selection'] == 'libmobility':
                parameters, stored = libmobility_parameters(
                    self._radius, self._z_mode, requested['Lx'], requested['Ly'], requested['zmin'],
                    requested['zmax'], include_angular=self._include_angular,
                    allow_changing_box_size=requested['allowChangingBoxSize'])
                requested.update(stored)    # libMobility keeps these: a second initialize widens z again
            else:
                parameters = dpstokes_parameters(
                    self._radius, _DP_KIND[self._z_mode], requested['Lx'], requested['Ly'], requested['zmin'],
                    requested['zmax'], kernel=requested['kernel'], has_torque=self._include_angular,
                    whole_cells_tolerance=1e-9, warn=False)
                self._check_box_unchanged(parameters)
            kind = _DP_GEOMETRY[self._z_mode]
            if kind == 'triply_periodic':
                geometry = Geometry(kind, (parameters.Lx, parameters.Ly, parameters.Lz))
            else:
                geometry = Geometry(kind, (parameters.Lx, parameters.Ly, 0.0), z_bounds=self._wall_bounds)
            self._mobility = make_mobility('spectral', geometry, self._eta, self._radius, parameters=parameters)
        except LibMobilityError:
            raise
        except UserInputError as err:
            raise LibMobilityError(_dpstokes_message(err)) from None
        self.parameters = parameters

    def _check_box_unchanged(self, parameters):
        """With allowChangingBoxSize False the DoublyPeriodicStokes selection must keep the lengths."""
        requested = self._requested
        if requested['allowChangingBoxSize']:
            return
        changes = [('Ly', requested['Ly'], parameters.Ly)]
        if self._z_mode == 'periodic':
            changes.append(('zmax - zmin', requested['zmax'] - requested['zmin'], parameters.Lz))
        for name, asked, used in changes:
            if abs(used - asked) > 1e-12 * asked:
                raise LibMobilityError("[DPStokes] parameter_selection='dpstokes' makes %s a whole number of cells "
                                       "(h = %.17g): %.17g instead of %.17g; pass allowChangingBoxSize=True or that "
                                       'length' % (name, parameters.hx, used, asked))

    def _check_positions(self, positions):
        from mobility.spectral.product import check_positions
        zmin, zmax = self._wall_bounds
        z = positions[:, 2]
        if self._z_mode in ('single_wall', 'two_walls'):
            below = np.flatnonzero(z < zmin)
            if below.size:
                raise LibMobilityError('[DPStokes] A particle has passed through a wall: particle %d at z = %.17g is '
                                       'below the bottom wall at zmin = %.17g' % (below[0], z[below[0]], zmin))
        if self._z_mode == 'two_walls':
            above = np.flatnonzero(z > zmax)
            if above.size:
                raise LibMobilityError('[DPStokes] A particle has passed through a wall: particle %d at z = %.17g is '
                                       'above the top wall at zmax = %.17g' % (above[0], z[above[0]], zmax))
        if positions.shape[0]:
            try:
                check_positions(self.parameters, positions)
            except UserInputError as err:
                raise LibMobilityError(_dpstokes_message(err)) from None

    def _check_net(self, values, what):
        """libMobility's open-z check: each component's net sum against the total magnitude."""
        if values is None or self._allow_unsafe or self._z_mode not in ('open', 'periodic'):
            return
        total = np.sum(np.abs(values))
        if total == 0:
            return
        net = np.abs(values.sum(axis=0)) / total
        if np.any(net > NET_FORCE_TOLERANCE):
            raise LibMobilityError('[DPStokes] The %s on the particles must add up to zero with periodicityZ %r (net '
                                   '%s / total = %.3g > %g: %s); pass allowUnsafeForces=True in setParameters to '
                                   'compute anyway' % (what, self._z_mode, what, float(net.max()), NET_FORCE_TOLERANCE,
                                                       'the k = 0 mode is dropped' if self._z_mode == 'open'
                                                       else 'the mean is dropped'))

    def _grand_product(self, positions, forces, torques):
        self._check_net(forces, 'forces')
        self._check_net(torques, 'torques')
        try:
            return _interface_product(self._mobility, positions, forces, torques, self._include_angular)
        except LibMobilityError:
            raise
        except UserInputError as err:
            raise LibMobilityError(_dpstokes_message(err)) from None

    def _drift(self, positions, prefactor):
        if prefactor == 0.0:
            return _Solver._drift(self, positions, prefactor)
        return _rfd_drift(self, positions, prefactor, self._delta * self._radius)


def _dpstokes_message(err):
    text = str(err)
    return text if text.startswith('[DPStokes]') else '[DPStokes] ' + text
