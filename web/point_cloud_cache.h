// What the viewer builds from a published map version and serves to every page that asks:
// the coloured surface points (here) and the mesh (web/viewer_mesh.h). Pages poll while a map
// grows and fetch again only when its version changed; MapVersionCache keeps the few newest
// results per (map, version) and builds one at a time, so many pages cost one build per
// version, not one per request, and the memory held stays bounded (entries x the largest
// result the builder makes).
#pragma once

#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "web/viewer_source.h"

namespace plx::web {

// The newest `entries` results of a build per (map name, variant, version); the results for an
// older version of a map (any variant) are dropped when a newer one is built. A variant tells
// results of one version apart (the mesh's levels of detail: its triangle budget, and a region's
// box with its budget); most caches have one (0). Thread-safe; builds run one at a time (the
// mutex is held while one runs, so a second page asking for the same version waits and then
// finds it). A failed build is not kept: the next request tries again.
template <typename T>
class MapVersionCache {
 public:
  using Build = std::function<absl::StatusOr<T>()>;

  explicit MapVersionCache(size_t entries) : max_entries_(entries < 1 ? 1 : entries) {}

  absl::StatusOr<std::shared_ptr<const T>> Get(const std::string& name, uint64_t version,
                                               const Build& build) {
    return Get(name, 0, version, build);
  }

  absl::StatusOr<std::shared_ptr<const T>> Get(const std::string& name, int64_t variant,
                                               uint64_t version, const Build& build) {
    return Get(name, std::to_string(variant), version, build);
  }

  // A variant named by text (a mesh region and its budget).
  absl::StatusOr<std::shared_ptr<const T>> Get(const std::string& name,
                                               const std::string& variant, uint64_t version,
                                               const Build& build) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
      if (it->name == name && it->variant == variant && it->version == version) {
        entries_.splice(entries_.begin(), entries_, it);
        return entries_.front().value;
      }
    }
    absl::StatusOr<T> built = build();
    if (!built.ok()) return built.status();
    auto value = std::make_shared<const T>(std::move(*built));
    // Another version of the same map is no use any more.
    entries_.remove_if([&](const Entry& e) { return e.name == name && e.version != version; });
    entries_.push_front(Entry{name, variant, version, value});
    while (entries_.size() > max_entries_) entries_.pop_back();
    return value;
  }

  size_t size() {
    std::lock_guard<std::mutex> lock(mutex_);
    return entries_.size();
  }

 private:
  struct Entry {
    std::string name;
    std::string variant;
    uint64_t version = 0;
    std::shared_ptr<const T> value;
  };
  const size_t max_entries_;
  std::mutex mutex_;
  std::list<Entry> entries_;  // newest first
};

// Binary little-endian PLY (x y z float, red green blue uchar), at most `max_points` points.
struct PointCloud {
  std::string ply;
  int64_t points = 0;        // in the PLY
  int64_t surface_points = 0;  // before thinning
};

// Keeps every k-th point of an ExportSurfacePointsPly file so at most `max_points` remain, and
// rewrites the header's count. InvalidArgument when `ply` is not such a file.
absl::StatusOr<PointCloud> ThinPointCloudPly(const std::string& ply, int64_t max_points);

// The map's surface points (core/formats/ply_export.h, as the Export RPC writes them), thinned.
// Built on the calling thread: the export reads the grid on the CPU.
class PointCloudCache {
 public:
  // Clouds kept (the newest built); each is at most max_points * 15 bytes plus the header.
  static constexpr size_t kEntries = 4;

  explicit PointCloudCache(int64_t max_points) : max_points_(max_points), cache_(kEntries) {}

  absl::StatusOr<std::shared_ptr<const PointCloud>> Get(const std::string& name,
                                                         const ViewerMap& map);

 private:
  const int64_t max_points_;
  MapVersionCache<PointCloud> cache_;
};

}  // namespace plx::web
