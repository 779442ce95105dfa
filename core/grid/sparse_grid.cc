#include "core/grid/sparse_grid.h"

#include <algorithm>
#include <limits>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {
// Extra bricks added on each side when the index grows, so a map that grows a little at a time
// does not rebuild its index on every allocation.
constexpr int32_t kGrowthMargin = 4;
}  // namespace

SparseGrid::SparseGrid(float voxel_size) : voxel_size_(voxel_size) {}

int64_t SparseGrid::IndexOf(const BrickCoord& b) const {
  const int64_t x = b.x - index_min_[0], y = b.y - index_min_[1], z = b.z - index_min_[2];
  if (x < 0 || y < 0 || z < 0 || x >= index_dims_[0] || y >= index_dims_[1] ||
      z >= index_dims_[2]) {
    return -1;
  }
  return (z * index_dims_[1] + y) * index_dims_[0] + x;
}

int32_t SparseGrid::FindBrick(const BrickCoord& brick) const {
  const int64_t i = IndexOf(brick);
  return i < 0 ? -1 : brick_slot_[i];
}

absl::Status SparseGrid::GrowIndexToCover(absl::Span<const BrickCoord> bricks) {
  if (bricks.empty()) return absl::OkStatus();
  std::array<int64_t, 3> lo, hi;
  bool inside = index_dims_[0] > 0 && index_dims_[1] > 0 && index_dims_[2] > 0;
  for (int a = 0; a < 3; ++a) {
    lo[a] = inside ? index_min_[a] : std::numeric_limits<int32_t>::max();
    hi[a] = inside ? int64_t{index_min_[a]} + index_dims_[a] - 1 : std::numeric_limits<int32_t>::min();
  }
  bool grow = !inside;
  for (const BrickCoord& b : bricks) {
    const int32_t c[3] = {b.x, b.y, b.z};
    for (int a = 0; a < 3; ++a) {
      if (c[a] < lo[a] || c[a] > hi[a]) grow = true;
      lo[a] = std::min<int64_t>(lo[a], c[a]);
      hi[a] = std::max<int64_t>(hi[a], c[a]);
    }
  }
  if (!grow) return absl::OkStatus();
  std::array<int64_t, 3> dims;
  int64_t entries = 1;
  for (int a = 0; a < 3; ++a) {
    lo[a] -= kGrowthMargin;
    hi[a] += kGrowthMargin;
    dims[a] = hi[a] - lo[a] + 1;
    entries *= dims[a];
  }
  if (entries > kMaxIndexEntries) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "map bounds of ", dims[0], "x", dims[1], "x", dims[2], " bricks (",
        dims[0] * kBrickEdge * voxel_size_, " m wide at ", voxel_size_,
        " m voxels) exceed the index limit; use a larger voxel size or a smaller depth range"));
  }
  for (int a = 0; a < 3; ++a) {
    index_min_[a] = static_cast<int32_t>(lo[a]);
    index_dims_[a] = static_cast<int32_t>(dims[a]);
  }
  RebuildIndex();
  return absl::OkStatus();
}

absl::Status SparseGrid::SetIndexBounds(const std::array<int32_t, 3>& min,
                                        const std::array<int32_t, 3>& dims) {
  if (num_bricks() > 0) return absl::FailedPreconditionError("index bounds of a non-empty grid");
  int64_t entries = 1;
  for (int a = 0; a < 3; ++a) {
    if (dims[a] < 0) return absl::InvalidArgumentError("negative index size");
    entries *= dims[a];
  }
  if (entries > kMaxIndexEntries) {
    return absl::ResourceExhaustedError(absl::StrCat("index of ", entries, " bricks is too large"));
  }
  index_min_ = min;
  index_dims_ = dims;
  RebuildIndex();
  return absl::OkStatus();
}

void SparseGrid::RebuildIndex() {
  const int64_t entries = int64_t{index_dims_[0]} * index_dims_[1] * index_dims_[2];
  brick_slot_.assign(entries, -1);
  block_cells_.assign(entries, -1);
  cell_bits_.clear();
  active_blocks_.clear();
  occupancy_stale_ = true;
  brick_origin_.resize(3 * brick_coords_.size());
  for (int64_t slot = 0; slot < num_bricks(); ++slot) {
    const BrickCoord& b = brick_coords_[slot];
    brick_slot_[IndexOf(b)] = static_cast<int32_t>(slot);
    SetBrickOrigin(slot);
    // Cells of block b - (dx, dy, dz) reach vertices of b through their +1 corners.
    for (int d = 0; d < 8; ++d) {
      ActivateBlock(IndexOf({b.x - (d & 1), b.y - ((d >> 1) & 1), b.z - ((d >> 2) & 1)}));
    }
  }
}

void SparseGrid::ActivateBlock(int64_t index) {
  if (index < 0 || block_cells_[index] >= 0) return;
  block_cells_[index] = static_cast<int32_t>(cell_bits_.size());
  cell_bits_.insert(cell_bits_.end(), kBrickEdge, ~uint64_t{0});
  active_blocks_.push_back(index);
}

void SparseGrid::SetBrickOrigin(int64_t slot) {
  const BrickCoord& b = brick_coords_[slot];
  brick_origin_[3 * slot + 0] = (b.x - index_min_[0]) * kBrickEdge;
  brick_origin_[3 * slot + 1] = (b.y - index_min_[1]) * kBrickEdge;
  brick_origin_[3 * slot + 2] = (b.z - index_min_[2]) * kBrickEdge;
}

absl::StatusOr<int64_t> SparseGrid::AllocateBricks(absl::Span<const BrickCoord> bricks,
                                                   float initial_density) {
  if (absl::Status s = GrowIndexToCover(bricks); !s.ok()) return s;
  int64_t added = 0;
  for (const BrickCoord& b : bricks) {
    const int64_t i = IndexOf(b);
    if (brick_slot_[i] >= 0) continue;
    if (num_bricks() >= std::numeric_limits<int32_t>::max() / kBrickVertices) {
      return absl::ResourceExhaustedError("too many bricks for 32-bit slot indices");
    }
    brick_slot_[i] = static_cast<int32_t>(num_bricks());
    brick_coords_.push_back(b);
    brick_origin_.resize(3 * brick_coords_.size());
    SetBrickOrigin(num_bricks() - 1);
    for (int d = 0; d < 8; ++d) {
      ActivateBlock(IndexOf({b.x - (d & 1), b.y - ((d >> 1) & 1), b.z - ((d >> 2) & 1)}));
    }
    occupancy_stale_ = true;
    ++added;
  }
  density_.resize(num_vertices(), initial_density);
  sh_.resize(num_vertices() * kShCoeffCount, 0.0f);
  return added;
}

std::array<float, 3> SparseGrid::VertexPosition(int64_t slot, int local) const {
  const BrickCoord& b = brick_coords_[slot];
  const int lx = local & (kBrickEdge - 1), ly = (local >> kBrickShift) & (kBrickEdge - 1),
            lz = local >> (2 * kBrickShift);
  return {(b.x * kBrickEdge + lx) * voxel_size_, (b.y * kBrickEdge + ly) * voxel_size_,
          (b.z * kBrickEdge + lz) * voxel_size_};
}

GridMemory SparseGrid::Memory() const {
  GridMemory m;
  m.bricks = num_bricks();
  m.vertices = num_vertices();
  m.parameter_bytes =
      static_cast<int64_t>((density_.size() + sh_.size()) * sizeof(float));
  m.index_bytes = static_cast<int64_t>((brick_slot_.size() + block_cells_.size() +
                                        brick_origin_.size()) * sizeof(int32_t) +
                                       cell_bits_.size() * sizeof(uint64_t) +
                                       active_blocks_.size() * sizeof(int64_t));
  return m;
}

}  // namespace plx
