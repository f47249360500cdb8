// The dense blob mobility matrices of mobility._mobility_cpp (dense_matrices.cpp).
#pragma once

#include <pybind11/pybind11.h>

// Adds the dense-matrix functions (dense_trans_trans, its stacks and cross blocks, dense_radii,
// dense_free_surface) to the module.
void register_dense_matrices(pybind11::module_ &m);
