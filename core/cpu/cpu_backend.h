// The multithreaded CPU backend. Declared here, beside its definition (cpu_backend.cc), so that
// core/kernels/backend.h, the interface every layer above the kernels uses, names no backend.
#pragma once

#include <memory>

#include "core/kernels/backend.h"

namespace plx {

// The multithreaded CPU backend (num_threads <= 0: the process-wide pool, one per core).
std::unique_ptr<Backend> MakeCpuBackend(int num_threads = 0);

}  // namespace plx
