// The mesh of a map of the synthetic room against the room's analytic surfaces: precision (mesh
// vertices within 2 cm of a true surface) and recall (held-out ground-truth points within 2 cm
// of the mesh), and what the unobserved-surface filter buys.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <tuple>
#include <vector>

#include "core/cpu/cpu_backend.h"
#include "core/eval/map_metrics.h"
#include "core/mapping/map_dataset.h"
#include "core/mapping/mapper.h"
#include "core/mesh/iso_surface.h"
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

// 3 keyframes of the noisy 128 x 96 room at 4 cm voxels (as MapperTest), 60 iterations.
TEST(SyntheticMeshTest, MeshLiesOnTheRoomsSurfaces) {
  auto dataset = testing::MakeSyntheticRoom(128, 96, 30, 0.0015, 0.05);
  ASSERT_NE(dataset, nullptr);
  std::unique_ptr<Backend> backend = MakeCpuBackend(2);
  MapperOptions o = MapperOptionsForVoxelSize(0.04f);
  o.max_iterations = 60;
  o.batch_size = 4096;
  auto mapped = MapDataset(*dataset, KeyframeIndices(dataset->size(), 10), o, *backend);
  ASSERT_TRUE(mapped.ok()) << mapped.status();
  std::vector<Eigen::Vector3d> truth;
  const PinholeIntrinsics& K = dataset->calibration().pinhole;
  for (int f : HeldOutFrames(dataset->size(), 10)) {
    const RgbdFrame& frame = dataset->frames()[f];
    for (int v = 0; v < K.height; v += 2) {
      for (int u = 0; u < K.width; u += 2) {
        const double z = *frame.depth.pixel(u, v);
        if (z <= 0) continue;
        truth.push_back(*frame.ground_truth * Eigen::Vector3d((u + 0.5 - K.cx) / K.fx * z,
                                                              (v + 0.5 - K.cy) / K.fy * z, z));
      }
    }
  }
  auto mesh = ExtractMesh(mapped->map->grid, *backend, MeshOptions{});
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  MeshOptions keep;
  keep.keep_unobserved = true;
  auto unfiltered = ExtractMesh(mapped->map->grid, *backend, keep);
  ASSERT_TRUE(unfiltered.ok()) << unfiltered.status();
  MeshOptions low;
  low.iso_level = 5.0f;
  auto thin = ExtractMesh(mapped->map->grid, *backend, low);
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

}  // namespace
}  // namespace plx
