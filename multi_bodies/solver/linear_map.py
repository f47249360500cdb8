"""The base of every square linear map the one solve takes: the problems' matrices and their preconditioners (floor 4).

``multi_bodies.solver.body_solver.solve`` runs GMRES on ``problem.operator`` preconditioned by
``preconditioner.operator``, SciPy ``LinearOperator`` objects.  Every problem and preconditioner of the package
makes its ``operator`` the same way, from this base:

* :class:`LinearMap` - ``size`` (int) and ``apply(x)``, ``(size,) -> (size,)`` (``matvec`` is it too, as a
  LinearOperator's); ``operator`` is ``apply`` as a ``LinearOperator`` of shape ``(size, size)``, made when it is
  asked for, so a copy of the object (``copy.copy``, as ``MobilityProblem.with_mobility`` makes) applies its own
  ``apply``;
* :class:`LinearProblem` - a problem of the protocol of the one solve (doc/adding_a_problem.md), whose matrix is its
  ``matvec(x)``;
* :class:`FunctionMap` - a map given by a function (the preconditioners built as closures).
"""
import scipy.sparse.linalg as spla


class LinearMap:
    """A square linear map: ``size`` and ``apply(x)`` (x (size,) -> (size,)); ``operator`` its LinearOperator."""

    def apply(self, x):
        raise NotImplementedError

    def matvec(self, x):
        return self.apply(x)

    @property
    def operator(self):
        """``apply`` as a ``scipy.sparse.linalg.LinearOperator`` of shape (size, size), float."""
        return spla.LinearOperator((self.size, self.size), matvec=self.apply, dtype=float)


class LinearProblem(LinearMap):
    """A problem of the one solve whose matrix ``A`` is ``matvec(x)`` (``apply`` is it)."""

    def matvec(self, x):
        raise NotImplementedError

    def apply(self, x):
        return self.matvec(x)


class FunctionMap(LinearMap):
    """The linear map ``function`` (x (size,) -> (size,)) of ``size`` unknowns."""

    def __init__(self, size, function):
        self.size = int(size)
        self.function = function

    def apply(self, x):
        return self.function(x)


class WrapsPreconditioner(LinearMap):
    """A preconditioner built on another (``self.base``, the block-diagonal one) that shares what the solves and
    the noise read of it, named rather than forwarded: where it was built (``configuration``) and the Lanczos
    factors ``L_dot``, ``L_inv_dot``, ``L_inv_T_dot`` (the base's block-diagonal Cholesky factors)."""

    @property
    def configuration(self):
        return self.base.configuration

    def L_dot(self, vector):
        return self.base.L_dot(vector)

    def L_inv_dot(self, vector):
        return self.base.L_inv_dot(vector)

    def L_inv_T_dot(self, vector):
        return self.base.L_inv_T_dot(vector)
