// C++ blob-blob energies of the Monte Carlo sampler (pybind11 module many_bodyMCMC._energy_cpp).
//
// Pair law (the default soft repulsion of the dynamic code, as a potential; SPEC section 9):
//   u(r) = eps + eps (d - r)/b   for r < d,
//   u(r) = eps exp(-(r - d)/b)   for r >= d,        d = 2a,
// written branch-free as eps exp(-max(r - d, 0)/b) + (eps/b) max(d - r, 0).  Displacements
// use the minimum image on the periodic axes (SPEC section 8).  Both come from
// mobility/cpp/pair_laws.h (rmb::blob_blob_energy, rmb::minimum_image), the one source of
// the compiled backends; this file adds only a vectorisable exp and the loops.
//
// pair_energy_total visits every unordered pair once (rows i split across OpenMP threads,
// dynamic schedule because row lengths differ); pair_energy_cross sums the pairs between a
// few target blobs (a moved body) and every source blob outside an excluded range (the
// body's own blobs), so a one-body move costs O(blobs of the body x N).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "openmp_threads.h"
#include "fast_exp.h"
#include "pair_laws.h"

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

namespace rmb_energy {
struct PairLaw {
  rmb::SoftRepulsion repulsion;
  double Lx, Ly, Lz;
};
}  // namespace rmb_energy

// total_sum and cross_sum, compiled once per vector path (the chosen one runs: mobility/cpp/simd_dispatch.h)
#define RMB_SIMD_KERNELS "energy_kernels.inc"
#include "simd_targets.h"

namespace {

using rmb_energy::PairLaw;

PairLaw make_law(const Array &periodic_length, double repulsion_strength, double debye_length, double blob_radius) {
  if (periodic_length.size() != 3) throw std::invalid_argument("periodic_length must hold 3 numbers");
  if (!(debye_length > 0.0)) throw std::invalid_argument("debye_length must be positive");
  const double *L = periodic_length.data();
  return PairLaw{rmb::soft_repulsion(repulsion_strength, debye_length, 2.0 * blob_radius), L[0], L[1], L[2]};
}

long count_rows(const Array &r, const char *name) {
  if (!(r.ndim() == 2 && r.shape(1) == 3) && !(r.ndim() == 1 && r.shape(0) % 3 == 0))
    throw std::invalid_argument(std::string(name) + " must have shape (N, 3)");
  return static_cast<long>(r.size() / 3);
}

void split_coordinates(const double *rp, long n, std::vector<double> &x, std::vector<double> &y,
                       std::vector<double> &z) {
  x.resize(n), y.resize(n), z.resize(n);
  for (long i = 0; i < n; ++i) x[i] = rp[3 * i], y[i] = rp[3 * i + 1], z[i] = rp[3 * i + 2];
}

bool is_periodic(const PairLaw &law) { return law.Lx > 0.0 || law.Ly > 0.0 || law.Lz > 0.0; }

// Sum over i < j of u(r_j - r_i).  r_vectors (N, 3).
double pair_energy_total(const Array &r_vectors, const Array &periodic_length, double repulsion_strength,
                         double debye_length, double blob_radius) {
  const long n = count_rows(r_vectors, "r_vectors");
  const PairLaw law = make_law(periodic_length, repulsion_strength, debye_length, blob_radius);
  std::vector<double> x, y, z;
  split_coordinates(r_vectors.data(), n, x, y, z);
  py::gil_scoped_release release;
  double total = 0.0;
  if (is_periodic(law))
    RMB_SIMD_DISPATCH(total_sum<true>(x, y, z, law, total));
  else
    RMB_SIMD_DISPATCH(total_sum<false>(x, y, z, law, total));
  return total;
}

// Sum over target blobs t and source blobs j outside [exclude_start, exclude_stop) of u(r_j - t).
// targets (m, 3), sources (N, 3).
double pair_energy_cross(const Array &targets, const Array &sources, long exclude_start, long exclude_stop,
                         const Array &periodic_length, double repulsion_strength, double debye_length,
                         double blob_radius) {
  const long m = count_rows(targets, "targets");
  const long n = count_rows(sources, "sources");
  if (exclude_start < 0 || exclude_stop < exclude_start || exclude_stop > n)
    throw std::invalid_argument("the excluded source range must lie inside [0, N]");
  const PairLaw law = make_law(periodic_length, repulsion_strength, debye_length, blob_radius);
  std::vector<double> x, y, z;
  split_coordinates(sources.data(), n, x, y, z);
  const double *tp = targets.data();
  py::gil_scoped_release release;
  double total = 0.0;
  if (is_periodic(law))
    RMB_SIMD_DISPATCH(cross_sum<true>(tp, m, x, y, z, exclude_start, exclude_stop, law, total));
  else
    RMB_SIMD_DISPATCH(cross_sum<false>(tp, m, x, y, z, exclude_start, exclude_stop, law, total));
  return total;
}


}  // namespace

PYBIND11_MODULE(_energy_cpp, m) {
  m.doc() = "C++ (OpenMP) blob-blob soft-repulsion energies of the Monte Carlo sampler";
  try {
    rmb_simd::chosen();  // RMB_SIMD naming a path that cannot run here stops the import with its one line
  } catch (const std::invalid_argument &err) {
    throw py::import_error(err.what());
  }
  m.def("simd_path", []() { return std::string(rmb_simd::path_name(rmb_simd::chosen())); },
        "The vector path of the energy sums (mobility/cpp/simd_dispatch.h).");
  m.def("pair_energy_total", &pair_energy_total, py::arg("r_vectors"), py::arg("periodic_length"),
        py::arg("repulsion_strength"), py::arg("debye_length"), py::arg("blob_radius"),
        "Sum over blob pairs i < j of the soft repulsion energy; r_vectors (N, 3).");
  m.def("pair_energy_cross", &pair_energy_cross, py::arg("targets"), py::arg("sources"), py::arg("exclude_start"),
        py::arg("exclude_stop"), py::arg("periodic_length"), py::arg("repulsion_strength"), py::arg("debye_length"),
        py::arg("blob_radius"),
        "Sum over targets (m, 3) and sources (N, 3) outside [exclude_start, exclude_stop) of the pair energy.");
  m.def("max_threads", &rmb::max_threads, "OpenMP threads available");
}
