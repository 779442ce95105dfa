// The checking half of Backend: argument checks shared by every backend, and allocation
// failures turned into a Status, before the backend's own Do* call.
#include "core/kernels/backend.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"

namespace plx {
namespace {

// The pointers every kernel reading `grid` dereferences.
absl::Status CheckGrid(const GridView& grid, const char* what) {
  if (grid.num_bricks < 0) return absl::InvalidArgumentError(absl::StrCat(what, ": negative size"));
  if (grid.num_bricks > 0 && (grid.brick_density == nullptr || grid.brick_sh == nullptr ||
                              grid.brick_origin == nullptr)) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": brick tables missing"));
  }
  if (int64_t{grid.dims[0]} * grid.dims[1] * grid.dims[2] > 0 &&
      (grid.brick_slot == nullptr || grid.block_cells == nullptr)) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": index missing"));
  }
  return absl::OkStatus();
}

absl::Status CheckWrite(const GridView& grid, const GridWriteView& write, const char* what) {
  if (grid.num_bricks > 0 && (write.brick_density == nullptr || write.brick_sh == nullptr)) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": writable brick tables missing"));
  }
  return absl::OkStatus();
}

absl::Status CheckCount(int64_t count, const char* what) {
  if (count < 0) return absl::InvalidArgumentError(absl::StrCat(what, " must not be negative"));
  return absl::OkStatus();
}

absl::Status CheckPointer(const void* p, int64_t count, const char* what) {
  if (count > 0 && p == nullptr) return absl::InvalidArgumentError(absl::StrCat(what, " is null"));
  return absl::OkStatus();
}

}  // namespace

absl::Status Backend::RenderPixels(const GridView& grid, const CameraView& camera,
                                   const int32_t* pixels, int64_t count,
                                   const RenderOptions& options, float* color, float* depth,
                                   float* opacity, float* median_depth) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(count, "pixel count"));
  PLX_RETURN_IF_ERROR(CheckPointer(color, count, "color"));
  PLX_RETURN_IF_ERROR(CheckPointer(depth, count, "depth"));
  PLX_RETURN_IF_ERROR(CheckPointer(opacity, count, "opacity"));
  PLX_RETURN_IF_ERROR(CheckPointer(median_depth, count, "median_depth"));
  return CatchAllocationFailure("RenderPixels", [&] {
    return DoRenderPixels(grid, camera, pixels, count, options, color, depth, opacity,
                          median_depth);
  });
}

absl::Status Backend::MappingForwardBackward(const GridView& grid, const GridGradView& grad,
                                             const TrainingRaysView& rays,
                                             const MappingBatchParams& params,
                                             MappingRayLoss* losses) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(params.batch_size, "batch size"));
  PLX_RETURN_IF_ERROR(CheckPointer(losses, params.batch_size, "losses"));
  if (params.batch_size > 0 && rays.num_rays <= 0) {
    return absl::FailedPreconditionError("MappingForwardBackward: no training rays");
  }
  return CatchAllocationFailure("MappingForwardBackward", [&] {
    return DoMappingForwardBackward(grid, grad, rays, params, losses);
  });
}

absl::Status Backend::RmsPropStep(const GridView& grid, const GridWriteView& write,
                                  const GridGradView& grad, const OptimizerStateView& state,
                                  const RmsPropParams& params) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckWrite(grid, write, "grid"));
  return CatchAllocationFailure(
      "RmsPropStep", [&] { return DoRmsPropStep(grid, write, grad, state, params); });
}

absl::Status Backend::FuseDepth(const GridView& grid, const GridWriteView& write,
                                int64_t first_vertex, int64_t vertex_count,
                                const TrainingFrameView* frames, int num_frames,
                                const FusionParams& params) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckWrite(grid, write, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(vertex_count, "vertex count"));
  PLX_RETURN_IF_ERROR(CheckPointer(frames, num_frames, "frames"));
  if (first_vertex < 0 || first_vertex + vertex_count > grid.num_vertices()) {
    return absl::InvalidArgumentError("FuseDepth: vertex range outside the grid");
  }
  return CatchAllocationFailure("FuseDepth", [&] {
    return DoFuseDepth(grid, write, first_vertex, vertex_count, frames, num_frames, params);
  });
}

absl::Status Backend::RefreshOccupancy(const GridView& grid, const GridWriteView& write,
                                       const int64_t* active_blocks, int64_t count,
                                       float threshold) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(count, "block count"));
  PLX_RETURN_IF_ERROR(CheckPointer(active_blocks, count, "active_blocks"));
  PLX_RETURN_IF_ERROR(CheckPointer(write.cell_bits, count, "cell_bits"));
  return CatchAllocationFailure("RefreshOccupancy", [&] {
    return DoRefreshOccupancy(grid, write, active_blocks, count, threshold);
  });
}

absl::Status Backend::ComputeTrackingTerms(const GridView& grid, const TrainingFrameView& frame,
                                           const int32_t* pixels, int64_t count,
                                           const TrackingParams& params,
                                           TrackingRayTerm* terms) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(count, "ray count"));
  PLX_RETURN_IF_ERROR(CheckPointer(pixels, count, "pixels"));
  PLX_RETURN_IF_ERROR(CheckPointer(terms, count, "terms"));
  return CatchAllocationFailure("ComputeTrackingTerms", [&] {
    return DoComputeTrackingTerms(grid, frame, pixels, count, params, terms);
  });
}

absl::Status Backend::ReduceTrackingTerms(const TrackingRayTerm* terms, int64_t count,
                                          TrackingLoss loss, float huber_k,
                                          const float scale[2], TrackingSums* sums) {
  PLX_RETURN_IF_ERROR(CheckCount(count, "ray count"));
  PLX_RETURN_IF_ERROR(CheckPointer(terms, count, "terms"));
  PLX_RETURN_IF_ERROR(CheckPointer(sums, 1, "sums"));
  return CatchAllocationFailure("ReduceTrackingTerms", [&] {
    return DoReduceTrackingTerms(terms, count, loss, huber_k, scale, sums);
  });
}

absl::Status Backend::ResampleGrid(const GridView& target, const GridWriteView& target_write,
                                   const GridView& source) {
  PLX_RETURN_IF_ERROR(CheckGrid(target, "target"));
  PLX_RETURN_IF_ERROR(CheckWrite(target, target_write, "target"));
  PLX_RETURN_IF_ERROR(CheckGrid(source, "source"));
  return CatchAllocationFailure(
      "ResampleGrid", [&] { return DoResampleGrid(target, target_write, source); });
}

absl::Status Backend::AddTvGradient(const GridView& grid, const GridGradView& grad,
                                    int64_t first_vertex, int64_t vertex_count,
                                    float lambda_density, float lambda_sh) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(vertex_count, "vertex count"));
  if (grid.num_vertices() == 0) return absl::OkStatus();
  return CatchAllocationFailure("AddTvGradient", [&] {
    return DoAddTvGradient(grid, grad, first_vertex, vertex_count, lambda_density, lambda_sh);
  });
}

namespace {

// What every marching-cubes driver needs: a readable grid, a table, a finite level, and cells
// named by stored vertices.
absl::Status CheckIsoSurface(const GridView& grid, const IsoSurfaceParams& params,
                             int64_t first_vertex, int64_t count, bool items) {
  PLX_RETURN_IF_ERROR(CheckGrid(grid, "grid"));
  PLX_RETURN_IF_ERROR(CheckCount(count, items ? "cell count" : "edge count"));
  if (params.table == nullptr) return absl::InvalidArgumentError("marching-cubes table is null");
  if (!std::isfinite(params.iso_level) || params.iso_level < 0.0f) {
    return absl::InvalidArgumentError(
        absl::StrCat("iso level must be finite and >= 0, got ", params.iso_level));
  }
  if (items && (first_vertex < 0 || count > grid.num_vertices() - first_vertex)) {
    return absl::InvalidArgumentError(absl::StrCat("cells [", first_vertex, ", +", count,
                                                   ") outside the grid's ",
                                                   grid.num_vertices(), " vertices"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status Backend::CountIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                        const IsoSurfaceParams& params, uint8_t* triangles) {
  PLX_RETURN_IF_ERROR(CheckIsoSurface(grid, params, first_vertex, count, true));
  PLX_RETURN_IF_ERROR(CheckPointer(triangles, count, "triangles"));
  if (count == 0) return absl::OkStatus();
  return CatchAllocationFailure("CountIsoTriangles", [&] {
    return DoCountIsoTriangles(grid, first_vertex, count, params, triangles);
  });
}

absl::Status Backend::EmitIsoTriangles(const GridView& grid, int64_t first_vertex, int64_t count,
                                       const IsoSurfaceParams& params,
                                       const int64_t* first_triangle, int64_t* edge_keys) {
  PLX_RETURN_IF_ERROR(CheckIsoSurface(grid, params, first_vertex, count, true));
  PLX_RETURN_IF_ERROR(CheckPointer(first_triangle, count, "first_triangle"));
  if (count == 0) return absl::OkStatus();
  // Null only when no cell has a triangle; the counts were the caller's to check.
  if (edge_keys == nullptr) return absl::InvalidArgumentError("edge_keys is null");
  return CatchAllocationFailure("EmitIsoTriangles", [&] {
    return DoEmitIsoTriangles(grid, first_vertex, count, params, first_triangle, edge_keys);
  });
}

absl::Status Backend::ComputeIsoVertices(const GridView& grid, const int64_t* edge_keys,
                                         int64_t count, const IsoSurfaceParams& params,
                                         float* positions, float* normals, uint8_t* colors,
                                         uint8_t* observed) {
  PLX_RETURN_IF_ERROR(CheckIsoSurface(grid, params, 0, count, false));
  PLX_RETURN_IF_ERROR(CheckPointer(edge_keys, count, "edge_keys"));
  PLX_RETURN_IF_ERROR(CheckPointer(positions, count, "positions"));
  PLX_RETURN_IF_ERROR(CheckPointer(normals, count, "normals"));
  PLX_RETURN_IF_ERROR(CheckPointer(colors, count, "colors"));
  PLX_RETURN_IF_ERROR(CheckPointer(observed, count, "observed"));
  if (count == 0) return absl::OkStatus();
  return CatchAllocationFailure("ComputeIsoVertices", [&] {
    return DoComputeIsoVertices(grid, edge_keys, count, params, positions, normals, colors,
                                observed);
  });
}

}  // namespace plx
