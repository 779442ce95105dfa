#include "clients/plenox/synthetic_flags.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace plx::cli {

void AddSyntheticFlags(FlagSet& flags, int default_frames, bool noise_by_default) {
  flags.Add("frames", "N", "frames in the sequence (30 per second)", std::to_string(default_frames))
      .Add("width", "W", "image width", "320")
      .Add("height", "H", "image height", "240");
  if (noise_by_default) {
    flags.AddSwitch("no-noise", "exact depth instead of sensor-like noise and holes");
  } else {
    flags.AddSwitch("noise",
                    "add sensor-like depth noise (1.5 mm at 1 m, growing with z^2) and holes");
  }
  flags.Add("noise-seed", "N", "seed of the depth noise", "7")
      .Add("path", "NAME",
           "camera path: circle (around the room centre), head-turns (the circle with yaw "
           "swings peaking at ~130 deg/s), walk-out (from the -x end into the unseen +x half), "
           "figure-eight (through the centre, one turn per 20 s: a loop), two-room-eight (a "
           "figure eight through two rooms joined by a doorway, one turn per 30 s)",
           "circle");
}

absl::StatusOr<SyntheticOptions> SyntheticOptionsFromFlags(const FlagSet& flags) {
  SyntheticOptions o;
  PLX_ASSIGN_OR_RETURN(o.num_frames, flags.GetInt("frames", 1, 100000));
  PLX_ASSIGN_OR_RETURN(o.width, flags.GetInt("width", 16, 8192));
  PLX_ASSIGN_OR_RETURN(o.height, flags.GetInt("height", 16, 8192));
  PLX_ASSIGN_OR_RETURN(const int seed, flags.GetInt("noise-seed", 0, 2147483647));
  o.seed = static_cast<uint64_t>(seed);
  absl::StatusOr<SyntheticPath> path = ParseSyntheticPath(flags.GetString("path"));
  if (!path.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--path: ", path.status().message()));
  }
  o.path = *path;
  if (flags.GetSwitch("noise") || (flags.Has("no-noise") && !flags.GetSwitch("no-noise"))) {
    o.depth_noise = 0.0015;
    o.hole_fraction = 0.05;
  }
  PLX_RETURN_IF_ERROR(ValidateSyntheticOptions(o));
  return o;
}

}  // namespace plx::cli
