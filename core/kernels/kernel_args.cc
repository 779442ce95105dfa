// The value checks of the kernels' argument structs (core/kernels/kernel_args.h): what their
// sizes and arrays do not say. Backend puts the kernel's name in front of each message.
#include "core/kernels/kernel_args.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"

namespace plx {

namespace {

absl::Status CheckIsoLevel(const IsoSurfaceParams& params) {
  if (!std::isfinite(params.iso_level) || params.iso_level < 0.0f) {
    return absl::InvalidArgumentError(
        absl::StrCat("`params.iso_level` must be finite and >= 0, got ", params.iso_level));
  }
  return absl::OkStatus();
}

// Marching cubes work items: the cells whose lowest corners are stored vertices, or the cells
// of a brick list (whose slots the kernel checks: a slot outside the grid has no cells).
absl::Status CheckIsoCells(const GridView& grid, int64_t first_vertex, int64_t count,
                           const IsoBrickList& bricks) {
  const bool listed = bricks.slots != nullptr || bricks.count != 0;
  const int64_t items = listed ? bricks.count * kBrickVertices : grid.num_vertices();
  if (first_vertex < 0 || count > items - first_vertex) {
    return absl::InvalidArgumentError(absl::StrCat(
        "`first_vertex`, `count`: cells [", first_vertex, ", +", count, ") outside the ",
        listed ? "brick list's " : "grid's ", items, listed ? " cells" : " vertices"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status MappingForwardBackwardArgs::Validate() const {
  if (params.batch_size > 0 && rays.num_rays <= 0) {
    return absl::FailedPreconditionError("no training rays");
  }
  return absl::OkStatus();
}

absl::Status FuseDepthArgs::Validate() const {
  if (first_vertex < 0 || first_vertex + vertex_count > grid.num_vertices()) {
    return absl::InvalidArgumentError(
        absl::StrCat("`first_vertex`, `vertex_count`: vertices [", first_vertex, ", +",
                     vertex_count, ") outside the grid's ", grid.num_vertices(), " vertices"));
  }
  return absl::OkStatus();
}

absl::Status AddTvGradientArgs::Validate() const {
  if (first_vertex < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("`first_vertex` must not be negative (got ", first_vertex, ")"));
  }
  return absl::OkStatus();
}

absl::Status CountIsoTrianglesArgs::Validate() const {
  PLX_RETURN_IF_ERROR(CheckIsoLevel(params));
  return CheckIsoCells(grid, first_vertex, count, bricks);
}

absl::Status EmitIsoTrianglesArgs::Validate() const {
  PLX_RETURN_IF_ERROR(CheckIsoLevel(params));
  return CheckIsoCells(grid, first_vertex, count, bricks);
}

absl::Status ComputeIsoVerticesArgs::Validate() const { return CheckIsoLevel(params); }

}  // namespace plx
