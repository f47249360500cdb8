// Run-time choice of the vector instruction set of the compiled kernels (every extension that includes it).
//
// The kernels of an extension are compiled once for each path below (simd_targets.h: the same source in one
// namespace per path, each under its own target attribute), and one path runs: the widest one that this build
// holds and this CPU reports, chosen once when the first kernel asks.  The environment variable RMB_SIMD forces
// a path (tests and benchmarks); a path the build or the CPU lacks is refused with one line naming the variable
// and the paths that can run here.
//
//   scalar  the portable source, one pair at a time (the compiler may still vectorise it for the baseline
//           instruction set, SSE2 on x86-64); the reference of the tests
//   avx2    4 doubles, AVX2 and FMA (x86-64)
//   avx512  8 doubles, AVX-512 F and DQ (x86-64)
//   neon    2 doubles, Advanced SIMD (every 64-bit ARM CPU)
//   sve     the scalar source vectorised by the compiler for SVE (length-agnostic; chosen over neon only when the
//           CPU's SVE vectors are wider than 128 bits)
#ifndef RMB_SIMD_DISPATCH_H
#define RMB_SIMD_DISPATCH_H

#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#if defined(__aarch64__) && defined(__linux__)
#include <sys/auxv.h>
#include <sys/prctl.h>
#endif

// Which paths this compiler can build (GCC vector extensions and target attributes: GCC and Clang).
#if (defined(__GNUC__) || defined(__clang__)) && !defined(RMB_SIMD_SCALAR_ONLY)
#if defined(__x86_64__)
#define RMB_BUILD_AVX2 1
#define RMB_BUILD_AVX512 1
#elif defined(__aarch64__)
#define RMB_BUILD_NEON 1
#if defined(__linux__) && defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 11
#define RMB_BUILD_SVE 1
#endif
#endif
#endif

namespace rmb_simd {

enum Path { kScalar = 0, kAVX2 = 1, kAVX512 = 2, kNEON = 3, kSVE = 4, kPathCount = 5 };

inline const char *path_name(int path) {
  static const char *names[kPathCount] = {"scalar", "avx2", "avx512", "neon", "sve"};
  return path >= 0 && path < kPathCount ? names[path] : "unknown";
}

// True when this build holds the kernels of `path`.
inline bool built(int path) {
  switch (path) {
    case kScalar: return true;
#ifdef RMB_BUILD_AVX2
    case kAVX2: return true;
#endif
#ifdef RMB_BUILD_AVX512
    case kAVX512: return true;
#endif
#ifdef RMB_BUILD_NEON
    case kNEON: return true;
#endif
#ifdef RMB_BUILD_SVE
    case kSVE: return true;
#endif
    default: return false;
  }
}

// Bytes of one SVE vector of this CPU (0: no SVE).
inline int sve_vector_bytes() {
#if defined(__aarch64__) && defined(__linux__) && defined(HWCAP_SVE) && defined(PR_SVE_GET_VL)
  if (!(getauxval(AT_HWCAP) & HWCAP_SVE)) return 0;
  const int vl = prctl(PR_SVE_GET_VL);
  return vl < 0 ? 0 : (vl & PR_SVE_VL_LEN_MASK);
#else
  return 0;
#endif
}

// True when this CPU runs the instructions of `path` (what it reports, asked once per call).
inline bool cpu_has(int path) {
  switch (path) {
    case kScalar: return true;
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
    case kAVX2: __builtin_cpu_init(); return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    case kAVX512:
      __builtin_cpu_init();
      return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
             __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#endif
#if defined(__aarch64__)
    case kNEON: return true;  // Advanced SIMD is part of every ARMv8-A CPU
    case kSVE: return sve_vector_bytes() > 0;
#endif
    default: return false;
  }
}

// The paths this build holds and this CPU runs, best first.
inline std::vector<int> usable_paths() {
  std::vector<int> paths;
  const bool wide_sve = sve_vector_bytes() > 16;
  const int order[] = {kAVX512, kAVX2, wide_sve ? kSVE : kNEON, wide_sve ? kNEON : kSVE, kScalar};
  for (int path : order)
    if (built(path) && cpu_has(path)) paths.push_back(path);
  return paths;
}

inline std::string usable_names() {
  std::string text;
  for (int path : usable_paths()) text += (text.empty() ? "" : ", ") + std::string(path_name(path));
  return text;
}

// The path RMB_SIMD asks for (unset, empty or "auto": the best usable one); throws std::invalid_argument with
// one line when it names a path that cannot run here.
inline int path_from_environment() {
  const char *value = std::getenv("RMB_SIMD");
  const std::string asked = value ? value : "";
  if (asked.empty() || asked == "auto") return usable_paths().front();
  for (int path = 0; path < kPathCount; ++path) {
    if (asked != path_name(path)) continue;
    if (!built(path))
      throw std::invalid_argument("RMB_SIMD=" + asked + ": this build has no " + asked + " kernels (" +
                                  "this machine runs: " + usable_names() + "); unset RMB_SIMD or choose one of those");
    if (!cpu_has(path))
      throw std::invalid_argument("RMB_SIMD=" + asked + ": this CPU does not report " + asked +
                                  " (this machine runs: " + usable_names() + "); unset RMB_SIMD or choose one of those");
    return path;
  }
  throw std::invalid_argument("RMB_SIMD=" + asked + " is not a kernel path; this machine runs: " + usable_names() +
                              " (or auto)");
}

// The path of this process, chosen at the first call (the module's import) and kept.
inline int &chosen_path_storage() {
  static int path = -1;
  return path;
}

inline int chosen() {
  int &path = chosen_path_storage();
  if (path < 0) path = path_from_environment();
  return path;
}

// Choose again from RMB_SIMD (for tests that switch paths in one process); returns the new path.
inline int choose_again() {
  chosen_path_storage() = -1;
  return chosen();
}

}  // namespace rmb_simd

// RMB_SIMD_DISPATCH(function<args>(arguments...)): call the kernel of the chosen path, which simd_targets.h
// placed in namespace rmb_k_<path>.  The kernel returns nothing (its results go to its arguments).
#ifdef RMB_BUILD_AVX512
#define RMB_SIMD_CASE_AVX512(...) \
  case rmb_simd::kAVX512: rmb_k_avx512::__VA_ARGS__; break;
#else
#define RMB_SIMD_CASE_AVX512(...)
#endif
#ifdef RMB_BUILD_AVX2
#define RMB_SIMD_CASE_AVX2(...) \
  case rmb_simd::kAVX2: rmb_k_avx2::__VA_ARGS__; break;
#else
#define RMB_SIMD_CASE_AVX2(...)
#endif
#ifdef RMB_BUILD_NEON
#define RMB_SIMD_CASE_NEON(...) \
  case rmb_simd::kNEON: rmb_k_neon::__VA_ARGS__; break;
#else
#define RMB_SIMD_CASE_NEON(...)
#endif
#ifdef RMB_BUILD_SVE
#define RMB_SIMD_CASE_SVE(...) \
  case rmb_simd::kSVE: rmb_k_sve::__VA_ARGS__; break;
#else
#define RMB_SIMD_CASE_SVE(...)
#endif
#define RMB_SIMD_DISPATCH(...)                                                                         \
  do {                                                                                                 \
    switch (rmb_simd::chosen()) {                                                                      \
      RMB_SIMD_CASE_AVX512(__VA_ARGS__) RMB_SIMD_CASE_AVX2(__VA_ARGS__) RMB_SIMD_CASE_NEON(__VA_ARGS__) \
      RMB_SIMD_CASE_SVE(__VA_ARGS__) default: rmb_k_scalar::__VA_ARGS__; break;                        \
    }                                                                                                  \
  } while (0)

#endif  // RMB_SIMD_DISPATCH_H
