// Terminal progress and summary text for mapping runs (plenox map, plenox demo).
#pragma once

#include <functional>
#include <string>

#include "clients/plenox/cli_common.h"
#include "core/mapping/map_dataset.h"

namespace plx::cli {

// A MapDataset progress callback that draws on `line`.
std::function<bool(const MapDatasetProgress&)> MappingProgressPrinter(ProgressLine* line);

std::string MappingSummaryText(const MappingSummary& summary);

}  // namespace plx::cli
