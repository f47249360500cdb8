// exp(x) for x <= 0 that vectorises (host code only: the C++ force and Monte Carlo energy modules).
// std::exp does not vectorise without -ffast-math, so the pair loops of the soft repulsions use this.
#pragma once

#include <cstdint>
#include <cstring>

namespace rmb {

// exp(x) for x <= 0, branch-free so that the pair loops vectorise (std::exp does not without
// -ffast-math).  x = n ln2 + s with |s| <= ln2/2 (Cody-Waite split of ln2), a degree-12 Taylor
// polynomial for exp(s) (truncation < 2e-17 relative) and 2^n from the exponent bits.  Agrees with
// std::exp to about one ulp; returns 0 below x = -708 (where exp(x) < 3.3e-308).
inline double exp_nonpositive(double x) {
  const double log2e = 1.4426950408889634, ln2_hi = 0.693147180369123816490, ln2_lo = 1.90821492927058770002e-10;
  const double shifter = 6755399441055744.0;  // 1.5 * 2^52: adding it rounds to an integer held in the low bits
  const bool underflow = x < -708.0;
  x = underflow ? -708.0 : x;
  const double t = x * log2e + shifter;
  const double n = t - shifter;
  const double s = (x - n * ln2_hi) - n * ln2_lo;
  double p = 1.0 / 479001600.0;
  p = p * s + 1.0 / 39916800.0;
  p = p * s + 1.0 / 3628800.0;
  p = p * s + 1.0 / 362880.0;
  p = p * s + 1.0 / 40320.0;
  p = p * s + 1.0 / 5040.0;
  p = p * s + 1.0 / 720.0;
  p = p * s + 1.0 / 120.0;
  p = p * s + 1.0 / 24.0;
  p = p * s + 1.0 / 6.0;
  p = p * s + 0.5;
  p = p * s + 1.0;
  p = p * s + 1.0;
  std::int64_t t_bits, shifter_bits;
  std::memcpy(&t_bits, &t, sizeof t);
  std::memcpy(&shifter_bits, &shifter, sizeof shifter);
  const std::int64_t scale_bits = (t_bits - shifter_bits + 1023) << 52;  // 2^n, n >= -1022 here
  double scale;
  std::memcpy(&scale, &scale_bits, sizeof scale);
  return underflow ? 0.0 : p * scale;
}

struct FastExp {
  double operator()(double x) const { return exp_nonpositive(x); }
};

}  // namespace rmb

