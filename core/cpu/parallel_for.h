// The CPU backend's ParallelFor: runs f(i) for i in [0, n) on the thread pool. core/kernels
// drivers call it unqualified; cuda/parallel_for.cuh defines the GPU twin in plx::cuda.
#pragma once

#include <algorithm>
#include <cstdint>

#include "core/cpu/thread_pool.h"

namespace plx::cpu {

struct ExecContext {
  ThreadPool* pool = &DefaultThreadPool();
};

template <typename F>
void ParallelFor(const ExecContext& ctx, int64_t n, F f) {
  // About 8 chunks per thread balances uneven rays without much scheduling overhead.
  const int64_t grain =
      std::max<int64_t>(1, std::min<int64_t>(4096, n / (8 * ctx.pool->num_threads())));
  ctx.pool->ParallelForChunks(n, grain, [&f](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) f(i);
  });
}

}  // namespace plx::cpu
