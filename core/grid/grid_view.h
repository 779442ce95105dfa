// Kernel-side view of the sparse brick grid (DESIGN.md §5): trivially copyable raw pointers
// and sizes. Vertices live in bricks of 8x8x8 allocated on demand; a dense coarse index (one
// int32 per brick position) maps brick coordinates to storage slots. Unallocated vertices read
// as zero density and zero SH. Templated on the scalar so tests can run it in double.
#pragma once

#include <cstdint>

#include "core/common/atomics.h"
#include "core/common/host_device.h"
#include "core/math/spherical_harmonics.h"
#include "core/math/vec3.h"

namespace plx {

inline constexpr int kBrickShift = 3;
inline constexpr int kBrickEdge = 1 << kBrickShift;                         // vertices per edge
inline constexpr int kBrickVertices = kBrickEdge * kBrickEdge * kBrickEdge;  // 512
inline constexpr int kValuesPerVertex = 1 + kShCoeffCount;                  // 28 floats

// Read-only: a published map is shared by many readers at once, so the view through which
// kernels read a grid cannot write to it (the writers get a GridWriteViewT besides).
template <typename T>
struct GridViewT {
  // Per brick slot: its 512 densities and its 512 * 27 SH coefficients (channel-major per
  // vertex). Tables rather than one array so that map versions can share unchanged bricks
  // (copy-on-write, see SparseGrid); vertex ids are still slot * 512 + local.
  const T* const* brick_density = nullptr;  // [num_bricks] -> [512]
  const T* const* brick_sh = nullptr;       // [num_bricks] -> [512 * 27]
  const int32_t* brick_slot = nullptr;    // [dims.x * dims.y * dims.z], x fastest; -1 = empty
  // Per index block: -1 when none of its cells touches a stored vertex (the march skips the
  // whole block), else the offset of its 512 occupancy bits in cell_bits (in 64-bit words).
  const int32_t* block_cells = nullptr;
  // One bit per cell, x fastest: set unless every corner of the cell is known to have density
  // at or below the map's threshold. Such cells contribute nothing and, because of the ReLU,
  // receive no gradient, so skipping them is exact. Conservative: a set bit may be stale.
  const uint64_t* cell_bits = nullptr;
  const int32_t* brick_origin = nullptr;  // [num_bricks * 3] vertex coords of each brick's corner
  int32_t dims[3] = {0, 0, 0};            // index size in bricks
  T origin[3] = {0, 0, 0};                // world position of vertex (0, 0, 0) of the index
  T voxel_size = T(1);                    // metres between vertices
  int64_t num_bricks = 0;

  PLX_HD int64_t num_vertices() const { return num_bricks * kBrickVertices; }
  PLX_HD int32_t vertex_extent(int axis) const { return dims[axis] * kBrickEdge; }

  // Parameters of stored vertex `vertex` (slot * 512 + local).
  PLX_HD T Density(int64_t vertex) const {
    return brick_density[vertex >> (3 * kBrickShift)][vertex & (kBrickVertices - 1)];
  }
  PLX_HD const T* Sh(int64_t vertex) const {
    return brick_sh[vertex >> (3 * kBrickShift)] + (vertex & (kBrickVertices - 1)) * kShCoeffCount;
  }

  PLX_HD bool BlockInside(int bx, int by, int bz) const {
    return bx >= 0 && by >= 0 && bz >= 0 && bx < dims[0] && by < dims[1] && bz < dims[2];
  }
  PLX_HD int64_t BlockLinear(int bx, int by, int bz) const {
    return (static_cast<int64_t>(bz) * dims[1] + by) * dims[0] + bx;
  }
  PLX_HD int32_t BlockCells(int bx, int by, int bz) const {
    return BlockInside(bx, by, bz) ? block_cells[BlockLinear(bx, by, bz)] : -1;
  }
  PLX_HD bool BlockActive(int bx, int by, int bz) const { return BlockCells(bx, by, bz) >= 0; }

  // Occupancy bit of the cell with local coordinates (lx, ly, lz) in a block's bits.
  PLX_HD bool CellOccupied(int32_t block_bits, int lx, int ly, int lz) const {
    return (cell_bits[block_bits + lz] >> (ly * kBrickEdge + lx)) & 1u;
  }

  // Storage slot of vertex (vx, vy, vz), or -1 when it is not stored.
  PLX_HD int64_t VertexSlot(int vx, int vy, int vz) const {
    const int bx = vx >> kBrickShift, by = vy >> kBrickShift, bz = vz >> kBrickShift;
    if (vx < 0 || vy < 0 || vz < 0 || !BlockInside(bx, by, bz)) return -1;
    const int32_t brick = brick_slot[BlockLinear(bx, by, bz)];
    if (brick < 0) return -1;
    const int local = (vx & (kBrickEdge - 1)) | ((vy & (kBrickEdge - 1)) << kBrickShift) |
                      ((vz & (kBrickEdge - 1)) << (2 * kBrickShift));
    return static_cast<int64_t>(brick) * kBrickVertices + local;
  }

  // Integer vertex coordinates (in this index) of stored vertex `vertex` (slot * 512 + local).
  PLX_HD void VertexCoords(int64_t vertex, int v[3]) const {
    const int64_t brick = vertex / kBrickVertices;
    const int local = static_cast<int>(vertex % kBrickVertices);
    v[0] = brick_origin[3 * brick + 0] + (local & (kBrickEdge - 1));
    v[1] = brick_origin[3 * brick + 1] + ((local >> kBrickShift) & (kBrickEdge - 1));
    v[2] = brick_origin[3 * brick + 2] + (local >> (2 * kBrickShift));
  }

  // World position -> continuous vertex coordinates.
  PLX_HD Vec3<T> ToGrid(const Vec3<T>& p) const {
    const T inv = T(1) / voxel_size;
    return {(p.x - origin[0]) * inv, (p.y - origin[1]) * inv, (p.z - origin[2]) * inv};
  }
  PLX_HD Vec3<T> VertexPosition(int vx, int vy, int vz) const {
    return {origin[0] + vx * voxel_size, origin[1] + vy * voxel_size, origin[2] + vz * voxel_size};
  }
};

// What the kernels that change a grid (fusion, the optimiser, resampling, occupancy refresh)
// may write, beside the grid's read view: only a mapping job's own, unpublished grid hands one
// out (SparseGrid::write_view), after making the bricks it will write private to it.
template <typename T>
struct GridWriteViewT {
  T* const* brick_density = nullptr;  // same tables as the read view, writable
  T* const* brick_sh = nullptr;
  uint64_t* cell_bits = nullptr;

  PLX_HD T& Density(int64_t vertex) const {
    return brick_density[vertex >> (3 * kBrickShift)][vertex & (kBrickVertices - 1)];
  }
  PLX_HD T* Sh(int64_t vertex) const {
    return brick_sh[vertex >> (3 * kBrickShift)] + (vertex & (kBrickVertices - 1)) * kShCoeffCount;
  }

  // Marks the 8 cells that have vertex (vx, vy, vz) of `grid` as a corner as occupied
  // (thread-safe).
  PLX_HD void MarkCellsAroundVertex(const GridViewT<T>& grid, int vx, int vy, int vz) const {
    for (int d = 0; d < 8; ++d) {
      const int cx = vx - (d & 1), cy = vy - ((d >> 1) & 1), cz = vz - ((d >> 2) & 1);
      if (cx < 0 || cy < 0 || cz < 0) continue;
      const int32_t bits =
          grid.BlockCells(cx >> kBrickShift, cy >> kBrickShift, cz >> kBrickShift);
      if (bits < 0) continue;
      const int lx = cx & (kBrickEdge - 1), ly = cy & (kBrickEdge - 1), lz = cz & (kBrickEdge - 1);
      AtomicOr(cell_bits + bits + lz, uint64_t{1} << (ly * kBrickEdge + lx));
    }
  }
};

using GridView = GridViewT<float>;
using GridWriteView = GridWriteViewT<float>;

// Gradient buffers with the same slot layout as GridView, plus a per-vertex "touched" flag so
// the optimiser only visits vertices that received gradient.
template <typename T>
struct GridGradViewT {
  T* density = nullptr;        // [num_vertices]
  T* sh = nullptr;             // [num_vertices * 27]
  uint8_t* touched = nullptr;        // [num_vertices]
  uint8_t* brick_touched = nullptr;  // [num_bricks]: some vertex of the brick is touched

  // Flags vertex `slot` (and its brick) as having gradient. Thread-safe.
  PLX_HD void MarkTouched(int64_t slot) const {
    AtomicSetFlag(touched + slot);
    AtomicSetFlag(brick_touched + slot / kBrickVertices);
  }
};

using GridGradView = GridGradViewT<float>;

}  // namespace plx
