#include "tests/backend_test_util.h"

#include "absl/strings/str_cat.h"

namespace plx::testing {

std::vector<BackendKind> AllTestBackends() { return {BackendKind::kCpu, BackendKind::kCuda}; }

std::string BackendParamName(const ::testing::TestParamInfo<BackendKind>& info) {
  return info.param == BackendKind::kCuda ? "cuda" : "cpu";
}

std::string CudaSkipReason() {
  if (!BuiltWithCuda()) {
    return "no CUDA device: this build has no CUDA backend (configured with "
           "-DPLX_WITH_CUDA=OFF or without nvcc)";
  }
  if (CudaDeviceCount() == 0) {
    return "no CUDA device: none is visible to this process (no NVIDIA GPU or driver, or "
           "CUDA_VISIBLE_DEVICES hides it); run bench/gpu.sh on a machine with one";
  }
  return "";
}

absl::StatusOr<std::unique_ptr<Backend>> MakeTestBackend(BackendKind kind) {
  return MakeBackend(kind, /*cuda_device=*/0, /*cpu_threads=*/2);
}

void BackendTest::SetUp() {
  if (GetParam() == BackendKind::kCuda) {
    const std::string reason = CudaSkipReason();
    if (!reason.empty()) GTEST_SKIP() << reason;
  }
  absl::StatusOr<std::unique_ptr<Backend>> backend = MakeTestBackend(GetParam());
  ASSERT_TRUE(backend.ok()) << backend.status();
  backend_ = std::move(*backend);
}

}  // namespace plx::testing
