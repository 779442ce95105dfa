#include "core/synthetic/synthetic_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <thread>
#include <vector>

namespace plx {
namespace {

constexpr float kTwoPi = 6.28318530717958647692f;

// ---------------------------------------------------------------------------------------------
// Geometry.

// A box with its yaw as a cosine/sine pair, so casting a ray costs no trigonometry.
struct PreparedBox {
  Eigen::Vector3d center;
  Eigen::Vector3d half;
  double c = 1.0, s = 0.0;
  double radius2 = 0.0;  // squared radius of the footprint's bounding circle

  // World -> box coordinates (rotation only) and back.
  Eigen::Vector3d ToLocal(const Eigen::Vector3d& v) const {
    return {c * v.x() + s * v.y(), -s * v.x() + c * v.y(), v.z()};
  }
  Eigen::Vector3d ToWorld(const Eigen::Vector3d& v) const {
    return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
  }
};

SyntheticBox MakeBox(double x, double y, double base_z, double sx, double sy, double sz,
                     double yaw_degrees) {
  SyntheticBox box;
  box.center = Eigen::Vector3d(x, y, base_z + 0.5 * sz);
  box.half_extents = Eigen::Vector3d(0.5 * sx, 0.5 * sy, 0.5 * sz);
  box.yaw = yaw_degrees * M_PI / 180.0;
  return box;
}

SyntheticScene BuildRoom() {
  SyntheticScene scene;
  scene.room_min = Eigen::Vector3d(-3.0, -2.5, 0.0);
  scene.room_max = Eigen::Vector3d(3.0, 2.5, 3.0);
  // Boxes sit near the walls so the camera path around the centre stays > 0.5 m from them;
  // the yaws are small and distinct so no two boxes share an edge direction.
  scene.boxes = {
      MakeBox(1.85, 1.25, 0.0, 1.2, 0.8, 0.75, 8.0),    // table-height box
      MakeBox(-2.45, -1.20, 0.0, 0.6, 1.0, 1.9, 0.0),   // tall cabinet, 0.25 m off the wall
      MakeBox(-1.25, 1.80, 0.0, 0.8, 0.7, 0.5, -15.0),  // crate
      MakeBox(-1.20, 1.78, 0.5, 0.3, 0.3, 0.3, 25.0),   // small cube on top of the crate
      MakeBox(1.70, -1.75, 0.0, 0.7, 0.7, 0.9, 35.0),   // medium box
  };
  return scene;
}

// Two rooms of 6 m x 5 m in a row along x, the partition at x = 0 with a doorway at
// |y| <= 0.8 m, z <= 2.1 m. The -x room is BuildRoom's furniture moved 3 m along -x; the +x
// room's keeps > 0.6 m from the two-room figure eight (synthetic_path.cc) and sits near its
// walls.
SyntheticScene BuildTwoRooms() {
  SyntheticScene scene;
  scene.room_min = Eigen::Vector3d(-6.0, -2.5, 0.0);
  scene.room_max = Eigen::Vector3d(6.0, 2.5, 3.0);
  for (SyntheticBox box : BuildRoom().boxes) {
    box.center.x() -= 3.0;
    scene.boxes.push_back(box);
  }
  const std::vector<SyntheticBox> rest = {
      MakeBox(0.0, -1.65, 0.0, 0.2, 1.7, 3.0, 0.0),   // partition, -y of the doorway
      MakeBox(0.0, 1.65, 0.0, 0.2, 1.7, 3.0, 0.0),    // partition, +y of the doorway
      MakeBox(0.0, 0.0, 2.1, 0.2, 1.6, 0.9, 0.0),     // lintel over the doorway
      MakeBox(4.6, 1.5, 0.0, 1.0, 1.4, 0.8, -12.0),   // long low box
      MakeBox(4.5, 1.45, 0.8, 0.45, 0.35, 0.3, 18.0),  // cushion on it
      MakeBox(5.45, -1.55, 0.0, 0.5, 0.9, 2.1, 5.0),  // tall shelf
      MakeBox(2.2, -1.95, 0.0, 0.9, 0.6, 1.1, 20.0),  // dresser
      MakeBox(2.6, 1.95, 0.0, 0.5, 0.5, 0.45, -30.0),  // stool
  };
  scene.boxes.insert(scene.boxes.end(), rest.begin(), rest.end());
  return scene;
}

std::vector<PreparedBox> Prepare(const SyntheticScene& scene) {
  std::vector<PreparedBox> out;
  for (const SyntheticBox& b : scene.boxes) {
    out.push_back({b.center, b.half_extents, std::cos(b.yaw), std::sin(b.yaw),
                   b.half_extents.head<2>().squaredNorm()});
  }
  return out;
}

const std::vector<PreparedBox>& PreparedBoxes(SyntheticSceneKind kind) {
  static const std::vector<PreparedBox>* room =
      new std::vector<PreparedBox>(Prepare(SyntheticSceneOf(SyntheticSceneKind::kRoom)));
  static const std::vector<PreparedBox>* two_rooms =
      new std::vector<PreparedBox>(Prepare(SyntheticSceneOf(SyntheticSceneKind::kTwoRooms)));
  return kind == SyntheticSceneKind::kTwoRooms ? *two_rooms : *room;
}

// Narrows [*t_near, *t_far] to where origin + t * direction lies within +-half along one axis
// (coordinates in the box frame). Returns false once the interval is empty.
bool ClipSlab(double o, double d, double half, int axis, double* t_near, double* t_far,
              int* near_axis, double* near_sign) {
  if (d == 0.0) return std::abs(o) <= half;
  const double inv = 1.0 / d;
  double t0 = (-half - o) * inv;
  double t1 = (half - o) * inv;
  if (t0 > t1) std::swap(t0, t1);
  if (t0 > *t_near) {
    *t_near = t0;
    *near_axis = axis;
    *near_sign = d > 0 ? -1.0 : 1.0;
  }
  *t_far = std::min(*t_far, t1);
  return *t_near <= *t_far;
}

// Casts many rays from one origin (a camera centre): the room and box-frame offsets of the
// origin are computed once per view, not once per ray.
class RayCaster {
 public:
  RayCaster(const Eigen::Vector3d& origin, SyntheticSceneKind scene)
      : origin_(origin), boxes_(PreparedBoxes(scene)) {
    const SyntheticScene& room = SyntheticSceneOf(scene);
    to_min_ = room.room_min - origin;
    to_max_ = room.room_max - origin;
    for (const PreparedBox& box : boxes_) {
      local_origins_.push_back(box.ToLocal(origin - box.center));
      to_centre_xy_.push_back((box.center - origin).head<2>());
    }
  }

  SyntheticHit Cast(const Eigen::Vector3d& direction) const {
    SyntheticHit hit;
    // Seen from inside, the room is hit where the ray leaves its bounding box.
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
      if (direction[i] == 0.0) continue;
      const bool positive = direction[i] > 0;
      const double t = (positive ? to_max_[i] : to_min_[i]) / direction[i];
      if (t < best) {
        best = t;
        // z -> floor/ceiling, x -> walls 2/3, y -> walls 4/5.
        static constexpr int kMinFace[3] = {kSyntheticWallMinX, kSyntheticWallMinY,
                                            kSyntheticFloor};
        hit.surface = kMinFace[i] + (positive ? 1 : 0);
      }
    }
    if (!(best > 0.0) || !std::isfinite(best)) return SyntheticHit{};
    int best_box = -1, best_axis = 0;
    double best_sign = 1.0;

    const std::vector<PreparedBox>& boxes = boxes_;
    const double planar_norm2 = direction.x() * direction.x() + direction.y() * direction.y();
    for (size_t b = 0; b < boxes.size(); ++b) {
      const PreparedBox& box = boxes[b];
      // Cheap reject: the ray's ground projection passes outside the box's bounding circle.
      const Eigen::Vector3d& o = local_origins_[b];
      const double cross =
          to_centre_xy_[b].x() * direction.y() - to_centre_xy_[b].y() * direction.x();
      if (cross * cross > box.radius2 * planar_norm2) continue;
      double t_near = -std::numeric_limits<double>::infinity();
      double t_far = best;
      int axis = 0;
      double sign = 1.0;
      // The vertical slab first: it needs no rotation and rejects most rays above the boxes.
      if (!ClipSlab(o.z(), direction.z(), box.half.z(), 2, &t_near, &t_far, &axis, &sign) ||
          t_far <= 0.0) {
        continue;
      }
      const double dx = box.c * direction.x() + box.s * direction.y();
      const double dy = -box.s * direction.x() + box.c * direction.y();
      if (!ClipSlab(o.x(), dx, box.half.x(), 0, &t_near, &t_far, &axis, &sign) ||
          !ClipSlab(o.y(), dy, box.half.y(), 1, &t_near, &t_far, &axis, &sign)) {
        continue;
      }
      if (t_near > 0.0 && t_near < best) {
        best = t_near;
        best_box = static_cast<int>(b);
        best_axis = axis;
        best_sign = sign;
      }
    }

    hit.t = best;
    hit.point = origin_ + best * direction;
    if (best_box >= 0) {
      hit.surface = kSyntheticFirstBox + best_box;
      Eigen::Vector3d local = Eigen::Vector3d::Zero();
      local[best_axis] = best_sign;
      hit.normal = boxes[best_box].ToWorld(local);
    } else {
      static constexpr Eigen::Index kAxis[6] = {2, 2, 0, 0, 1, 1};
      hit.normal[kAxis[hit.surface]] = (hit.surface % 2 == 0) ? 1.0 : -1.0;
    }
    return hit;
  }

 private:
  Eigen::Vector3d origin_;
  const std::vector<PreparedBox>& boxes_;
  Eigen::Vector3d to_min_, to_max_;
  std::vector<Eigen::Vector3d> local_origins_;  // per box, in the box frame
  std::vector<Eigen::Vector2d> to_centre_xy_;   // per box, world xy
};

// ---------------------------------------------------------------------------------------------
// Textures. All patterns are smooth functions of surface coordinates (s, t) in metres: colour
// ramps of 1-2.5 m, waves of 15-60 cm, soft checkers of 10-50 cm cells, an 11 cm brightness
// ripple, and on the floor 7 cm wood grain. The shortest period is 7 cm and soft edges are
// >= 2.4 cm wide, so a 1-2 cm voxel grid can represent them.
//
// Colour samples are shaded kLanes at a time (the subsamples of a pixel nearly always hit the
// same surface), written as branch-free per-lane loops that the compiler vectorises; this is
// most of the generator's run time.

constexpr int kLanes = 4;
constexpr int kMaxSupersampling = 4;  // ShadeHits tracks up to 32 samples in a bitmask

// Integer part rounded down, for |x| < 1000 (branch free, unlike a floorf call).
inline int FloorInt(float x) { return static_cast<int>(x + 1024.0f) - 1024; }

// sin(2 pi x) to ~1e-6 for |x| < 1000 (texture coordinates stay far below): a short polynomial,
// much cheaper than sinf, and the textures need no more accuracy.
inline float SinTurns(float x) {
  const float y = x - static_cast<float>(FloorInt(x + 0.5f));  // in [-0.5, 0.5]
  const float a = std::abs(y);
  const float z = kTwoPi * std::min(a, 0.5f - a);  // sin(pi - b) = sin(b); z in [0, pi/2]
  const float z2 = z * z;
  const float sine =
      z * (1.0f + z2 * (-1.0f / 6 + z2 * (1.0f / 120 + z2 * (-1.0f / 5040 + z2 / 362880.0f))));
  return std::copysign(sine, y);
}

// 0.5 + 0.5 sin(2 pi x): a ramp between two colours.
inline float Ramp(float x) { return 0.5f + 0.5f * SinTurns(x); }

// Hermite step from 0 at x = edge0 to 1 at x = edge0 + 1 / inv_width. The clamp to [0, 1] is
// written with abs() because GCC turns min/max-then-polynomial into branches it cannot
// vectorise (it folds the polynomial on the clamped sides).
inline float SmoothStep(float edge0, float inv_width, float x) {
  const float v = (x - edge0) * inv_width;
  const float t = 0.5f * (std::abs(v) - std::abs(v - 1.0f) + 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

// Deterministic value in [0, 1) for an integer cell (plank tones).
inline float Hash01(int a, int b) {
  uint32_t h = static_cast<uint32_t>(a) * 0x8da6b343u ^ static_cast<uint32_t>(b) * 0xd8163841u;
  h ^= h >> 15;
  h *= 0x2c1b3c6du;
  h ^= h >> 12;
  h *= 0x297a2d39u;
  h ^= h >> 15;
  return static_cast<float>(static_cast<int>(h >> 8)) * (1.0f / 16777216.0f);
}

inline float Mix(float a, float b, float w) { return a + w * (b - a); }

// Colour ramps at three scales plus a soft-edged checker, in one palette. Frequencies are in
// cycles per metre.
struct Palette {
  float base[3], ramp[3], accent[3], tile[3];
  float ramp_s, ramp_t;  // large-scale ramps along s and t (periods of 1-2.5 m)
  float wave_s, wave_t;  // mid-scale oblique wave (periods of 15-60 cm)
  float tile_size;       // checker cell (m); edges are about tile_size / 4 wide
  float phase;           // turns; decorrelates surfaces
};

// Planar per-lane colour channels.
struct LaneColors {
  float rgb[3][kLanes];
};

void PatternLanes(const Palette& p, const float* s, const float* t, LaneColors* out) {
  const float cells_per_metre = 0.5f / p.tile_size;
  // A fine brightness ripple (11 cm period) across the mid-scale wave keeps gradients inside
  // the flat checker cells.
  const float wave_norm = std::sqrt(p.wave_s * p.wave_s + p.wave_t * p.wave_t);
  const float fine_s = -9.0f * p.wave_t / wave_norm, fine_t = 9.0f * p.wave_s / wave_norm;
  float w_ramp[kLanes], w_accent[kLanes], w_tile[kLanes], brightness[kLanes];
  for (int i = 0; i < kLanes; ++i) {
    const float r1 = Ramp(s[i] * p.ramp_s + p.phase);
    const float r2 = Ramp(t[i] * p.ramp_t + 1.7f * p.phase);
    const float wave = Ramp(s[i] * p.wave_s + t[i] * p.wave_t + 2.3f * p.phase);
    const float fine = Ramp(s[i] * fine_s + t[i] * fine_t + 3.1f * p.phase);
    // A smoothstep of a product of sines: flat cells with soft edges.
    const float cells = SinTurns(s[i] * cells_per_metre) * SinTurns(t[i] * cells_per_metre);
    w_ramp[i] = 0.6f * r1 + 0.4f * wave;
    w_accent[i] = 0.55f * r2;
    w_tile[i] = 0.4f * SmoothStep(-0.4f, 1.0f / 0.8f, cells);
    brightness[i] = 0.86f + 0.28f * fine;
  }
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < kLanes; ++i) {
      const float base = Mix(Mix(p.base[c], p.ramp[c], w_ramp[i]), p.accent[c], w_accent[i]);
      out->rgb[c][i] = brightness[i] * Mix(base, p.tile[c], w_tile[i]);
    }
  }
}

// Wooden planks along x (s = x, t = y): per-plank tone, wavy grain stripes and soft grooves
// between planks (the groove colour is shared, so the albedo stays continuous across plank
// boundaries).
void WoodLanes(const float* s, const float* t, LaneColors* out) {
  constexpr float kPlankWidth = 0.2f, kPlankLength = 1.2f, kGroove = 0.012f;
  constexpr float kLight[3] = {0.78f, 0.58f, 0.36f}, kDark[3] = {0.42f, 0.25f, 0.12f};
  constexpr float kReddish[3] = {0.62f, 0.30f, 0.20f}, kGrooveColor[3] = {0.18f, 0.11f, 0.06f};
  float w_dark[kLanes], w_red[kLanes], w_wood[kLanes];
  for (int i = 0; i < kLanes; ++i) {
    const float x = s[i], y = t[i];
    const int row = FloorInt(y * (1.0f / kPlankWidth));
    const float across = y - static_cast<float>(row) * kPlankWidth;
    const float shifted = x + kPlankLength * Hash01(row, 7);
    const int column = FloorInt(shifted * (1.0f / kPlankLength));
    const float along = shifted - static_cast<float>(column) * kPlankLength;
    const float tone = Hash01(row, column);
    const float wobble = 0.03f * SinTurns(x * (1.0f / 0.9f) + tone);
    const float grain = Ramp((across + wobble) * (1.0f / 0.07f) + tone);
    const float ramp = Ramp(x * (1.0f / 2.7f) + 0.13f * SinTurns(0.16f * y));
    w_dark[i] = 0.45f * tone + 0.3f * grain + 0.25f * ramp;
    w_red[i] = 0.35f * Ramp(y * (1.0f / 1.9f));
    w_wood[i] = SmoothStep(0.0f, 1.0f / kGroove, std::min(across, kPlankWidth - across)) *
                SmoothStep(0.0f, 1.0f / kGroove, std::min(along, kPlankLength - along));
  }
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < kLanes; ++i) {
      const float wood = Mix(Mix(kLight[c], kDark[c], w_dark[i]), kReddish[c], w_red[i]);
      out->rgb[c][i] = Mix(kGrooveColor[c], wood, w_wood[i]);
    }
  }
}

const Palette& SurfacePalette(int surface) {
  // Room faces, then boxes (boxes beyond the list reuse the box palettes cyclically).
  // clang-format off
  static const Palette kPalettes[] = {
      // Floor (drawn as wood; kept so indices line up with SyntheticSurface).
      {{0.6f, 0.4f, 0.2f}, {0.4f, 0.3f, 0.2f}, {0.5f, 0.3f, 0.2f}, {0.3f, 0.2f, 0.1f},
       0.5f, 0.5f, 2.0f, 1.0f, 0.3f, 0.0f},
      // Ceiling: light, low contrast but still graded.
      {{0.92f, 0.90f, 0.84f}, {0.75f, 0.80f, 0.88f}, {0.95f, 0.85f, 0.75f},
       {0.70f, 0.72f, 0.70f}, 0.43f, 0.53f, 1.54f, 0.65f, 0.5f, 0.05f},
      // Wall -x: blue/teal wallpaper.
      {{0.25f, 0.45f, 0.70f}, {0.20f, 0.70f, 0.65f}, {0.85f, 0.80f, 0.55f},
       {0.12f, 0.20f, 0.40f}, 0.59f, 0.77f, 2.19f, 1.84f, 0.25f, 0.18f},
      // Wall +x: warm ochre/red.
      {{0.85f, 0.65f, 0.30f}, {0.80f, 0.35f, 0.25f}, {0.45f, 0.60f, 0.35f},
       {0.40f, 0.20f, 0.15f}, 0.53f, 0.91f, 2.09f, -1.14f, 0.30f, 0.32f},
      // Wall -y: green/grey.
      {{0.45f, 0.65f, 0.40f}, {0.70f, 0.75f, 0.70f}, {0.30f, 0.40f, 0.70f},
       {0.15f, 0.30f, 0.18f}, 0.67f, 0.63f, 1.29f, 3.33f, 0.20f, 0.08f},
      // Wall +y: violet/pink.
      {{0.60f, 0.45f, 0.70f}, {0.90f, 0.60f, 0.65f}, {0.55f, 0.80f, 0.85f},
       {0.30f, 0.20f, 0.35f}, 0.48f, 0.71f, 2.58f, 0.52f, 0.35f, 0.43f},
      // Box 0 (table): dark walnut and sand.
      {{0.55f, 0.35f, 0.20f}, {0.80f, 0.70f, 0.50f}, {0.30f, 0.45f, 0.50f},
       {0.20f, 0.12f, 0.08f}, 1.1f, 1.4f, 2.83f, 3.56f, 0.12f, 0.06f},
      // Box 1 (cabinet): cream and slate.
      {{0.88f, 0.85f, 0.75f}, {0.45f, 0.55f, 0.65f}, {0.85f, 0.55f, 0.35f},
       {0.25f, 0.28f, 0.35f}, 0.9f, 1.25f, 2.16f, -3.37f, 0.15f, 0.30f},
      // Box 2 (crate): orange and olive.
      {{0.90f, 0.55f, 0.15f}, {0.55f, 0.60f, 0.20f}, {0.95f, 0.85f, 0.55f},
       {0.35f, 0.25f, 0.10f}, 1.7f, 2.0f, 5.12f, 2.16f, 0.10f, 0.49f},
      // Box 3 (small cube): red and cyan.
      {{0.85f, 0.20f, 0.25f}, {0.20f, 0.75f, 0.80f}, {0.95f, 0.90f, 0.30f},
       {0.20f, 0.10f, 0.30f}, 2.0f, 2.2f, 5.1f, 4.3f, 0.10f, 0.14f},
      // Box 4 (medium box): indigo and lime.
      {{0.30f, 0.30f, 0.70f}, {0.60f, 0.85f, 0.35f}, {0.90f, 0.60f, 0.80f},
       {0.10f, 0.10f, 0.25f}, 1.25f, 1.7f, 4.78f, -1.48f, 0.14f, 0.38f},
  };
  // clang-format on
  constexpr int kCount = sizeof(kPalettes) / sizeof(kPalettes[0]);
  if (surface < kCount) return kPalettes[surface];
  return kPalettes[kSyntheticFirstBox +
                   (surface - kSyntheticFirstBox) % (kCount - kSyntheticFirstBox)];
}

// Fixed diffuse light: a face's brightness depends only on its normal, so shading stays view
// independent and neighbouring faces of a box differ in brightness.
float Shading(const Eigen::Vector3d& normal) {
  static const Eigen::Vector3d kLight = Eigen::Vector3d(0.35, -0.45, 0.82).normalized();
  return static_cast<float>(0.7 + 0.3 * normal.dot(kLight));
}

// Texture coordinates of a hit on its surface: floor and ceiling (x, y), walls (horizontal
// coordinate, height), box faces the two in-face axes of the box frame, offset per face so
// opposite faces do not look alike.
void SurfaceCoordinates(const SyntheticHit& hit, const std::vector<PreparedBox>& boxes, float* s,
                        float* t) {
  const Eigen::Vector3d& p = hit.point;
  if (hit.surface <= kSyntheticCeiling) {
    *s = static_cast<float>(p.x()), *t = static_cast<float>(p.y());
  } else if (hit.surface <= kSyntheticWallMaxX) {
    *s = static_cast<float>(p.y()), *t = static_cast<float>(p.z());
  } else if (hit.surface <= kSyntheticWallMaxY) {
    *s = static_cast<float>(p.x()), *t = static_cast<float>(p.z());
  } else {
    const PreparedBox& box = boxes[hit.surface - kSyntheticFirstBox];
    const Eigen::Vector3d local = box.ToLocal(p - box.center);
    const Eigen::Vector3d n = box.ToLocal(hit.normal);
    int axis = 0;
    n.cwiseAbs().maxCoeff(&axis);
    const int a = (axis + 1) % 3, b = (axis + 2) % 3;
    const float offset = 0.37f * static_cast<float>(axis) + (n[axis] > 0 ? 0.11f : 0.0f);
    *s = static_cast<float>(local[a]) + offset;
    *t = static_cast<float>(local[b]) + 0.5f * offset;
  }
}

// Shades 1..kLanes hits that all lie on one surface (not kSyntheticNoHit) and adds
// weight * colour of each into *sum. Unused lanes repeat the last hit.
void ShadeSameSurface(const SyntheticHit* const* hits, int count, float weight,
                      const std::vector<PreparedBox>& boxes, Eigen::Vector3f* sum) {
  float s[kLanes], t[kLanes];
  for (int i = 0; i < kLanes; ++i) {
    SurfaceCoordinates(*hits[std::min(i, count - 1)], boxes, &s[i], &t[i]);
  }
  LaneColors colors;
  const int surface = hits[0]->surface;
  if (surface == kSyntheticFloor) {
    WoodLanes(s, t, &colors);
  } else {
    PatternLanes(SurfacePalette(surface), s, t, &colors);
  }
  for (int i = 0; i < count; ++i) {
    const float shade = Shading(hits[i]->normal);
    for (int c = 0; c < 3; ++c) {
      (*sum)[c] += weight * std::clamp(colors.rgb[c][i] * shade, 0.0f, 1.0f);
    }
  }
}

// Adds weight * colour of each hit (count <= 32) into *sum, grouping hits on one surface into
// lanes.
void ShadeHits(const SyntheticHit* hits, int count, float weight,
               const std::vector<PreparedBox>& boxes, Eigen::Vector3f* sum) {
  const SyntheticHit* group[kLanes];
  uint32_t done = 0;
  for (int first = 0; first < count; ++first) {
    if (done & (1u << first)) continue;
    const int surface = hits[first].surface;
    int n = 0;
    for (int i = first; i < count && n < kLanes; ++i) {
      if (!(done & (1u << i)) && hits[i].surface == surface) {
        group[n++] = &hits[i];
        done |= 1u << i;
      }
    }
    if (surface != kSyntheticNoHit) ShadeSameSurface(group, n, weight, boxes, sum);  // or black
  }
}

}  // namespace

const SyntheticScene& SyntheticSceneOf(SyntheticSceneKind kind) {
  static const SyntheticScene* room = new SyntheticScene(BuildRoom());
  static const SyntheticScene* two_rooms = new SyntheticScene(BuildTwoRooms());
  return kind == SyntheticSceneKind::kTwoRooms ? *two_rooms : *room;
}

const SyntheticScene& SyntheticRoom() { return SyntheticSceneOf(SyntheticSceneKind::kRoom); }

SyntheticHit CastSyntheticRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                              SyntheticSceneKind scene) {
  return RayCaster(origin, scene).Cast(direction);
}

Eigen::Vector3f SyntheticSurfaceColor(const SyntheticHit& hit, SyntheticSceneKind scene) {
  Eigen::Vector3f rgb = Eigen::Vector3f::Zero();
  ShadeHits(&hit, 1, 1.0f, PreparedBoxes(scene), &rgb);
  return rgb;
}

namespace internal {

void RenderSyntheticRows(const SE3& world_T_camera, const PinholeIntrinsics& k, int supersampling,
                         SyntheticSceneKind scene, int row_begin, int row_end,
                         RgbdFrame* frame) {
  const Eigen::Matrix3d rotation = world_T_camera.rotation_matrix();
  const Eigen::Vector3d origin = world_T_camera.translation();
  const int ss = std::clamp(supersampling, 1, kMaxSupersampling);
  const float weight = 1.0f / static_cast<float>(ss * ss);
  // Camera-frame ray slopes of the pixel centres and of the subsample columns/rows.
  auto slopes = [ss](int count, double centre, double focal, std::vector<double>* at_centre,
                     std::vector<double>* at_samples) {
    at_centre->resize(count);
    at_samples->resize(static_cast<size_t>(count) * ss);
    for (int p = 0; p < count; ++p) {
      (*at_centre)[p] = (p + 0.5 - centre) / focal;
      for (int i = 0; i < ss; ++i) {
        (*at_samples)[p * ss + i] = (p + (i + 0.5) / ss - centre) / focal;
      }
    }
  };
  std::vector<double> x_centre, x_sample, y_centre, y_sample;
  slopes(k.width, k.cx, k.fx, &x_centre, &x_sample);
  slopes(k.height, k.cy, k.fy, &y_centre, &y_sample);
  const Eigen::Vector3d right = rotation.col(0), down = rotation.col(1), forward = rotation.col(2);
  const RayCaster caster(origin, scene);
  const std::vector<PreparedBox>& boxes = PreparedBoxes(scene);
  std::vector<SyntheticHit> samples(ss * ss);
  for (int v = row_begin; v < row_end; ++v) {
    for (int u = 0; u < k.width; ++u) {
      // With a camera direction of z = 1 the ray parameter is the z-depth.
      const SyntheticHit centre = caster.Cast(right * x_centre[u] + down * y_centre[v] + forward);
      frame->depth.pixel(u, v)[0] =
          centre.surface == kSyntheticNoHit ? 0.0f : static_cast<float>(centre.t);
      for (int j = 0; j < ss; ++j) {
        const Eigen::Vector3d row_direction = down * y_sample[v * ss + j] + forward;
        for (int i = 0; i < ss; ++i) {
          // With an odd factor the middle subsample is the pixel centre: reuse its hit.
          samples[j * ss + i] = (2 * i + 1 == ss && 2 * j + 1 == ss)
                                    ? centre
                                    : caster.Cast(right * x_sample[u * ss + i] + row_direction);
        }
      }
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      ShadeHits(samples.data(), ss * ss, weight, boxes, &sum);
      float* rgb = frame->color.pixel(u, v);
      for (int c = 0; c < 3; ++c) rgb[c] = sum[c];
    }
  }
}

}  // namespace internal

RgbdFrame RenderSyntheticView(const SE3& world_T_camera, const PinholeIntrinsics& intrinsics,
                              int supersampling, SyntheticSceneKind scene) {
  RgbdFrame frame;
  frame.ground_truth = world_T_camera;
  if (intrinsics.width <= 0 || intrinsics.height <= 0) return frame;
  frame.color = ColorImage(intrinsics.width, intrinsics.height, 3);
  frame.depth = DepthImage(intrinsics.width, intrinsics.height, 1);
  // Bands of rows are independent, so threads write disjoint memory and results do not depend
  // on the thread count.
  const int hardware = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int num_threads = std::clamp(intrinsics.height / 32, 1, hardware);
  std::vector<std::thread> workers;
  for (int w = 1; w < num_threads; ++w) {
    const int begin = intrinsics.height * w / num_threads;
    const int end = intrinsics.height * (w + 1) / num_threads;
    workers.emplace_back([&, begin, end] {
      internal::RenderSyntheticRows(world_T_camera, intrinsics, supersampling, scene, begin, end,
                                    &frame);
    });
  }
  internal::RenderSyntheticRows(world_T_camera, intrinsics, supersampling, scene, 0,
                                intrinsics.height / num_threads, &frame);
  for (std::thread& t : workers) t.join();
  return frame;
}

}  // namespace plx
