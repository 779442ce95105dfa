// Backend-parameterised tests (DESIGN.md §3.6): every suite instantiated with
// PLX_INSTANTIATE_BACKEND_SUITE runs once per backend: CPU always, CUDA when a device is
// visible. Without one the CUDA instance is skipped with a message saying why, so a CPU-only
// machine reports those tests as skipped, never as passed.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "app/make_backend.h"
#include "core/kernels/backend.h"

namespace plx::testing {

// {kCpu, kCuda}: the backends every parameterised suite is instantiated with.
std::vector<BackendKind> AllTestBackends();

// "cpu" / "cuda", for test names.
std::string BackendParamName(const ::testing::TestParamInfo<BackendKind>& info);

// Why the CUDA instance cannot run here, or empty when a CUDA device is visible.
std::string CudaSkipReason();

// The backend of `kind` for a test (CPU with 2 threads). Creating the CUDA backend installs the
// managed-memory hooks, so tests make their backend before any map or frame they pass to it.
absl::StatusOr<std::unique_ptr<Backend>> MakeTestBackend(BackendKind kind);

// Fixture for backend-parameterised tests: backend() is ready in the test body; the CUDA
// instance is skipped (GTEST_SKIP) when no device is visible and fails when one is visible but
// the backend cannot be created.
class BackendTest : public ::testing::TestWithParam<BackendKind> {
 protected:
  void SetUp() override;
  Backend& backend() { return *backend_; }

 private:
  std::unique_ptr<Backend> backend_;
};

}  // namespace plx::testing

#define PLX_INSTANTIATE_BACKEND_SUITE(suite)                                        \
  INSTANTIATE_TEST_SUITE_P(Backends, suite,                                         \
                           ::testing::ValuesIn(::plx::testing::AllTestBackends()), \
                           ::plx::testing::BackendParamName)
