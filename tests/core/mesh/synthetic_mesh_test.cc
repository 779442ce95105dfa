// The mesh of a map of the synthetic room against the room's analytic surfaces: precision (mesh
// vertices within 2 cm of a true surface) and recall (held-out ground-truth points within 2 cm
// of the mesh), what the unobserved-surface filter buys, and the mesh of a box around half the
// room (MeshOptions::region).
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <map>
#include <tuple>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/eval/map_metrics.h"
#include "core/geometry/kernel_camera.h"
#include "core/mapping/map_dataset.h"
#include "core/mapping/mapper.h"
#include "core/mesh/iso_surface.h"
#include "core/mesh/observed_surface.h"
#include "core/synthetic/synthetic_scene.h"
#include "tests/synthetic_distance.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

constexpr double kTolerance = 0.02;  // metres, the F-score distance of docs/BENCHMARKS.md

struct MeshScore {
  double precision = 0.0, recall = 0.0;
};

Eigen::Vector3d Vertex(const TriangleMesh& m, int32_t v) {
  return {m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]};
}

// Recall looks for a mesh sample (vertex or triangle centroid) within the tolerance, through a
// hash of tolerance-sized cells.
MeshScore Score(const TriangleMesh& mesh, const std::vector<Eigen::Vector3d>& truth) {
  MeshScore score;
  std::map<std::tuple<int, int, int>, std::vector<Eigen::Vector3d>> cells;
  auto cell = [](const Eigen::Vector3d& p) {
    return std::make_tuple(static_cast<int>(std::floor(p.x() / kTolerance)),
                           static_cast<int>(std::floor(p.y() / kTolerance)),
                           static_cast<int>(std::floor(p.z() / kTolerance)));
  };
  int64_t near = 0;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    const Eigen::Vector3d p = Vertex(mesh, v);
    near += testing::DistanceToSyntheticRoom(p) < kTolerance;
    cells[cell(p)].push_back(p);
  }
  for (int64_t t = 0; t < mesh.num_triangles(); ++t) {
    const int32_t* f = &mesh.triangles[3 * t];
    const Eigen::Vector3d c = (Vertex(mesh, f[0]) + Vertex(mesh, f[1]) + Vertex(mesh, f[2])) / 3;
    cells[cell(c)].push_back(c);
  }
  int64_t found = 0;
  for (const Eigen::Vector3d& g : truth) {
    const auto [x, y, z] = cell(g);
    bool hit = false;
    for (int d = 0; d < 27 && !hit; ++d) {
      const auto it = cells.find({x + d % 3 - 1, y + (d / 3) % 3 - 1, z + d / 9 - 1});
      if (it == cells.end()) continue;
      for (const Eigen::Vector3d& q : it->second) hit = hit || (q - g).norm() < kTolerance;
    }
    found += hit;
  }
  score.precision = mesh.num_vertices() ? static_cast<double>(near) / mesh.num_vertices() : 0;
  score.recall = truth.empty() ? 0 : static_cast<double>(found) / truth.size();
  return score;
}

// Vertices further than `margin` outside the room's inner faces.
int64_t VerticesOutsideTheRoom(const TriangleMesh& mesh, double margin) {
  const SyntheticScene& room = SyntheticRoom();
  int64_t outside = 0;
  for (int32_t v = 0; v < mesh.num_vertices(); ++v) {
    const Eigen::Vector3d p = Vertex(mesh, v);
    bool in = true;
    for (int a = 0; a < 3; ++a) {
      in = in && p[a] > room.room_min[a] - margin && p[a] < room.room_max[a] + margin;
    }
    outside += !in;
  }
  return outside;
}

// 3 keyframes of the noisy 128 x 96 room at 4 cm voxels (as MapperTest), 60 iterations: mapped
// once for the suite's tests.
class SyntheticMeshTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dataset_ = testing::MakeSyntheticRoom(128, 96, 30, 0.0015, 0.05).release();
    ASSERT_NE(dataset_, nullptr);
    backend_ = MakeCpuBackend(2).release();
    MapperOptions o = MapperOptionsForVoxelSize(0.04f);
    o.max_iterations = 60;
    o.batch_size = 4096;
    auto mapped = MapDataset(*dataset_, KeyframeIndices(dataset_->size(), 10), o, *backend_);
    ASSERT_TRUE(mapped.ok()) << mapped.status();
    map_ = mapped->map.release();
    keyframes_ = new MapKeyframes(std::move(mapped->keyframes));
  }
  static void TearDownTestSuite() {
    delete map_;
    delete keyframes_;
    delete backend_;
    delete dataset_;
    map_ = nullptr;
    keyframes_ = nullptr;
    backend_ = nullptr;
    dataset_ = nullptr;
  }
  void SetUp() override { ASSERT_NE(map_, nullptr) << "mapping the room failed"; }

  static InMemoryDataset* dataset_;
  static Backend* backend_;
  static PlenoxelMap* map_;
  static MapKeyframes* keyframes_;

  // The ground truth: held-out frames' depth, back-projected with their true poses.
  static std::vector<Eigen::Vector3d> HeldOutPoints() {
    std::vector<Eigen::Vector3d> truth;
    const PinholeIntrinsics& K = dataset_->calibration().pinhole;
    for (int f : HeldOutFrames(dataset_->size(), 10)) {
      const RgbdFrame& frame = dataset_->frames()[f];
      for (int v = 0; v < K.height; v += 2) {
        for (int u = 0; u < K.width; u += 2) {
          const double z = *frame.depth.pixel(u, v);
          if (z <= 0) continue;
          truth.push_back(*frame.ground_truth * Eigen::Vector3d((u + 0.5 - K.cx) / K.fx * z,
                                                                (v + 0.5 - K.cy) / K.fy * z, z));
        }
      }
    }
    return truth;
  }
};

InMemoryDataset* SyntheticMeshTest::dataset_ = nullptr;
Backend* SyntheticMeshTest::backend_ = nullptr;
PlenoxelMap* SyntheticMeshTest::map_ = nullptr;
MapKeyframes* SyntheticMeshTest::keyframes_ = nullptr;

TEST_F(SyntheticMeshTest, MeshLiesOnTheRoomsSurfaces) {
  Backend* backend = backend_;
  const std::vector<Eigen::Vector3d> truth = HeldOutPoints();
  auto mesh = ExtractMesh(map_->grid, *backend, MeshOptions{});
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  MeshOptions keep;
  keep.keep_unobserved = true;
  auto unfiltered = ExtractMesh(map_->grid, *backend, keep);
  ASSERT_TRUE(unfiltered.ok()) << unfiltered.status();
  MeshOptions low;
  low.iso_level = 5.0f;
  auto thin = ExtractMesh(map_->grid, *backend, low);
  ASSERT_TRUE(thin.ok()) << thin.status();

  const MeshScore s = Score(*mesh, truth), u = Score(*unfiltered, truth), t = Score(*thin, truth);
  std::printf("default: precision %.3f recall %.3f (%ld triangles); unfiltered %.3f %.3f; "
              "iso 5: %.3f %.3f\n",
              s.precision, s.recall, static_cast<long>(mesh->num_triangles()), u.precision,
              u.recall, t.precision, t.recall);
  EXPECT_GT(s.precision, 0.5);
  EXPECT_GT(s.recall, 0.7);
  // Dropping unobserved surfaces removes back faces only: precision up, recall unchanged.
  EXPECT_GT(s.precision, u.precision + 0.05);
  EXPECT_NEAR(s.recall, u.recall, 0.01);
  // The default level beats the point export's 5/m on both counts.
  EXPECT_GT(s.precision, t.precision);
  EXPECT_GT(s.recall, t.recall);
}

// The surface the keyframes saw (core/mesh/observed_surface.h) against the density's: no back
// faces and nothing unseen, so nearly every vertex lies on the room, with no loss of recall;
// fewer triangles; and every vertex inside the room (a back face lies outside its walls).
TEST_F(SyntheticMeshTest, TheObservedSurfaceHasOneFacePerWall) {
  const std::vector<Eigen::Vector3d> truth = HeldOutPoints();
  const absl::StatusOr<TriangleMesh> observed =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, MeshOptions{});
  ASSERT_TRUE(observed.ok()) << observed.status();
  const absl::StatusOr<TriangleMesh> density = ExtractMesh(map_->grid, *backend_, MeshOptions{});
  ASSERT_TRUE(density.ok()) << density.status();
  const MeshScore o = Score(*observed, truth), d = Score(*density, truth);
  std::printf("observed: precision %.3f recall %.3f (%ld triangles); density: %.3f %.3f (%ld)\n",
              o.precision, o.recall, static_cast<long>(observed->num_triangles()), d.precision,
              d.recall, static_cast<long>(density->num_triangles()));
  EXPECT_GT(o.precision, 0.85);
  EXPECT_GT(o.precision, d.precision + 0.2);
  // Recall: within 0.05. This map is small and short-trained (3 keyframes at 128 x 96, 4 cm
  // voxels, 60 iterations), and the 2-voxel truncation leaves the rims of grazing views
  // without values (0.741 against 0.771); on the benchmark's maps recall is within 0.006
  // (docs/BENCHMARKS.md, "Surfaces seen once").
  EXPECT_GT(o.recall, d.recall - 0.05);
  EXPECT_LT(observed->num_triangles(), density->num_triangles());
  // Back faces lie behind the walls, outside the room. The margin is the depth noise's reach
  // plus a voxel. The density surface has thousands of vertices there; the observed one at
  // most the few where a wall renders too thin to stop a keyframe's ray before its back (none
  // here; 5 of 20 k with a 3-voxel truncation).
  const double margin = 0.05 + map_->grid.voxel_size();
  const int64_t o_outside = VerticesOutsideTheRoom(*observed, margin);
  const int64_t d_outside = VerticesOutsideTheRoom(*density, margin);
  std::printf("vertices outside the room: observed %ld of %ld, density %ld of %ld\n",
              static_cast<long>(o_outside), static_cast<long>(observed->num_vertices()),
              static_cast<long>(d_outside), static_cast<long>(density->num_vertices()));
  EXPECT_LT(o_outside, observed->num_vertices() / 1000);
  EXPECT_GT(d_outside, 100 * std::max<int64_t>(o_outside, 1));
}

TEST_F(SyntheticMeshTest, BoxesTileTheObservedSurface) {
  const absl::StatusOr<TriangleMesh> full =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, MeshOptions{});
  ASSERT_TRUE(full.ok()) << full.status();
  MeshOptions minus_y, plus_y;
  minus_y.region = AxisBox{{-10.0, -10.0, -10.0}, {10.0, 0.0, 10.0}};
  plus_y.region = AxisBox{{-10.0, 0.0, -10.0}, {10.0, 10.0, 10.0}};
  const absl::StatusOr<TriangleMesh> half =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, minus_y);
  const absl::StatusOr<TriangleMesh> other =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, plus_y);
  ASSERT_TRUE(half.ok()) << half.status();
  ASSERT_TRUE(other.ok()) << other.status();
  EXPECT_GT(half->num_triangles(), full->num_triangles() / 10);
  EXPECT_GT(other->num_triangles(), 0);
  EXPECT_EQ(half->num_triangles() + other->num_triangles(), full->num_triangles());
}

TEST_F(SyntheticMeshTest, GroupsOfBricksGiveTheFieldOfEveryKeyframeBitForBit) {
  // The keyframes' measured depths as their views, and a far-away fourth keyframe looking out
  // of the room (it sees no brick: every group culls it).
  const std::vector<int> indices = KeyframeIndices(dataset_->size(), 10);
  ASSERT_EQ(indices.size(), keyframes_->size());
  std::vector<const MapKeyframe*> keyframes;
  for (const MapKeyframe& k : *keyframes_) keyframes.push_back(&k);
  MapKeyframe away = keyframes_->front();
  away.pose = SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.0, 0.0, 40.0));
  keyframes.push_back(&away);
  std::vector<TrainingFrameView> frames;
  for (size_t i = 0; i < keyframes.size(); ++i) {
    const RgbdFrame& f = dataset_->frames()[indices[std::min(i, indices.size() - 1)]];
    TrainingFrameView view;
    view.camera = ToKernelCamera(keyframes[i]->pose, keyframes[i]->intrinsics);
    view.color = nullptr;
    view.depth = f.depth.data.data();
    frames.push_back(view);
  }
  FusionParams params;
  params.min_truncation = 2.0f * map_->grid.voxel_size();
  params.truncation_sigmas = 0.0f;
  std::vector<int32_t> slots(static_cast<size_t>(map_->grid.num_bricks()));
  for (size_t s = 0; s < slots.size(); ++s) slots[s] = static_cast<int32_t>(s);
  const size_t n = static_cast<size_t>(map_->grid.num_vertices());
  std::vector<float> single(n, kIsoNoValue), grouped(n, kIsoNoValue);
  ASSERT_TRUE(backend_->ObserveSurface(map_->grid.view(),
                                       IsoBrickList{slots.data(),
                                                    static_cast<int64_t>(slots.size())},
                                       frames.data(), static_cast<int>(frames.size()), params,
                                       single.data()).ok());
  ASSERT_TRUE(ObserveFieldByGroups(map_->grid, slots, keyframes, frames, params,
                                   params.max_depth + params.min_truncation, *backend_,
                                   grouped.data()).ok());
  int64_t differ = 0, observed = 0;
  for (size_t v = 0; v < n; ++v) {
    // Bit for bit: the same additions in the same order, only of views that add something.
    differ += std::memcmp(&single[v], &grouped[v], sizeof(float)) != 0;
    observed += IsoHasValue(single[v]);
  }
  EXPECT_EQ(differ, 0);
  EXPECT_GT(observed, static_cast<int64_t>(n / 10));  // the comparison is not of empty fields
  // One view per keyframe.
  frames.pop_back();
  EXPECT_EQ(ObserveFieldByGroups(map_->grid, slots, keyframes, frames, params, params.max_depth,
                                 *backend_, grouped.data()).code(),
            absl::StatusCode::kInvalidArgument);
}

TEST_F(SyntheticMeshTest, TheObservedSurfaceNeedsKeyframes) {
  const absl::StatusOr<TriangleMesh> none =
      ExtractObservedMesh(*map_, MapKeyframes(), *backend_, MeshOptions{});
  EXPECT_EQ(none.status().code(), absl::StatusCode::kFailedPrecondition) << none.status();
  ObservedSurfaceOptions coarse;
  coarse.render_scale = 0.0;
  const absl::StatusOr<TriangleMesh> bad =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, MeshOptions{}, coarse);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument) << bad.status();
  EXPECT_NE(bad.status().message().find("render_scale"), std::string::npos) << bad.status();
  ObservedSurfaceOptions no_budget;
  no_budget.max_rendered_pixels = 0;
  const absl::StatusOr<TriangleMesh> refused =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, MeshOptions{}, no_budget);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument) << refused.status();
  EXPECT_NE(refused.status().message().find("max_rendered_pixels"), std::string::npos);
}

// A pixel budget below the keyframes' size renders them all smaller: still the room's surface
// (coarser views: a little less of it), not an error and not a subset of the views.
TEST_F(SyntheticMeshTest, APixelBudgetRendersTheKeyframesSmaller) {
  const std::vector<Eigen::Vector3d> truth = HeldOutPoints();
  ObservedSurfaceOptions budget;
  const PinholeIntrinsics& k = (*keyframes_)[0].intrinsics;
  budget.max_rendered_pixels = static_cast<int64_t>(keyframes_->size()) * k.width * k.height / 4;
  const absl::StatusOr<TriangleMesh> full =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, MeshOptions{});
  const absl::StatusOr<TriangleMesh> half =
      ExtractObservedMesh(*map_, *keyframes_, *backend_, MeshOptions{}, budget);
  ASSERT_TRUE(full.ok()) << full.status();
  ASSERT_TRUE(half.ok()) << half.status();
  const MeshScore f = Score(*full, truth), h = Score(*half, truth);
  std::printf("full-size views: precision %.3f recall %.3f; half-size: %.3f %.3f\n",
              f.precision, f.recall, h.precision, h.recall);
  EXPECT_NE(half->num_triangles(), full->num_triangles());  // the budget took effect
  EXPECT_GT(h.precision, 0.85);
  EXPECT_GT(h.recall, f.recall - 0.05);
}

// A box around the room's -y half (y = 0 is a lattice plane at 4 cm voxels, so no cell
// straddles it; the views look across -x, which holds almost all of what they saw): exactly the
// full mesh's triangles whose centroids lie below y = 0, and with the box around the +y half
// the whole mesh.
TEST_F(SyntheticMeshTest, ABoxAroundHalfTheRoomHoldsThatHalfsTriangles) {
  const absl::StatusOr<TriangleMesh> full = ExtractMesh(map_->grid, *backend_, MeshOptions{});
  ASSERT_TRUE(full.ok()) << full.status();
  const SyntheticScene& room = SyntheticRoom();
  const double margin = 0.2;  // past the walls, floor and ceiling, where depth noise put them
  MeshOptions minus_y;
  minus_y.region = AxisBox{{room.room_min.x() - margin, room.room_min.y() - margin,
                            room.room_min.z() - margin},
                           {room.room_max.x() + margin, 0.0, room.room_max.z() + margin}};
  MeshOptions plus_y;
  plus_y.region = AxisBox{{room.room_min.x() - margin, 0.0, room.room_min.z() - margin},
                          {room.room_max.x() + margin, room.room_max.y() + margin,
                           room.room_max.z() + margin}};
  const absl::StatusOr<TriangleMesh> half = ExtractMesh(map_->grid, *backend_, minus_y);
  const absl::StatusOr<TriangleMesh> other = ExtractMesh(map_->grid, *backend_, plus_y);
  ASSERT_TRUE(half.ok()) << half.status();
  ASSERT_TRUE(other.ok()) << other.status();

  int64_t expected = 0;  // the full mesh's triangles with centroids below y = 0
  for (int64_t t = 0; t < full->num_triangles(); ++t) {
    const int32_t* f = &full->triangles[3 * t];
    const double y = Vertex(*full, f[0]).y() + Vertex(*full, f[1]).y() + Vertex(*full, f[2]).y();
    expected += y < 0.0;
  }
  const double share = static_cast<double>(half->num_triangles()) / full->num_triangles();
  std::printf("-y half: %ld of %ld triangles (%.2f), %ld with centroids below y = 0\n",
              static_cast<long>(half->num_triangles()), static_cast<long>(full->num_triangles()),
              share, static_cast<long>(expected));
  // Both halves of the room were seen: the box holds a real share, not all or nothing.
  EXPECT_GT(share, 0.1);
  EXPECT_LT(share, 0.9);
  EXPECT_EQ(half->num_triangles(), expected);
  EXPECT_EQ(half->num_triangles() + other->num_triangles(), full->num_triangles());
  // Kept whole, each triangle inside its cell: at most half a voxel past the box, and not past
  // y = 0 at all (cells with centres below it end there).
  const AxisBox& box = *minus_y.region;
  const double slack = 0.5 * map_->grid.voxel_size() + 1e-6;
  for (int32_t v = 0; v < half->num_vertices(); ++v) {
    const Eigen::Vector3d p = Vertex(*half, v);
    for (int a = 0; a < 3; ++a) {
      ASSERT_GE(p[a], box.min[a] - slack) << "vertex " << v;
      ASSERT_LE(p[a], box.max[a] + (a == 1 ? 1e-6 : slack)) << "vertex " << v;
    }
  }
}

}  // namespace
}  // namespace plx
