// The multithreaded CPU backend. Declared here, beside its definition (cpu_backend.cc), so that
// core/kernels/backend.h, the interface every layer above the kernels uses, names no backend.
#pragma once

#include <memory>

#include "core/kernels/backend.h"

namespace plx {

// The multithreaded CPU backend (num_threads <= 0: the process-wide pool, one per core).
// `nice` > 0 (0-19): a pool of its own (one thread per core when num_threads <= 0) whose
// workers run at a lower CPU priority, for background work beside interactive work on the
// same cores; the thread calling the backend should lower its own priority too.
std::unique_ptr<Backend> MakeCpuBackend(int num_threads = 0, int nice = 0);

}  // namespace plx
