// The map store's one-writer lease remembers what holds it, so a client told that a map is busy
// learns what to stop: a Slam stream's SLAM job, or an Integrate stream.
#include "server/map_store.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace plx::server {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;

TEST(MapStoreTest, DeletingAMapBeingMappedNamesWhatMapsIt) {
  MapStore store(MapStoreOptions{});
  ASSERT_TRUE(store.Create("room", 0.05f).ok());

  ASSERT_TRUE(store.BeginMapping("room", MappingJobKind::kSlam).ok());
  const absl::Status slam = store.Delete("room");
  EXPECT_EQ(slam.code(), absl::StatusCode::kFailedPrecondition) << slam;
  EXPECT_THAT(slam.message(), AllOf(HasSubstr("map \"room\" is being mapped by its SLAM job"),
                                    HasSubstr("end its Slam streams first"),
                                    Not(HasSubstr("Integrate"))));
  const absl::Status second = store.BeginMapping("room", MappingJobKind::kIntegrate);
  EXPECT_EQ(second.code(), absl::StatusCode::kFailedPrecondition) << second;
  EXPECT_THAT(second.message(), HasSubstr("already has a mapping job, its SLAM job"));
  store.EndMapping("room");

  ASSERT_TRUE(store.BeginMapping("room", MappingJobKind::kIntegrate).ok());
  const absl::Status integrate = store.Delete("room");
  EXPECT_EQ(integrate.code(), absl::StatusCode::kFailedPrecondition) << integrate;
  EXPECT_THAT(integrate.message(),
              AllOf(HasSubstr("map \"room\" is being mapped by an Integrate stream"),
                    Not(HasSubstr("SLAM"))));
  store.EndMapping("room");

  EXPECT_TRUE(store.Delete("room").ok());
}

}  // namespace
}  // namespace plx::server
