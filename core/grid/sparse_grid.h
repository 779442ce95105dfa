// Owner of the sparse brick grid (DESIGN.md §5). Bricks of 8x8x8 vertices are stored in
// allocation order ("slots"); a dense coarse index over the current bounds maps brick
// coordinates to slots and grows when bricks appear outside it. Kernels see it as a GridView;
// every array a kernel reads is UnifiedVector memory, so the GPU backend reads it in place.
//
// Copy-on-write versions: each brick's parameters (512 densities, 512 * 27 SH coefficients) are
// a separately owned block, shared between the grids of several map versions. Publish() gives
// readers a grid that shares every brick (it copies only the index and the brick tables), and
// marks the writer's bricks shared; the writer clones a shared brick before it first writes it
// (MakePrivate), so a publish costs in proportion to the bricks changed since the last one and
// unchanged bricks are stored once.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/common/unified_allocator.h"
#include "core/grid/grid_view.h"

namespace plx {

// Brick coordinates in the world lattice: brick b holds vertices 8*b .. 8*b+7 per axis, and
// vertex a sits at world position a * voxel_size.
struct BrickCoord {
  int32_t x = 0, y = 0, z = 0;
  bool operator==(const BrickCoord&) const = default;
  template <typename H>
  friend H AbslHashValue(H h, const BrickCoord& b) {
    return H::combine(std::move(h), b.x, b.y, b.z);
  }
};

// Where the bytes of a map go; reported by the CLI and the benchmark.
struct GridMemory {
  int64_t bricks = 0;
  int64_t vertices = 0;
  int64_t parameter_bytes = 0;  // density + SH, 28 floats per vertex
  int64_t index_bytes = 0;      // coarse index + activity mask
  int64_t total_bytes() const { return parameter_bytes + index_bytes; }
};

// Floats per brick: 512 densities, then 512 * 27 SH coefficients.
inline constexpr int64_t kBrickFloats = int64_t{kBrickVertices} * kValuesPerVertex;

// Brick coordinates [lo, hi] per axis (the same on every axis).
struct BrickRange {
  int64_t lo = 0, hi = 0;
};

class SparseGrid {
 public:
  // The coarse index is capped so a runaway allocation fails cleanly instead of eating memory.
  static constexpr int64_t kMaxIndexEntries = int64_t{1} << 27;
  // Bricks added on each side when the index grows (so a map growing a little at a time does
  // not rebuild its index on every allocation); index bounds reach this far past the bricks.
  static constexpr int32_t kIndexGrowthMargin = 4;

  // The bricks a grid of `voxel_size` may store: those holding a point within the world extent
  // (core/common/world_extent.h), clamped so that every vertex coordinate the grid computes
  // (8 per brick, relative to the index) stays far inside int32.
  static BrickRange WorldBrickRange(float voxel_size);
  // InvalidArgument naming the brick and the range when a coordinate is outside
  // WorldBrickRange(voxel_size).
  static absl::Status CheckBrickInsideWorld(const BrickCoord& brick, float voxel_size);
  // InvalidArgument unless dims are not negative and [min, min + dims) lies within
  // WorldBrickRange(voxel_size) widened by kIndexGrowthMargin on each side.
  static absl::Status CheckIndexBoundsInsideWorld(const std::array<int32_t, 3>& min,
                                                  const std::array<int32_t, 3>& dims,
                                                  float voxel_size);

  explicit SparseGrid(float voxel_size);
  // Copies would silently share bricks without marking them: use Publish or ShareCopy.
  SparseGrid(const SparseGrid&) = delete;
  SparseGrid& operator=(const SparseGrid&) = delete;
  SparseGrid(SparseGrid&&) = default;
  SparseGrid& operator=(SparseGrid&&) = default;

  float voxel_size() const { return voxel_size_; }
  int64_t num_bricks() const { return static_cast<int64_t>(brick_coords_.size()); }
  int64_t num_vertices() const { return num_bricks() * kBrickVertices; }
  const std::vector<BrickCoord>& brick_coords() const { return brick_coords_; }

  // Stores every brick of `bricks` that is not stored yet, in the given order; new vertices get
  // density `initial_density` and zero SH. Returns how many were added. InvalidArgument, and no
  // brick added, when one is outside the world (CheckBrickInsideWorld).
  absl::StatusOr<int64_t> AllocateBricks(absl::Span<const BrickCoord> bricks,
                                         float initial_density = 0.0f);
  // For allocating `bricks` in pieces: checks them all (InvalidArgument, nothing changed, when
  // one is outside the world) and grows the index to cover them all now. AllocateBricks over
  // consecutive pieces of `bricks` then leaves the grid exactly as AllocateBricks(bricks) would
  // (the index bounds depend on the bricks covered at once; the slots on the order).
  absl::Status PrepareToAllocate(absl::Span<const BrickCoord> bricks);

  // Sets the coarse index bounds (in bricks) of an empty grid, e.g. to restore a saved map's:
  // ray marching works in index coordinates, so the same bounds give bit-identical renders.
  // Later allocations outside them still grow the index. InvalidArgument for bounds outside the
  // world (CheckIndexBoundsInsideWorld).
  absl::Status SetIndexBounds(const std::array<int32_t, 3>& min,
                              const std::array<int32_t, 3>& dims);

  // Slot of a brick, or -1.
  int32_t FindBrick(const BrickCoord& brick) const;

  // World position of vertex `local` (0..511, x fastest) of the brick in `slot`.
  std::array<float, 3> VertexPosition(int64_t slot, int local) const;

  // Read view for kernels; invalidated by AllocateBricks and MakePrivate.
  GridView view() const {
    return ViewOf<float>(density_table_.data(), sh_table_.data());
  }
  // What the writing kernels may change: the parameters of private bricks (new ones, and those
  // passed through MakePrivate since the last Publish) and the cell occupancy bits. Only a grid
  // nobody else reads hands one out; invalidated like view().
  GridWriteView write_view() {
    return GridWriteView{density_table_.data(), sh_table_.data(), cell_bits_.data()};
  }

  // This grid's index with other per-brick value tables of the same slot layout
  // (double-precision copies in tests, see ContiguousBrickTables).
  template <typename T>
  GridViewT<T> ViewOf(const T* const* brick_density, const T* const* brick_sh) const {
    GridViewT<T> v;
    v.brick_density = brick_density;
    v.brick_sh = brick_sh;
    v.brick_slot = brick_slot_.data();
    v.block_cells = block_cells_.data();
    v.cell_bits = cell_bits_.data();
    v.brick_origin = brick_origin_.data();
    for (int a = 0; a < 3; ++a) {
      v.dims[a] = index_dims_[a];
      v.origin[a] = static_cast<T>(index_min_[a]) * kBrickEdge * static_cast<T>(voxel_size_);
    }
    v.voxel_size = static_cast<T>(voxel_size_);
    v.num_bricks = num_bricks();
    return v;
  }

  // Host access to one brick's parameters: 512 densities (x fastest) and 512 * 27 SH.
  const float* brick_density(int64_t slot) const { return density_table_[slot]; }
  const float* brick_sh(int64_t slot) const { return sh_table_[slot]; }
  // The same for writing: clones the brick first when another version shares it.
  float* mutable_brick_density(int64_t slot);
  float* mutable_brick_sh(int64_t slot);
  float density(int64_t vertex) const {
    return density_table_[vertex / kBrickVertices][vertex % kBrickVertices];
  }
  const float* sh(int64_t vertex) const {
    return sh_table_[vertex / kBrickVertices] + (vertex % kBrickVertices) * kShCoeffCount;
  }
  // Every vertex's density [num_vertices] / SH [num_vertices * 27] in slot order (copies, for
  // comparisons and exports).
  std::vector<float> DensityValues() const;
  std::vector<float> ShValues() const;

  // Copy-on-write. Publish: a grid for readers that shares every brick with this one, after
  // which this grid treats all its bricks as shared. ShareCopy: the same from a grid that is not
  // written any more (a published version), e.g. to continue mapping it.
  SparseGrid Publish();
  SparseGrid ShareCopy() const;
  // A grid of the bricks whose flag in `keep` [num_bricks] is non-zero, sharing them (as
  // ShareCopy) in slot order, over the same index bounds (so it renders as this grid would
  // without the others). Its occupancy is stale. Like ShareCopy, for a grid not written any
  // more.
  SparseGrid ShareSubset(absl::Span<const uint8_t> keep) const;
  // Clones every shared brick whose flag in `brick_flags` [num_bricks] is non-zero, so kernels
  // may write it; returns how many were cloned. With `max_clones` >= 0 at most that many are
  // cloned and the slots of the flagged bricks still shared are appended to `still_shared`.
  int64_t MakePrivate(const uint8_t* brick_flags, int64_t max_clones = -1,
                      std::vector<int64_t>* still_shared = nullptr);

  // Brick blocks freed by dropped versions are pooled (up to 4096) for the next allocations;
  // this returns them to their allocator (memory pressure, tests that count allocations).
  static void ReleasePooledBricks();

  GridMemory Memory() const;
  // What Memory() would report after AllocateBricks(bricks) (`bricks` without repeats), without
  // allocating: a limit is checked before the allocation. A lower bound: cell-occupancy blocks
  // are counted once per new brick, though a brick may activate up to 8.
  GridMemory MemoryAfterAllocating(absl::Span<const BrickCoord> bricks) const;
  // The same lower bound for a grid of `bricks` bricks and an index of `index_dims` (a map
  // file's header, before loading it).
  static GridMemory EstimateMemory(int64_t bricks, const std::array<int32_t, 3>& index_dims);

  // Cell occupancy (GridViewT::cell_bits) starts conservative (every cell of an active block
  // occupied) and is made exact for the current densities by a backend's RefreshOccupancy.
  // New bricks make it stale again; kernels that raise densities mark cells themselves.
  bool occupancy_stale() const { return occupancy_stale_; }
  void set_occupancy_fresh() { occupancy_stale_ = false; }
  void mark_occupancy_stale() { occupancy_stale_ = true; }
  int64_t num_active_blocks() const { return static_cast<int64_t>(cell_bits_.size() / kBrickEdge); }
  // Linear index (in the coarse index) of every active block, in cell_bits order.
  const UnifiedVector<int64_t>& active_blocks() const { return active_blocks_; }

  // Brick-coordinate bounds of the index: [index_min, index_min + index_dims).
  const std::array<int32_t, 3>& index_min() const { return index_min_; }
  const std::array<int32_t, 3>& index_dims() const { return index_dims_; }

 private:
  // One brick's parameters, owned jointly by every grid version that contains it.
  using BrickStorage = std::shared_ptr<float>;
  static BrickStorage NewBrickStorage();

  struct IndexBounds {
    std::array<int64_t, 3> min = {0, 0, 0}, dims = {0, 0, 0};
  };
  // Index bounds covering the current ones and `bricks` (plus the growth margin), or nullopt
  // when the current ones already cover them.
  std::optional<IndexBounds> BoundsCovering(absl::Span<const BrickCoord> bricks) const;
  absl::Status GrowIndexToCover(absl::Span<const BrickCoord> bricks);
  // Index memory (see Memory()): per brick, its slot-table pointers (2), origin (3 int32) and at
  // least one active block's occupancy bits (8 uint64) and position (1 int64); per index entry,
  // its slot and block offset (2 int32).
  static constexpr int64_t kIndexBytesPerBrick = 2 * 8 + 3 * 4 + 8 * 8 + 8;
  static constexpr int64_t kIndexBytesPerEntry = 2 * 4;
  void RebuildIndex();
  void SetBrickOrigin(int64_t slot);
  void ActivateBlock(int64_t index);
  int64_t IndexOf(const BrickCoord& b) const;
  void SetBrick(int64_t slot, BrickStorage storage);
  void ClonePrivate(int64_t slot);

  float voxel_size_;
  std::vector<BrickCoord> brick_coords_;  // per slot
  std::vector<BrickStorage> bricks_;      // per slot
  std::vector<uint8_t> brick_shared_;     // per slot: 1 = another version may read it
  int64_t clone_cursor_ = 0;              // where a capped MakePrivate starts next
  UnifiedVector<float*> density_table_;   // per slot: bricks_[slot].get()
  UnifiedVector<float*> sh_table_;        // per slot: bricks_[slot].get() + 512
  std::array<int32_t, 3> index_min_ = {0, 0, 0};
  std::array<int32_t, 3> index_dims_ = {0, 0, 0};
  UnifiedVector<int32_t> brick_slot_;     // coarse index
  UnifiedVector<int32_t> block_cells_;    // per index block: offset into cell_bits_, or -1
  UnifiedVector<uint64_t> cell_bits_;     // 8 words (512 cells) per active block
  UnifiedVector<int64_t> active_blocks_;  // index position of each active block
  bool occupancy_stale_ = true;
  UnifiedVector<int32_t> brick_origin_;   // [num_bricks * 3] index vertex coords of brick corners
};

// Brick tables over contiguous per-vertex arrays in a grid's slot layout, for
// SparseGrid::ViewOf (e.g. double-precision copies of a grid in tests).
template <typename T>
struct ContiguousBrickTables {
  ContiguousBrickTables(T* density, T* sh, int64_t num_bricks) {
    for (int64_t b = 0; b < num_bricks; ++b) {
      density_table.push_back(density + b * kBrickVertices);
      sh_table.push_back(sh + b * kBrickVertices * kShCoeffCount);
    }
  }
  GridViewT<T> ViewOf(const SparseGrid& grid) const {
    return grid.ViewOf<T>(density_table.data(), sh_table.data());
  }
  std::vector<T*> density_table, sh_table;
};

}  // namespace plx
