#include "server/export_reactor.h"

#include <algorithm>
#include <new>
#include <utility>

#include "core/export/map_export.h"
#include "proto/export_codec.h"
#include "proto/map_codec.h"
#include "proto/wire.h"
#include "server/grpc_status.h"
#include "server/log.h"

namespace plx::server {

ExportReactor::ExportReactor(DaemonState* state, grpc::CallbackServerContext* context,
                             const pb::ExportRequest* request)
    : state_(state), context_(context) {
  absl::Status status = slot_.Acquire(*state_, context);
  if (!status.ok()) {
    Done(status);
    return;
  }
  status = CheckMapName(request->map(), "map");
  absl::StatusOr<MapVersion> map =
      status.ok() ? state_->maps->Latest(request->map()) : absl::StatusOr<MapVersion>(status);
  if (!map.ok()) {
    Done(map.status());
    return;
  }
  absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(*request);
  if (!spec.ok()) {
    Done(spec.status());
    return;
  }
  state_->workers->Pick(Priority::kBackground)
      .Post(Priority::kBackground,
            [this, map = *map, spec = *spec](Backend* backend, bool stopped) {
              if (absl::Status queued = QueuedCallStatus(stopped, context_); !queued.ok()) {
                Done(queued);
                return;
              }
              // A call cancelled while exporting stops within a few bricks (or after the
              // simplification step that runs).
              static const MapKeyframes kNone;
              absl::StatusOr<MapExport> file =
                  ExportMap(spec, *map.map, map.keyframes ? *map.keyframes : kNone, *backend,
                            [this] { return context_->IsCancelled(); });
              if (!file.ok()) {
                Done(file.status());
                return;
              }
              bytes_ = std::move(file->bytes);
              WriteNext();
            });
}

void ExportReactor::OnWriteDone(bool ok) {
  if (!ok) {
    Done(CancelledCallStatus(*state_, context_, "client gone"));
    return;
  }
  WriteNext();
}

// The slot goes back with the reactor (StreamSlot's destructor).
void ExportReactor::OnDone() { delete this; }

void ExportReactor::WriteNext() {
  if (offset_ >= bytes_.size() && sent_last_) {
    Done(absl::OkStatus());
    return;
  }
  const size_t n = std::min(kChunkBytes, bytes_.size() - offset_);
  try {
    chunk_.set_data(bytes_.data() + offset_, n);
  } catch (const std::bad_alloc&) {
    Done(absl::ResourceExhaustedError("Export: out of memory"));
    return;
  }
  chunk_.set_offset(offset_);
  offset_ += n;
  sent_last_ = offset_ >= bytes_.size();
  chunk_.set_last(sent_last_);
  StartWrite(&chunk_);
}

void ExportReactor::Done(const absl::Status& status) {
  if (!status.ok()) {
    state_->metrics->rpc_errors++;
    LogEvent("warning", "rpc",
             {{"method", "Export"},
              {"code", absl::StatusCodeToString(status.code())},
              {"message", std::string(status.message())}});
  }
  Finish(ToGrpcStatus(status));
}

}  // namespace plx::server
