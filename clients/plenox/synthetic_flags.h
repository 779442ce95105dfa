// Flags describing the synthetic sequence, shared by `plenox synth` and `plenox demo`.
#pragma once

#include "absl/status/statusor.h"
#include "app/flags.h"
#include "core/synthetic/synthetic_sequence.h"

namespace plx::cli {

// --frames, --width, --height, --noise-seed, --path (the camera path, default circle), and
// --noise (synth: noise is off unless asked) or --no-noise (demo: the sequence is sensor-like
// unless asked otherwise).
void AddSyntheticFlags(FlagSet& flags, int default_frames, bool noise_by_default);
absl::StatusOr<SyntheticOptions> SyntheticOptionsFromFlags(const FlagSet& flags);

}  // namespace plx::cli
