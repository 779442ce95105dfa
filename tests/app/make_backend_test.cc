// The backend-selection helpers both programs share (app/make_backend.h) that need no daemon:
// the text of a BackendKind and the one --gpus / --backend check.
#include "app/make_backend.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <utility>
#include <vector>

namespace plx {
namespace {

using ::testing::HasSubstr;

TEST(BackendKindTextTest, IsTheInverseOfParseBackendKind) {
  for (BackendKind kind : {BackendKind::kCpu, BackendKind::kCuda, BackendKind::kAuto}) {
    const absl::StatusOr<BackendKind> parsed = ParseBackendKind(BackendKindText(kind));
    ASSERT_TRUE(parsed.ok()) << BackendKindText(kind);
    EXPECT_EQ(*parsed, kind);
  }
}

TEST(SplitCoresForSlamTest, TrackingAndMappingEachGetTheirOwnHalfAndAtLeastOneThread) {
  const std::vector<std::pair<int, std::pair<int, int>>> cases = {
      {1, {1, 1}}, {2, {1, 1}}, {3, {2, 1}}, {8, {4, 4}}, {0, {1, 1}}};
  for (const auto& [cores, want] : cases) {
    const SlamCpuThreads got = SplitCoresForSlam(cores);
    EXPECT_EQ(got.tracking, want.first) << cores << " cores";
    EXPECT_EQ(got.mapping, want.second) << cores << " cores";
  }
}

TEST(CheckGpusApplyTest, GpusNeedABackendThatCanUseThem) {
  const absl::Status cpu = CheckGpusApply(BackendKind::kCpu, /*gpus_given=*/true);
  EXPECT_EQ(cpu.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(cpu.message(), HasSubstr("--gpus only applies with --backend cuda or auto"));
  EXPECT_TRUE(CheckGpusApply(BackendKind::kCpu, /*gpus_given=*/false).ok());
  EXPECT_TRUE(CheckGpusApply(BackendKind::kCuda, /*gpus_given=*/true).ok());
  EXPECT_TRUE(CheckGpusApply(BackendKind::kAuto, /*gpus_given=*/true).ok());
}

}  // namespace
}  // namespace plx
