// The Export stream (server-streaming): the file a map's published version makes (PLY points,
// or a mesh by marching cubes as PLY or binary glTF, at a level of detail when asked;
// core/export/map_export.h), built on a device worker at background priority from the version
// that was newest when the call came, then written in chunks of kChunkBytes. Each chunk says
// its offset and whether it is the last, so a client can tell a complete file from a cut one.
#pragma once

#include <cstddef>
#include <string>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"
#include "server/stream_slot.h"

namespace plx::server {

class ExportReactor final : public grpc::ServerWriteReactor<plenoxd::v1::ExportChunk> {
 public:
  static constexpr size_t kChunkBytes = 1 << 20;

  // Admits the call, checks the request and posts the build, or finishes at once.
  ExportReactor(DaemonState* state, grpc::CallbackServerContext* context,
                const plenoxd::v1::ExportRequest* request);

  void OnWriteDone(bool ok) override;
  void OnDone() override;

 private:
  void WriteNext();
  // Finishes the call with `status`; an error is counted and logged.
  void Done(const absl::Status& status);

  DaemonState* const state_;
  grpc::CallbackServerContext* const context_;
  StreamSlot slot_;
  // Only the worker's task, then the write reactions one at a time, touch these.
  std::string bytes_;
  size_t offset_ = 0;
  bool sent_last_ = false;
  plenoxd::v1::ExportChunk chunk_;
};

}  // namespace plx::server
