// The CPU backend's kernel drivers (declared once in core/kernels/kernel_declarations.inc).
#pragma once

#include "core/cpu/parallel_for.h"
#include "absl/status/status.h"
#include "core/grid/grid_view.h"
#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_types.h"
#include "core/kernels/marching_cubes.h"
#include "core/kernels/tracking_terms.h"

namespace plx::cpu {
#include "core/kernels/kernel_declarations.inc"
}  // namespace plx::cpu
