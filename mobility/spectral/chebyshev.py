"""Chebyshev tools of the doubly periodic solves: transforms between node values and coefficients, the
integration ("Chebyshev integral") discretisation of the two-point boundary-value problems, and their
solution vectorised over wavenumbers (NumPy; the compiled path uses the same matrices and bands).

Conventions.  Nodes ``z_k = (Lz/2)(1 + cos(pi k/(N-1)))``, k = 0..N-1 (top first), ``xi = 2z/Lz - 1``;
a function is ``f(z_k) = sum_j c_j cos(pi j k/(N-1)) = sum_j c_j T_j(xi_k)``; ``H = Lz/2``.

The boundary-value problem ``(D^2 - K^2) u = r`` on [0, Lz] with Robin conditions
``u' + K u = beta_top`` at z = Lz and ``u' - K u = beta_bottom`` at z = 0 is discretised as in
Greengard's spectral integration method (SIAM J. Numer. Anal. 28, 1071, 1991), the form used by
Hashemi et al. (J. Chem. Phys. 158, 154101, 2023): the unknowns are the coefficients ``a`` of ``u''`` and
two integration constants ``(c0, d0)``; the coefficients of u and of u' are ``S x`` and ``F x`` with
``x = (a, c0, d0)``, ``S = H^2 S1``, ``F = H F1``.  The N equation rows ``a - K^2 S x = r`` couple only
coefficients of one parity (tridiagonal in each parity) plus the two constants in rows 0 and 1; the two
boundary rows are dense.  They are solved by elimination of the two tridiagonal chains (diagonally
dominant once row 0 is used, no pivoting needed) and a 2 x 2 Schur complement for (c0, d0): O(N) per
wavenumber.

Array namespace: ``ChebyshevSystem(N, Lz, xp)`` keeps its matrices in ``xp`` (numpy by default, or cupy for
the GPU product, ``mobility.spectral.array_product``), and its methods work on arrays of that namespace; the
transforms use scipy's DCT on NumPy arrays and the matrices ``forward`` and ``backward`` otherwise.
"""
import numpy as np


def integration_matrices(N):
    """``(S1, F1)``, each (N, N + 2): unscaled Chebyshev coefficients of u (S1) and u' (F1) from
    ``x = (a, c0, d0)``, a the coefficients of u''."""
    S1 = np.zeros((N, N + 2))
    F1 = np.zeros((N, N + 2))
    F1[1, 0] = 1.0
    for j in range(2, N):
        F1[j, j - 1] = 1.0 / (2 * j)
    F1[1, 2] = -0.5
    for j in range(2, N - 1):
        F1[j, j + 1] = -1.0 / (2 * j)
    F1[0, N + 1] = 1.0
    S1[2, 0] = 0.25
    for j in range(3, N):
        S1[j, j - 2] = 1.0 / (4 * j * (j - 1))
    S1[1, 1] = -1.0 / 8
    S1[2, 2] = -1.0 / 8 - 1.0 / 24
    for j in range(3, N - 1):
        S1[j, j] = -1.0 / (4 * j * (j - 1)) - 1.0 / (4 * j * (j + 1))
    S1[N - 1, N - 1] = -1.0 / (4 * (N - 1) * (N - 2))
    S1[1, 3] = 1.0 / 8
    S1[2, 4] = 1.0 / 24
    for j in range(3, N - 2):
        S1[j, j + 2] = 1.0 / (4 * j * (j + 1))
    S1[0, N] = 1.0
    S1[1, N + 1] = 1.0
    return S1, F1


class ChebyshevSystem:
    """The matrices of the boundary-value problems on an N-point Chebyshev grid of height Lz.

    Attributes: N, H = Lz/2; S1, F1 (N, N+2); boundary rows R2, L2 (value at top, minus value at bottom, of
    S1 x) and R1, L1 (derivative rows of F1 x), each (N+2,); the bands of S1 on its first N columns:
    ``s_diag[j] = S1[j, j]``, ``s_low[j] = S1[j, j-2]``, ``s_up[j] = S1[j, j+2]`` (zero where absent);
    ``forward`` (N, N) and ``backward`` (N, N): node values -> coefficients and back.
    xp : the array namespace of the matrices and of the arrays the methods take (numpy, or cupy).
    """

    ARRAYS = ('S1', 'F1', 'R2', 'L2', 'R1', 'L1', 's_diag', 's_low', 's_up', 'backward', 'forward')

    def __init__(self, N, Lz, xp=np):
        self.xp = xp
        self.N = N
        self.H = Lz / 2.0
        S1, F1 = integration_matrices(N)
        self.S1, self.F1 = S1, F1
        alternating = (-1.0) ** np.arange(N)
        self.R2 = S1.sum(axis=0)
        self.L2 = -(alternating @ S1)
        self.R1 = F1.sum(axis=0)
        self.L1 = alternating @ F1
        j = np.arange(N)
        self.s_diag = S1[j, j].copy()
        self.s_low = np.zeros(N)
        self.s_low[2:] = S1[j[2:], j[2:] - 2]
        self.s_up = np.zeros(N)
        self.s_up[:N - 2] = S1[j[:N - 2], j[:N - 2] + 2]
        # transforms as matrices (the compiled solve applies them per block of wavenumbers)
        jk = np.outer(j, j) % (2 * (N - 1))
        cosines = np.cos(np.pi * jk / (N - 1))
        self.backward = cosines.copy()                       # f_k = sum_j c_j cos(pi j k/(N-1))
        ends = np.ones(N)
        ends[0] = ends[-1] = 0.5
        self.forward = 2.0 * (ends[:, None] * cosines * ends[None, :]) / (N - 1)
        self.host = {name: getattr(self, name) for name in self.ARRAYS}   # NumPy copies (small constants)
        if xp is not np:
            for name in self.ARRAYS:
                setattr(self, name, xp.asarray(getattr(self, name)))

    # -------------------------------------------------------------- transforms along axis 0
    def to_coefficients(self, values):
        """Chebyshev coefficients (axis 0) from node values (axis 0), by the DCT-I (NumPy) or the matrix."""
        if self.xp is not np:
            return self.xp.tensordot(self.forward, values, axes=(1, 0))
        from scipy import fft
        c = fft.dct(values, type=1, axis=0) / (2 * (self.N - 1))
        c[1:-1] *= 2.0
        return c

    def to_values(self, coefficients):
        """Node values (axis 0) from Chebyshev coefficients (axis 0), by the DCT-I (NumPy) or the matrix."""
        if self.xp is not np:
            return self.xp.tensordot(self.backward, coefficients, axes=(1, 0))
        from scipy import fft
        c = np.array(coefficients, copy=True)
        c[1:-1] *= 0.5
        return fft.dct(c, type=1, axis=0)

    def derivative(self, c):
        """Coefficients of d/dz from coefficients ``c`` (axis 0) by the Chebyshev recurrence."""
        N, H = self.N, self.H
        d = self.xp.zeros_like(c)
        d[N - 2] = 2 * (N - 1) * c[N - 1] / H
        for j in range(N - 2, 0, -1):
            d[j - 1] = d[j + 1] + 2 * j * c[j] / H
        d[0] = d[0] / 2
        return d

    # -------------------------------------------------------------- the solve
    def factor(self, K):
        """Elimination of the two tridiagonal chains of ``I - K^2 H^2 S1[:, :N]`` for wavenumbers K (nk,).

        Returns ``(pivot, multiplier, upper, q)``, each (N, nk) but q (nk,) = K^2 H^2.
        """
        N = self.N
        q = (K * self.H) ** 2
        diag = 1.0 - q[None, :] * self.s_diag[:, None]
        low = -q[None, :] * self.s_low[:, None]
        upper = -q[None, :] * self.s_up[:, None]
        pivot = self.xp.empty_like(diag)
        multiplier = self.xp.zeros_like(diag)
        pivot[:2] = diag[:2]
        for j in range(2, N):
            multiplier[j] = low[j] / pivot[j - 2]
            pivot[j] = diag[j] - multiplier[j] * upper[j - 2]
        return pivot, multiplier, upper, q

    @staticmethod
    def chain_solve(factors, r):
        """Solve ``(I - K^2 H^2 S1[:, :N]) a = r`` for r (N, nk) with the :meth:`factor` output."""
        pivot, multiplier, upper, _ = factors
        N = r.shape[0]
        y = r.astype(np.result_type(r.dtype, pivot.dtype), copy=True)
        for j in range(2, N):
            y[j] -= multiplier[j] * y[j - 2]
        y[N - 1] /= pivot[N - 1]
        y[N - 2] /= pivot[N - 2]
        for j in range(N - 3, -1, -1):
            y[j] = (y[j] - upper[j] * y[j + 2]) / pivot[j]
        return y

    def solve(self, K, factors, rhs, top, bottom):
        """Solve the Robin BVPs ``(D^2 - K^2) u = r``, ``u' + K u = top`` at z = Lz, ``u' - K u = bottom``
        at z = 0 for wavenumbers K (nk,) > 0; rhs (N, nk) coefficients, top and bottom (nk,).

        Returns ``x = (a, c0, d0)`` as (N + 2, nk): coefficients of u are ``H^2 S1 x``, of u' ``H F1 x``.
        """
        N, H = self.N, self.H
        q = factors[3]
        c_top = (H * H) * K[None, :] * self.R2[:, None] + H * self.R1[:, None]
        c_bottom = (H * H) * K[None, :] * self.L2[:, None] + H * self.L1[:, None]
        e0 = self.xp.zeros((N, K.size))
        e0[0] = 1.0
        e1 = self.xp.zeros((N, K.size))
        e1[1] = 1.0
        z0 = self.chain_solve(factors, e0)
        z1 = self.chain_solve(factors, e1)
        a_r = self.chain_solve(factors, rhs)
        g_t0 = q * (c_top[:N] * z0).sum(axis=0) + c_top[N]
        g_t1 = q * (c_top[:N] * z1).sum(axis=0) + c_top[N + 1]
        g_b0 = q * (c_bottom[:N] * z0).sum(axis=0) + c_bottom[N]
        g_b1 = q * (c_bottom[:N] * z1).sum(axis=0) + c_bottom[N + 1]
        r_t = top - (c_top[:N] * a_r).sum(axis=0)
        r_b = bottom - (c_bottom[:N] * a_r).sum(axis=0)
        det = g_t0 * g_b1 - g_t1 * g_b0
        c0 = (r_t * g_b1 - g_t1 * r_b) / det
        d0 = (g_t0 * r_b - g_b0 * r_t) / det
        x = self.xp.empty((N + 2, K.size), dtype=a_r.dtype)
        x[:N] = a_r + q * (c0 * z0 + d0 * z1)
        x[N] = c0
        x[N + 1] = d0
        return x

    def values_of(self, x):
        """Coefficients of u (N, nk) from x = (a, c0, d0) (N+2, nk)."""
        return (self.H * self.H) * (self.S1 @ x)

    def derivatives_of(self, x):
        """Coefficients of u' (N, nk) from x."""
        return self.H * (self.F1 @ x)

    def mean_flow(self, rhs, geometry):
        """The k = 0 problem ``u'' = rhs`` with u = 0 at the bottom wall and, above it, u' = 0 at the top
        (DPBW) or u = 0 at the top wall (DPSC); rhs (N, m) coefficients.  Returns the coefficients of u."""
        N, xp = self.N, self.xp
        top = self.R1 if geometry == 'DPBW' else self.R2
        bottom = self.L2
        host_top, host_bottom = self.host['R1' if geometry == 'DPBW' else 'R2'], self.host['L2']
        a = rhs
        matrix = np.array([[host_top[N], host_top[N + 1]], [host_bottom[N], host_bottom[N + 1]]])
        right = -xp.stack([top[:N] @ a, bottom[:N] @ a])
        constants = xp.linalg.solve(xp.asarray(matrix), right.reshape(2, -1)).reshape((2,) + a.shape[1:])
        x = xp.concatenate([a, constants], axis=0)
        return self.values_of(x)
