// The arguments of each Backend kernel (core/kernels/backend.h), one struct per kernel: what
// the kernel computes, the arrays it reads and writes with their sizes, and the checks its
// values need beyond those sizes. Each struct is the one place its kernel's buffers are
// described; Backend checks them (backend.cc), both backends forward them to their driver
// `Run(ctx, args)` (core/kernels/kernel_declarations.inc) and the CUDA backend checks and
// prefetches them, all through ForEachArgument.
//
// Every struct has:
//   kName                   the kernel's name, for messages;
//   ForEachArgument(visit)  its size arguments (KernelCount) and arrays (KernelBuffer), see
//                           core/kernels/kernel_buffers.h;
// and may have:
//   absl::Status Validate() checks of values that are not sizes (ranges, levels), run after
//                           the size and null checks; the message gets the kernel's name;
//   bool Empty()            true when the call has nothing to do: it succeeds without
//                           reaching the backend.
//
// Adding a kernel: its struct here (and in KernelArgs at the end), its driver declaration in
// kernel_declarations.inc, its *_impl.h with the two shells (core/cpu/foo_cpu.cc,
// cuda/foo_cuda.cu), and its public method in backend.h.
#pragma once

#include <cstdint>
#include <variant>

#include "absl/status/status.h"
#include "core/grid/grid_view.h"
#include "core/kernels/depth_fusion.h"
#include "core/kernels/kernel_buffers.h"
#include "core/kernels/kernel_types.h"
#include "core/kernels/marching_cubes.h"
#include "core/kernels/tracking_terms.h"

namespace plx {

// Renders `count` pixels of `camera` (pixel ids v * width + u, or every pixel in order when
// `pixels` is null). Outputs: colour [count * 3], expected range [count], opacity [count] and
// median range [count] (see RayRenderResult).
struct RenderPixelsArgs {
  static constexpr char kName[] = "RenderPixels";
  GridView grid{};
  CameraView camera{};
  const int32_t* pixels = nullptr;
  int64_t count = 0;
  RenderOptions options;
  float* color = nullptr;
  float* depth = nullptr;
  float* opacity = nullptr;
  float* median_depth = nullptr;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("count", count));
    VisitGrid(visit, "grid", grid);
    visit(Read("pixels", pixels, count).Optional());
    visit(Write("color", color, 3 * count));
    visit(Write("depth", depth, count));
    visit(Write("opacity", opacity, count));
    visit(Write("median_depth", median_depth, count));
  }
};

// One batch of the mapping loss: forward and backward per ray, gradients accumulated into
// `grad`; per-ray loss terms written to `losses` [batch_size].
struct MappingForwardBackwardArgs {
  static constexpr char kName[] = "MappingForwardBackward";
  GridView grid{};
  GridGradView grad{};
  TrainingRaysView rays{};
  MappingBatchParams params;
  MappingRayLoss* losses = nullptr;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("batch_size", params.batch_size).Of("params"));
    visit(Count("num_rays", rays.num_rays).Of("rays"));
    VisitGrid(visit, "grid", grid);
    VisitGrad(visit, "grad", grid, grad);
    // The frames' count is not in the view, nor therefore their images'.
    visit(Read("frames", rays.frames, kUnknownSize).Of("rays").RequiredIf(rays.num_rays > 0));
    visit(Read("ray_frame", rays.ray_frame, rays.num_rays).Of("rays"));
    visit(Read("ray_pixel", rays.ray_pixel, rays.num_rays).Of("rays"));
    visit(Write("losses", losses, params.batch_size));
  }
  absl::Status Validate() const;  // a batch needs rays to draw from (FailedPrecondition)
};

// RMSProp on every touched vertex of [0, num_vertices); clears gradients and touched flags.
// Writes `write`'s parameters and cell bits only.
struct RmsPropStepArgs {
  static constexpr char kName[] = "RmsPropStep";
  GridView grid{};
  GridWriteView write{};
  GridGradView grad{};
  OptimizerStateView state{};
  RmsPropParams params;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    const int64_t vertices = grid.num_vertices();
    VisitGrid(visit, "grid", grid);
    VisitGridWrite(visit, "write", grid, write, BufferAccess::kReadWrite);
    // Written only in active blocks, like the grid's.
    visit(Write("cell_bits", write.cell_bits, kUnknownSize).Of("write").Optional());
    VisitGrad(visit, "grad", grid, grad);
    visit(ReadWrite("rms_density", state.rms_density, vertices).Of("state").Prefetched());
    visit(ReadWrite("rms_sh", state.rms_sh, vertices * kShCoeffCount).Of("state").Prefetched());
  }
};

// Depth-guided initialisation of vertices [first_vertex, first_vertex + vertex_count): density
// and SH DC from the keyframes (core/kernels/depth_fusion.h); other SH coefficients zeroed.
struct FuseDepthArgs {
  static constexpr char kName[] = "FuseDepth";
  GridView grid{};
  GridWriteView write{};
  int64_t first_vertex = 0;
  int64_t vertex_count = 0;
  const TrainingFrameView* frames = nullptr;
  int num_frames = 0;
  FusionParams params;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("vertex_count", vertex_count));
    visit(Count("num_frames", num_frames));
    VisitGrid(visit, "grid", grid);
    VisitGridWrite(visit, "write", grid, write, BufferAccess::kWrite);
    visit(Read("frames", frames, num_frames));
    for (int f = 0; frames != nullptr && f < num_frames; ++f) {
      const int64_t pixels = int64_t{frames[f].camera.width} * frames[f].camera.height;
      visit(Read("color", frames[f].color, 3 * pixels).Of("frames[]"));
      visit(Read("depth", frames[f].depth, pixels).Of("frames[]"));
    }
  }
  absl::Status Validate() const;  // the vertices lie in the grid
};

// The observed surface's field (core/mesh/observed_surface.h) at the vertices of the bricks
// listed (work item i: local vertex i % 512 of the brick in slot bricks.slots[i / 512]):
// value[slot * 512 + local] = -tsdf (metres, positive inside) averaged over `frames` (depth
// images rendered from the map; their colour pointers may be null), or kIsoNoValue where no
// frame observed the vertex. `value` holds every vertex of the grid; those of unlisted bricks
// are left as they are.
struct ObserveSurfaceArgs {
  static constexpr char kName[] = "ObserveSurface";
  GridView grid{};
  IsoBrickList bricks;
  const TrainingFrameView* frames = nullptr;
  int num_frames = 0;
  FusionParams params;
  float* value = nullptr;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("num_frames", num_frames));
    VisitGrid(visit, "grid", grid);
    visit(Read("slots", bricks.slots, bricks.count).Of("bricks"));
    visit(Read("frames", frames, num_frames));
    // Only the depth images are read (no colour: the mesh's colours are the map's SH).
    for (int f = 0; frames != nullptr && f < num_frames; ++f) {
      const int64_t pixels = int64_t{frames[f].camera.width} * frames[f].camera.height;
      visit(Read("depth", frames[f].depth, pixels).Of("frames[]"));
    }
    visit(Write("value", value, grid.num_vertices()).RequiredIf(bricks.count > 0));
  }
  bool Empty() const { return bricks.count == 0; }
};

// Recomputes the cell occupancy bits of the `count` active blocks listed (index positions) from
// the current densities.
struct RefreshOccupancyArgs {
  static constexpr char kName[] = "RefreshOccupancy";
  GridView grid{};
  GridWriteView write{};
  const int64_t* active_blocks = nullptr;
  int64_t count = 0;
  float threshold = 0.0f;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("count", count));
    VisitGrid(visit, "grid", grid);
    visit(Read("active_blocks", active_blocks, count));
    visit(Write("cell_bits", write.cell_bits, kUnknownSize).Of("write").RequiredIf(count > 0));
  }
};

// Tracking: residuals (rendered - measured) and pose Jacobians of the rays through `pixels`
// [count] of `frame`, rendered from frame.camera.world_T_camera (the current estimate), into
// `terms` [count]. A ray whose measurement is invalid or that the map does not render gets all
// weights 0.
struct ComputeTrackingTermsArgs {
  static constexpr char kName[] = "ComputeTrackingTerms";
  GridView grid{};
  TrainingFrameView frame{};
  const int32_t* pixels = nullptr;
  int64_t count = 0;
  TrackingParams params;
  TrackingRayTerm* terms = nullptr;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    const int64_t image = int64_t{frame.camera.width} * frame.camera.height;
    visit(Count("count", count));
    VisitGrid(visit, "grid", grid);
    visit(Read("color", frame.color, 3 * image).Of("frame"));
    visit(Read("depth", frame.depth, image).Of("frame"));
    visit(Read("pixels", pixels, count));
    visit(Write("terms", terms, count));
  }
};

// Sums the `count` per-ray terms into normal equations `sums` (per backend: CPU per-chunk
// partials added in a fixed order, so the result does not depend on thread timing). The one
// driver that allocates (CUDA: its partial sums), hence its Status.
struct ReduceTrackingTermsArgs {
  static constexpr char kName[] = "ReduceTrackingTerms";
  const TrackingRayTerm* terms = nullptr;
  int64_t count = 0;
  TrackingLoss loss = TrackingLoss::kHuber;
  float huber_k = 0.0f;
  float scale[2] = {1.0f, 1.0f};
  TrackingSums* sums = nullptr;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("count", count));
    visit(Read("terms", terms, count));
    visit(Write("sums", sums, 1).OnHost());
  }
};

// Sets every stored vertex of `target` to the trilinear sample of `source` at its position
// (zero outside `source`): coarse-to-fine upsampling.
struct ResampleGridArgs {
  static constexpr char kName[] = "ResampleGrid";
  GridView target{};
  GridWriteView target_write{};
  GridView source{};

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    VisitGrid(visit, "target", target);
    VisitGridWrite(visit, "target_write", target, target_write, BufferAccess::kWrite);
    VisitGrid(visit, "source", source);
  }
};

// Adds total-variation gradients for `vertex_count` vertices starting at `first_vertex`
// (wrapping around), with weights lambda_density and lambda_sh (0 disables a term).
struct AddTvGradientArgs {
  static constexpr char kName[] = "AddTvGradient";
  GridView grid{};
  GridGradView grad{};
  int64_t first_vertex = 0;
  int64_t vertex_count = 0;
  float lambda_density = 0.0f;
  float lambda_sh = 0.0f;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("vertex_count", vertex_count));
    VisitGrid(visit, "grid", grid);
    VisitGrad(visit, "grad", grid, grad);
  }
  absl::Status Validate() const;  // the run starts at a vertex
  bool Empty() const { return grid.num_vertices() == 0; }
};

// Marching cubes (core/kernels/marching_cubes.h) on work items [first_vertex, first_vertex +
// count): without a brick list the cells whose lowest corners are those stored vertices, with
// one the cells of the listed bricks (IsoBrickList); the triangles each cell makes (`triangles`
// [count]).
struct CountIsoTrianglesArgs {
  static constexpr char kName[] = "CountIsoTriangles";
  GridView grid{};
  int64_t first_vertex = 0;
  int64_t count = 0;
  IsoSurfaceParams params;
  uint8_t* triangles = nullptr;
  IsoBrickList bricks;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("count", count));
    VisitGrid(visit, "grid", grid);
    visit(Read("table", params.table, 1).Of("params"));
    visit(Read("slots", bricks.slots, bricks.count).Of("bricks"));
    visit(Write("triangles", triangles, count));
  }
  absl::Status Validate() const;  // a finite level; the cells lie in the grid or the list
  bool Empty() const { return count == 0; }
};

// Then, with `first_triangle` [count] the exclusive prefix sum of those counts, the three edge
// keys of each triangle (`edge_keys` [3 * total]).
struct EmitIsoTrianglesArgs {
  static constexpr char kName[] = "EmitIsoTriangles";
  GridView grid{};
  int64_t first_vertex = 0;
  int64_t count = 0;
  IsoSurfaceParams params;
  const int64_t* first_triangle = nullptr;
  int64_t* edge_keys = nullptr;
  IsoBrickList bricks;  // the same list as the counts'

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("count", count));
    VisitGrid(visit, "grid", grid);
    visit(Read("table", params.table, 1).Of("params"));
    visit(Read("slots", bricks.slots, bricks.count).Of("bricks"));
    visit(Read("first_triangle", first_triangle, count));
    // The total is the caller's (the counts' sum), not in the arguments.
    visit(Write("edge_keys", edge_keys, kUnknownSize).RequiredIf(count > 0));
  }
  absl::Status Validate() const;  // a finite level; the cells lie in the grid or the list
  bool Empty() const { return count == 0; }
};

// Position [count * 3], normal [count * 3], RGB colour [count * 3] and observed flag [count]
// (IsoVertex) of the mesh vertex on each of `count` edge keys.
struct ComputeIsoVerticesArgs {
  static constexpr char kName[] = "ComputeIsoVertices";
  GridView grid{};
  const int64_t* edge_keys = nullptr;
  int64_t count = 0;
  IsoSurfaceParams params;
  float* positions = nullptr;
  float* normals = nullptr;
  uint8_t* colors = nullptr;
  uint8_t* observed = nullptr;

  template <typename Visit>
  void ForEachArgument(Visit&& visit) const {
    visit(Count("count", count));
    VisitGrid(visit, "grid", grid);
    visit(Read("table", params.table, 1).Of("params"));
    visit(Read("edge_keys", edge_keys, count));
    visit(Write("positions", positions, 3 * count));
    visit(Write("normals", normals, 3 * count));
    visit(Write("colors", colors, 3 * count));
    visit(Write("observed", observed, count));
  }
  absl::Status Validate() const;  // a finite level
  bool Empty() const { return count == 0; }
};

// Every kernel's arguments: what Backend hands its implementation (Backend::Launch).
using KernelArgs =
    std::variant<RenderPixelsArgs, MappingForwardBackwardArgs, RmsPropStepArgs, FuseDepthArgs,
                 RefreshOccupancyArgs, ComputeTrackingTermsArgs, ReduceTrackingTermsArgs,
                 ResampleGridArgs, AddTvGradientArgs, CountIsoTrianglesArgs, EmitIsoTrianglesArgs,
                 ComputeIsoVerticesArgs, ObserveSurfaceArgs>;

}  // namespace plx
