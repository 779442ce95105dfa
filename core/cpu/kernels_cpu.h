// The CPU backend's kernel drivers (declared once in core/kernels/kernel_declarations.inc).
#pragma once

#include "core/cpu/parallel_for.h"
#include "absl/status/status.h"
#include "core/kernels/kernel_args.h"

namespace plx::cpu {
#include "core/kernels/kernel_declarations.inc"
}  // namespace plx::cpu
