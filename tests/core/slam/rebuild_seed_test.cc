// The seed of a loop correction's rebuild: which keyframes moved, and the old map without what
// they saw, on a small map of the synthetic room.
#include "core/slam/rebuild_seed.h"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "absl/container/flat_hash_set.h"
#include "core/common/status_macros.h"
#include "core/cpu/cpu_backend.h"
#include "core/mapping/mapping_session.h"
#include "tests/synthetic_room.h"

namespace plx {
namespace {

constexpr float kVoxel = 0.03f;

class RebuildSeedTest : public ::testing::Test {
 protected:
  void SetUp() override {
    room_ = testing::MakeSyntheticRoom(96, 72, 30);
    ASSERT_NE(room_, nullptr);
    backend_ = MakeCpuBackend(2);
    MappingSessionOptions o;
    o.mapper = MapperOptionsForVoxelSize(kVoxel);
    o.mapper.batch_size = 1024;
    o.iterations_per_keyframe = 2;
    o.min_publish_interval_s = 0.0;
    absl::StatusOr<std::unique_ptr<MappingSession>> session =
        MappingSession::Create(o, backend_.get(), nullptr);
    ASSERT_TRUE(session.ok()) << session.status();
    session_ = *std::move(session);
    allocation_ = o.mapper.allocation;
    for (int f : {0, 10, 20}) {
      const RgbdFrame& frame = room_->frames()[f];
      ASSERT_TRUE(session_->AddKeyframe(frame, *frame.ground_truth, K()).ok());
      poses_.push_back(*frame.ground_truth);
    }
    while (session_->has_work()) ASSERT_TRUE(session_->Step(/*finish=*/true).ok());
    ASSERT_NE(session_->latest(), nullptr);
  }

  const PinholeIntrinsics& K() const { return room_->calibration().pinhole; }

  // `poses_` with keyframe `i` moved by `metres` along world x.
  std::vector<SE3> MovedBy(int i, double metres) const {
    std::vector<SE3> after = poses_;
    after[i] = SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(metres, 0.0, 0.0)) * after[i];
    return after;
  }

  // The seed of the latest map once the keyframes move from `poses_` to `after` (the moves
  // measured as the coordinator measures them).
  absl::StatusOr<RebuildSeed> Seed(const std::vector<SE3>& after,
                                   const RebuildSeedOptions& options = {}) {
    PLX_ASSIGN_OR_RETURN(KeyframeMoves moves,
                         MeasureKeyframeMoves(session_->keyframes(), poses_, after, kVoxel,
                                              allocation_.max_depth, options));
    return SeedRebuild(*session_->latest(), session_->keyframes(), poses_, moves, allocation_,
                       *backend_);
  }

  std::unique_ptr<InMemoryDataset> room_;
  std::unique_ptr<Backend> backend_;
  std::unique_ptr<MappingSession> session_;
  AllocationOptions allocation_;
  std::vector<SE3> poses_;
};

TEST_F(RebuildSeedTest, TheSurfaceShiftIsHowFarTheKeyframesPointsMove) {
  const DepthImage& depth = session_->keyframes().frame(1).depth;
  // after * before^-1 is the identity up to double rounding of the quaternion product.
  EXPECT_NEAR(KeyframeSurfaceShift(depth, K(), poses_[1], poses_[1], 4, 10.0f), 0.0, 1e-12);
  // A translation moves every point by itself (double arithmetic on metre-scale points).
  EXPECT_NEAR(KeyframeSurfaceShift(depth, K(), poses_[1], MovedBy(1, 0.05)[1], 4, 10.0f), 0.05,
              1e-9);
  // A turn about the camera moves the farthest points most: more than the nearest ones would.
  const SE3 turned = poses_[1] * SE3(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitY())
                                         .toRotationMatrix(),
                                     Eigen::Vector3d::Zero());
  const double shift = KeyframeSurfaceShift(depth, K(), poses_[1], turned, 4, 10.0f);
  EXPECT_GT(shift, 0.01 * 0.5);  // the room's walls are more than 0.5 m away
  EXPECT_LT(shift, 0.01 * 10.0);
}

TEST_F(RebuildSeedTest, WhatAMovedKeyframeSawIsDroppedAndTheRestShared) {
  const PlenoxelMap& map = *session_->latest();
  absl::StatusOr<RebuildSeed> seed = Seed(MovedBy(2, 0.05));
  ASSERT_TRUE(seed.ok()) << seed.status();
  EXPECT_EQ(seed->moved, (std::vector<uint8_t>{0, 0, 1}));
  EXPECT_EQ(seed->moved_keyframes, 1);
  EXPECT_GT(seed->dropped_bricks, 0);
  EXPECT_GT(seed->kept_bricks, 0);
  EXPECT_EQ(seed->kept_bricks + seed->dropped_bricks, map.grid.num_bricks());
  ASSERT_NE(seed->map, nullptr);
  EXPECT_EQ(seed->map->grid.num_bricks(), seed->kept_bricks);
  EXPECT_FALSE(seed->map->grid.occupancy_stale());

  // Exactly the bricks keyframe 2's band covers at its old pose are gone; every other brick is
  // the old map's own storage.
  const std::vector<BrickCoord> seen = BricksNearSurface(
      session_->keyframes().frame(2).depth, poses_[2], K(), kVoxel, allocation_);
  const absl::flat_hash_set<BrickCoord> dropped(seen.begin(), seen.end());
  int64_t shared = 0;
  for (int64_t slot = 0; slot < map.grid.num_bricks(); ++slot) {
    const BrickCoord& b = map.grid.brick_coords()[slot];
    const int32_t other = seed->map->grid.FindBrick(b);
    if (dropped.contains(b)) {
      EXPECT_EQ(other, -1);
    } else {
      ASSERT_GE(other, 0);
      shared += seed->map->grid.brick_density(other) == map.grid.brick_density(slot);
    }
  }
  EXPECT_EQ(shared, seed->kept_bricks);
}

TEST_F(RebuildSeedTest, AMoveUnderTheToleranceKeepsEverything) {
  const PlenoxelMap& map = *session_->latest();
  // 0.4 voxel: under the default half-voxel tolerance.
  absl::StatusOr<RebuildSeed> seed = Seed(MovedBy(1, 0.4 * kVoxel));
  ASSERT_TRUE(seed.ok()) << seed.status();
  EXPECT_EQ(seed->moved_keyframes, 0);
  EXPECT_EQ(seed->dropped_bricks, 0);
  EXPECT_EQ(seed->map->grid.num_bricks(), map.grid.num_bricks());
  // A tolerance of 0.1 voxel calls the same move a move.
  RebuildSeedOptions strict;
  strict.moved_tolerance_voxels = 0.1;
  seed = Seed(MovedBy(1, 0.4 * kVoxel), strict);
  ASSERT_TRUE(seed.ok()) << seed.status();
  EXPECT_EQ(seed->moved, (std::vector<uint8_t>{0, 1, 0}));
}

TEST_F(RebuildSeedTest, RejectsMismatchedPosesAndBadOptions) {
  const PlenoxelMap& map = *session_->latest();
  std::vector<SE3> short_list = poses_;
  short_list.pop_back();
  EXPECT_EQ(Seed(short_list).status().code(), absl::StatusCode::kInvalidArgument);
  // Moves measured for other keyframes (none here).
  EXPECT_EQ(SeedRebuild(map, session_->keyframes(), poses_, KeyframeMoves{}, allocation_,
                        *backend_).status().code(),
            absl::StatusCode::kInvalidArgument);
  RebuildSeedOptions bad;
  bad.moved_tolerance_voxels = -1.0;
  EXPECT_EQ(ValidateRebuildSeedOptions(bad).code(), absl::StatusCode::kInvalidArgument);
  bad = RebuildSeedOptions{};
  bad.pixel_stride = 0;
  EXPECT_EQ(Seed(poses_, bad).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace plx
