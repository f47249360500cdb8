// The blob-blob soft repulsion of multi_bodies/solver/cpp/forces_kernels.inc without Python: every path this CPU
// runs against the scalar path on the same blobs (free and periodic, one radius and per-blob radii, a coincident
// pair, contacts on both sides of the law's kink).  tests/test_simd_cross.py builds it natively and for AArch64
// under an emulator (the NEON path, whose vector exponential and 1/|r| no x86-64 CPU runs).
// Output: one line per path, "<path> <worst difference to scalar relative to the largest force> 0".
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "fast_exp.h"
#include "openmp_threads.h"
#include "pair_laws.h"
#include "worst_difference.h"

#define RMB_SIMD_KERNELS "forces_kernels.inc"
#include "simd_targets.h"

// The forces (3n: x, y, z apart) of the blobs in the path chosen now, for one radius (radii empty) or per-blob radii.
static std::vector<double> forces(const std::vector<double> &x, const std::vector<double> &y,
                                  const std::vector<double> &z, const std::vector<double> &radii, double L) {
  const long n = static_cast<long>(x.size());
  std::vector<double> acc(3 * n, 0.0);
  const rmb::SoftRepulsion law = rmb::soft_repulsion(1.3, 0.7, 2.0 * 0.25);
  if (radii.empty())
    RMB_SIMD_DISPATCH(blob_blob_pair_sums<false>(n, x.data(), y.data(), z.data(), nullptr, L, L, 0.0, law, 1.3, 0.7,
                                                 acc.data(), false));
  else
    RMB_SIMD_DISPATCH(blob_blob_pair_sums<true>(n, x.data(), y.data(), z.data(), radii.data(), L, L, 0.0, law, 1.3,
                                                0.7, acc.data(), false));
  return acc;
}

int main() {
  std::mt19937_64 generator(3);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const int n = 101;  // not a multiple of any vector width
  std::vector<double> x(n), y(n), z(n), radii(n);
  for (int i = 0; i < n; ++i)
    x[i] = 6 * uniform(generator), y[i] = 6 * uniform(generator), z[i] = 6 * uniform(generator),
    radii[i] = 0.1 + 0.3 * uniform(generator);
  x[5] = x[4], y[5] = y[4], z[5] = z[4];  // a coincident pair (|r| floored)
  x[7] = x[6] + 0.3, y[7] = y[6], z[7] = z[6];  // overlapping (|r| < 2a)
  const std::vector<double> none;
  auto all = [&]() {
    std::vector<std::vector<double>> out;
    for (double L : {0.0, 5.0}) {
      out.push_back(forces(x, y, z, none, L));
      out.push_back(forces(x, y, z, radii, L));
    }
    return out;
  };
  setenv("RMB_SIMD", "scalar", 1);
  rmb_simd::choose_again();
  const std::vector<std::vector<double>> reference = all();
  for (int path : rmb_simd::usable_paths()) {
    setenv("RMB_SIMD", rmb_simd::path_name(path), 1);
    rmb_simd::choose_again();
    const std::vector<std::vector<double>> ours = all();
    const double worst = worst_relative_difference(reference, ours);
    std::printf("%s %.3g 0\n", rmb_simd::path_name(path), worst);
  }
  return 0;
}
