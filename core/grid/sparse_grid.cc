#include "core/grid/sparse_grid.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/common/world_extent.h"

namespace plx {
namespace {
constexpr int32_t kGrowthMargin = SparseGrid::kIndexGrowthMargin;
// |brick coordinate| never exceeds this whatever the voxel size: vertex coordinates are 8 per
// brick and index differences add another factor 2, all in int32 (2^26 * 8 * 2 = 2^30).
constexpr int64_t kMaxBrickCoordinate = int64_t{1} << 26;
}  // namespace

SparseGrid::SparseGrid(float voxel_size) : voxel_size_(voxel_size) {}

BrickRange SparseGrid::WorldBrickRange(float voxel_size) {
  const double brick_size = static_cast<double>(voxel_size) * kBrickEdge;
  const auto clamp = [](double b) {
    if (!(b > -static_cast<double>(kMaxBrickCoordinate))) return -kMaxBrickCoordinate;  // NaN too
    if (b > static_cast<double>(kMaxBrickCoordinate)) return kMaxBrickCoordinate;
    return static_cast<int64_t>(b);
  };
  // Points p in [-E, E] lie in bricks floor(p / brick_size).
  return BrickRange{clamp(std::floor(-kWorldExtentMeters / brick_size)),
                    clamp(std::floor(kWorldExtentMeters / brick_size))};
}

absl::Status SparseGrid::CheckBrickInsideWorld(const BrickCoord& b, float voxel_size) {
  const BrickRange range = WorldBrickRange(voxel_size);
  for (int32_t c : {b.x, b.y, b.z}) {
    if (c < range.lo || c > range.hi) {
      return absl::InvalidArgumentError(absl::StrCat(
          "brick (", b.x, ", ", b.y, ", ", b.z, ") is outside the world extent of +-",
          kWorldExtentMeters, " m per axis (bricks ", range.lo, " to ", range.hi, " at ",
          voxel_size, " m voxels)"));
    }
  }
  return absl::OkStatus();
}

absl::Status SparseGrid::CheckIndexBoundsInsideWorld(const std::array<int32_t, 3>& min,
                                                     const std::array<int32_t, 3>& dims,
                                                     float voxel_size) {
  const BrickRange range = WorldBrickRange(voxel_size);
  for (int a = 0; a < 3; ++a) {
    const int64_t end = int64_t{min[a]} + dims[a];  // exclusive
    if (dims[a] < 0 || min[a] < range.lo - kGrowthMargin ||
        end > range.hi + 1 + kGrowthMargin) {
      return absl::InvalidArgumentError(absl::StrCat(
          "index bounds [", min[a], ", ", end, ") on axis ", a,
          " are outside the world extent (bricks ", range.lo - kGrowthMargin, " to ",
          range.hi + kGrowthMargin, " at ", voxel_size, " m voxels)"));
    }
  }
  return absl::OkStatus();
}

namespace {

constexpr size_t kBrickBytes = kBrickFloats * sizeof(float);

// Brick blocks freed by dropped map versions, kept for the next clones and allocations: a
// mapping job that publishes clones a few thousand bricks between versions while readers drop
// as many, and reusing those blocks spares the page faults of fresh memory (on this project's
// VMs, copying into fresh memory is ~7x slower than into memory used before). Capped, so a
// deleted map gives its memory back beyond kMaxPooledBricks (235 MB).
class BrickPool {
 public:
  static constexpr size_t kMaxPooledBricks = 4096;

  static BrickPool& Get() {
    static BrickPool* pool = new BrickPool;  // never destroyed: bricks may outlive main()
    return *pool;
  }

  // A block from the current unified-memory hooks; throws std::bad_alloc.
  float* Take() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const UnifiedMemoryHooks* hooks = &CurrentUnifiedMemoryHooks();
      while (!free_.empty()) {
        float* block = free_.back();
        free_.pop_back();
        // Blocks of other hooks (made before a CUDA backend existed) are not handed out.
        if (&UnifiedBlockHooks(block) == hooks) return block;
        UnifiedDeallocate(block, kBrickBytes);
      }
    }
    return static_cast<float*>(UnifiedAllocate(kBrickBytes));
  }

  void Clear() {
    std::vector<float*> blocks;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      blocks.swap(free_);
      free_.reserve(kMaxPooledBricks);
    }
    for (float* block : blocks) UnifiedDeallocate(block, kBrickBytes);
  }

  void Give(float* block) noexcept {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (free_.size() < kMaxPooledBricks && free_.capacity() > free_.size()) {
        free_.push_back(block);
        return;
      }
    }
    UnifiedDeallocate(block, kBrickBytes);
  }

 private:
  BrickPool() { free_.reserve(kMaxPooledBricks); }
  std::mutex mutex_;
  std::vector<float*> free_;
};

}  // namespace

void SparseGrid::ReleasePooledBricks() { BrickPool::Get().Clear(); }

SparseGrid::BrickStorage SparseGrid::NewBrickStorage() {
  float* data = BrickPool::Get().Take();  // throws std::bad_alloc
  return BrickStorage(data, [](float* p) { BrickPool::Get().Give(p); });
}

void SparseGrid::SetBrick(int64_t slot, BrickStorage storage) {
  density_table_[slot] = storage.get();
  sh_table_[slot] = storage.get() + kBrickVertices;
  bricks_[slot] = std::move(storage);
}

void SparseGrid::ClonePrivate(int64_t slot) {
  BrickStorage copy = NewBrickStorage();
  UnifiedCopy(copy.get(), bricks_[slot].get(), kBrickFloats * sizeof(float));
  SetBrick(slot, std::move(copy));
  brick_shared_[slot] = 0;
}

float* SparseGrid::mutable_brick_density(int64_t slot) {
  if (brick_shared_[slot]) ClonePrivate(slot);
  return density_table_[slot];
}

float* SparseGrid::mutable_brick_sh(int64_t slot) {
  if (brick_shared_[slot]) ClonePrivate(slot);
  return sh_table_[slot];
}

int64_t SparseGrid::MakePrivate(const uint8_t* brick_flags, int64_t max_clones,
                                std::vector<int64_t>* still_shared) {
  int64_t cloned = 0;
  const int64_t n = num_bricks();
  // With a cap, start where the last capped call stopped, so that every brick is reached in
  // turn and none waits for ever behind lower slots.
  const int64_t start = max_clones >= 0 && n > 0 ? clone_cursor_ % n : 0;
  for (int64_t i = 0; i < n; ++i) {
    const int64_t slot = (start + i) % n;
    if (brick_flags[slot] == 0 || !brick_shared_[slot]) continue;
    if (max_clones >= 0 && cloned >= max_clones) {
      if (still_shared != nullptr) still_shared->push_back(slot);
      continue;
    }
    ClonePrivate(slot);
    ++cloned;
    clone_cursor_ = slot + 1;
  }
  return cloned;
}

namespace {
// Room for `n` elements, growing geometrically like push_back would.
template <typename Vector>
void ReserveGeometric(Vector& v, size_t n) {
  if (v.capacity() < n) v.reserve(std::max(n, 2 * v.capacity()));
}

// An index array copied where it lives (see UnifiedCopy): on the CUDA backend a publish copies
// device pages on the device.
template <typename T>
UnifiedVector<T> CopyOf(const UnifiedVector<T>& source) {
  UnifiedVector<T> copy(source.size());
  UnifiedCopy(copy.data(), source.data(), source.size() * sizeof(T));
  return copy;
}
}  // namespace

SparseGrid SparseGrid::ShareCopy() const {
  SparseGrid copy(voxel_size_);
  copy.brick_coords_ = brick_coords_;
  copy.bricks_ = bricks_;
  copy.brick_shared_.assign(bricks_.size(), 1);
  copy.density_table_ = CopyOf(density_table_);
  copy.sh_table_ = CopyOf(sh_table_);
  copy.index_min_ = index_min_;
  copy.index_dims_ = index_dims_;
  copy.brick_slot_ = CopyOf(brick_slot_);
  copy.block_cells_ = CopyOf(block_cells_);
  copy.cell_bits_ = CopyOf(cell_bits_);
  copy.active_blocks_ = CopyOf(active_blocks_);
  copy.occupancy_stale_ = occupancy_stale_;
  copy.brick_origin_ = CopyOf(brick_origin_);
  return copy;
}

SparseGrid SparseGrid::ShareSubset(absl::Span<const uint8_t> keep) const {
  SparseGrid subset(voxel_size_);
  subset.index_min_ = index_min_;
  subset.index_dims_ = index_dims_;
  for (int64_t slot = 0; slot < num_bricks() && slot < static_cast<int64_t>(keep.size());
       ++slot) {
    if (keep[slot] == 0) continue;
    subset.brick_coords_.push_back(brick_coords_[slot]);
    subset.bricks_.push_back(bricks_[slot]);
    subset.density_table_.push_back(density_table_[slot]);
    subset.sh_table_.push_back(sh_table_[slot]);
  }
  subset.brick_shared_.assign(subset.bricks_.size(), 1);
  subset.RebuildIndex();
  return subset;
}

SparseGrid SparseGrid::Publish() {
  std::fill(brick_shared_.begin(), brick_shared_.end(), uint8_t{1});
  return ShareCopy();
}

std::vector<float> SparseGrid::DensityValues() const {
  std::vector<float> values(static_cast<size_t>(num_vertices()));
  for (int64_t slot = 0; slot < num_bricks(); ++slot) {
    std::memcpy(values.data() + slot * kBrickVertices, density_table_[slot],
                kBrickVertices * sizeof(float));
  }
  return values;
}

std::vector<float> SparseGrid::ShValues() const {
  constexpr int64_t kShPerBrick = int64_t{kBrickVertices} * kShCoeffCount;
  std::vector<float> values(static_cast<size_t>(num_vertices() * kShCoeffCount));
  for (int64_t slot = 0; slot < num_bricks(); ++slot) {
    std::memcpy(values.data() + slot * kShPerBrick, sh_table_[slot], kShPerBrick * sizeof(float));
  }
  return values;
}

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

namespace {
// Entries of an index of `dims`, saturating just above kMaxIndexEntries (each factor may be
// up to 2^27, so the plain product could overflow int64).
int64_t IndexEntries(const std::array<int64_t, 3>& dims) {
  if (dims[0] <= 0 || dims[1] <= 0 || dims[2] <= 0) return 0;
  int64_t entries = 1;
  for (int a = 0; a < 3; ++a) {
    entries *= dims[a];
    if (entries > SparseGrid::kMaxIndexEntries) return SparseGrid::kMaxIndexEntries + 1;
  }
  return entries;
}
}  // namespace

std::optional<SparseGrid::IndexBounds> SparseGrid::BoundsCovering(
    absl::Span<const BrickCoord> bricks) const {
  if (bricks.empty()) return std::nullopt;
  std::array<int64_t, 3> lo, hi;
  bool inside = index_dims_[0] > 0 && index_dims_[1] > 0 && index_dims_[2] > 0;
  for (int a = 0; a < 3; ++a) {
    lo[a] = inside ? index_min_[a] : std::numeric_limits<int32_t>::max();
    hi[a] = inside ? int64_t{index_min_[a]} + index_dims_[a] - 1
                   : std::numeric_limits<int32_t>::min();
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
  if (!grow) return std::nullopt;
  IndexBounds bounds;
  for (int a = 0; a < 3; ++a) {
    bounds.min[a] = lo[a] - kGrowthMargin;
    bounds.dims[a] = hi[a] + kGrowthMargin - bounds.min[a] + 1;
  }
  return bounds;
}

absl::Status SparseGrid::GrowIndexToCover(absl::Span<const BrickCoord> bricks) {
  const std::optional<IndexBounds> bounds = BoundsCovering(bricks);
  if (!bounds) return absl::OkStatus();
  const std::array<int64_t, 3>& dims = bounds->dims;
  if (IndexEntries(dims) > kMaxIndexEntries) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "map bounds of ", dims[0], "x", dims[1], "x", dims[2], " bricks (",
        dims[0] * kBrickEdge * voxel_size_, " m wide at ", voxel_size_,
        " m voxels) exceed the index limit; use a larger voxel size or a smaller depth range"));
  }
  for (int a = 0; a < 3; ++a) {
    index_min_[a] = static_cast<int32_t>(bounds->min[a]);
    index_dims_[a] = static_cast<int32_t>(dims[a]);
  }
  RebuildIndex();
  return absl::OkStatus();
}

GridMemory SparseGrid::MemoryAfterAllocating(absl::Span<const BrickCoord> bricks) const {
  GridMemory m = Memory();
  int64_t added = 0;
  for (const BrickCoord& b : bricks) added += FindBrick(b) < 0 ? 1 : 0;
  m.bricks += added;
  m.vertices += added * kBrickVertices;
  m.parameter_bytes += added * kBrickFloats * static_cast<int64_t>(sizeof(float));
  m.index_bytes += added * kIndexBytesPerBrick;
  if (const std::optional<IndexBounds> bounds = BoundsCovering(bricks)) {
    const int64_t old_entries = int64_t{index_dims_[0]} * index_dims_[1] * index_dims_[2];
    m.index_bytes += (IndexEntries(bounds->dims) - old_entries) * kIndexBytesPerEntry;
  }
  return m;
}

GridMemory SparseGrid::EstimateMemory(int64_t bricks, const std::array<int32_t, 3>& index_dims) {
  GridMemory m;
  m.bricks = bricks;
  m.vertices = bricks * kBrickVertices;
  m.parameter_bytes = bricks * kBrickFloats * static_cast<int64_t>(sizeof(float));
  m.index_bytes = bricks * kIndexBytesPerBrick +
                  IndexEntries({index_dims[0], index_dims[1], index_dims[2]}) * kIndexBytesPerEntry;
  return m;
}

absl::Status SparseGrid::SetIndexBounds(const std::array<int32_t, 3>& min,
                                        const std::array<int32_t, 3>& dims) {
  if (num_bricks() > 0) return absl::FailedPreconditionError("index bounds of a non-empty grid");
  PLX_RETURN_IF_ERROR(CheckIndexBoundsInsideWorld(min, dims, voxel_size_));
  if (IndexEntries({dims[0], dims[1], dims[2]}) > kMaxIndexEntries) {
    return absl::ResourceExhaustedError(absl::StrCat("index of ", dims[0], "x", dims[1], "x",
                                                     dims[2], " bricks is too large"));
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
  return CatchAllocationFailure("allocating bricks", [&]() -> absl::StatusOr<int64_t> {
    // Before anything changes: a brick outside the world would wrap the index's coordinates.
    for (const BrickCoord& b : bricks) PLX_RETURN_IF_ERROR(CheckBrickInsideWorld(b, voxel_size_));
    PLX_RETURN_IF_ERROR(GrowIndexToCover(bricks));
    int64_t added = 0;
    for (const BrickCoord& b : bricks) {
      const int64_t i = IndexOf(b);
      if (brick_slot_[i] >= 0) continue;
      if (num_bricks() >= std::numeric_limits<int32_t>::max() / kBrickVertices) {
        return absl::ResourceExhaustedError("too many bricks for 32-bit slot indices");
      }
      // Everything that can throw std::bad_alloc happens before the grid changes, so a failed
      // allocation leaves a consistent grid with the bricks added so far.
      BrickStorage storage = NewBrickStorage();
      const size_t n = brick_coords_.size() + 1;
      ReserveGeometric(density_table_, n);
      ReserveGeometric(sh_table_, n);
      ReserveGeometric(brick_coords_, n);
      ReserveGeometric(bricks_, n);
      ReserveGeometric(brick_shared_, n);
      ReserveGeometric(brick_origin_, 3 * n);
      ReserveGeometric(cell_bits_, cell_bits_.size() + 8 * kBrickEdge);
      ReserveGeometric(active_blocks_, active_blocks_.size() + 8);
      std::fill(storage.get(), storage.get() + kBrickVertices, initial_density);
      std::fill(storage.get() + kBrickVertices, storage.get() + kBrickFloats, 0.0f);
      brick_slot_[i] = static_cast<int32_t>(num_bricks());
      brick_coords_.push_back(b);
      bricks_.emplace_back();
      brick_shared_.push_back(0);
      density_table_.push_back(nullptr);
      sh_table_.push_back(nullptr);
      SetBrick(num_bricks() - 1, std::move(storage));
      brick_origin_.resize(3 * brick_coords_.size());
      SetBrickOrigin(num_bricks() - 1);
      for (int d = 0; d < 8; ++d) {
        ActivateBlock(IndexOf({b.x - (d & 1), b.y - ((d >> 1) & 1), b.z - ((d >> 2) & 1)}));
      }
      occupancy_stale_ = true;
      ++added;
    }
    return added;
  });
}

absl::Status SparseGrid::PrepareToAllocate(absl::Span<const BrickCoord> bricks) {
  return CatchAllocationFailure("allocating bricks", [&]() -> absl::Status {
    for (const BrickCoord& b : bricks) PLX_RETURN_IF_ERROR(CheckBrickInsideWorld(b, voxel_size_));
    return GrowIndexToCover(bricks);
  });
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
  m.parameter_bytes = num_bricks() * kBrickFloats * static_cast<int64_t>(sizeof(float));
  m.index_bytes = static_cast<int64_t>((brick_slot_.size() + block_cells_.size() +
                                        brick_origin_.size()) * sizeof(int32_t) +
                                       (density_table_.size() + sh_table_.size()) *
                                           sizeof(float*) +
                                       cell_bits_.size() * sizeof(uint64_t) +
                                       active_blocks_.size() * sizeof(int64_t));
  return m;
}

}  // namespace plx
