// pybind11 module mobility._spectral_cpp: the compiled steps of the spectral Stokes product
// (spreading, interpolation, the per-wavenumber solves); mobility/spectral/compiled.py drives them and
// mobility/spectral/reference.py states the same steps in NumPy.  Arrays are checked here (dtype, layout,
// shapes) so that a wrong call raises instead of reading out of bounds.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <complex>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "openmp_threads.h"
#include "spectral_solve.h"
#include "spectral_spread.h"

// The spreading, interpolation and solves, compiled once per vector path (the chosen one runs:
// simd_dispatch.h).
#define RMB_SIMD_KERNELS "spectral_kernels.inc"
#include "fast_exp.h"   // rmb::exp_nonpositive: the wall corrections of the solve
#include "pair_laws.h"
#include "simd_targets.h"

namespace py = pybind11;
using rmb_spectral::cplx;

namespace {

template <class T>
using In = py::array_t<T, py::array::c_style>;

template <class T>
const T *data_of(const In<T> &a, py::ssize_t size, const char *name) {
  if (a.size() != size)
    throw std::invalid_argument(std::string("_spectral_cpp: ") + name + " has " + std::to_string(a.size()) +
                                " entries, expected " + std::to_string(size));
  return a.data();
}

// The (3, Nz, Ny, row) float64 grid, C-contiguous and writable.
rmb_spectral::Grid grid_of(py::array_t<double> &grid) {
  if (grid.ndim() != 4 || grid.shape(0) != 3)
    throw std::invalid_argument("_spectral_cpp: the grid must have shape (3, Nz, Ny, row)");
  if (!(grid.flags() & py::array::c_style) || !grid.writeable())
    throw std::invalid_argument("_spectral_cpp: the grid must be C-contiguous and writable");
  rmb_spectral::Grid g;
  g.Nz = grid.shape(1), g.Ny = grid.shape(2), g.row = grid.shape(3);
  double *base = grid.mutable_data();
  for (int a = 0; a < 3; ++a) g.c[a] = base + a * g.Nz * g.Ny * g.row;
  return g;
}

rmb_spectral::Stencil stencil_of(const In<std::int32_t> &ix, const In<std::int32_t> &iy, const In<std::int32_t> &iz,
                                 const In<double> &px, const In<double> &py, const In<double> &pz,
                                 const rmb_spectral::Grid &g, std::int64_t Nx) {
  if (ix.ndim() != 2 || iy.ndim() != 2 || iz.ndim() != 2)
    throw std::invalid_argument("_spectral_cpp: stencil indices must be (n, w) arrays");
  rmb_spectral::Stencil s;
  s.n = ix.shape(0), s.wx = ix.shape(1), s.wy = iy.shape(1), s.wz = iz.shape(1);
  if (iy.shape(0) != s.n || iz.shape(0) != s.n)
    throw std::invalid_argument("_spectral_cpp: stencil arrays disagree on the number of blobs");
  s.ix = ix.data(), s.iy = iy.data(), s.iz = iz.data();
  s.phi_x = data_of(px, s.n * s.wx, "phi_x");
  s.phi_y = data_of(py, s.n * s.wy, "phi_y");
  s.phi_z = data_of(pz, s.n * s.wz, "phi_z");
  // every index inside the grid (a wrong stencil must not write out of bounds)
  auto check = [&](const std::int32_t *idx, std::int64_t count, std::int64_t bound, const char *name) {
    for (std::int64_t i = 0; i < count; ++i)
      if (idx[i] < 0 || idx[i] >= bound)
        throw std::invalid_argument(std::string("_spectral_cpp: stencil index out of the grid in ") + name);
  };
  check(s.ix, s.n * s.wx, Nx, "ix");
  check(s.iy, s.n * s.wy, g.Ny, "iy");
  check(s.iz, s.n * s.wz, g.Nz, "iz");
  if (Nx > g.row) throw std::invalid_argument("_spectral_cpp: Nx exceeds the grid's row length");
  return s;
}

rmb_spectral::Stripes stripes_of(const In<std::int64_t> &order, const In<std::int64_t> &start, std::int64_t n) {
  rmb_spectral::Stripes s;
  if (order.size() != n || start.size() < 2)
    throw std::invalid_argument("_spectral_cpp: the stripe order must list every blob once");
  s.order = order.data(), s.start = start.data(), s.count = start.size() - 1;
  if (s.start[0] != 0 || s.start[s.count] != n)
    throw std::invalid_argument("_spectral_cpp: stripe offsets must run from 0 to n");
  for (std::int64_t i = 0; i < n; ++i)
    if (s.order[i] < 0 || s.order[i] >= n) throw std::invalid_argument("_spectral_cpp: stripe order out of range");
  return s;
}

void spread_forces(py::array_t<double> grid, std::int64_t Nx, In<std::int32_t> ix, In<std::int32_t> iy,
                   In<std::int32_t> iz, In<double> px, In<double> py, In<double> pz, In<double> forces,
                   In<std::int64_t> order, In<std::int64_t> start) {
  rmb_spectral::Grid g = grid_of(grid);
  rmb_spectral::Stencil s = stencil_of(ix, iy, iz, px, py, pz, g, Nx);
  const double *f = data_of(forces, 3 * s.n, "forces");
  rmb_spectral::Stripes st = stripes_of(order, start, s.n);
  py::gil_scoped_release release;
  RMB_SIMD_DISPATCH(spread_forces(s, st, f, g));
}

void spread_torques(py::array_t<double> grid, std::int64_t Nx, In<std::int32_t> ix, In<std::int32_t> iy,
                    In<std::int32_t> iz, In<double> px, In<double> py, In<double> pz, In<double> dpx,
                    In<double> dpy, In<double> dpz, In<double> torques, In<std::int64_t> order,
                    In<std::int64_t> start) {
  rmb_spectral::Grid g = grid_of(grid);
  rmb_spectral::Stencil s = stencil_of(ix, iy, iz, px, py, pz, g, Nx);
  s.dphi_x = data_of(dpx, s.n * s.wx, "dphi_x");
  s.dphi_y = data_of(dpy, s.n * s.wy, "dphi_y");
  s.dphi_z = data_of(dpz, s.n * s.wz, "dphi_z");
  const double *t = data_of(torques, 3 * s.n, "torques");
  rmb_spectral::Stripes st = stripes_of(order, start, s.n);
  py::gil_scoped_release release;
  RMB_SIMD_DISPATCH(spread_torques(s, st, t, g));
}

py::array_t<double> interpolate_velocities(py::array_t<double> grid, std::int64_t Nx, In<std::int32_t> ix,
                                           In<std::int32_t> iy, In<std::int32_t> iz, In<double> px, In<double> py,
                                           In<double> qz) {
  rmb_spectral::Grid g = grid_of(grid);
  rmb_spectral::Stencil s = stencil_of(ix, iy, iz, px, py, qz, g, Nx);
  py::array_t<double> U({static_cast<py::ssize_t>(s.n), static_cast<py::ssize_t>(3)});
  double *u = U.mutable_data();
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(interpolate_velocities(s, s.phi_z, g, u));
  }
  return U;
}

py::array_t<double> interpolate_rotations(py::array_t<double> grid, std::int64_t Nx, In<std::int32_t> ix,
                                          In<std::int32_t> iy, In<std::int32_t> iz, In<double> px, In<double> py,
                                          In<double> qz, In<double> dpx, In<double> dpy, In<double> dqz) {
  rmb_spectral::Grid g = grid_of(grid);
  rmb_spectral::Stencil s = stencil_of(ix, iy, iz, px, py, qz, g, Nx);
  s.dphi_x = data_of(dpx, s.n * s.wx, "dphi_x");
  s.dphi_y = data_of(dpy, s.n * s.wy, "dphi_y");
  const double *dq = data_of(dqz, s.n * s.wz, "dqz");
  py::array_t<double> W({static_cast<py::ssize_t>(s.n), static_cast<py::ssize_t>(3)});
  double *w = W.mutable_data();
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(interpolate_rotations(s, s.phi_z, dq, g, w));
  }
  return W;
}

cplx *complex_grid(py::array_t<std::complex<double>> &grid, std::int64_t Nz, std::int64_t Ny, std::int64_t Nxh) {
  if (grid.ndim() != 4 || grid.shape(0) != 3 || grid.shape(1) != Nz || grid.shape(2) != Ny || grid.shape(3) != Nxh)
    throw std::invalid_argument("_spectral_cpp: the transformed grid must have shape (3, Nz, Ny, Nx//2+1)");
  if (!(grid.flags() & py::array::c_style) || !grid.writeable())
    throw std::invalid_argument("_spectral_cpp: the transformed grid must be C-contiguous and writable");
  return grid.mutable_data();
}

void solve_doubly_periodic(py::array_t<std::complex<double>> grid, py::dict cheb, py::dict modes) {
  rmb_spectral::Chebyshev c;
  c.N = cheb["N"].cast<int>();
  c.H = cheb["H"].cast<double>();
  c.Lz = cheb["Lz"].cast<double>();
  c.eta = cheb["eta"].cast<double>();
  c.geometry = cheb["geometry"].cast<int>();
  c.pressure_derivative_by_recurrence = cheb["pressure_derivative_by_recurrence"].cast<bool>();
  c.unpaired_correction_as_is = cheb["unpaired_correction_as_is"].cast<bool>();
  const py::ssize_t N = c.N;
  if (N < 3) throw std::invalid_argument("_spectral_cpp: a Chebyshev grid needs N >= 3");
  // keep the arrays alive while the solve runs
  auto get = [&](const char *name, py::ssize_t size) {
    In<double> a = cheb[name].cast<In<double>>();
    if (a.size() != size) throw std::invalid_argument(std::string("_spectral_cpp: cheb[") + name + "] size");
    return a;
  };
  In<double> fwd = get("forward", N * N), bwd = get("backward", N * N), s_low = get("s_low", N),
             s_diag = get("s_diag", N), s_up = get("s_up", N), s_c0 = get("s_c0", N), s_d0 = get("s_d0", N),
             f_low = get("f_low", N), f_up = get("f_up", N), f_d0 = get("f_d0", N), R2 = get("R2", N + 2),
             L2 = get("L2", N + 2), R1 = get("R1", N + 2), L1 = get("L1", N + 2), z = get("z", N);
  c.forward = fwd.data(), c.backward = bwd.data(), c.s_low = s_low.data(), c.s_diag = s_diag.data();
  c.s_up = s_up.data(), c.s_c0 = s_c0.data(), c.s_d0 = s_d0.data(), c.f_low = f_low.data(), c.f_up = f_up.data();
  c.f_d0 = f_d0.data(), c.R2 = R2.data(), c.L2 = L2.data(), c.R1 = R1.data(), c.L1 = L1.data(), c.z = z.data();
  rmb_spectral::Modes m;
  m.Ny = modes["Ny"].cast<std::int64_t>();
  m.Nxh = modes["Nxh"].cast<std::int64_t>();
  auto getm = [&](const char *name, py::ssize_t size) {
    In<double> a = modes[name].cast<In<double>>();
    if (a.size() != size) throw std::invalid_argument(std::string("_spectral_cpp: modes[") + name + "] size");
    return a;
  };
  In<double> kx = getm("kx", m.Nxh), ky = getm("ky", m.Ny), dx = getm("dx", m.Nxh), dy = getm("dy", m.Ny),
             kxp = getm("kx_partner", m.Nxh), kyp = getm("ky_partner", m.Ny);
  In<std::uint8_t> ux = modes["unpaired_x"].cast<In<std::uint8_t>>(), uy = modes["unpaired_y"].cast<In<std::uint8_t>>();
  if (ux.size() != m.Nxh || uy.size() != m.Ny) throw std::invalid_argument("_spectral_cpp: unpaired flags size");
  m.kx = kx.data(), m.ky = ky.data(), m.dx = dx.data(), m.dy = dy.data(), m.kx_partner = kxp.data();
  m.ky_partner = kyp.data(), m.unpaired_x = ux.data(), m.unpaired_y = uy.data();
  cplx *g = complex_grid(grid, N, m.Ny, m.Nxh);
  py::gil_scoped_release release;
  RMB_SIMD_DISPATCH(solve_doubly_periodic(c, m, g));
}

void solve_triply_periodic(py::array_t<std::complex<double>> grid, In<double> kz, In<double> ky, In<double> kx,
                           In<double> dz, In<double> dy, In<double> dx, double eta) {
  const std::int64_t Nz = kz.size(), Ny = ky.size(), Nxh = kx.size();
  cplx *g = complex_grid(grid, Nz, Ny, Nxh);
  if (dz.size() != Nz || dy.size() != Ny || dx.size() != Nxh)
    throw std::invalid_argument("_spectral_cpp: derivative factors disagree with the wavenumbers");
  py::gil_scoped_release release;
  const double *kzp = kz.data(), *kyp = ky.data(), *kxp = kx.data(), *dzp = dz.data(), *dyp = dy.data(),
               *dxp = dx.data();
  RMB_SIMD_DISPATCH(solve_triply_periodic(g, Nz, Ny, Nxh, kzp, kyp, kxp, dzp, dyp, dxp, eta));
}

}  // namespace

PYBIND11_MODULE(_spectral_cpp, m) {
  m.doc() = "Compiled steps of the spectral Stokes product (mobility.spectral.compiled drives them)";
  try {
    rmb_simd::chosen();  // RMB_SIMD naming a path that cannot run here stops the import with its one line
  } catch (const std::invalid_argument &err) {
    throw py::import_error(err.what());
  }
  m.def("simd_path", []() { return std::string(rmb_simd::path_name(rmb_simd::chosen())); },
        "The vector path of the spreading, interpolation and solves (mobility/cpp/simd_dispatch.h).");
  m.def("max_threads", &rmb::max_threads, "OpenMP threads the kernels may use");
  // the grids are written in place: never accept a converted copy
  m.def("spread_forces", &spread_forces, "grid += forces spread with a monopole stencil", py::arg("grid").noconvert(),
        py::arg("Nx"), py::arg("ix"), py::arg("iy"), py::arg("iz"), py::arg("phi_x"), py::arg("phi_y"),
        py::arg("phi_z"), py::arg("forces"), py::arg("order"), py::arg("start"));
  m.def("spread_torques", &spread_torques, "grid += half the curl of the torques spread with a dipole stencil",
        py::arg("grid").noconvert(), py::arg("Nx"), py::arg("ix"), py::arg("iy"), py::arg("iz"), py::arg("phi_x"),
        py::arg("phi_y"), py::arg("phi_z"), py::arg("dphi_x"), py::arg("dphi_y"), py::arg("dphi_z"),
        py::arg("torques"), py::arg("order"), py::arg("start"));
  m.def("interpolate_velocities", &interpolate_velocities, "(n, 3) velocities averaged with a monopole stencil",
        py::arg("grid").noconvert(), py::arg("Nx"), py::arg("ix"), py::arg("iy"), py::arg("iz"), py::arg("phi_x"),
        py::arg("phi_y"), py::arg("qz"));
  m.def("interpolate_rotations", &interpolate_rotations, "(n, 3) half vorticities averaged with a dipole stencil",
        py::arg("grid").noconvert(), py::arg("Nx"), py::arg("ix"), py::arg("iy"), py::arg("iz"), py::arg("phi_x"),
        py::arg("phi_y"), py::arg("qz"), py::arg("dphi_x"), py::arg("dphi_y"), py::arg("dqz"));
  m.def("solve_doubly_periodic", &solve_doubly_periodic, "DP/DPBW/DPSC solve in place (all modes but k = 0)",
        py::arg("grid").noconvert(), py::arg("cheb"), py::arg("modes"));
  m.def("solve_triply_periodic", &solve_triply_periodic, "triply periodic solve in place", py::arg("grid").noconvert(),
        py::arg("kz"), py::arg("ky"), py::arg("kx"), py::arg("dz"), py::arg("dy"), py::arg("dx"), py::arg("eta"));
}
