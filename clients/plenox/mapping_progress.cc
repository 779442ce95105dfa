#include "clients/plenox/mapping_progress.h"

#include "absl/strings/str_format.h"

namespace plx::cli {

std::function<bool(const MapDatasetProgress&)> MappingProgressPrinter(ProgressLine* line) {
  return [line](const MapDatasetProgress& p) {
    if (!p.optimizing) {
      line->Update(absl::StrFormat("loading keyframes %d/%d", p.keyframes_loaded,
                                   p.keyframes_total));
    } else {
      const MappingProgress& o = p.optimization;
      line->Update(absl::StrFormat(
          "mapping %3.0f%%  iter %5d  %6.1f s  train PSNR %5.2f dB  depth L1 %5.2f cm  "
          "opacity %.3f",
          100.0 * o.progress, o.iteration, o.elapsed_s, o.psnr, 100.0 * o.depth_l1_m,
          o.opacity));
    }
    return true;
  };
}

std::string MappingSummaryText(const MappingSummary& s) {
  return absl::StrFormat(
      "mapped %d keyframes (%d rays) in %.1f s (init %.1f s): %d iterations, %d bricks, "
      "%.1f MB map + %.1f MB optimiser state%s; last batch PSNR %.2f dB, depth L1 %.2f cm",
      s.keyframes, s.training_rays, s.allocation_s + s.optimization_s, s.allocation_s,
      s.iterations, s.memory.bricks, s.memory.total_bytes() / 1e6, s.optimizer_bytes / 1e6,
      s.upsampled ? " (coarse-to-fine)" : "", s.last.psnr, 100.0 * s.last.depth_l1_m);
}

}  // namespace plx::cli
