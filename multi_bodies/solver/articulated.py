"""Articulated rigid bodies: rigid bodies linked by joints (Balboa Usabiaga and Delmotte, JCP 464, 111365, 2022).

An articulated body is a set of rigid bodies (one ``.list_vertex`` file
names their vertex files) whose joints (one ``.const`` file) make the
material points at each joint move together.  Joint ``c`` links bodies
``p`` and ``q``; ``l_p``, ``l_q`` (body frames, length units) go from each
body's location to the joint, so the joint holds when

    g_c = q_p + R_p l_p - q_q - R_q l_q = 0          (3 per joint).

Its time derivative is the linear velocity constraint ``C U = B`` on the
body velocities ``U = [v, w]`` (Nb, 6):

    C_c U = v_p + w_p x a_p - v_q - w_q x a_q,   a = R l (lab frame),
    B_c   = -(R_p dl_p/dt - R_q dl_q/dt),

with Lagrange multipliers ``phi`` (3 per joint, force units) whose forces
``C^T phi`` (force ``phi`` and torque ``a_p x phi`` on ``p``, the opposite
on ``q``) enter the force balance of the bodies.  The mobility problem of
:mod:`multi_bodies.solver.body_solver` gains the constraint rows::

    [ M    -K     0  ] [lambda]   [ slip ]
    [-K^T   0   -C^T ] [  U   ] = [ -F   ]
    [ 0    -C     0  ] [ phi  ]   [ -B   ]

solved by one preconditioned GMRES (``body_solver.gmres_solve``).  The
preconditioner is the block-diagonal body preconditioner plus the exact
(pseudo-)inverse of the small constraint Schur complement ``C N C^T`` of
each articulated body (``N`` the bodies' block-diagonal mobilities).

Time-dependent joints (active constraints): a ``.const`` line may give 12
expressions of the time ``t`` after its 8 numbers: ``l_p(t)`` (3),
``l_q(t)`` (3) and their time derivatives (6), all in the body frames.
They are evaluated by a small safe evaluator (numbers, ``t``, ``pi``,
``+ - * / **`` and ``sin cos tan exp log sqrt abs arcsin arccos arctan
sinh cosh tanh``), the subset of numexpr the published files use.

After each update the positions are restored (:meth:`ArticulatedSet.restore`):
the bodies' locations are solved from their orientations (least squares on the
joint equations, ``pinv`` of the connectivity), shifted so that each
articulated body's geometric centre (mean of its bodies' locations) is the
one advanced with the mean linear velocity, then a nonlinear least-squares
correction of locations and orientations brings the joint residuals below
``nonlinear_solver_tolerance`` (as the published code does).
"""
import ast
import math
import os
from collections import namedtuple

import numpy as np
import scipy.optimize as scop
import scipy.sparse as scsp

from body.body import as_configuration
from body.geometry import rotation_matrices
from multi_bodies.solver import articulated_preconditioner
from multi_bodies.solver.body_solver import SolutionParts
from multi_bodies.solver.linear_map import FunctionMap, LinearMap, LinearProblem
from multi_bodies.files.expressions import parse_expression
from utils import SimulationStopped, UserInputError, read_text_file

# ---------------------------------------------------------------------------------------------- files
_FUNCTIONS = {name: getattr(np, name) for name in ('sin', 'cos', 'tan', 'exp', 'log', 'sqrt', 'abs', 'arcsin',
                                                     'arccos', 'arctan', 'sinh', 'cosh', 'tanh')}
_CONSTANTS = {'pi': math.pi, 'e': math.e}
_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}


def compile_expression(text, where):
    """A function ``f(t) -> float`` of the expression ``text`` in ``t`` (the safe subset, see module doc)."""
    tree = parse_expression(text, where)  # size and depth limited: one line, never a RecursionError

    def build(node):
        if isinstance(node, ast.Expression):
            return build(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            value = float(node.value)
            return lambda t: value
        if isinstance(node, ast.Name):
            if node.id == 't':
                return lambda t: t
            if node.id in _CONSTANTS:
                value = _CONSTANTS[node.id]
                return lambda t: value
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            inner = build(node.operand)
            return (lambda t: -inner(t)) if isinstance(node.op, ast.USub) else inner
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            left, right, op = build(node.left), build(node.right), _BINARY[type(node.op)]
            return lambda t: op(left(t), right(t))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS \
                and len(node.args) == 1 and not node.keywords:
            function, inner = _FUNCTIONS[node.func.id], build(node.args[0])
            return lambda t: function(inner(t))
        raise UserInputError("%s: the expression '%s' uses '%s', which is not allowed; use numbers, t, pi, "
                             "+ - * / ** and %s" % (where, text, ast.unparse(node) if hasattr(ast, 'unparse')
                                                    else type(node).__name__, ', '.join(sorted(_FUNCTIONS))))
    evaluate = build(tree)

    def expression(t):
        with np.errstate(all='ignore'):  # overflow and division give inf or NaN, which the caller names
            return float(np.float64(evaluate(np.float64(t))))
    expression.text, expression.where = text, where
    return expression


def non_finite_expression(function, t, error):
    """Raise ``error`` (UserInputError at set-up, SimulationStopped during a run) naming the file, line and
    expression when ``function`` (of :func:`compile_expression`) is not a finite number of magnitude at most
    ``LARGEST_LINK`` at time ``t`` (as the eight numbers of a joint: a larger one overflows the joint algebra)."""
    value = function(t)
    if not (math.isfinite(value) and abs(value) <= LARGEST_LINK):
        raise error("%s: the expression '%s' is %r at t = %r, not a finite number of magnitude at most %g (a joint "
                    "vector or its rate must be one at every time of the run); fix the expression"
                    % (function.where, function.text, value, float(t), LARGEST_LINK))


Restored = namedtuple('Restored', ['configuration', 'nonlinear_iterations'])
Restored.__doc__ = """Result of :meth:`ArticulatedSet.restore`: the Configuration with the joints restored and the
residual evaluations of its nonlinear correction (the published ``nonlinear_iterations_count`` adds them)."""

ConstFile = namedtuple('ConstFile', ['num_bodies', 'bodies', 'links', 'expressions', 'path', 'extras'],
                       defaults=(None,))
ConstFile.__doc__ = """A ``.const`` file: ``num_bodies``; ``bodies`` (Nc, 2) int (p, q); ``links`` (Nc, 6) the
body-frame vectors ``[l_p, l_q]`` (length units); ``expressions``: per joint None (passive) or 12 functions of t
(``l_p, l_q, dl_p/dt, dl_q/dt``); ``path``."""


def _text_lines(path, what):
    """Lines of the UTF-8 file ``path`` (one-line UserInputError for other bytes, as every text file)."""
    return read_text_file(path, what, 'give the path relative to the run directory').splitlines()


def read_list_vertex_file(path, where):
    """The vertex file names of a ``.list_vertex`` file (one per line, ``#`` comments), as written."""
    if not os.path.isfile(path):
        raise UserInputError('%s: the list_vertex file %s does not exist; give the path relative to the run '
                             'directory' % (where, path))
    names = [line.split('#', 1)[0].strip() for line in _text_lines(path, 'list_vertex file')]
    names = [n for n in names if n]
    if not names:
        raise UserInputError('%s: the list_vertex file %s names no vertex file; write one vertex file per line'
                             % (where, path))
    return names


LARGEST_LINK = 1e150  # as every number of a structure file: its square still fits in a double


def read_const_file(path, where):
    """Read a ``.const`` file (manual section 4.3) into :data:`ConstFile`; bad content is a UserInputError."""
    if not os.path.isfile(path):
        raise UserInputError('%s: the const file %s does not exist; give the path relative to the run directory'
                             % (where, path))
    lines = [(k, line.split('#', 1)[0].split()) for k, line in enumerate(_text_lines(path, 'const file'), start=1)]
    lines = [(k, words) for k, words in lines if words]
    try:
        num_bodies, num_constraints = int(lines[0][1][0]), int(lines[1][1][0])
    except (IndexError, ValueError):
        raise UserInputError('%s: %s must start with the number of bodies and the number of constraints, one per '
                             'line' % (where, path))
    if len(lines) - 2 != num_constraints:
        raise UserInputError('%s: %s announces %d constraints but has %d constraint lines'
                             % (where, path, num_constraints, len(lines) - 2))
    bodies = np.zeros((num_constraints, 2), dtype=int)
    links = np.zeros((num_constraints, 6))
    expressions, extras = [], []
    for c, (number, words) in enumerate(lines[2:]):
        at = '%s, line %d' % (path, number)
        if len(words) < 8:
            raise UserInputError('%s: a constraint line has 8 numbers (body_p body_q l_p l_q), optionally followed '
                                 'by 12 expressions of t (l_p l_q dl_p/dt dl_q/dt); got %d fields'
                                 % (at, len(words)))
        try:
            bodies[c] = [int(words[0]), int(words[1])]
            links[c] = [float(w) for w in words[2:8]]
        except ValueError:
            raise UserInputError('%s: the first 8 fields must be two body indices and six numbers' % at)
        if not np.all(np.abs(links[c]) <= LARGEST_LINK):  # also NaN and inf
            raise UserInputError('%s: a joint vector component is not a finite number of magnitude at most %g; fix '
                                 'the value' % (at, LARGEST_LINK))
        if np.any(bodies[c] < 0) or np.any(bodies[c] >= num_bodies):
            raise UserInputError('%s: body indices must be between 0 and %d' % (at, num_bodies - 1))
        if bodies[c, 0] == bodies[c, 1]:
            raise UserInputError('%s: a joint of body %d with itself (body_p and body_q are the same); a joint links '
                                 'two different bodies of the articulated body (a rigid body cannot satisfy a joint '
                                 'between two of its own points): fix the body indices' % (at, bodies[c, 0]))
        # other extra fields are the published constraint_extra of a user's Constraint.update_links override
        # (checked by :meth:`ArticulatedSet.check_extras` once the overrides are known)
        expressions.append([compile_expression(w, at) for w in words[8:]] if len(words) == 20 else None)
        for function in expressions[-1] or ():
            non_finite_expression(function, 0.0, UserInputError)  # at the start of the run
        extras.append((tuple(words[8:]), at) if len(words) not in (8, 20) else None)
    return ConstFile(num_bodies, bodies, links, expressions, path, extras)


# ---------------------------------------------------------------------------------------------- geometry
def _cross(a, b):
    return np.cross(a, b)


def quaternion_rotation(theta):
    """Rotation matrices (n, 3, 3) of (not necessarily unit) scalar-first quaternions theta (n, 4)."""
    s, p = theta[:, 0], theta[:, 1:]
    R = 2.0 * (p[:, :, None] * p[:, None, :])
    diag = 2.0 * s ** 2 - 1.0
    R[:, 0, 0] += diag
    R[:, 1, 1] += diag
    R[:, 2, 2] += diag
    R[:, 0, 1] -= 2 * s * p[:, 2]
    R[:, 1, 0] += 2 * s * p[:, 2]
    R[:, 0, 2] += 2 * s * p[:, 1]
    R[:, 2, 0] -= 2 * s * p[:, 1]
    R[:, 1, 2] -= 2 * s * p[:, 0]
    R[:, 2, 1] += 2 * s * p[:, 0]
    return R


def rotated_vector_jacobian(theta, a):
    """d(R(theta) a)/d theta, shape (n, 3, 4), for quaternions theta (n, 4) (scalar first) and vectors a (n, 3).

    Each entry is evaluated term by term in the published code's order: the joint restoration's least-squares
    path depends on the Jacobian's last bit (see ``_nonlinear_correction``)."""
    t0, t1, t2, t3 = theta[:, 0], theta[:, 1], theta[:, 2], theta[:, 3]
    l0, l1, l2 = a[:, 0], a[:, 1], a[:, 2]
    J = np.empty((theta.shape[0], 3, 4))
    J[:, 0, 0] = 2 * l2 * t2 - 2 * l1 * t3 + 4 * l0 * t0
    J[:, 1, 0] = -2 * l2 * t1 + 2 * l0 * t3 + 4 * l1 * t0
    J[:, 2, 0] = 2 * l1 * t1 - 2 * l0 * t2 + 4 * l2 * t0
    J[:, 0, 1] = 4 * l0 * t1 + 2 * l1 * t2 + 2 * l2 * t3
    J[:, 1, 1] = 2 * l0 * t2 - 2 * l2 * t0
    J[:, 2, 1] = 2 * l0 * t3 + 2 * l1 * t0
    J[:, 0, 2] = 2 * l1 * t1 + 2 * l2 * t0
    J[:, 1, 2] = 2 * l0 * t1 + 4 * l1 * t2 + 2 * l2 * t3
    J[:, 2, 2] = 2 * l1 * t3 - 2 * l0 * t0
    J[:, 0, 3] = 2 * l2 * t1 - 2 * l1 * t0
    J[:, 1, 3] = 2 * l2 * t2 + 2 * l0 * t0
    J[:, 2, 3] = 2 * l0 * t1 + 2 * l1 * t2 + 4 * l2 * t3
    return J


class ArticulatedBody:
    """One articulated body: its bodies ``body_indices`` (global, consecutive) and joints (global indices)."""

    def __init__(self, body_indices, constraint_indices, local_bodies):
        self.body_indices = np.asarray(body_indices, dtype=int)
        self.constraint_indices = np.asarray(constraint_indices, dtype=int)
        self.local_bodies = np.asarray(local_bodies, dtype=int).reshape(-1, 2)
        nb, nc = self.body_indices.size, self.constraint_indices.size
        A = np.zeros((3 * nc, 3 * nb))
        for c, (p, q) in enumerate(self.local_bodies):
            A[3 * c:3 * c + 3, 3 * p:3 * p + 3] += np.eye(3)
            A[3 * c:3 * c + 3, 3 * q:3 * q + 3] -= np.eye(3)
        self.A = A
        self.A_pinv = np.linalg.pinv(A)


class ArticulatedSet:
    """Every joint of a run and the articulated bodies they form.

    Attributes: ``bodies`` (Nc, 2) global body indices (p, q); ``reference_links`` (Nc, 6); ``groups`` list of
    :class:`ArticulatedBody`; ``num_constraints``; ``names`` per group (input IDs).  Built once at set-up
    (:meth:`add`); nothing here changes during a run (the residual evaluations of the nonlinear correction
    are returned by :meth:`restore`).
    """

    def __init__(self):
        self.bodies = np.zeros((0, 2), dtype=int)
        self.reference_links = np.zeros((0, 6))
        self.expressions = []
        self.extras = []  # per constraint: (fields, where) of a published constraint_extra, or None
        self.groups = []
        self.link_override = None  # callable (t, links (Nc, 6)) -> (links, rates) or None (user hook)
        # callable (t, links (Nc, 6)) -> links, or None: the links the joints hold at the positions (the restoration
        # and the residuals), when a user's published-style Articulated.update_links gives them apart from the solve's
        self.position_link_override = None
        self.step_event = None  # callable (t) called at the start of every step, or None (published tumbling_event)

    @property
    def num_constraints(self):
        return self.bodies.shape[0]

    def check_extras(self):
        """Refuse extra ``.const`` fields that no user ``Constraint.update_links`` reads (the published faces)."""
        if self.link_override is None:
            for extra in self.extras:
                if extra is not None:
                    raise UserInputError(
                        '%s: a constraint line has 8 numbers (body_p body_q l_p l_q), optionally followed by 12 '
                        'expressions of t (l_p l_q dl_p/dt dl_q/dt); got %d fields (other extra fields are read '
                        'only by a Constraint.update_links of user_defined_functions.py)' % (extra[1], 8 + len(extra[0])))

    def add(self, const, first_body, num_copies):
        """Add ``num_copies`` articulated bodies of the :data:`ConstFile` ``const`` from global body ``first_body``."""
        n = const.num_bodies
        for k in range(num_copies):
            start = first_body + k * n
            c0 = self.num_constraints
            self.bodies = np.concatenate((self.bodies, const.bodies + start))
            self.reference_links = np.concatenate((self.reference_links, const.links))
            self.expressions.extend(const.expressions)
            self.extras.extend(const.extras if const.extras is not None else [None] * len(const.expressions))
            self.groups.append(ArticulatedBody(np.arange(start, start + n), np.arange(c0, self.num_constraints),
                                               const.bodies))

    # -------------------------------------------------------------- links
    def links(self, t, positions=False):
        """Body-frame links (Nc, 6) and their time derivatives (Nc, 6) at time ``t``.

        ``positions``: the links the joints hold at the positions (restoration, residuals) rather than those of
        the velocity solve; they differ only under a user's ``Articulated.update_links`` (the published code
        restores the joints with it and solves with ``Constraint.update_links``); the rates are the solve's."""
        links = self.reference_links.copy()
        rates = np.zeros_like(links)
        for c, functions in enumerate(self.expressions):
            if functions is not None:
                values = [f(t) for f in functions]
                if not np.all(np.abs(values) <= LARGEST_LINK):  # also NaN and inf
                    for function in functions:
                        non_finite_expression(function, t, SimulationStopped)
                links[c], rates[c] = values[:6], values[6:]
        if positions and self.position_link_override is not None:
            return self.position_link_override(t, links), rates
        if self.link_override is not None:
            links, rates = self.link_override(t, links, rates)
        return links, rates

    def lab_links(self, configuration, t, positions=False):
        """(a (Nc, 6) lab-frame links ``[R_p l_p, R_q l_q]``, b (Nc, 6) lab-frame rates) at ``configuration``
        (``positions``: see :meth:`links`)."""
        links, rates = self.links(t, positions)
        R = rotation_matrices(as_configuration(configuration).orientations)
        Rp, Rq = R[self.bodies[:, 0]], R[self.bodies[:, 1]]
        a = np.concatenate((np.einsum('kij,kj->ki', Rp, links[:, :3]), np.einsum('kij,kj->ki', Rq, links[:, 3:])),
                           axis=1)
        b = np.concatenate((np.einsum('kij,kj->ki', Rp, rates[:, :3]), np.einsum('kij,kj->ki', Rq, rates[:, 3:])),
                           axis=1)
        return a, b

    def violation(self, configuration, t):
        """Joint residuals ``g = q_p + R_p l_p - q_q - R_q l_q``, shape (Nc, 3) (length units)."""
        configuration = as_configuration(configuration)
        a, _ = self.lab_links(configuration, t, positions=True)
        q = configuration.locations
        return q[self.bodies[:, 0]] + a[:, :3] - q[self.bodies[:, 1]] - a[:, 3:]

    # -------------------------------------------------------------- the linear constraint
    def C_dot(self, a, velocities):
        """``C U`` (Nc, 3) for lab links ``a`` (Nc, 6) and body velocities (Nb, 6)."""
        U = np.asarray(velocities, dtype=float).reshape(-1, 6)
        p, q = self.bodies[:, 0], self.bodies[:, 1]
        return U[p, :3] + _cross(U[p, 3:], a[:, :3]) - U[q, :3] - _cross(U[q, 3:], a[:, 3:])

    def CT_dot(self, a, phi, num_bodies):
        """``C^T phi``: force-torque (Nb, 6) of joint multipliers phi (Nc, 3)."""
        phi = np.asarray(phi, dtype=float).reshape(-1, 3)
        out = np.zeros((num_bodies, 6))
        p, q = self.bodies[:, 0], self.bodies[:, 1]
        np.add.at(out[:, :3], p, phi)
        np.add.at(out[:, 3:], p, _cross(a[:, :3], phi))
        np.add.at(out[:, :3], q, -phi)
        np.add.at(out[:, 3:], q, -_cross(a[:, 3:], phi))
        return out

    def B(self, rates_lab):
        """Right-hand side ``B = -(R_p dl_p - R_q dl_q)`` (Nc, 3) of ``C U = B``."""
        return -(rates_lab[:, :3] - rates_lab[:, 3:])

    def C_dense_group(self, group, a):
        """Dense ``C`` of one articulated body, shape (3 nc, 6 nb) (local body order)."""
        nb, nc = group.body_indices.size, group.constraint_indices.size
        C = np.zeros((3 * nc, 6 * nb))
        for c, (p, q) in zip(range(nc), group.local_bodies):
            ap, aq = a[group.constraint_indices[c], :3], a[group.constraint_indices[c], 3:]
            C[3 * c:3 * c + 3, 6 * p:6 * p + 3] += np.eye(3)
            C[3 * c:3 * c + 3, 6 * p + 3:6 * p + 6] -= _skew(ap)
            C[3 * c:3 * c + 3, 6 * q:6 * q + 3] -= np.eye(3)
            C[3 * c:3 * c + 3, 6 * q + 3:6 * q + 6] += _skew(aq)
        return C

    # -------------------------------------------------------------- positions
    def centres(self, configuration):
        """Geometric centre (mean of the bodies' locations) of every articulated body, (n_groups, 3)."""
        q = as_configuration(configuration).locations
        return np.array([q[g.body_indices].mean(axis=0) for g in self.groups]).reshape(-1, 3)

    def mean_velocities(self, velocities):
        """Mean linear velocity of the bodies of every articulated body, (n_groups, 3)."""
        U = np.asarray(velocities, dtype=float).reshape(-1, 6)
        return np.array([U[g.body_indices, :3].mean(axis=0) for g in self.groups]).reshape(-1, 3)

    def restore(self, configuration, centres, t, tolerance, verbose=False):
        """Joints restored at time ``t``: :data:`Restored` (a new Configuration, see module docstring).

        centres (n_groups, 3): the geometric centres to keep; tolerance: ``nonlinear_solver_tolerance``
        (length units) on :func:`joint_residual_norm` of each articulated body.
        """
        from body.body import Configuration
        configuration = as_configuration(configuration)
        locations, orientations = configuration.copy_arrays()
        a, _ = self.lab_links(configuration, t, positions=True)
        for group, centre in zip(self.groups, centres):
            ac = a[group.constraint_indices]
            relative = (group.A_pinv @ (-(ac[:, :3] - ac[:, 3:])).reshape(-1)).reshape(-1, 3)
            locations[group.body_indices] = relative + centre - relative.mean(axis=0)
        new = Configuration(locations, orientations)
        a, _ = self.lab_links(new, t, positions=True)
        g_all = self.violation(new, t)
        evaluations = 0
        for group in self.groups:
            evaluations += self._nonlinear_correction(group, locations, orientations, a[group.constraint_indices],
                                                      g_all[group.constraint_indices], tolerance, verbose)
        return Restored(Configuration(locations, orientations), evaluations)

    def _nonlinear_correction(self, group, locations, orientations, a, g, tolerance, verbose):
        """Least-squares correction of one articulated body (in place on locations, orientations).

        Returns the number of residual evaluations (0 when the joints already hold to ``tolerance``).  The
        tolerance check and the bounds of the unknowns use :func:`joint_residual_norm` of ``g`` (nc, 3)."""
        if group.constraint_indices.size == 0:
            return 0
        g_inf = joint_residual_norm(g)
        if g_inf < tolerance:
            return 0
        nb = group.body_indices.size
        pairs = group.local_bodies
        q = locations[group.body_indices].copy()
        counter = [0]

        def residual(x):
            counter[0] += 1
            dq, theta = x[:3 * nb], x[3 * nb:].reshape(nb, 4)
            R = quaternion_rotation(theta)
            g_new = (group.A @ dq).reshape(-1, 3) + np.einsum('kij,kj->ki', R[pairs[:, 0]], a[:, :3]) \
                - np.einsum('kij,kj->ki', R[pairs[:, 1]], a[:, 3:]) + (q[pairs[:, 0]] - q[pairs[:, 1]])
            # |theta|^2 - 1 as the published norm squared, not a sum of squares: the dogbox path (and the point of
            # the solution set it stops at, 1.6e-5 apart after a bacterium's step) depends on that round-off
            return np.concatenate((g_new.reshape(-1), np.linalg.norm(theta, axis=1) ** 2 - 1))

        def jacobian(x):
            theta = x[3 * nb:].reshape(nb, 4)
            nc = pairs.shape[0]
            J = np.zeros((3 * nc + nb, 7 * nb))
            J[:3 * nc, :3 * nb] = group.A
            Jp = rotated_vector_jacobian(theta[pairs[:, 0]], a[:, :3])
            Jq = rotated_vector_jacobian(theta[pairs[:, 1]], a[:, 3:])
            for c, (p, qq) in enumerate(pairs):
                J[3 * c:3 * c + 3, 3 * nb + 4 * p:3 * nb + 4 * p + 4] += Jp[c]
                J[3 * c:3 * c + 3, 3 * nb + 4 * qq:3 * nb + 4 * qq + 4] -= Jq[c]
            rows = 3 * nc + np.arange(nb)
            for j in range(4):
                J[rows, 3 * nb + 4 * np.arange(nb) + j] = 2 * theta[:, j]
            return scsp.csr_matrix(J)

        x0 = np.zeros(7 * nb)
        x0[3 * nb::4] = 1.0
        bound = np.sqrt(nb) * g_inf
        low, high = -np.ones(x0.size) * bound, np.ones(x0.size) * bound
        low[3 * nb::4], high[3 * nb::4] = -1 - bound, 1 + bound
        result = scop.least_squares(residual, x0, jac=jacobian, bounds=(low, high), method='dogbox',
                                    ftol=tolerance, xtol=tolerance * 1e-3, gtol=None, x_scale='jac',
                                    max_nfev=x0.size, verbose=2 if verbose else 0)
        x = result.x
        dq = x[:3 * nb].reshape(nb, 3)
        dq = dq - dq.mean(axis=0)
        theta = x[3 * nb:].reshape(nb, 4)
        theta = theta / np.linalg.norm(theta, axis=1)[:, None]
        from body.geometry import quaternion_products
        locations[group.body_indices] += dq
        orientations[group.body_indices] = quaternion_products(theta, orientations[group.body_indices])
        return counter[0]


def joint_residual_norm(g):
    """The published size of the joint residuals ``g`` (nc, 3): ``np.linalg.norm(g, ord=np.inf)`` of the
    (nc, 3) matrix, i.e. the largest over joints of ``|g_x| + |g_y| + |g_z|`` (not the largest component).

    It decides whether the nonlinear correction runs (``>= nonlinear_solver_tolerance``) and sets the bounds of
    its unknowns (``sqrt(n_bodies)`` times it).  The bounds steer the dogbox iterations, and with a hinge (two
    joints on one axis) the spin about the axis is free in the least-squares problem, so its value decides the
    spin that the correction adds: with the largest component instead, the published constant-torque bacterium
    differs by 4e-6 per step (the flagellum's spin), with this norm by 4e-15.
    """
    g = np.asarray(g, dtype=float).reshape(-1, 3)
    return float(np.max(np.sum(np.abs(g), axis=1))) if g.size else 0.0


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# ---------------------------------------------------------------------------------------------- the solve
# Singular values of an articulated body's C below this fraction of the largest are redundant joint directions:
# two joints on one hinge axis give a sixth one of the size of the axes' misalignment (the joints hold to
# nonlinear_solver_tolerance, not exactly), which would make the solve ill-conditioned.
RANK_RCOND = 1e-6
class ArticulatedProblem(LinearProblem):
    """The mobility problem with joints at one configuration (unknowns ``[lambda (3N), U (6Nb), psi]``).

    Reuses the products of a ``body_solver.MobilityProblem`` (``M_dot``, ``K_dot``, ``KT_dot``) and adds the
    rows of ``C U = B``.  Redundant joints (three joints locking two bodies, two joints on one hinge axis) make
    rows of ``C`` dependent and the saddle-point system singular; so, per articulated body, ``C`` is replaced by
    ``Q^T C`` with ``Q`` (3 nc, r) an orthonormal basis of its range (SVD, ``r`` its rank to ``RANK_RCOND``), and
    ``B`` by
    ``Q^T B``: the same velocities, a nonsingular system, reduced multipliers ``psi`` (r per articulated body)
    and joint forces ``phi = Q psi`` (the least-norm ones).

    Attributes: ``problem``, ``articulated``, ``a`` (Nc, 6) lab links, ``rates``, ``reduced`` (per articulated
    body: (Q (3nc, r), Q^T C (r, 6nb))), ``num_multipliers``, ``size``, ``operator``.
    """

    def __init__(self, problem, articulated, configuration, t):
        self.problem, self.articulated, self.t = problem, articulated, float(t)
        self.a, self.rates = articulated.lab_links(configuration, t)
        self.num_blobs, self.num_bodies = problem.num_blobs, problem.num_bodies
        self.num_constraints = articulated.num_constraints
        # Bodies whose blobs cannot resist every rigid motion (a single blob, blobs on a line) have no velocity
        # along the null space of their K (the pinv answer of body_solver): C acts on the projected velocities.
        self.projectors = None
        ranges = problem._range_projectors()
        if ranges:
            self.projectors = np.broadcast_to(np.eye(6), (self.num_bodies, 6, 6)).copy()
            for bodies, P in ranges:
                self.projectors[bodies] = P
        self.reduced, self.offsets = [], [0]
        for group in articulated.groups:
            C = articulated.C_dense_group(group, self.a)
            if self.projectors is not None:
                P = np.zeros((C.shape[1], C.shape[1]))
                for k, body in enumerate(group.body_indices):
                    P[6 * k:6 * k + 6, 6 * k:6 * k + 6] = self.projectors[body]
                C = C @ P
            if C.size == 0:
                Q = np.zeros((C.shape[0], 0))
            else:
                left, singular, _ = np.linalg.svd(C, full_matrices=False)
                rank = int(np.sum(singular > RANK_RCOND * max(singular[0], 1e-300)))
                Q = left[:, :rank]
            self.reduced.append((Q, Q.T @ C))
            self.offsets.append(self.offsets[-1] + Q.shape[1])
        self.num_multipliers = self.offsets[-1]
        self.size = 3 * self.num_blobs + 6 * self.num_bodies + self.num_multipliers

    def split(self, x):
        n3, n6 = 3 * self.num_blobs, 3 * self.num_blobs + 6 * self.num_bodies
        return x[:n3], x[n3:n6], x[n6:]

    def prepare_rhs(self, rhs):
        """The right-hand side as :meth:`rhs` made it (its force part is projected there)."""
        return rhs

    def solution(self, x):
        """``[lambda; U; psi]`` split: SolutionParts(lambda (N, 3), U (Nb, 6) projected, joint forces (Nc, 3))."""
        lam, U, psi = self.split(x)
        return SolutionParts(lam.reshape(-1, 3), self.project_velocities(U), self.joint_forces(psi))

    def C_dot(self, velocities):
        """``Q^T C U`` (num_multipliers,) of body velocities (Nb, 6)."""
        U = np.asarray(velocities, dtype=float).reshape(-1, 6)
        out = np.empty(self.num_multipliers)
        for group, (_, QC), start, stop in zip(self.articulated.groups, self.reduced, self.offsets[:-1],
                                                 self.offsets[1:]):
            out[start:stop] = QC @ U[group.body_indices].reshape(-1)
        return out

    def CT_dot(self, psi):
        """``C^T Q psi``: force-torque (Nb, 6) of reduced multipliers psi (num_multipliers,)."""
        out = np.zeros((self.num_bodies, 6))
        for group, (_, QC), start, stop in zip(self.articulated.groups, self.reduced, self.offsets[:-1],
                                                 self.offsets[1:]):
            out[group.body_indices] += (QC.T @ psi[start:stop]).reshape(-1, 6)
        return out

    def joint_forces(self, psi):
        """Joint multipliers ``phi = Q psi``, shape (Nc, 3)."""
        phi = np.zeros((self.num_constraints, 3))
        for group, (Q, _), start, stop in zip(self.articulated.groups, self.reduced, self.offsets[:-1],
                                                self.offsets[1:]):
            phi[group.constraint_indices] = (Q @ psi[start:stop]).reshape(-1, 3)
        return phi

    def matvec(self, x):
        lam, U, psi = self.split(np.asarray(x, dtype=float).reshape(-1))
        first = self.problem.matvec(np.concatenate((lam, U)))
        n3 = 3 * self.num_blobs
        first[n3:] -= self.CT_dot(psi).reshape(-1)
        return np.concatenate((first, -self.C_dot(U)))

    def rhs(self, slip, force_torque):
        """``[slip; -F; -Q^T B]`` with ``B`` the prescribed joint velocities at this problem's time."""
        B = self.articulated.B(self.rates)
        reduced_B = np.empty(self.num_multipliers)
        for group, (Q, _), start, stop in zip(self.articulated.groups, self.reduced, self.offsets[:-1],
                                                self.offsets[1:]):
            reduced_B[start:stop] = Q.T @ B[group.constraint_indices].reshape(-1)
        force_torque = None if force_torque is None else self.problem.project_forces(force_torque)
        return np.concatenate((self.problem.rhs(slip=slip, force_torque=force_torque), -reduced_B))

    def project_velocities(self, velocities):
        """Velocities (Nb, 6) without their part along the null space of each body's K (unchanged if full rank)."""
        U = np.asarray(velocities, dtype=float).reshape(-1, 6)
        if self.projectors is None:
            return U
        return np.matmul(self.projectors, U[:, :, None])[:, :, 0]


class ArticulatedPreconditioner(LinearMap):
    """Block-diagonal body preconditioner plus the exact constraint Schur complement of each articulated body.

    For ``[s; f; b]``: ``(lambda0, U0) = P_body [s; f]``; per articulated body
    ``psi = (C N C^T)^{-1} (b + C U0)`` (``C`` the reduced ``Q^T C``, ``N`` the bodies' block-diagonal
    mobilities); then ``(lambda, U) = (lambda0, U0) + P_body [0; C^T psi]``.  This is the exact inverse when
    the bodies do not interact hydrodynamically.
    """

    def __init__(self, problem, body_preconditioner):
        self.problem, self.body = problem, body_preconditioner
        mobilities = np.zeros((problem.num_bodies, 6, 6))
        block_diagonal = body_preconditioner  # the neighbour and corotated preconditioners hold theirs as .base
        while not hasattr(block_diagonal, 'body_mobilities') and hasattr(block_diagonal, 'base'):
            block_diagonal = block_diagonal.base
        for (bodies, _), N in zip(block_diagonal.body_arrays.type_slices, block_diagonal.body_mobilities):
            mobilities[bodies] = N
        self.schur = []
        for group, (_, QC) in zip(problem.articulated.groups, problem.reduced):
            N = np.zeros((QC.shape[1], QC.shape[1]))
            for k, body in enumerate(group.body_indices):
                N[6 * k:6 * k + 6, 6 * k:6 * k + 6] = mobilities[body]
            self.schur.append(np.linalg.pinv(QC @ N @ QC.T, rcond=1e-12, hermitian=True))
        self.size = problem.size

    def apply(self, x):
        problem = self.problem
        lam, U, b = problem.split(np.asarray(x, dtype=float).reshape(-1))
        first = self.body.apply(np.concatenate((lam, U)))
        n3 = 3 * problem.num_blobs
        residual = b + problem.C_dot(first[n3:])
        psi = np.empty(problem.num_multipliers)
        for S, start, stop in zip(self.schur, problem.offsets[:-1], problem.offsets[1:]):
            psi[start:stop] = S @ residual[start:stop]
        correction = self.body.apply(np.concatenate((np.zeros(n3), problem.CT_dot(psi).reshape(-1))))
        return np.concatenate((first + correction, psi))


# ---------------------------------------------------------------------------------------------- single blobs
def roller_mobility_product(system, r_vectors):
    """``[v; w] = M6 [F; T]`` of single-blob bodies at blob positions (N, 3): a function of (N, 6) -> (N, 6)
    (the grand product of the model's ``roller_mobility``)."""
    roller = system.roller_mobility
    for kind in ('rot_times_force', 'rot_times_torque'):  # refused now (domain in_plane), not in the solve
        roller.check_coupling(kind)

    def apply(force_torque):
        ft = np.asarray(force_torque, dtype=float).reshape(-1, 6)
        F, T = ft[:, :3].reshape(-1).copy(), ft[:, 3:].reshape(-1).copy()
        v, w = roller.product(r_vectors, F, T)
        return np.concatenate((v.reshape(-1, 3), w.reshape(-1, 3)), axis=1)
    return apply


class RollerJointProblem(LinearProblem):
    """Single-blob bodies with joints at one configuration and time: the constraint Schur complement.

    ``U = M6 (F + C^T phi)`` with ``C U = B`` gives ``C M6 C^T phi = B - C M6 F`` (unknowns phi, size 3Nc);
    ``M6`` is the roller mobility of the blobs (:func:`roller_mobility_product`).  Implements the problem
    protocol of ``body_solver.solve``; ``rhs()`` is ``B - C M6 F`` of the force-torque given at construction,
    ``solution(phi)`` the velocities ``U_free + M6 C^T phi`` and the joint forces.  The preconditioner
    (:meth:`preconditioner`) is the exact inverse of ``C D C^T`` per articulated body with ``D`` the self
    mobility (``1/(6 pi eta a)``, ``1/(8 pi eta a^3)``).
    """

    def __init__(self, model, articulated, configuration, t, force_torque):
        configuration = as_configuration(configuration)
        self.articulated = articulated
        self.M6 = roller_mobility_product(model, model.blob_positions(configuration))
        self.a, self.rates = articulated.lab_links(configuration, t)
        self.num_bodies, self.num_constraints = configuration.num_bodies, articulated.num_constraints
        self.eta, self.blob_radius = model.eta, model.blob_radius
        self.U_free = self.M6(force_torque)
        self.size = 3 * self.num_constraints

    def matvec(self, phi):
        articulated, a = self.articulated, self.a
        return articulated.C_dot(a, self.M6(articulated.CT_dot(a, phi, self.num_bodies))).reshape(-1)

    def rhs(self):
        """``B - C M6 F`` (3Nc,)."""
        return (self.articulated.B(self.rates) - self.articulated.C_dot(self.a, self.U_free)).reshape(-1)

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, phi):
        """SolutionParts(None, velocities (Nb, 6), joint forces (Nc, 3))."""
        velocities = self.U_free + self.M6(self.articulated.CT_dot(self.a, phi, self.num_bodies))
        return SolutionParts(None, velocities, np.asarray(phi).reshape(-1, 3))

    def preconditioner(self):
        """The exact inverse of ``C D C^T`` per articulated body, a LinearOperator of size 3Nc."""
        articulated, a = self.articulated, self.a
        D = np.diag([1 / (6 * np.pi * self.eta * self.blob_radius)] * 3
                    + [1 / (8 * np.pi * self.eta * self.blob_radius ** 3)] * 3)
        blocks = []
        for group in articulated.groups:
            C = articulated.C_dense_group(group, a)
            Dg = np.kron(np.eye(group.body_indices.size), D)
            blocks.append(np.linalg.pinv(C @ Dg @ C.T, rcond=1e-12, hermitian=True))

        def precondition(r):
            r = np.asarray(r).reshape(-1, 3)
            out = np.zeros_like(r)
            for group, S in zip(articulated.groups, blocks):
                out[group.constraint_indices] = (S @ r[group.constraint_indices].reshape(-1)).reshape(-1, 3)
            return out.reshape(-1)
        return FunctionMap(self.size, precondition)


def articulated_problem(model, articulated, configuration, t, force_torque=None, slip=None, single_blobs=False):
    """The problem of every body with the joints of ``articulated`` at ``configuration`` and time ``t``.

    force_torque (Nb, 6) and slip (N, 3): None for those of the model's hooks.  ``single_blobs``: the roller
    model (:class:`RollerJointProblem`), else the blob saddle-point problem (:class:`ArticulatedProblem`).
    Returns (problem, right-hand side, preconditioner) for the one solve (``body_solver.solve``).
    """
    if single_blobs:
        if force_torque is None:
            force_torque = model.forces_torques(configuration)
        problem = RollerJointProblem(model, articulated, configuration, t, force_torque)
        return problem, problem.rhs(), problem.preconditioner()
    if force_torque is None or slip is None:
        _, hooks_force_torque, hooks_slip = model.forces_and_slip(configuration)
        force_torque = hooks_force_torque if force_torque is None else force_torque
        slip = hooks_slip if slip is None else slip
    problem = ArticulatedProblem(model.mobility_problem(configuration), articulated, configuration, t)
    preconditioner = None  # every articulated body solved exactly as if alone, where it applies
    if not model.published_solves:
        preconditioner = articulated_preconditioner.build(problem, model, configuration)
    if preconditioner is None:  # the published one
        preconditioner = ArticulatedPreconditioner(problem, model.build_preconditioner(configuration))
    return problem, problem.rhs(slip, force_torque), preconditioner


def articulated_velocities(model, articulated, configuration, t, force_torque=None, slip=None, x0=None,
                           single_blobs=False, solver=None):
    """Velocities of every body with the joints of ``articulated`` at ``configuration`` and time ``t``.

    The problem of :func:`articulated_problem` solved by ``solver`` (a ``solves.Solver``, the one way into the
    package's one solve; None: ``model.solver()``, at ``solver_tolerance``, which raises SimulationStopped when
    GMRES does not converge), from the normalised first guess ``x0``.  Returns its ``body_solver.SolveResult``: ``velocities`` (Nb, 6), the joint forces (Nc, 3)
    in ``constraint_force_torque``, ``lambda_blobs`` (None for single blobs), ``iterations``.  Nothing is
    counted here.
    """
    problem, rhs, preconditioner = articulated_problem(model, articulated, configuration, t, force_torque, slip,
                                                       single_blobs)
    what = 'the articulated roller problem' if single_blobs else 'the articulated mobility problem'
    solver = model.solver() if solver is None else solver
    return solver.solve(problem, rhs, preconditioner, x0=x0, what=what)
