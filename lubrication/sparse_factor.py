"""Factorisations of the lubrication preconditioners' sparse symmetric matrices: ``A + s I`` solved many times.

The lubrication step factors ``R_sup + s I`` (6 x 6 blocks, one block row per sphere; the published preconditioner,
:class:`lubrication.problem.LubricationPreconditioner`) and ``Delta_R_tt + 6 pi eta a I`` (3 x 3 blocks; the torque
problem's, :func:`lubrication.integrators.torque_preconditioner`).  Both are symmetric positive definite.
:func:`factorise` gives ``x = (A + s I)^-1 b`` by

* ``'block_ldlt'`` (the default where built): the package's sparse block LDL^T, ``P (A + s I) P^T = L D L^T``
  (``lubrication/cpp/block_ldlt_module.cpp``): minimum-degree ordering on the graph of blocks, left-looking
  numeric factorisation without pivoting, dense B x B kernels (George and Liu, *Computer Solution of Large Sparse
  Positive Definite Systems*, 1981; Davis, *Direct Methods for Sparse Linear Systems*, SIAM 2006).  It factors only
  L, and its symbolic part (ordering, structure) is reused when the scalar pattern is unchanged: from the last
  factorisation of the same block size (kept here), or from the factor given to
  :meth:`SymmetricFactor.refactor` or ``factorise(..., previous=...)``;
* ``'superlu'``: SciPy's SuperLU in symmetric mode (``permc_spec='MMD_AT_PLUS_A'``, ``diag_pivot_thresh=0``): the
  fallback when the extension is not built, and the method of the package before the extension.

The two answers agree to round-off (different orderings, so not bit for bit).  Only the lower triangle (in the
block ordering chosen) is read by the block LDL^T: ``A`` must be symmetric, as the lubrication matrices are by
construction.  A zero or non-finite pivot raises :class:`FactorisationError` (a ValueError); a negative pivot is
allowed and flagged (``positive_definite`` False).
"""
import importlib

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # by importlib: the extension module is not a file of the package's import graph (tests/test_layout.py)
    _block_ldlt = importlib.import_module('._block_ldlt_cpp', __package__)
except ImportError:  # pragma: no cover - the extension was not built: SuperLU is used
    _block_ldlt = None

METHODS = ('block_ldlt', 'superlu')
_DEFAULT = ['block_ldlt' if _block_ldlt is not None else 'superlu']
# The last block LDL^T of each block size, whose symbolic part (ordering and structure: a function of the scalar
# pattern alone) the next factorisation reuses when its pattern is the same (the usual case from solve to solve and
# step to step).  A cache, not state: a factorisation with and without it is the same to the bit.
_LAST_BY_BLOCK = {}


class FactorisationError(ValueError):
    """A matrix that cannot be factored without pivoting (a zero or non-finite pivot, a non-finite entry)."""


def available():
    """True when the compiled block LDL^T ``lubrication._block_ldlt_cpp`` is built."""
    return _block_ldlt is not None


def default_method():
    """The method :func:`factorise` uses when none is named (``'block_ldlt'`` where built)."""
    return _DEFAULT[0]


def _checked(method):
    if method not in METHODS:
        raise ValueError('sparse factorisation %r is not one of %s' % (method, ', '.join(METHODS)))
    if method == 'block_ldlt' and not available():
        raise ValueError('the block LDL^T extension lubrication._block_ldlt_cpp is not built (python3 setup.py '
                         'build_ext --inplace)')
    return method


def forget_orderings():
    """Drop the kept symbolic parts (the next block LDL^T of each block size orders its pattern anew: benchmarks
    and tests)."""
    _LAST_BY_BLOCK.clear()


def use_method(method):
    """Make ``method`` ('block_ldlt' or 'superlu'; 'block_ldlt' only where built) the default; returns the previous
    default (benchmarks and the equality tests)."""
    previous = _DEFAULT[0]
    _DEFAULT[0] = _checked(method)
    return previous


class SymmetricFactor:
    """``(A + shift I)^-1`` of a sparse symmetric matrix ``A`` (n, n) made of ``block`` x ``block`` blocks.

    A : scipy sparse or dense (n, n), n a multiple of ``block``; shift : a number added to the diagonal;
    block : 6 (one block row per sphere: forces and torques) or 3 (translations), 1 or 2 also accepted;
    method : ``'block_ldlt'``, ``'superlu'`` or None (:func:`default_method`); previous : a SymmetricFactor whose
    symbolic part is reused when its block size and scalar pattern equal this one's (block LDL^T only).
    ``solve(b)`` for b (n,) or (n, k); ``positive_definite``; ``size``; ``method``; ``ordering_reused`` (the block
    LDL^T took its ordering from an earlier factorisation).
    """

    def __init__(self, A, shift=0.0, block=6, method=None, previous=None):
        self.method = _checked(default_method() if method is None else method)
        self.block = int(block)
        self._factor, self._lu = None, None
        self.refactor(A, shift, previous)

    def refactor(self, A, shift=0.0, previous=None):
        """Factor ``A + shift I`` in this object (same method and block size), reusing the symbolic part of
        ``previous`` (default: this object's own factor) when the scalar pattern is the same; returns self."""
        A = sp.csr_matrix(A, dtype=float)
        n = A.shape[0]
        if A.shape[0] != A.shape[1] or n % self.block:
            raise ValueError('factorise needs a square matrix of %d x %d blocks, got shape %s'
                             % (self.block, self.block, A.shape))
        self.size, self.shift = n, float(shift)
        if self.method == 'superlu':
            shifted = (A + self.shift * sp.identity(n, format='csr')).tocsc() if self.shift else A.tocsc()
            try:
                self._lu = spla.splu(shifted, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                                     options={'SymmetricMode': True}) if n else None
            except RuntimeError as error:  # SuperLU's 'Factor is exactly singular'
                raise FactorisationError('zero or non-finite pivot (SuperLU: %s): the matrix is singular or not '
                                         'symmetric positive definite' % error) from None
            pivots = self._lu.U.diagonal() if n else np.ones(0)
            if not np.all(np.isfinite(pivots)) or np.any(pivots == 0):
                raise FactorisationError('zero or non-finite pivot: the matrix is singular or not symmetric '
                                         'positive definite')
            self.ordering_reused = False
            self.positive_definite = bool(np.all(pivots > 0)) and (not n or np.array_equal(self._lu.perm_r,
                                                                                              self._lu.perm_c))
            return self
        kept = previous if previous is not None else self
        kept = kept._factor if isinstance(kept, SymmetricFactor) and kept.method == 'block_ldlt' else None
        if kept is None:
            kept = _LAST_BY_BLOCK.get(self.block)
        try:
            self._factor = _block_ldlt.factorise(A.indptr.astype(np.int64), A.indices.astype(np.int64), A.data, n,
                                                 self.block, self.shift, kept)
        except _block_ldlt.PivotError as error:
            raise FactorisationError(str(error)) from None
        _LAST_BY_BLOCK[self.block] = self._factor.ordering_only()  # no values: a kept ordering costs O(blocks of L)
        self.positive_definite = bool(self._factor.positive_definite)
        self.ordering_reused = bool(self._factor.ordering_reused)
        return self

    def solve(self, b):
        """``x`` with ``(A + shift I) x = b``; b (n,) or (n, k)."""
        b = np.asarray(b, dtype=float)
        if self.method == 'superlu':
            return self._lu.solve(b) if self.size else b.copy()
        return self._factor.solve(b)

    def factors(self):
        """Block LDL^T only: ``(perm (n,), L (n, n) sparse unit lower triangular, d (n,))`` with
        ``(A + shift I)[perm][:, perm] = L diag(d) L^T``."""
        if self.method != 'block_ldlt':
            raise ValueError('factors() is the block LDL^T one; this factor is %s' % self.method)
        perm, (data, indices, indptr), d = self._factor.factors()
        return perm, sp.csr_matrix((data, indices, indptr), shape=(self.size, self.size)), d

    @property
    def nonzero_blocks(self):
        """Block LDL^T only: the stored B x B blocks of L (diagonal ones included)."""
        return self._factor.nonzero_blocks if self._factor is not None else None


def factorise(A, shift=0.0, block=6, method=None, previous=None):
    """:class:`SymmetricFactor` of ``A + shift I`` (see there)."""
    return SymmetricFactor(A, shift, block, method, previous)
