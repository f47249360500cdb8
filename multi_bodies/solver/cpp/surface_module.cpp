// Surface kernels of phoretic and slip-length bodies (pybind11 module multi_bodies.solver._surface_cpp).
//
// layers: the Laplace layer potentials on the blobs, the compiled twin of multi_bodies/solver/laplace_kernels.py (the NumPy reference, same formulas, used when
// this module is not built): point quadrature at the blob centres, the free-space self term (j = i) dropped,
// and with a wall (z = 0) the Neumann image of every source, j = i included, with R = (x_i - x_j, y_i - y_j,
// z_i + z_j) and n* = (n_x, n_y, -n_z).  One pass over the pairs gives the four sums the solute needs:
//   single_i = sum_j ws_j / r,  double_i = sum_j wd_j (r.n_j) / r^3,
//   dipole_i = sum_j wp_j r / r^3,  grad_i = sum_j wg_j (n_j - 3 r (r.n_j) / r^2) / r^3
// (densities already multiplied by the quadrature weights; the 1/(4 pi) is applied by the caller).
// OpenMP over targets: each thread writes its own rows, no reductions across threads.
//
// Layouts (C-contiguous doubles): x, normals (N, 3); densities (N,) or empty (not computed); outputs
// single, double (N,), dipole, grad (N, 3).
//
// stokes_double_layer_blocks: the dense blocks of the same double layer from source blobs to targets, for a stack
// of P pairs (the slip-length neighbour correction, slip_length.py; NumPy reference double_layer_blocks):
// targets (P, nt, 3), sources and normals (P, ns, 3), weights (P, ns); out (P, 3 nt, 3 ns), its 3x3 block
// (i, j) = -(3/4 pi) w_j / r^5 [ (1 - 10 a^2/(3 r^2)) (r.n_j) r r^T + (2 a^2/3) (r n_j^T + n_j r^T + (r.n_j) I) ],
// zero for r < 1e-14.  OpenMP over the rows (pair and target): each thread writes its own rows.
//
// slip_length_near_field: the near field of the slip-length neighbour correction computed on the fly
// (slip_length.SlipLengthNeighbourPreconditioner; the stored-block path there is the reference):
//   out_i = sum over the partners q of body(i), over the blobs j of body partners[q], of
//           M(x_i - x_j - shift_q) lam_j - [double_layer_q] D(x_i - x_j) v_j,
// M the free-space RPY of blobs of radius a (viscosity eta, rpy_trans_trans_coefficients), D the double layer
// above.  offsets (Nb + 1,) the bodies' first blobs; target_start (Nb + 1,) each body's range of partners
// (partners (Q,), shifts (Q, 3), double_layer (Q,) 0 or 1).  OpenMP over the target blobs.  It reads only
// positions, so it costs the share of near pairs of one M f product, not a pass over stored blocks.
//
// laplace_blocks_and_moments: the pieces of the concentration problem's two-level preconditioner
// (multi_bodies/solver/laplace_preconditioner.py, NumPy reference there), in one pass over the pairs, of the
// pair kernel of the operator without its 1/2 and its 1/(4 pi):
//   K_ij = ws_j / r - wd_j (r.n_j) / r^3   (+ the same with the image R, n*; self terms as in layers)
// * every body's own block K_ij, i and j of body b, written row-major at block_start[b] + (i - o_b) n_b + (j - o_b);
// * the moments out[i, b, m] = sum over j of body b of K_ij Z_jm (Z (N, m): the coarse modes on every blob).
// OpenMP over targets i: each thread writes its own rows of both.
//
// stokes_double_layer: the regularised Stokes double layer of multi_bodies/solver/slip_length.py
// (double_layer, the NumPy reference): with r = x_i - x_j, pairs closer than 1e-14 skipped,
//   (D v)_i = -(3/4 pi) sum_j w_j / r^5 [ (1 - 10 a^2/(3 r^2)) (r.n_j)(r.v_j) r
//             + (2 a^2/3) ((n_j.v_j) r + (r.v_j) n_j + (r.n_j) v_j) ],  free space only.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "blob_pair_kernels.h"  // the free-space RPY of the mobility backends (mobility/cpp)
#include "openmp_threads.h"

// The loops, compiled once per vector path (the chosen one runs: mobility/cpp/simd_dispatch.h)
#define RMB_SIMD_KERNELS "surface_kernels.inc"
#include "simd_targets.h"

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

namespace {

const double *optional(const Array &a, long n, const char *name, bool &want) {
  want = a.size() > 0;
  if (want && (a.ndim() != 1 || a.shape(0) != n)) throw std::invalid_argument(std::string(name) + " must be (N,)");
  return want ? a.data() : nullptr;
}

py::tuple layers(const Array &x, const Array &normals, const Array &ws, const Array &wd, const Array &wp,
                 const Array &wg, bool wall) {
  if (x.ndim() != 2 || x.shape(1) != 3) throw std::invalid_argument("x must be (N, 3)");
  const long N = x.shape(0);
  if (normals.ndim() != 2 || normals.shape(0) != N || normals.shape(1) != 3)
    throw std::invalid_argument("normals must be (N, 3)");
  bool want_s, want_d, want_p, want_g;
  const double *s_ = optional(ws, N, "single density", want_s), *d_ = optional(wd, N, "double density", want_d);
  const double *p_ = optional(wp, N, "dipole density", want_p), *g_ = optional(wg, N, "gradient density", want_g);
  py::array_t<double> single(N), dbl(N), dip({N, 3L}), grad({N, 3L});
  const double *X = x.data(), *Nn = normals.data();
  double *out_s = single.mutable_data(), *out_d = dbl.mutable_data(), *out_p = dip.mutable_data(),
         *out_g = grad.mutable_data();
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(layers_loop(N, X, Nn, s_, d_, p_, g_, want_s, want_d, want_p, want_g, wall, out_s, out_d, out_p, out_g));
  }
  return py::make_tuple(single, dbl, dip, grad);
}

py::array_t<double> stokes_double_layer(const Array &x, const Array &normals, const Array &weights, double a,
                                        const Array &v) {
  if (x.ndim() != 2 || x.shape(1) != 3) throw std::invalid_argument("x must be (N, 3)");
  const long N = x.shape(0);
  if (normals.size() != 3 * N || v.size() != 3 * N || weights.size() != N)
    throw std::invalid_argument("normals and v must be (N, 3), weights (N,)");
  py::array_t<double> out({N, 3L});
  const double *X = x.data(), *Nn = normals.data(), *W = weights.data(), *V = v.data();
  double *O = out.mutable_data();
  const double a2 = a * a, self2 = 1e-28, factor = -3.0 / (4.0 * M_PI);
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(stokes_double_layer_loop(N, X, Nn, W, V, O, a2, self2, factor));
  }
  return out;
}

py::array_t<double> stokes_double_layer_blocks(const Array &targets, const Array &sources, const Array &normals,
                                               const Array &weights, double a) {
  if (targets.ndim() != 3 || targets.shape(2) != 3) throw std::invalid_argument("targets must be (P, nt, 3)");
  if (sources.ndim() != 3 || sources.shape(2) != 3 || sources.shape(0) != targets.shape(0))
    throw std::invalid_argument("sources must be (P, ns, 3) with the targets' P");
  const long P = targets.shape(0), nt = targets.shape(1), ns = sources.shape(1);
  if (normals.size() != P * ns * 3 || weights.size() != P * ns)
    throw std::invalid_argument("normals must be (P, ns, 3), weights (P, ns)");
  py::array_t<double> out({P, 3 * nt, 3 * ns});
  const double *T = targets.data(), *S = sources.data(), *Nn = normals.data(), *W = weights.data();
  double *O = out.mutable_data();
  const double a2 = a * a, self2 = 1e-28, factor = -3.0 / (4.0 * M_PI), b = (2.0 / 3.0) * a2;
  const long row_length = 3 * ns;
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(stokes_double_layer_blocks_loop(P, nt, ns, T, S, Nn, W, O, a2, self2, factor, b, row_length));
  }
  return out;
}

using Index = py::array_t<long, py::array::c_style | py::array::forcecast>;

py::array_t<double> slip_length_near_field(const Array &x, const Array &normals, const Array &weights, double a,
                                           double eta, const Index &offsets, const Index &target_start,
                                           const Index &partners, const Array &shifts, const Index &double_layer,
                                           const Array &lam, const Array &v) {
  if (x.ndim() != 2 || x.shape(1) != 3) throw std::invalid_argument("x must be (N, 3)");
  const long N = x.shape(0);
  if (normals.size() != 3 * N || weights.size() != N || lam.size() != 3 * N || v.size() != 3 * N)
    throw std::invalid_argument("normals, lam and v must be (N, 3), weights (N,)");
  const long B = offsets.shape(0) - 1;
  if (B < 0 || target_start.shape(0) != B + 1) throw std::invalid_argument("offsets and target_start: (Nb + 1,)");
  const long *off = offsets.data(), *start = target_start.data(), *partner = partners.data();
  const long Q = partners.shape(0);
  if (off[0] != 0 || off[B] != N || start[0] != 0 || start[B] != Q || shifts.size() != 3 * Q ||
      double_layer.shape(0) != Q)
    throw std::invalid_argument("offsets must span the blobs, target_start the partners; shifts (Q, 3), "
                                "double_layer (Q,)");
  for (long q = 0; q < Q; ++q)
    if (partner[q] < 0 || partner[q] >= B) throw std::invalid_argument("partners must be body indices");
  std::vector<long> body(N);
  for (long b = 0; b < B; ++b)
    for (long i = off[b]; i < off[b + 1]; ++i) body[i] = b;
  py::array_t<double> out({N, 3L});
  const double *X = x.data(), *Nn = normals.data(), *W = weights.data(), *L = lam.data(), *V = v.data();
  const double *S = shifts.data();
  const long *dl = double_layer.data();
  double *O = out.mutable_data();
  const double a2 = a * a, inv_a = 1.0 / a, mobility_unit = 1.0 / (8.0 * M_PI * eta * a), self2 = 1e-28;
  const double factor = -3.0 / (4.0 * M_PI), b2 = (2.0 / 3.0) * a2;
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(slip_length_near_field_loop(N, X, Nn, W, L, V, S, dl, O, a2, inv_a, mobility_unit, self2, factor, b2, start, off, partner, body));
  }
  return out;
}

py::tuple laplace_blocks_and_moments(const Array &x, const Array &normals, const Array &ws, const Array &wd,
                                    const py::array_t<long, py::array::c_style | py::array::forcecast> &offsets,
                                    const Array &modes, bool wall) {
  if (x.ndim() != 2 || x.shape(1) != 3) throw std::invalid_argument("x must be (N, 3)");
  const long N = x.shape(0);
  if (normals.size() != 3 * N || ws.size() != N || wd.size() != N)
    throw std::invalid_argument("normals must be (N, 3), ws and wd (N,)");
  if (offsets.ndim() != 1 || offsets.shape(0) < 1) throw std::invalid_argument("offsets must be (B + 1,)");
  const long B = offsets.shape(0) - 1;
  const long *off = offsets.data();
  if (off[0] != 0 || off[B] != N) throw std::invalid_argument("offsets must start at 0 and end at N");
  if (modes.ndim() != 2 || modes.shape(0) != N) throw std::invalid_argument("modes must be (N, m)");
  const long m = modes.shape(1);
  std::vector<long> body(N), block_start(B + 1, 0);
  for (long b = 0; b < B; ++b) {
    if (off[b + 1] < off[b]) throw std::invalid_argument("offsets must not decrease");
    for (long j = off[b]; j < off[b + 1]; ++j) body[j] = b;
    block_start[b + 1] = block_start[b] + (off[b + 1] - off[b]) * (off[b + 1] - off[b]);
  }
  py::array_t<double> blocks(block_start[B]), moments({N, B, m});
  const double *X = x.data(), *Nn = normals.data(), *S = ws.data(), *D = wd.data(), *Z = modes.data();
  double *out_blocks = blocks.mutable_data(), *out_moments = moments.mutable_data();
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(laplace_blocks_and_moments_loop(N, B, m, X, Nn, S, D, Z, body, block_start, off, out_blocks, out_moments, wall));
  }
  return py::make_tuple(blocks, moments);
}

}  // namespace

PYBIND11_MODULE(_surface_cpp, m) {
  m.doc() = "Laplace layers (laplace_kernels.py) and the Stokes double layer (slip_length.py) on the blobs";
  try {
    rmb_simd::chosen();  // RMB_SIMD naming a path that cannot run here stops the import with its one line
  } catch (const std::invalid_argument &err) {
    throw py::import_error(err.what());
  }
  m.def("simd_path", []() { return std::string(rmb_simd::path_name(rmb_simd::chosen())); },
        "The vector path of the surface loops (mobility/cpp/simd_dispatch.h).");
  m.def("layers", &layers, py::arg("x"), py::arg("normals"), py::arg("single"), py::arg("double_"),
        py::arg("dipole"), py::arg("grad_double"), py::arg("wall"),
        "(single (N,), double (N,), dipole (N, 3), grad_double (N, 3)); empty densities are not computed");
  m.def("stokes_double_layer", &stokes_double_layer, py::arg("x"), py::arg("normals"), py::arg("weights"),
        py::arg("blob_radius"), py::arg("v"), "(D v) (N, 3): the regularised free-space Stokes double layer");
  m.def("stokes_double_layer_blocks", &stokes_double_layer_blocks, py::arg("targets"), py::arg("sources"),
        py::arg("normals"), py::arg("weights"), py::arg("blob_radius"),
        "(P, 3 nt, 3 ns): the dense blocks of the double layer from a stack of source blobs to targets");
  m.def("slip_length_near_field", &slip_length_near_field, py::arg("x"), py::arg("normals"), py::arg("weights"),
        py::arg("blob_radius"), py::arg("eta"), py::arg("offsets"), py::arg("target_start"), py::arg("partners"),
        py::arg("shifts"), py::arg("double_layer"), py::arg("lam"), py::arg("v"),
        "(N, 3): M_near lam - D_near v over the listed body pairs, computed from the positions");
  m.def("laplace_blocks_and_moments", &laplace_blocks_and_moments, py::arg("x"), py::arg("normals"),
        py::arg("single"), py::arg("double_"), py::arg("offsets"), py::arg("modes"), py::arg("wall"),
        "(blocks (sum n_b^2,), moments (N, B, m)) of the Laplace pair kernel ws/r - wd r.n/r^3 (+ images)");
}
