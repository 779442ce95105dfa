// CPU shell for core/kernels/tracking_impl.h (the CUDA twin is cuda/tracking_cuda.cu), plus the
// CPU reduction of the per-ray terms.
#define PLX_BACKEND_NS cpu
#include <algorithm>
#include <vector>

#include "core/cpu/kernels_cpu.h"
#include "core/kernels/tracking_impl.h"

namespace plx::cpu {

absl::Status Run(const ExecContext& ctx, const ReduceTrackingTermsArgs& args) {
  const TrackingRayTerm* const terms = args.terms;
  const int64_t count = args.count;
  // Fixed chunks, each summed by whichever thread takes it, then added in chunk order.
  constexpr int64_t kChunk = 256;
  const int64_t chunks = (count + kChunk - 1) / kChunk;
  std::vector<TrackingSums> partial(static_cast<size_t>(chunks));
  ctx.pool->ParallelForChunks(chunks, 1, [&](int64_t begin, int64_t end) {
    for (int64_t c = begin; c < end; ++c) {
      TrackingSums& s = partial[c];
      s.Clear();
      for (int64_t i = c * kChunk; i < std::min(count, (c + 1) * kChunk); ++i) {
        AccumulateTrackingTerm(terms[i], args.loss, args.huber_k, args.scale, &s);
      }
    }
  });
  args.sums->Clear();
  for (const TrackingSums& s : partial) args.sums->Add(s);
  return absl::OkStatus();
}

}  // namespace plx::cpu
