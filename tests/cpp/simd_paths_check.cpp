// The kernel paths of mobility/cpp without Python: every path this CPU runs against the scalar path on the
// same blobs, and the vector 1/sqrt against long double.  tests/test_simd_cross.py cross-compiles it for
// AArch64 and runs it under an emulator (the NEON and SVE paths); it builds natively as well.
// Output: one line per path, "<path> <worst relative difference to scalar> <worst 1/sqrt error in ulp>".
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <type_traits>
#include <vector>

#include "blob_pair_kernels.h"
#include "openmp_threads.h"
#include "worst_difference.h"

// The few helpers of blob_arrays.h the kernels use, without pybind11.
namespace rmb_blobs {
struct Blobs {
  std::size_t n = 0;
  std::vector<double> x, y, z, vx, vy, vz, damping, radius;
};
inline bool worth_threads(std::size_t targets, std::size_t sources) {
  return static_cast<double>(targets) * static_cast<double>(sources) > 1e5;
}
inline std::vector<double> image_shifts(const std::vector<double> &L) {
  std::vector<double> shifts;
  const int nx = L[0] > 0, ny = L[1] > 0, nz = L[2] > 0;
  for (int i = -nx; i <= nx; ++i)
    for (int j = -ny; j <= ny; ++j)
      for (int k = -nz; k <= nz; ++k) {
        shifts.push_back(i * L[0]);
        shifts.push_back(j * L[1]);
        shifts.push_back(k * L[2]);
      }
  return shifts;
}
enum Domain { kNoWall = 0, kWall = 1, kFreeSurface = 2 };
}  // namespace rmb_blobs

#define RMB_SIMD_KERNELS "mobility_kernels.inc"
#include "simd_targets.h"

using rmb_blobs::Blobs;

// Every product of the kernels on b (targets t for the source-target sums), in the path chosen now.
static std::vector<std::vector<double>> products(const Blobs &b, const Blobs &t) {
  std::vector<std::vector<double>> out;
  std::vector<double> ux, uy, uz, two;
  auto keep = [&]() {
    std::vector<double> v(ux);
    v.insert(v.end(), uy.begin(), uy.end());
    v.insert(v.end(), uz.begin(), uz.end());
    out.push_back(v);
  };
  const std::vector<double> L0 = {0, 0, 0}, L = {5.5, 4.5, 0}, L3 = {5.5, 4.5, 6.0};
  RMB_SIMD_DISPATCH(trans_times_force_symmetric<true, false, double>(b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(trans_times_force_symmetric<false, false, double>(b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(trans_times_force_symmetric<true, true, double>(b, L, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(trans_times_force_symmetric<false, true, double>(b, L3, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(one_sided_sum<0, true, false>(b, b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(one_sided_sum<1, true, true>(b, b, L, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(one_sided_sum<2, false, false>(b, b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(one_sided_sum<3, false, true>(b, b, L, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(radii_symmetric_sum<true, false>(b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(radii_symmetric_sum<false, true>(b, L3, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(source_target_sum<rmb_blobs::kWall, false>(t, b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(source_target_sum<rmb_blobs::kFreeSurface, false>(t, b, L0, ux, uy, uz));
  keep();
  RMB_SIMD_DISPATCH(trans_times_force_symmetric_two<true>(b, b, two));
  out.push_back(two);
  Blobs g = b;  // a second vector (the torques of the grand product): the first one reversed
  std::reverse(g.vx.begin(), g.vx.end()), std::reverse(g.vy.begin(), g.vy.end()), std::reverse(g.vz.begin(), g.vz.end());
  RMB_SIMD_DISPATCH(trans_times_force_symmetric_two<false>(b, g, two));
  out.push_back(two);
  RMB_SIMD_DISPATCH(grand_product_symmetric<true, false>(b, g, L0, two));
  out.push_back(two);
  RMB_SIMD_DISPATCH(grand_product_symmetric<false, true>(b, g, L, two));
  out.push_back(two);
  return out;
}

int main() {
  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Blobs b;
  b.n = 45;  // not a multiple of any vector width
  for (std::size_t i = 0; i < b.n; ++i) {
    b.x.push_back(5 * uniform(generator)), b.y.push_back(5 * uniform(generator));
    b.z.push_back(0.5 + 3 * uniform(generator));
    b.vx.push_back(uniform(generator) - 0.5), b.vy.push_back(uniform(generator) - 0.5);
    b.vz.push_back(uniform(generator) - 0.5), b.radius.push_back(0.15 + 0.3 * uniform(generator));
  }
  b.x[1] = b.x[0] + 0.2, b.y[1] = b.y[0], b.z[1] = b.z[0];  // an overlapping pair
  Blobs t = b;
  t.n = 20;
  setenv("RMB_SIMD", "scalar", 1);
  rmb_simd::choose_again();
  const std::vector<std::vector<double>> reference = products(b, t);
  std::vector<double> x(4000), rsqrt(4000), image(4000);
  for (double &v : x) v = std::pow(10.0, -300.0 + 600.0 * uniform(generator));
  for (int path : rmb_simd::usable_paths()) {
    setenv("RMB_SIMD", rmb_simd::path_name(path), 1);
    rmb_simd::choose_again();
    const std::vector<std::vector<double>> ours = products(b, t);
    const double worst = worst_relative_difference(reference, ours);
    RMB_SIMD_DISPATCH(math_check(x.data(), x.size(), 5.0, rsqrt.data(), image.data()));
    double ulps = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      const long double exact = 1.0L / std::sqrt(static_cast<long double>(x[i]));
      const double nearest = static_cast<double>(exact);
      const long double spacing = std::nextafter(nearest, INFINITY) - nearest;
      ulps = std::fmax(ulps, static_cast<double>(std::fabs(rsqrt[i] - exact) / spacing));
    }
    std::printf("%s %.3g %.3f\n", rmb_simd::path_name(path), worst, ulps);
  }
  return 0;
}
