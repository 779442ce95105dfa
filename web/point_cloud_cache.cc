#include "web/point_cloud_cache.h"

#include <algorithm>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "core/formats/ply_export.h"

namespace plx::web {
namespace {

// x y z float32 + red green blue uint8, as ExportSurfacePointsPly writes each point.
constexpr size_t kPointBytes = 15;
constexpr char kCountLine[] = "\nelement vertex ";
constexpr char kEndHeader[] = "end_header\n";

}  // namespace

absl::StatusOr<PointCloud> ThinPointCloudPly(const std::string& ply, int64_t max_points) {
  const size_t count_at = ply.find(kCountLine);
  const size_t end_at = ply.find(kEndHeader);
  if (count_at == std::string::npos || end_at == std::string::npos || count_at > end_at) {
    return absl::InvalidArgumentError("not a point-cloud PLY");
  }
  const size_t digits_at = count_at + sizeof(kCountLine) - 1;
  const size_t digits_end = ply.find('\n', digits_at);
  int64_t points = 0;
  if (!absl::SimpleAtoi(ply.substr(digits_at, digits_end - digits_at), &points) || points < 0) {
    return absl::InvalidArgumentError("PLY: bad vertex count");
  }
  const size_t body_at = end_at + sizeof(kEndHeader) - 1;
  if (ply.size() - body_at != static_cast<size_t>(points) * kPointBytes) {
    return absl::InvalidArgumentError("PLY: the body does not hold the vertex count's points");
  }
  PointCloud out;
  out.surface_points = points;
  const int64_t stride = max_points <= 0 ? 1 : std::max<int64_t>(1, (points + max_points - 1) /
                                                                        max_points);
  if (stride == 1) {
    out.ply = ply;
    out.points = points;
    return out;
  }
  std::string body;
  body.reserve(static_cast<size_t>(points / stride + 1) * kPointBytes);
  for (int64_t i = 0; i < points; i += stride) {
    body.append(ply, body_at + static_cast<size_t>(i) * kPointBytes, kPointBytes);
    ++out.points;
  }
  out.ply = absl::StrCat(ply.substr(0, digits_at), out.points,
                         ply.substr(digits_end, body_at - digits_end), body);
  return out;
}

absl::StatusOr<std::shared_ptr<const PointCloud>> PointCloudCache::Get(const std::string& name,
                                                                        const ViewerMap& map) {
  return cache_.Get(name, map.version, [&]() -> absl::StatusOr<PointCloud> {
    absl::StatusOr<PlyExport> exported =
        ExportSurfacePointsPly(*map.map, kDefaultExportMinDensity);
    if (!exported.ok()) return exported.status();
    return ThinPointCloudPly(exported->bytes, max_points_);
  });
}

}  // namespace plx::web
