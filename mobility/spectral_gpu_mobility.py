"""The spectral product on an NVIDIA GPU: backend ``spectral_gpu`` of the mobility interface (CuPy).

    from mobility.interface import Geometry, make_mobility
    box = Geometry('doubly_periodic_wall', periodic_length=(64.0, 64.0, 0.0), z_bounds=(0.0, 10.0))
    mob = make_mobility('spectral_gpu', box, eta=1.0, blob_radius=1.0)     # as 'spectral', on the GPU
    U = mob.velocities(r_vectors, forces)

Everything of the ``spectral`` backend (``mobility.spectral_mobility.SpectralMobility``: geometries, kernels,
``rotation``, ``near_wall``, the Lanczos noise, ``dense_matrix``, the random-finite-difference drift) with the
products computed by :class:`mobility.spectral.array_product.ArrayStokes` in CuPy arrays: the kernel weights
made on the host and kept on the device, spreading and interpolation by raw CUDA kernels
(``mobility/cuda/spectral_grid_kernels.cu``), the transforms by ``cupy.fft``, the Chebyshev solves vectorised
over the wavenumbers.  The numbers are the CPU product's to round-off (1e-12 is tested where a GPU is lent).
Positions are NumPy arrays; forces and torques may be NumPy arrays (the results are then NumPy) or CuPy arrays
(the results stay on the device).  DoublyPeriodicStokes' rules only (``parameters`` with libMobility's UAMMD
rules are refused); ``path`` and ``workers`` of the CPU backend are accepted and ignored; the exact triply
periodic noise (``noise='fluctuating'``) is computed on the CPU.

CuPy is imported only when this backend is made or checked (``unusable_reason``), never by the package itself.
Floor 2 of the house (beside the interface).
"""
from utils import UserInputError

from .spectral_mobility import SpectralMobility

_REASON = []


def unusable_reason():
    """None when CuPy imports, a CUDA device is present and the kernels compile; else why not (a str)."""
    if not _REASON:
        try:
            import cupy
            if cupy.cuda.runtime.getDeviceCount() < 1:
                raise RuntimeError('no CUDA device found')
            from .spectral import cuda_kernels
            cuda_kernels.kernels()
            _REASON.append(None)
        except Exception as err:  # any failure means: not here (ImportError, CUDA driver or compiler errors)
            _REASON.append('%s: %s' % (type(err).__name__, err))
    return _REASON[0]


class SpectralGpuMobility(SpectralMobility):
    """The spectral (force-coupling) blob mobility computed on the GPU (see the module docstring)."""
    backend = 'spectral_gpu'

    def __init__(self, geometry, eta, blob_radius, **options):
        reason = unusable_reason()
        if reason is not None:
            raise UserInputError('the spectral_gpu backend cannot run here (%s); use the spectral backend (CPU)'
                                 % reason)
        super().__init__(geometry, eta, blob_radius, **options)

    def _product_engine(self, parameters, path, workers):
        import cupy
        from .spectral import cuda_kernels
        from .spectral.array_product import ArrayStokes
        return ArrayStokes(parameters, self.eta, xp=cupy, kernels=cuda_kernels)
