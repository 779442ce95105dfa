// Trilinear sampling of the brick grid at a point: the 8 corner slots and weights of the cell
// that holds it, then density, SH coefficients and their scatter (backward) through the same
// weights.
#pragma once

#include "core/common/atomics.h"
#include "core/common/host_device.h"
#include "core/grid/grid_view.h"
#include "core/math/trilinear.h"

namespace plx {

template <typename T>
struct CellSample {
  int64_t slots[8];  // storage slot per corner, -1 when not stored
  T weights[8];      // trilinear weights (sum to 1)
  Vec3<T> frac;      // position inside the cell, voxel units
  int cell[3];       // integer vertex coordinates of corner 0
};

// Fills `sample` for continuous vertex coordinates q (the caller keeps q inside the grid).
template <typename T>
PLX_HD void LocateCell(const GridViewT<T>& grid, const Vec3<T>& q, CellSample<T>* sample) {
  int c[3];
  T f[3];
  for (int a = 0; a < 3; ++a) {
    const T v = q[a];
    int i = static_cast<int>(floor(v));
    const int hi = grid.vertex_extent(a) - 2;
    i = i < 0 ? 0 : (i > hi ? hi : i);
    c[a] = i;
    f[a] = v - T(i);
  }
  sample->cell[0] = c[0];
  sample->cell[1] = c[1];
  sample->cell[2] = c[2];
  sample->frac = {f[0], f[1], f[2]};
  TrilinearWeights(sample->frac, sample->weights);
  const int lx = c[0] & (kBrickEdge - 1), ly = c[1] & (kBrickEdge - 1),
            lz = c[2] & (kBrickEdge - 1);
  if (lx < kBrickEdge - 1 && ly < kBrickEdge - 1 && lz < kBrickEdge - 1) {
    // All corners share one brick: one index lookup, fixed offsets.
    const int64_t base = grid.VertexSlot(c[0], c[1], c[2]);
    for (int k = 0; k < 8; ++k) {
      sample->slots[k] =
          base < 0 ? -1
                   : base + (k & 1) + ((k >> 1) & 1) * kBrickEdge +
                         ((k >> 2) & 1) * kBrickEdge * kBrickEdge;
    }
    return;
  }
  for (int k = 0; k < 8; ++k) {
    sample->slots[k] =
        grid.VertexSlot(c[0] + (k & 1), c[1] + ((k >> 1) & 1), c[2] + ((k >> 2) & 1));
  }
}

template <typename T>
PLX_HD void GatherCornerDensity(const GridViewT<T>& grid, const CellSample<T>& s, T values[8]) {
  for (int k = 0; k < 8; ++k) values[k] = s.slots[k] >= 0 ? grid.Density(s.slots[k]) : T(0);
}

template <typename T>
PLX_HD T SampleDensity(const GridViewT<T>& grid, const CellSample<T>& s) {
  T v = T(0);
  for (int k = 0; k < 8; ++k) {
    if (s.slots[k] >= 0) v += s.weights[k] * grid.Density(s.slots[k]);
  }
  return v;
}

// Interpolated SH coefficients (27, channel-major).
template <typename T>
PLX_HD void SampleSh(const GridViewT<T>& grid, const CellSample<T>& s, T sh[kShCoeffCount]) {
  for (int j = 0; j < kShCoeffCount; ++j) sh[j] = T(0);
  for (int k = 0; k < 8; ++k) {
    if (s.slots[k] < 0) continue;
    const T* src = grid.Sh(s.slots[k]);
    const T w = s.weights[k];
    for (int j = 0; j < kShCoeffCount; ++j) sh[j] += w * src[j];
  }
}

// Colour before activation per channel: sum_k sh[c*9+k] * basis[k].
template <typename T>
PLX_HD void ShToRawColor(const T sh[kShCoeffCount], const T basis[kShBasisCount], T raw[3]) {
  for (int c = 0; c < 3; ++c) {
    T v = T(0);
    for (int k = 0; k < kShBasisCount; ++k) v += sh[c * kShBasisCount + k] * basis[k];
    raw[c] = v;
  }
}

// Adds one vertex's share of a sample's gradient: d_density to its density and
// scale * d_sh[j] to its SH coefficients (d_sh may be null). GPU: one atomicAdd per value.
// CPU: a spin lock in bit 1 of the vertex's touched flag guards plain adds, which costs one
// atomic pair per vertex instead of 28 compare-and-swap loops.
template <typename T>
PLX_HD void AccumulateVertexGrad(GridGradViewT<T> grad, int64_t slot, T d_density,
                                 const T* d_sh, T scale) {
#if defined(__CUDA_ARCH__)
  AtomicAdd(grad.density + slot, d_density);
  if (d_sh != nullptr) {
    T* dst = grad.sh + slot * kShCoeffCount;
    for (int j = 0; j < kShCoeffCount; ++j) {
      if (d_sh[j] != T(0)) AtomicAdd(dst + j, scale * d_sh[j]);
    }
  }
  grad.MarkTouched(slot);
#else
  std::atomic_ref<uint8_t> flag(grad.touched[slot]);
  uint8_t before;
  while ((before = flag.fetch_or(uint8_t{2}, std::memory_order_acquire)) & 2) {
  }
  if ((before & 1) == 0) AtomicSetFlag(grad.brick_touched + slot / kBrickVertices);
  grad.density[slot] += d_density;
  if (d_sh != nullptr) {
    T* dst = grad.sh + slot * kShCoeffCount;
    for (int j = 0; j < kShCoeffCount; ++j) dst[j] += scale * d_sh[j];
  }
  flag.store(uint8_t{1}, std::memory_order_release);  // unlock, mark touched
#endif
}

// Backward of SampleDensity (and, when dL_draw is not null, of SampleSh + ShToRawColor):
// d L / d density[corner] += w_corner * dL_dsigma and
// d L / d sh[corner][c*9+k] += w_corner * dL_draw[c] * basis[k].
template <typename T>
PLX_HD void ScatterSampleGrad(const CellSample<T>& s, T dL_dsigma, const T* dL_draw,
                              const T basis[kShBasisCount], GridGradViewT<T> grad) {
  T per_coeff[kShCoeffCount];
  if (dL_draw != nullptr) {
    for (int c = 0; c < 3; ++c) {
      for (int k = 0; k < kShBasisCount; ++k) {
        per_coeff[c * kShBasisCount + k] = dL_draw[c] * basis[k];
      }
    }
  }
  for (int k = 0; k < 8; ++k) {
    if (s.slots[k] < 0) continue;
    AccumulateVertexGrad(grad, s.slots[k], s.weights[k] * dL_dsigma,
                         dL_draw != nullptr ? per_coeff : nullptr, s.weights[k]);
  }
}

}  // namespace plx
