// Compiles one kernel source once for every path of simd_dispatch.h.
//
// Usage, in a translation unit, after every standard and pybind11 header it needs:
//   #define RMB_SIMD_KERNELS "mobility_kernels.inc"
//   #include "simd_targets.h"
// For each path this build holds, the kernel source is included inside namespace rmb_k_<path>, after the
// path's vector type and math (simd_vector.inc), the tiled two-pass rows (simd_tiles.inc) and the pair formulas
// (blob_pair_formulas.inc), between
// `#pragma GCC push_options / target(...)` (Clang: `#pragma clang attribute`), so that every function defined
// there is compiled for that instruction set and nothing else is: the standard library and pybind11 code stay
// compiled for the baseline (an inline function compiled with AVX2 in one file and chosen by the linker for
// every caller would crash a CPU without AVX2).  Templates defined in the region keep its target where they are
// instantiated.  Kernel sources hold no #include of their own.
#include "simd_dispatch.h"

#ifndef RMB_SIMD_KERNELS
#error "define RMB_SIMD_KERNELS (the kernel source to compile for every path) before including simd_targets.h"
#endif

#define RMB_KIND_SCALAR 0
#define RMB_KIND_AVX2 1
#define RMB_KIND_AVX512 2
#define RMB_KIND_NEON 3
#define RMB_KIND_SVE 4

#if defined(__x86_64__) && (defined(RMB_BUILD_AVX2) || defined(RMB_BUILD_AVX512))
#include <immintrin.h>
#endif
#if defined(RMB_BUILD_NEON)
#include <arm_neon.h>
#endif

// ---- scalar: the baseline target of the build
#define RMB_SIMD_KIND RMB_KIND_SCALAR
namespace rmb_k_scalar {
#include "simd_vector.inc"
#include "simd_tiles.inc"
#include "blob_pair_formulas.inc"
#include RMB_SIMD_KERNELS
#undef RMB_SIMD_ONE_LANE
}  // namespace rmb_k_scalar
#undef RMB_SIMD_KIND

#ifdef RMB_BUILD_AVX2
#define RMB_SIMD_KIND RMB_KIND_AVX2
#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx2,fma"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#endif
namespace rmb_k_avx2 {
#include "simd_vector.inc"
#include "simd_tiles.inc"
#include "blob_pair_formulas.inc"
#include RMB_SIMD_KERNELS
#undef RMB_SIMD_ONE_LANE
}  // namespace rmb_k_avx2
#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#undef RMB_SIMD_KIND
#endif

#ifdef RMB_BUILD_AVX512
#define RMB_SIMD_KIND RMB_KIND_AVX512
#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx512f,avx512dq,avx2,fma"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx512f,avx512dq,avx2,fma")
#endif
namespace rmb_k_avx512 {
#include "simd_vector.inc"
#include "simd_tiles.inc"
#include "blob_pair_formulas.inc"
#include RMB_SIMD_KERNELS
#undef RMB_SIMD_ONE_LANE
}  // namespace rmb_k_avx512
#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#undef RMB_SIMD_KIND
#endif

#ifdef RMB_BUILD_NEON
// Advanced SIMD is the baseline of AArch64: no target attribute needed
#define RMB_SIMD_KIND RMB_KIND_NEON
namespace rmb_k_neon {
#include "simd_vector.inc"
#include "simd_tiles.inc"
#include "blob_pair_formulas.inc"
#include RMB_SIMD_KERNELS
#undef RMB_SIMD_ONE_LANE
}  // namespace rmb_k_neon
#undef RMB_SIMD_KIND
#endif

#ifdef RMB_BUILD_SVE
#define RMB_SIMD_KIND RMB_KIND_SVE
#pragma GCC push_options
#pragma GCC target("+sve")
namespace rmb_k_sve {
#include "simd_vector.inc"
#include "simd_tiles.inc"
#include "blob_pair_formulas.inc"
#include RMB_SIMD_KERNELS
#undef RMB_SIMD_ONE_LANE
}  // namespace rmb_k_sve
#pragma GCC pop_options
#undef RMB_SIMD_KIND
#endif

#undef RMB_SIMD_KERNELS
