// OpenMP thread queries shared by the compiled modules (mobility, forces, Monte Carlo energies).
// Without OpenMP the kernels run on one thread and these return 1 and 0.
#pragma once

#ifdef _OPENMP
#include <omp.h>
#endif

namespace rmb {

// Threads a parallel region of the kernels may use.
inline int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

// Index of the calling thread inside a parallel region (0 outside one).
inline int thread_index() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

}  // namespace rmb
