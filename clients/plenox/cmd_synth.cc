// plenox synth: write the synthetic RGB-D sequence to disk in the TUM layout.
#include <iostream>

#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/synthetic_flags.h"

namespace plx::cli {

int RunSynth(const std::vector<std::string>& args) {
  FlagSet flags("plenox synth",
                "Writes the procedural synthetic room sequence (exact ground-truth poses) to a\n"
                "folder in the TUM layout, readable by every other command.");
  flags.Add("out", "DIR", "folder to write", std::nullopt, true);
  AddSyntheticFlags(flags, 60, /*noise_by_default=*/false);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<SyntheticOptions> options = SyntheticOptionsFromFlags(flags);
  if (!options.ok()) return ReportError("synth", options.status(), true);
  absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(*options);
  if (!dataset.ok()) return ReportError("synth", dataset.status());
  const std::string out = flags.GetString("out");
  if (absl::Status s = WriteTumDataset(*dataset, out); !s.ok()) return ReportError("synth", s);
  std::cout << absl::StrFormat("wrote %d frames (%dx%d) to %s\n", dataset->size(), options->width,
                               options->height, out);
  return kExitOk;
}

}  // namespace plx::cli
