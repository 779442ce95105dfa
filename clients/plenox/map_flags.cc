#include "clients/plenox/map_flags.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/mapping/mapper.h"

namespace plx::cli {

void AddEveryFlag(FlagSet& flags, const std::string& value_name) {
  const std::string& n = value_name;
  flags.Add("every", n, absl::StrFormat("map every %s-th frame (0, %s, 2%s, ...)", n, n, n), "10");
}

absl::StatusOr<int> EveryFromFlags(const FlagSet& flags) {
  return flags.GetInt("every", 1, 1000000);
}

void AddVoxelSizeFlag(FlagSet& flags, const std::string& help) {
  flags.Add("voxel-size", "M", help, absl::StrCat(MapperOptions{}.voxel_size));
}

absl::StatusOr<double> VoxelSizeFromFlags(const FlagSet& flags) {
  return flags.GetDouble("voxel-size", kMinVoxelSize, kMaxVoxelSize);
}

void AddBatchAndMaxDepthFlags(FlagSet& flags) {
  const MapperOptions defaults;
  flags.Add("batch", "N", "rays per iteration", absl::StrCat(defaults.batch_size))
      .Add("max-depth", "M", "ignore depth measurements beyond this (metres)",
           absl::StrCat(defaults.allocation.max_depth));
}

absl::StatusOr<int> BatchFromFlags(const FlagSet& flags) {
  return flags.GetInt("batch", 1, kMaxBatchSize);
}

absl::StatusOr<double> MaxDepthFromFlags(const FlagSet& flags) {
  return flags.GetDouble("max-depth", 0.1, 1000.0);
}

}  // namespace plx::cli
