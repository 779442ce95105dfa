// Flags describing the synthetic sequence, shared by `plenox synth` and `plenox demo`.
#pragma once

#include "absl/status/statusor.h"
#include "clients/plenox/flags.h"
#include "core/io/synthetic_sequence.h"

namespace plx::cli {

// --frames, --width, --height, --noise, --seed with the given default frame count.
void AddSyntheticFlags(FlagSet& flags, int default_frames);
absl::StatusOr<SyntheticOptions> SyntheticOptionsFromFlags(const FlagSet& flags);

}  // namespace plx::cli
