#include "server/grpc_status.h"

#include <string>

namespace plx::server {

grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  // Messages travel in a header; keep them to a readable size.
  std::string message(status.message());
  if (message.size() > 1024) message = message.substr(0, 1021) + "...";
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), message);
}

}  // namespace plx::server
