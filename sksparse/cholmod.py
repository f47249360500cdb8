"""``sksparse.cholmod.cholesky`` of a sparse symmetric positive definite matrix, over SciPy (a face: see
``sksparse/__init__.py``; the package never imports it).

``cholesky(A, beta=0)`` factors ``A + beta I`` as ``P (A + beta I) P^T = L L^T`` with a fill-reducing permutation
``P``: the package's sparse LDL^T ``L_u D L_u^T`` without pivoting (:mod:`lubrication.sparse_factor`, minimum-degree
ordering; scalar blocks) where its extension is built, else SuperLU's symmetric minimum-degree ordering of
``A^T + A`` without pivoting (the LU factors are then ``L_u D L_u^T``); ``L = L_u D^(1/2)``.  The :class:`Factor`
answers the calls of scikit-sparse's factor that the published codes use: ``factor(b)`` and ``solve_A(b)`` solve
``(A + beta I) x = b`` for b of shape (n,) or (n, k); ``L()`` (n, n) sparse lower triangular, ``P()`` (n,) the
permutation as an index array (``A[P][:, P] = L L^T``), ``apply_P``, ``apply_Pt``, ``logdet()``;
``cholesky_inplace(A, beta)`` refactors.  A matrix that is not positive definite raises
:class:`CholmodNotPositiveDefiniteError`.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from lubrication import sparse_factor


class CholmodError(Exception):
    """A matrix this face cannot factor (not square, not symmetric)."""


class CholmodNotPositiveDefiniteError(CholmodError):
    """The matrix is not positive definite (a pivot of the factorisation is not positive)."""


class Factor:
    """``P (A + beta I) P^T = L L^T`` of one matrix (see the module docstring)."""

    def __init__(self, A, beta=0.0):
        self.cholesky_inplace(A, beta)

    def cholesky_inplace(self, A, beta=0.0):
        """Factor ``A + beta I`` (A sparse or dense, (n, n), symmetric positive definite) in this object."""
        A = sp.csc_matrix(A, dtype=float)
        if A.shape[0] != A.shape[1]:
            raise CholmodError('cholesky needs a square matrix, got shape %s' % (A.shape,))
        if beta:
            A = (A + beta * sp.identity(A.shape[0], format='csc')).tocsc()
        if A.nnz and abs(A - A.T).max() > 1e-12 * abs(A).max():
            raise CholmodError('cholesky needs a symmetric matrix')
        if sparse_factor.available():
            return self._block_ldlt(A)
        lu = spla.splu(A, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0, options={'SymmetricMode': True})
        if not np.array_equal(lu.perm_r, lu.perm_c):  # a pivot left the diagonal: not positive definite
            raise CholmodNotPositiveDefiniteError('the matrix is not positive definite (pivoting was needed)')
        pivots = lu.U.diagonal()
        if np.any(~(pivots > 0)):
            raise CholmodNotPositiveDefiniteError('the matrix is not positive definite (pivot %d is %g)'
                                                  % (int(np.argmax(~(pivots > 0))), pivots[~(pivots > 0)][0]))
        self._solve, self._n = lu.solve, A.shape[0]
        self._P = np.argsort(lu.perm_c)
        self._L = (lu.L @ sp.diags(np.sqrt(pivots))).tocsc()
        self._logdet = float(np.sum(np.log(pivots)))
        return self

    def _block_ldlt(self, A):
        """The factorisation of the symmetric ``A`` (already shifted) by :func:`lubrication.sparse_factor.factorise`."""
        try:
            factor = sparse_factor.factorise(A, block=1, method='block_ldlt')
        except sparse_factor.FactorisationError as error:
            raise CholmodNotPositiveDefiniteError('the matrix is not positive definite (%s)' % error) from None
        perm, unit_lower, pivots = factor.factors()
        if not factor.positive_definite:
            raise CholmodNotPositiveDefiniteError('the matrix is not positive definite (pivot %g)' % pivots.min())
        self._solve, self._n = factor.solve, A.shape[0]
        self._P = np.asarray(perm, dtype=np.int64)
        self._L = (unit_lower @ sp.diags(np.sqrt(pivots))).tocsc()
        self._logdet = float(np.sum(np.log(pivots)))
        return self

    def __call__(self, b):
        return self.solve_A(b)

    def solve_A(self, b):
        """``x`` with ``(A + beta I) x = b``; b of shape (n,) or (n, k), dense or sparse (then a dense answer)."""
        b = b.toarray() if sp.issparse(b) else np.asarray(b, dtype=float)
        return self._solve(b)

    def L(self):
        """The lower triangular factor, sparse (n, n): ``A[P][:, P] = L L^T``."""
        return self._L

    def P(self):
        """The fill-reducing permutation (n,) int."""
        return self._P.copy()

    def apply_P(self, b):
        """``b[P]`` (rows permuted)."""
        return np.asarray(b)[self._P]

    def apply_Pt(self, b):
        """The inverse of :meth:`apply_P`."""
        out = np.empty_like(np.asarray(b))
        out[self._P] = b
        return out

    def logdet(self):
        """``log det(A + beta I)``."""
        return self._logdet


def cholesky(A, beta=0.0, mode='auto', ordering_method='default', use_long=None):
    """The :class:`Factor` of ``A + beta I`` (``mode``, ``ordering_method``, ``use_long``: accepted and unused)."""
    return Factor(A, beta)
