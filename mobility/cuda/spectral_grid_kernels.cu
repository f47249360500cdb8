// Spreading onto the grid and interpolation from it for the spectral product on the GPU
// (mobility/spectral/cuda_kernels.py compiles this file with NVRTC through CuPy).
//
// The NumPy functions of mobility/spectral/grid_kernels.py compute the same numbers with the same arithmetic per
// stencil point; tests/test_spectral_gpu.py compares the two where a GPU is lent.
//
// Layout (all arrays C-contiguous): grid (3, Nz, Ny, Nx) doubles, node (c, k, j, i) at ((c Nz + k) Ny + j) Nx + i;
// per blob b: ix[b * wx + a], iy[b * wy + a], iz[b * nzs + a] node indices (int), phi_x, phi_y, phi_z the 1-D
// kernel factors, qz = phi_z times the quadrature weight of the node (interpolation), dphi_* and dqz the
// derivative kernel's; vectors (n, 3).  Padded z slots carry weight 0.
//
// Spreading: one thread per (blob, stencil point), atomicAdd of double (compute capability 6.0 and later).
// Interpolation: one block per blob (grid-stride over blobs), threads over the stencil points, a shared-memory
// tree reduction; blockDim.x must be a power of two and the shared memory (sums per thread) * blockDim.x doubles.

extern "C" {

__global__ void spread_forces(double* __restrict__ grid, const int n, const int nzs, const int wy, const int wx,
                              const int* __restrict__ ix, const int* __restrict__ iy, const int* __restrict__ iz,
                              const double* __restrict__ phi_x, const double* __restrict__ phi_y,
                              const double* __restrict__ phi_z, const double* __restrict__ forces,
                              const int Nx, const int Ny, const int Nz)
{
    const long long per_blob = (long long)nzs * wy * wx;
    const long long total = per_blob * n;
    const long long plane = (long long)Nz * Ny * Nx;
    for (long long t = blockIdx.x * (long long)blockDim.x + threadIdx.x; t < total;
         t += (long long)gridDim.x * blockDim.x) {
        const int b = (int)(t / per_blob);
        int rest = (int)(t - (long long)b * per_blob);
        const int kz = rest / (wy * wx);
        rest -= kz * wy * wx;
        const int jy = rest / wx;
        const int kx = rest - jy * wx;
        const double w = phi_z[b * nzs + kz] * phi_y[b * wy + jy] * phi_x[b * wx + kx];
        if (w == 0.0) {
            continue;
        }
        const long long node = ((long long)iz[b * nzs + kz] * Ny + iy[b * wy + jy]) * Nx + ix[b * wx + kx];
        atomicAdd(grid + node, w * forces[3 * b]);
        atomicAdd(grid + plane + node, w * forces[3 * b + 1]);
        atomicAdd(grid + 2 * plane + node, w * forces[3 * b + 2]);
    }
}

__global__ void spread_torques(double* __restrict__ grid, const int n, const int nzs, const int wy, const int wx,
                               const int* __restrict__ ix, const int* __restrict__ iy, const int* __restrict__ iz,
                               const double* __restrict__ phi_x, const double* __restrict__ phi_y,
                               const double* __restrict__ phi_z, const double* __restrict__ dphi_x,
                               const double* __restrict__ dphi_y, const double* __restrict__ dphi_z,
                               const double* __restrict__ torques, const int Nx, const int Ny, const int Nz)
{
    const long long per_blob = (long long)nzs * wy * wx;
    const long long total = per_blob * n;
    const long long plane = (long long)Nz * Ny * Nx;
    for (long long t = blockIdx.x * (long long)blockDim.x + threadIdx.x; t < total;
         t += (long long)gridDim.x * blockDim.x) {
        const int b = (int)(t / per_blob);
        int rest = (int)(t - (long long)b * per_blob);
        const int kz = rest / (wy * wx);
        rest -= kz * wy * wx;
        const int jy = rest / wx;
        const int kx = rest - jy * wx;
        const double pz = phi_z[b * nzs + kz], py = phi_y[b * wy + jy], px = phi_x[b * wx + kx];
        const double Dx = pz * py * dphi_x[b * wx + kx];
        const double Dy = pz * dphi_y[b * wy + jy] * px;
        const double Dz = dphi_z[b * nzs + kz] * py * px;
        const double T0 = torques[3 * b], T1 = torques[3 * b + 1], T2 = torques[3 * b + 2];
        const long long node = ((long long)iz[b * nzs + kz] * Ny + iy[b * wy + jy]) * Nx + ix[b * wx + kx];
        atomicAdd(grid + node, 0.5 * (T2 * Dy - T1 * Dz));
        atomicAdd(grid + plane + node, 0.5 * (T0 * Dz - T2 * Dx));
        atomicAdd(grid + 2 * plane + node, 0.5 * (T1 * Dx - T0 * Dy));
    }
}

// Tree reduction of `count` sums of blockDim.x partial values each (sums[s * blockDim.x + thread]).
__device__ void reduce_sums(double* sums, const int count)
{
    __syncthreads();
    for (int stride = blockDim.x / 2; stride > 0; stride >>= 1) {
        if (threadIdx.x < stride) {
            for (int s = 0; s < count; ++s) {
                sums[s * blockDim.x + threadIdx.x] += sums[s * blockDim.x + threadIdx.x + stride];
            }
        }
        __syncthreads();
    }
}

__global__ void interpolate_velocities(const double* __restrict__ grid, const int n, const int nzs, const int wy,
                                       const int wx, const int* __restrict__ ix, const int* __restrict__ iy,
                                       const int* __restrict__ iz, const double* __restrict__ phi_x,
                                       const double* __restrict__ phi_y, const double* __restrict__ qz,
                                       double* __restrict__ out, const int Nx, const int Ny, const int Nz)
{
    extern __shared__ double sums[];   // 3 * blockDim.x
    const int per_blob = nzs * wy * wx;
    const long long plane = (long long)Nz * Ny * Nx;
    for (int b = blockIdx.x; b < n; b += gridDim.x) {
        double u0 = 0.0, u1 = 0.0, u2 = 0.0;
        for (int s = threadIdx.x; s < per_blob; s += blockDim.x) {
            const int kz = s / (wy * wx);
            const int rest = s - kz * wy * wx;
            const int jy = rest / wx;
            const int kx = rest - jy * wx;
            const double w = qz[b * nzs + kz] * phi_y[b * wy + jy] * phi_x[b * wx + kx];
            const long long node = ((long long)iz[b * nzs + kz] * Ny + iy[b * wy + jy]) * Nx + ix[b * wx + kx];
            u0 += grid[node] * w;
            u1 += grid[plane + node] * w;
            u2 += grid[2 * plane + node] * w;
        }
        sums[threadIdx.x] = u0;
        sums[blockDim.x + threadIdx.x] = u1;
        sums[2 * blockDim.x + threadIdx.x] = u2;
        reduce_sums(sums, 3);
        if (threadIdx.x == 0) {
            out[3 * b] = sums[0];
            out[3 * b + 1] = sums[blockDim.x];
            out[3 * b + 2] = sums[2 * blockDim.x];
        }
        __syncthreads();
    }
}

__global__ void interpolate_rotations(const double* __restrict__ grid, const int n, const int nzs, const int wy,
                                      const int wx, const int* __restrict__ ix, const int* __restrict__ iy,
                                      const int* __restrict__ iz, const double* __restrict__ phi_x,
                                      const double* __restrict__ phi_y, const double* __restrict__ qz,
                                      const double* __restrict__ dphi_x, const double* __restrict__ dphi_y,
                                      const double* __restrict__ dqz, double* __restrict__ out, const int Nx,
                                      const int Ny, const int Nz)
{
    extern __shared__ double sums[];   // 6 * blockDim.x
    const int per_blob = nzs * wy * wx;
    const long long plane = (long long)Nz * Ny * Nx;
    for (int b = blockIdx.x; b < n; b += gridDim.x) {
        // u2 Dy, u1 Dz, u0 Dz, u2 Dx, u1 Dx, u0 Dy
        double g[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
        for (int s = threadIdx.x; s < per_blob; s += blockDim.x) {
            const int kz = s / (wy * wx);
            const int rest = s - kz * wy * wx;
            const int jy = rest / wx;
            const int kx = rest - jy * wx;
            const double qzb = qz[b * nzs + kz], py = phi_y[b * wy + jy], px = phi_x[b * wx + kx];
            const double Dx = qzb * py * dphi_x[b * wx + kx];
            const double Dy = qzb * dphi_y[b * wy + jy] * px;
            const double Dz = dqz[b * nzs + kz] * py * px;
            const long long node = ((long long)iz[b * nzs + kz] * Ny + iy[b * wy + jy]) * Nx + ix[b * wx + kx];
            const double u0 = grid[node], u1 = grid[plane + node], u2 = grid[2 * plane + node];
            g[0] += u2 * Dy;
            g[1] += u1 * Dz;
            g[2] += u0 * Dz;
            g[3] += u2 * Dx;
            g[4] += u1 * Dx;
            g[5] += u0 * Dy;
        }
        for (int k = 0; k < 6; ++k) {
            sums[k * blockDim.x + threadIdx.x] = g[k];
        }
        reduce_sums(sums, 6);
        if (threadIdx.x == 0) {
            out[3 * b] = -0.5 * (sums[0] - sums[blockDim.x]);
            out[3 * b + 1] = -0.5 * (sums[2 * blockDim.x] - sums[3 * blockDim.x]);
            out[3 * b + 2] = -0.5 * (sums[4 * blockDim.x] - sums[5 * blockDim.x]);
        }
        __syncthreads();
    }
}

}  // extern "C"
