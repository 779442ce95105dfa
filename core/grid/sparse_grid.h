// Owner of the sparse brick grid (DESIGN.md §5). Bricks of 8x8x8 vertices are stored in
// allocation order ("slots"); a dense coarse index over the current bounds maps brick
// coordinates to slots and grows when bricks appear outside it. Kernels see it as a GridView;
// every array a kernel reads is a UnifiedVector, so the GPU backend reads it in place.
#pragma once

#include <array>
#include <cstdint>
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

class SparseGrid {
 public:
  // The coarse index is capped so a runaway allocation fails cleanly instead of eating memory.
  static constexpr int64_t kMaxIndexEntries = int64_t{1} << 27;

  explicit SparseGrid(float voxel_size);

  float voxel_size() const { return voxel_size_; }
  int64_t num_bricks() const { return static_cast<int64_t>(brick_coords_.size()); }
  int64_t num_vertices() const { return num_bricks() * kBrickVertices; }
  const std::vector<BrickCoord>& brick_coords() const { return brick_coords_; }

  // Stores every brick of `bricks` that is not stored yet, in the given order; new vertices get
  // density `initial_density` and zero SH. Returns how many were added.
  absl::StatusOr<int64_t> AllocateBricks(absl::Span<const BrickCoord> bricks,
                                         float initial_density = 0.0f);

  // Sets the coarse index bounds (in bricks) of an empty grid, e.g. to restore a saved map's:
  // ray marching works in index coordinates, so the same bounds give bit-identical renders.
  // Later allocations outside them still grow the index.
  absl::Status SetIndexBounds(const std::array<int32_t, 3>& min, const std::array<int32_t, 3>& dims);

  // Slot of a brick, or -1.
  int32_t FindBrick(const BrickCoord& brick) const;

  // World position of vertex `local` (0..511, x fastest) of the brick in `slot`.
  std::array<float, 3> VertexPosition(int64_t slot, int local) const;

  // Mutable view for kernels; invalidated by AllocateBricks.
  GridView view() { return ViewOf(density_.data(), sh_.data()); }

  // This grid's index with other value arrays of the same slot layout (double-precision copies
  // in tests, device mirrors).
  template <typename T>
  GridViewT<T> ViewOf(T* density, T* sh) const {
    GridViewT<T> v;
    v.density = density;
    v.sh = sh;
    v.brick_slot = brick_slot_.data();
    v.block_cells = block_cells_.data();
    v.cell_bits = const_cast<uint64_t*>(cell_bits_.data());
    v.brick_origin = brick_origin_.data();
    for (int a = 0; a < 3; ++a) {
      v.dims[a] = index_dims_[a];
      v.origin[a] = static_cast<T>(index_min_[a]) * kBrickEdge * static_cast<T>(voxel_size_);
    }
    v.voxel_size = static_cast<T>(voxel_size_);
    v.num_bricks = num_bricks();
    return v;
  }

  UnifiedVector<float>& density() { return density_; }
  const UnifiedVector<float>& density() const { return density_; }
  UnifiedVector<float>& sh() { return sh_; }
  const UnifiedVector<float>& sh() const { return sh_; }

  GridMemory Memory() const;

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
  absl::Status GrowIndexToCover(absl::Span<const BrickCoord> bricks);
  void RebuildIndex();
  void SetBrickOrigin(int64_t slot);
  void ActivateBlock(int64_t index);
  int64_t IndexOf(const BrickCoord& b) const;

  float voxel_size_;
  std::vector<BrickCoord> brick_coords_;  // per slot
  UnifiedVector<float> density_;          // [num_vertices]
  UnifiedVector<float> sh_;               // [num_vertices * 27]
  std::array<int32_t, 3> index_min_ = {0, 0, 0};
  std::array<int32_t, 3> index_dims_ = {0, 0, 0};
  UnifiedVector<int32_t> brick_slot_;     // coarse index
  UnifiedVector<int32_t> block_cells_;    // per index block: offset into cell_bits_, or -1
  UnifiedVector<uint64_t> cell_bits_;     // 8 words (512 cells) per active block
  UnifiedVector<int64_t> active_blocks_;  // index position of each active block
  bool occupancy_stale_ = true;
  UnifiedVector<int32_t> brick_origin_;   // [num_bricks * 3] index vertex coords of brick corners
};

}  // namespace plx
