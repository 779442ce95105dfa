// The flags that `plenox map` takes both in-process (cli_common's AddMapperFlags) and on a
// daemon (remote_map.cc): one name, help text, default and range each, and the voxel size's
// default taken from MapperOptions, which the daemon's CreateMap uses too.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "app/flags.h"

namespace plx::cli {

// --every <value_name>: the keyframes are frames 0, N, 2N, ... of the dataset.
void AddEveryFlag(FlagSet& flags, const std::string& value_name);
absl::StatusOr<int> EveryFromFlags(const FlagSet& flags);

// --voxel-size M, defaulting to MapperOptions' voxel size; `help` says what it applies to.
void AddVoxelSizeFlag(FlagSet& flags, const std::string& help);
absl::StatusOr<double> VoxelSizeFromFlags(const FlagSet& flags);

// --batch N (rays per iteration) and --max-depth M (depth measurements beyond it are ignored).
void AddBatchAndMaxDepthFlags(FlagSet& flags);
absl::StatusOr<int> BatchFromFlags(const FlagSet& flags);
absl::StatusOr<double> MaxDepthFromFlags(const FlagSet& flags);

}  // namespace plx::cli
