// The one conversion from absl::Status to grpc::Status (both use the canonical codes 0-16).
#pragma once

#include <grpcpp/support/status.h>

#include "absl/status/status.h"

namespace plx::server {

grpc::Status ToGrpcStatus(const absl::Status& status);

}  // namespace plx::server
