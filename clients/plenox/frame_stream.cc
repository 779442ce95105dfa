#include "clients/plenox/frame_stream.h"

#include "absl/strings/str_cat.h"

namespace plx::cli {

absl::Time FramePacing::Due(absl::Time start, double t0, double t) const {
  if (kind != Kind::kRealtime) return start;
  return start + absl::Seconds((t - t0) / speed);
}

std::vector<double> RoundtripMs(const std::vector<FrameRecord>& records, size_t first) {
  std::vector<double> ms;
  for (size_t k = first; k < records.size(); ++k) ms.push_back(records[k].roundtrip_ms);
  return ms;
}

std::vector<double> DaemonMs(const std::vector<FrameRecord>& records, size_t first) {
  std::vector<double> ms;
  for (size_t k = first; k < records.size(); ++k) ms.push_back(records[k].daemon_ms);
  return ms;
}

std::string FrameTimingsText(const std::string& header, const std::vector<FrameRecord>& records,
                             size_t first) {
  std::string text = header;
  for (size_t k = first; k < records.size(); ++k) {
    const FrameRecord& r = records[k];
    absl::StrAppendFormat(&text, "%d %.6f %.3f %.3f%s\n", r.index, r.timestamp, r.roundtrip_ms,
                          r.daemon_ms, r.note.empty() ? "" : absl::StrCat(" ", r.note));
  }
  return text;
}

}  // namespace plx::cli
