// Shared by the path check programs of tests/cpp (each built on its own by tests/test_simd_cross.py).
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

// The largest difference between a path's results and the scalar path's, each result (a vector) relative to its
// largest scalar entry; the worst over the results.
inline double worst_relative_difference(const std::vector<std::vector<double>> &reference,
                                        const std::vector<std::vector<double>> &ours) {
  double worst = 0.0;
  for (std::size_t k = 0; k < reference.size(); ++k) {
    double scale = 1e-300, difference = 0.0;
    for (std::size_t i = 0; i < reference[k].size(); ++i) {
      scale = std::fmax(scale, std::fabs(reference[k][i]));
      difference = std::fmax(difference, std::fabs(reference[k][i] - ours[k][i]));
    }
    worst = std::fmax(worst, difference / scale);
  }
  return worst;
}
