// The CUDA backend's kernel drivers: the same list as the CPU backend
// (core/kernels/kernel_declarations.inc), compiled by nvcc from the same *_impl.h sources.
#pragma once

#include "core/grid/grid_view.h"
#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_types.h"
#include "core/tracking/tracking_terms.h"
#include "cuda/parallel_for.cuh"

namespace plx::cuda {
#include "core/kernels/kernel_declarations.inc"
}  // namespace plx::cuda
