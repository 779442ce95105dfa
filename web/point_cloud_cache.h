// The viewer's point clouds: the map's coloured surface points (core/formats/ply_export.h, as
// the Export RPC writes them) for one published version, thinned to a bounded number of points,
// built once per (map, version) and kept for the next requests. Pages poll while a map grows and
// fetch a cloud only when its version changed; the cache keeps the few newest clouds and builds
// one at a time, so many pages cost one export per version, not one per request.
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "web/viewer_source.h"

namespace plx::web {

// Binary little-endian PLY (x y z float, red green blue uchar), at most `max_points` points.
struct PointCloud {
  std::string ply;
  int64_t points = 0;        // in the PLY
  int64_t surface_points = 0;  // before thinning
};

// Keeps every k-th point of an ExportSurfacePointsPly file so at most `max_points` remain, and
// rewrites the header's count. InvalidArgument when `ply` is not such a file.
absl::StatusOr<PointCloud> ThinPointCloudPly(const std::string& ply, int64_t max_points);

class PointCloudCache {
 public:
  // Clouds kept (the newest built); each is at most max_points * 15 bytes plus the header.
  static constexpr size_t kEntries = 4;

  explicit PointCloudCache(int64_t max_points) : max_points_(max_points) {}

  absl::StatusOr<std::shared_ptr<const PointCloud>> Get(const std::string& name,
                                                         const ViewerMap& map);

 private:
  struct Entry {
    std::string name;
    uint64_t version = 0;
    std::shared_ptr<const PointCloud> cloud;
  };
  const int64_t max_points_;
  std::mutex mutex_;  // held while a cloud is built: one export at a time
  std::list<Entry> entries_;  // newest first
};

}  // namespace plx::web
