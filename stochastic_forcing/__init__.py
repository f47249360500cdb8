"""Brownian noise: ``M^{1/2} z`` (Lanczos, Cholesky, symmetric eigen roots) and random finite differences."""
from .stochastic_forcing import (LANCZOS_MAX_ITERATIONS, LanczosResult, cholesky_root,  # noqa: F401
                                 displace_positions, lanczos_square_root, rfd, symmetric_root,
                                 symmetric_root_matrix)
