// C++ blob-blob soft repulsion (pybind11 module multi_bodies._forces_cpp).
//
// Force on blob i from blob j, with r = r_j - r_i (minimum image on the
// periodic axes, SPEC section 8; the image of r_i - r_j is minus that of
// r_j - r_i, so each pair is visited once) and d = 2a:
//   f_i = -(eps/b) exp(-(|r| - d)/b) r/|r|   for |r| > d,
//   f_i = -(eps/b) r/|r|                     otherwise,
// |r| floored by machine epsilon.  With per-blob radii a_i (blob_blob_forces_radii)
// the contact distance of a pair is d = a_i + a_j (twice the mean radius, the rule of
// the published radii_numba forces).  The law and the minimum image are those of
// mobility/cpp/pair_laws.h (the one source of the compiled backends); edit
// rmb::blob_blob_force_factor there to change the law of the C++ and CUDA backends
// (then rebuild with pip install -e .).  OpenMP splits the rows i of the pair
// triangle; every thread has its own force accumulator.  pair_laws() evaluates the
// header's three laws, force and energy, for the tests.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "openmp_threads.h"
#include "fast_exp.h"
#include "pair_laws.h"

// blob_blob_pair_sums, compiled once per vector path (the chosen one runs: mobility/cpp/simd_dispatch.h)
#define RMB_SIMD_KERNELS "forces_kernels.inc"
#include "simd_targets.h"

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

namespace {



template <bool Radii>
Array blob_blob_forces_any(const Array &r_vectors, const Array &periodic_length, double repulsion_strength,
                           double debye_length, double blob_radius, const Array *radii) {
  if (!(r_vectors.ndim() == 2 && r_vectors.shape(1) == 3) && !(r_vectors.ndim() == 1 && r_vectors.shape(0) % 3 == 0))
    throw std::invalid_argument("r_vectors must have shape (N, 3)");
  if (periodic_length.size() != 3) throw std::invalid_argument("periodic_length must hold 3 numbers");
  if (debye_length <= 0.0) throw std::invalid_argument("debye_length must be positive");
  const long n = static_cast<long>(r_vectors.size() / 3);
  if (Radii && radii->size() != n) throw std::invalid_argument("blob_radii must hold one radius per blob");
  std::vector<double> x(n), y(n), z(n), a(Radii ? n : 0);
  const double *rp = r_vectors.data();
  for (long i = 0; i < n; ++i) x[i] = rp[3 * i], y[i] = rp[3 * i + 1], z[i] = rp[3 * i + 2];
  if (Radii)
    for (long i = 0; i < n; ++i) a[i] = radii->data()[i];
  const double Lx = periodic_length.data()[0], Ly = periodic_length.data()[1], Lz = periodic_length.data()[2];
  const rmb::SoftRepulsion law = rmb::soft_repulsion(repulsion_strength, debye_length, 2.0 * blob_radius);
  Array result({static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(3)});
  double *out = result.mutable_data();
  {
    py::gil_scoped_release release;
    const int threads = rmb::max_threads();
    // Each unordered pair is visited once; thread t adds into its own accumulators (x, y and z apart, so
    // that the inner loop vectorises, with the exponential of fast_exp.h), summed at the end.
    std::vector<double> accumulators(static_cast<std::size_t>(threads) * 3 * n, 0.0);
    // one thread for small systems: a parallel region costs more than ~1e5 pairs
    const bool use_threads = static_cast<double>(n) * n > 2e5;
    const double *px = x.data(), *py = y.data(), *pz = z.data(), *pa = Radii ? a.data() : nullptr;
    RMB_SIMD_DISPATCH(blob_blob_pair_sums<Radii>(n, px, py, pz, pa, Lx, Ly, Lz, law, repulsion_strength, debye_length,
                                                 accumulators.data(), use_threads));
#pragma omp parallel for schedule(static) if (use_threads)
    for (long k = 0; k < n; ++k) {
      for (int c = 0; c < 3; ++c) {
        double sum = 0.0;
        for (int t = 0; t < threads; ++t) sum += accumulators[static_cast<std::size_t>(t) * 3 * n + c * n + k];
        out[3 * k + c] = sum;
      }
    }
  }
  return result;
}

Array blob_blob_forces(const Array &r_vectors, const Array &periodic_length, double repulsion_strength,
                       double debye_length, double blob_radius) {
  return blob_blob_forces_any<false>(r_vectors, periodic_length, repulsion_strength, debye_length, blob_radius,
                                     nullptr);
}

Array blob_blob_forces_radii(const Array &r_vectors, const Array &periodic_length, double repulsion_strength,
                             double debye_length, const Array &blob_radii) {
  return blob_blob_forces_any<true>(r_vectors, periodic_length, repulsion_strength, debye_length, 0.0, &blob_radii);
}

// The same soft repulsion with a cell list: only pairs with |r| <= cutoff (minimum image) are summed, in
// O(N) for a bounded density.  Periodic axes (L > 0) are cut into floor(L / cutoff) cells (at least one) and
// positions are wrapped into [0, L) for the binning only; the other axes span the blobs' bounding box (the
// pseudo-periodic boxes of the published code: periodic in x and y above a wall).  Cells are at least
// `cutoff` wide (wider when the box would need more than ~2 cells per blob), so every pair within the
// cutoff lies in neighbouring cells; the neighbour offsets of an axis with fewer than three cells are
// deduplicated, so each pair is found once per blob.  Each blob sums its own neighbours (every pair twice,
// no write conflicts), so OpenMP needs no accumulators.
Array blob_blob_forces_cell_list(const Array &r_vectors, const Array &periodic_length, double repulsion_strength,
                                 double debye_length, double blob_radius, double cutoff) {
  if (!(r_vectors.ndim() == 2 && r_vectors.shape(1) == 3) && !(r_vectors.ndim() == 1 && r_vectors.shape(0) % 3 == 0))
    throw std::invalid_argument("r_vectors must have shape (N, 3)");
  if (periodic_length.size() != 3) throw std::invalid_argument("periodic_length must hold 3 numbers");
  if (debye_length <= 0.0) throw std::invalid_argument("debye_length must be positive");
  if (!(cutoff > 0.0) || !std::isfinite(cutoff)) throw std::invalid_argument("cutoff must be positive and finite");
  const long n = static_cast<long>(r_vectors.size() / 3);
  const double *rp = r_vectors.data();
  const double *Lp = periodic_length.data();
  for (long k = 0; k < 3 * n; ++k)
    if (!std::isfinite(rp[k])) throw std::invalid_argument("r_vectors must be finite");
  const rmb::SoftRepulsion law = rmb::soft_repulsion(repulsion_strength, debye_length, 2.0 * blob_radius);
  Array result({static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(3)});
  double *out = result.mutable_data();
  if (n == 0) return result;
  py::gil_scoped_release release;
  // cell geometry per axis
  double low[3], width[3];
  long cells[3];
  bool periodic[3];
  for (int d = 0; d < 3; ++d) {
    periodic[d] = Lp[d] > 0.0;
    if (periodic[d]) {
      low[d] = 0.0;
      cells[d] = std::max(1L, static_cast<long>(std::floor(Lp[d] / cutoff)));
      width[d] = Lp[d] / cells[d];
    } else {
      double lo = rp[d], hi = rp[d];
      for (long i = 1; i < n; ++i) lo = std::min(lo, rp[3 * i + d]), hi = std::max(hi, rp[3 * i + d]);
      low[d] = lo;
      cells[d] = std::max(1L, static_cast<long>(std::floor((hi - lo) / cutoff)));
      width[d] = std::max((hi - lo) / cells[d], cutoff);
    }
  }
  // at most ~2 cells per blob: merge cells (never narrower than the cutoff) on sparse boxes
  while (static_cast<double>(cells[0]) * cells[1] * cells[2] > 2.0 * n + 27.0) {
    int d = 0;
    for (int e = 1; e < 3; ++e)
      if (cells[e] > cells[d]) d = e;
    const long merged = std::max(1L, cells[d] / 2);
    width[d] *= static_cast<double>(cells[d]) / merged;
    cells[d] = merged;
  }
  auto axis_cell = [&](double x, int d) {
    if (periodic[d]) x -= Lp[d] * std::floor(x / Lp[d]);
    long c = static_cast<long>(std::floor((x - low[d]) / width[d]));
    return std::min(std::max(c, 0L), cells[d] - 1);
  };
  const long total = cells[0] * cells[1] * cells[2];
  std::vector<long> cell_of(n), start(total + 1, 0), order(n);
  for (long i = 0; i < n; ++i) {
    const long c = (axis_cell(rp[3 * i], 0) * cells[1] + axis_cell(rp[3 * i + 1], 1)) * cells[2] +
                   axis_cell(rp[3 * i + 2], 2);
    cell_of[i] = c;
    ++start[c + 1];
  }
  for (long c = 0; c < total; ++c) start[c + 1] += start[c];
  {
    std::vector<long> fill(start.begin(), start.end() - 1);
    for (long i = 0; i < n; ++i) order[fill[cell_of[i]]++] = i;
  }
  // neighbour cells of an axis cell index: offsets -1, 0, 1 (wrapped on periodic axes), duplicates removed
  auto neighbours = [&](long c, int d, long *list) {
    int count = 0;
    for (long o = -1; o <= 1; ++o) {
      long m = c + o;
      if (periodic[d]) m = ((m % cells[d]) + cells[d]) % cells[d];
      else if (m < 0 || m >= cells[d]) continue;
      bool seen = false;
      for (int k = 0; k < count; ++k) seen = seen || list[k] == m;
      if (!seen) list[count++] = m;
    }
    return count;
  };
  const double cutoff2 = cutoff * cutoff;
  const bool use_threads = n > 2000;
#pragma omp parallel for schedule(dynamic, 64) if (use_threads)
  for (long i = 0; i < n; ++i) {
    const double xi = rp[3 * i], yi = rp[3 * i + 1], zi = rp[3 * i + 2];
    const long c = cell_of[i];
    const long cz = c % cells[2], cy = (c / cells[2]) % cells[1], cx = c / (cells[1] * cells[2]);
    long nx[3], ny[3], nz[3];
    const int kx = neighbours(cx, 0, nx), ky = neighbours(cy, 1, ny), kz = neighbours(cz, 2, nz);
    double fx = 0.0, fy = 0.0, fz = 0.0;
    for (int a = 0; a < kx; ++a)
      for (int b = 0; b < ky; ++b)
        for (int e = 0; e < kz; ++e) {
          const long cell = (nx[a] * cells[1] + ny[b]) * cells[2] + nz[e];
          for (long p = start[cell]; p < start[cell + 1]; ++p) {
            const long j = order[p];
            if (j == i) continue;
            const double rx = rmb::minimum_image(rp[3 * j] - xi, Lp[0]);
            const double ry = rmb::minimum_image(rp[3 * j + 1] - yi, Lp[1]);
            const double rz = rmb::minimum_image(rp[3 * j + 2] - zi, Lp[2]);
            const double r2 = rx * rx + ry * ry + rz * rz;
            if (r2 > cutoff2) continue;
            const double m = rmb::blob_blob_force_factor(std::sqrt(r2), law);
            fx -= m * rx, fy -= m * ry, fz -= m * rz;
          }
        }
    out[3 * i] = fx, out[3 * i + 1] = fy, out[3 * i + 2] = fz;
  }
  return result;
}

// The laws of pair_laws.h at many points, for the tests: law "wall" (x = heights z,
// contact a), "blob_blob" (x = distances, contact 2a) or "body_body" (x = distances).
// Returns (energies, forces) of the shape of x: the wall force f_z, and for the pair laws
// the factor m of the force -m r on i.
py::tuple pair_laws(const std::string &law_name, const Array &x, double repulsion_strength, double debye_length,
                    double blob_radius) {
  if (!(debye_length > 0.0)) throw std::invalid_argument("debye_length must be positive");
  int kind;
  if (law_name == "wall") kind = 0;
  else if (law_name == "blob_blob") kind = 1;
  else if (law_name == "body_body") kind = 2;
  else throw std::invalid_argument("law must be wall, blob_blob or body_body, got " + law_name);
  const rmb::SoftRepulsion law =
      rmb::soft_repulsion(repulsion_strength, debye_length, (kind == 1 ? 2.0 : 1.0) * blob_radius);
  std::vector<py::ssize_t> shape(x.shape(), x.shape() + x.ndim());
  Array energy(shape), force(shape);
  const double *xp = x.data();
  double *e = energy.mutable_data(), *f = force.mutable_data();
  for (py::ssize_t k = 0; k < x.size(); ++k) {
    if (kind == 0) e[k] = rmb::wall_energy(xp[k], law), f[k] = rmb::wall_force(xp[k], law);
    if (kind == 1) e[k] = rmb::blob_blob_energy(xp[k], law), f[k] = rmb::blob_blob_force_factor(xp[k], law);
    if (kind == 2) e[k] = rmb::body_body_energy(xp[k], law), f[k] = rmb::body_body_force_factor(xp[k], law);
  }
  return py::make_tuple(energy, force);
}

// Minimum image of every entry of d (..., 3) in the box L (3,), for the tests.
Array minimum_images(const Array &d, const Array &periodic_length) {
  if (periodic_length.size() != 3) throw std::invalid_argument("periodic_length must hold 3 numbers");
  if (d.size() % 3 != 0) throw std::invalid_argument("displacements must have shape (..., 3)");
  std::vector<py::ssize_t> shape(d.shape(), d.shape() + d.ndim());
  Array out(shape);
  const double *dp = d.data(), *L = periodic_length.data();
  double *o = out.mutable_data();
  for (py::ssize_t k = 0; k < d.size(); ++k) o[k] = rmb::minimum_image(dp[k], L[k % 3]);
  return out;
}


}  // namespace

PYBIND11_MODULE(_forces_cpp, m) {
  m.doc() = "C++ (OpenMP) blob-blob soft repulsion: all pairs, or the pairs within a cutoff (cell list)";
  try {
    rmb_simd::chosen();  // RMB_SIMD naming a path that cannot run here stops the import with its one line
  } catch (const std::invalid_argument &err) {
    throw py::import_error(err.what());
  }
  m.def("simd_path", []() { return std::string(rmb_simd::path_name(rmb_simd::chosen())); },
        "The vector path of the all-pairs loop (mobility/cpp/simd_dispatch.h).");
  m.def("blob_blob_forces", &blob_blob_forces, py::arg("r_vectors"), py::arg("periodic_length"),
        py::arg("repulsion_strength"), py::arg("debye_length"), py::arg("blob_radius"),
        "Forces (N, 3) of the default soft repulsion between all blob pairs; r_vectors (N, 3).");
  m.def("blob_blob_forces_radii", &blob_blob_forces_radii, py::arg("r_vectors"), py::arg("periodic_length"),
        py::arg("repulsion_strength"), py::arg("debye_length"), py::arg("blob_radii"),
        "Forces (N, 3) of the soft repulsion with per-blob radii (N,): contact distance a_i + a_j.");
  m.def("blob_blob_forces_cell_list", &blob_blob_forces_cell_list, py::arg("r_vectors"), py::arg("periodic_length"),
        py::arg("repulsion_strength"), py::arg("debye_length"), py::arg("blob_radius"), py::arg("cutoff"),
        "Forces (N, 3) of the default soft repulsion over the pairs closer than cutoff (cell list, O(N)).");
  m.def("pair_laws", &pair_laws, py::arg("law"), py::arg("x"), py::arg("repulsion_strength"),
        py::arg("debye_length"), py::arg("blob_radius"),
        "(energies, forces) of the header's law 'wall', 'blob_blob' or 'body_body' at the heights or distances x.");
  m.def("minimum_images", &minimum_images, py::arg("displacements"), py::arg("periodic_length"),
        "Minimum image of displacements (..., 3) in the box periodic_length (3,) (L <= 0: not periodic).");
  m.def("max_threads", &rmb::max_threads, "Number of OpenMP threads the kernel uses.");
}
