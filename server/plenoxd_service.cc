#include "server/plenoxd_service.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <mutex>
#include <new>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"
#include "core/mapping/mapper.h"
#include "core/render/render_view.h"
#include "proto/render_size.h"
#include "server/export_request.h"
#include "server/grpc_status.h"
#include "server/integrate_reactor.h"
#include "server/log.h"
#include "server/proto_convert.h"
#include "server/slam_reactor.h"
#include "server/track_reactor.h"

namespace plx::server {
namespace {

void ToProto(const MapStatus& s, pb::MapInfo* out) {
  out->set_name(s.name);
  out->set_voxel_size(s.voxel_size);
  out->set_version(s.version);
  out->set_bricks(static_cast<uint64_t>(s.bricks));
  out->set_memory_bytes(static_cast<uint64_t>(s.memory_bytes));
  out->set_keyframes(static_cast<uint32_t>(s.keyframes));
  out->set_dirty(s.dirty);
  out->set_mapping(s.mapping);
  out->set_source(s.source);
}

// Whether a call's task, now taken from a worker's queue, should still run: UNAVAILABLE when
// the worker stopped (the daemon drains), CANCELLED when the call was cancelled while it was
// queued (client gone, deadline passed: nobody would read the result), else OK.
absl::Status QueuedCallStatus(bool worker_stopped, const grpc::CallbackServerContext* context) {
  if (worker_stopped) return absl::UnavailableError("plenoxd is shutting down");
  if (context->IsCancelled()) {
    return absl::CancelledError("the call was cancelled before its work started");
  }
  return absl::OkStatus();
}

absl::Status StatusToProto(const absl::StatusOr<MapStatus>& status, pb::MapInfo* out) {
  if (status.ok()) ToProto(*status, out);
  return status.status();
}

pb::JobStatus::State ToProto(JobState state) {
  switch (state) {
    case JobState::kQueued: return pb::JobStatus::STATE_QUEUED;
    case JobState::kRunning: return pb::JobStatus::STATE_RUNNING;
    case JobState::kDone: return pb::JobStatus::STATE_DONE;
    case JobState::kFailed: return pb::JobStatus::STATE_FAILED;
    case JobState::kCancelled: return pb::JobStatus::STATE_CANCELLED;
  }
  return pb::JobStatus::STATE_UNSPECIFIED;
}

// Export: the PLY (points or mesh) is built on a device worker from a published version, then
// streamed in chunks.
class ExportReactor final : public grpc::ServerWriteReactor<pb::ExportChunk> {
 public:
  static constexpr size_t kChunkBytes = 1 << 20;

  ExportReactor(DaemonState* state, grpc::CallbackServerContext* context,
                const pb::ExportRequest* request)
      : state_(state), context_(context) {
    absl::Status status = AcquireStreamSlot(*state_, context);
    if (!status.ok()) {
      Done(status);
      return;
    }
    holds_slot_ = true;
    status = CheckMapName(request->map(), "map");
    absl::StatusOr<MapVersion> map =
        status.ok() ? state_->maps->Latest(request->map()) : absl::StatusOr<MapVersion>(status);
    if (!map.ok()) {
      Done(map.status());
      return;
    }
    absl::StatusOr<ExportSpec> spec = ParseExportRequest(*request);
    if (!spec.ok()) {
      Done(spec.status());
      return;
    }
    state_->workers->Pick(Priority::kBackground).Post(
        Priority::kBackground, [this, map = *map, spec = *spec](Backend* backend, bool stopped) {
          if (absl::Status queued = QueuedCallStatus(stopped, context_); !queued.ok()) {
            Done(queued);
            return;
          }
          // A call cancelled while exporting stops within a few bricks.
          absl::StatusOr<std::string> bytes = BuildExport(
              spec, *map.map, *backend, [this] { return context_->IsCancelled(); });
          if (!bytes.ok()) {
            Done(bytes.status());
            return;
          }
          bytes_ = *std::move(bytes);
          WriteNext();
        });
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Done(CancelledCallStatus(*state_, context_, "client gone"));
      return;
    }
    WriteNext();
  }

  void OnDone() override {
    if (holds_slot_) ReleaseStreamSlot(*state_);
    delete this;
  }

 private:
  void WriteNext() {
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
  void Done(const absl::Status& status) {
    if (!status.ok()) {
      state_->metrics->rpc_errors++;
      LogEvent("warning", "rpc", {{"method", "Export"},
                                  {"code", absl::StatusCodeToString(status.code())},
                                  {"message", std::string(status.message())}});
    }
    Finish(ToGrpcStatus(status));
  }

  DaemonState* state_;
  grpc::CallbackServerContext* const context_;
  bool holds_slot_ = false;
  std::string bytes_;
  size_t offset_ = 0;
  bool sent_last_ = false;
  pb::ExportChunk chunk_;
};

// WatchJob: the job's status now and after every change, until it ends. Updates that arrive
// while a write is in flight are coalesced to the newest.
class WatchJobReactor final : public grpc::ServerWriteReactor<pb::JobStatus> {
 public:
  WatchJobReactor(DaemonState* state, grpc::CallbackServerContext* context,
                  const pb::WatchJobRequest* request)
      : state_(state) {
    absl::Status status = AcquireStreamSlot(*state_, context);
    if (!status.ok()) {
      Finish(ToGrpcStatus(status));
      return;
    }
    holds_slot_ = true;
    absl::StatusOr<int64_t> handle = state_->jobs->Watch(
        request->job_id(), [this](const JobInfo& info) { OnJobChanged(info); });
    std::lock_guard<std::mutex> lock(mutex_);
    if (!handle.ok()) {
      finished_ = true;
      Finish(ToGrpcStatus(handle.status()));
      return;
    }
    handle_ = *handle;
    watching_ = true;
    MaybeFinishLocked();
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mutex_);
    write_in_flight_ = false;
    if (!ok) ended_ = true;
    if (next_ && !ended_) {
      current_ = *next_;
      next_.reset();
      write_in_flight_ = true;
      StartWrite(&current_);
    }
    MaybeFinishLocked();
  }

  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mutex_);
    ended_ = true;
    MaybeFinishLocked();
  }

  void OnDone() override {
    if (watching_) state_->jobs->Unwatch(handle_);
    if (holds_slot_) ReleaseStreamSlot(*state_);
    delete this;
  }

 private:
  void OnJobChanged(const JobInfo& info) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_ || ended_) return;
    pb::JobStatus status;
    status.set_job_id(info.id);
    status.set_kind(info.kind);
    status.set_map(info.map);
    status.set_state(ToProto(info.state));
    status.set_progress(info.progress);
    status.set_message(info.message);
    if (info.terminal()) terminal_seen_ = true;
    if (write_in_flight_) {
      next_ = status;
    } else {
      current_ = status;
      write_in_flight_ = true;
      StartWrite(&current_);
    }
  }
  void MaybeFinishLocked() {
    // A cancelled or broken stream never sends the update still waiting.
    if (ended_) next_.reset();
    if (finished_ || write_in_flight_ || next_) return;
    if (!(terminal_seen_ || ended_)) return;
    finished_ = true;
    Finish(ended_ && !terminal_seen_ ? grpc::Status(grpc::StatusCode::CANCELLED, "cancelled")
                                     : grpc::Status::OK);
  }

  DaemonState* state_;
  bool holds_slot_ = false;
  std::mutex mutex_;
  int64_t handle_ = 0;
  bool watching_ = false;
  bool write_in_flight_ = false;
  bool terminal_seen_ = false;
  bool ended_ = false;
  bool finished_ = false;
  pb::JobStatus current_;
  std::optional<pb::JobStatus> next_;
};

}  // namespace

void PlenoxdService::Finish(grpc::ServerUnaryReactor* reactor, const char* method,
                            const absl::Status& status) {
  if (!status.ok()) {
    state_->metrics->rpc_errors++;
    LogEvent("warning", "rpc", {{"method", method}, {"code", absl::StatusCodeToString(status.code())},
                                {"message", std::string(status.message())}});
  }
  reactor->Finish(ToGrpcStatus(status));
}

grpc::ServerUnaryReactor* PlenoxdService::CreateMap(grpc::CallbackServerContext* context,
                                                    const pb::CreateMapRequest* request,
                                                    pb::MapInfo* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  absl::Status status = CheckCall(*state_, context);
  if (status.ok()) {
    // Only exactly 0 means the default; negative and NaN sizes reach the store's range check.
    const float voxel =
        request->voxel_size() == 0.0f ? MapperOptions{}.voxel_size : request->voxel_size();
    status = StatusToProto(state_->maps->Create(request->name(), voxel), response);
  }
  Finish(reactor, "CreateMap", status);
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::GetMap(grpc::CallbackServerContext* context,
                                                 const pb::GetMapRequest* request,
                                                 pb::MapInfo* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  absl::Status status = CheckCall(*state_, context);
  if (status.ok()) status = StatusToProto(state_->maps->Info(request->name()), response);
  Finish(reactor, "GetMap", status);
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::ListMaps(grpc::CallbackServerContext* context,
                                                   const pb::ListMapsRequest*,
                                                   pb::ListMapsResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const absl::Status status = CheckCall(*state_, context);
  if (status.ok()) {
    for (const MapStatus& s : state_->maps->List()) ToProto(s, response->add_maps());
  }
  Finish(reactor, "ListMaps", status);
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::GetServerInfo(grpc::CallbackServerContext* context,
                                                        const pb::GetServerInfoRequest*,
                                                        pb::ServerInfo* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const absl::Status status = CheckCall(*state_, context);
  if (status.ok()) {
    response->set_version(state_->config.version);
    response->set_backend(state_->config.backend);
    response->set_cuda_built(state_->config.cuda_built);
    response->set_maps(static_cast<uint32_t>(state_->maps->size()));
    for (size_t i = 0; i < state_->workers->size(); ++i) {
      const DeviceWorker& w = state_->workers->worker(i);
      pb::Device* d = response->add_devices();
      d->set_id(w.device().id);
      d->set_kind(w.device().kind);
      d->set_name(w.device().name);
      d->set_queue_depth(static_cast<uint32_t>(w.queue_depth()));
      d->set_streams(static_cast<uint32_t>(w.streams()));
    }
  }
  Finish(reactor, "GetServerInfo", status);
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::DeleteMap(grpc::CallbackServerContext* context,
                                                    const pb::DeleteMapRequest* request,
                                                    pb::DeleteMapResponse*) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  absl::Status status = CheckCall(*state_, context);
  if (status.ok()) status = state_->maps->Delete(request->name());
  Finish(reactor, "DeleteMap", status);
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::SaveMap(grpc::CallbackServerContext* context,
                                                  const pb::SaveMapRequest* request,
                                                  pb::MapInfo* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const absl::Status status = CheckCall(*state_, context);
  if (!status.ok()) {
    Finish(reactor, "SaveMap", status);
    return reactor;
  }
  // Writing hundreds of MB takes a while: off the gRPC thread, on the I/O worker.
  const std::string name = request->name();
  state_->io->Post(Priority::kInteractive,
                   [this, context, reactor, name, response](Backend*, bool stopped) {
                     absl::Status status = QueuedCallStatus(stopped, context);
                     if (status.ok()) {
                       status = CatchAllocationFailure("SaveMap", [&] {
                         return StatusToProto(state_->maps->Save(name), response);
                       });
                     }
                     Finish(reactor, "SaveMap", status);
                   });
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::LoadMap(grpc::CallbackServerContext* context,
                                                  const pb::LoadMapRequest* request,
                                                  pb::MapInfo* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const absl::Status status = CheckCall(*state_, context);
  if (!status.ok()) {
    Finish(reactor, "LoadMap", status);
    return reactor;
  }
  const std::string name = request->name();
  state_->io->Post(Priority::kInteractive,
                   [this, context, reactor, name, response](Backend*, bool stopped) {
                     absl::Status status = QueuedCallStatus(stopped, context);
                     if (status.ok()) {
                       status = CatchAllocationFailure("LoadMap", [&] {
                         return StatusToProto(state_->maps->Load(name), response);
                       });
                     }
                     Finish(reactor, "LoadMap", status);
                   });
  return reactor;
}

grpc::ServerUnaryReactor* PlenoxdService::Render(grpc::CallbackServerContext* context,
                                                 const pb::RenderRequest* request,
                                                 pb::RenderResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  absl::Status status = CheckCall(*state_, context);
  absl::StatusOr<SE3> pose = SE3();
  absl::StatusOr<CameraCalibration> calibration = CameraCalibration();
  absl::StatusOr<MapVersion> map = MapVersion();
  if (status.ok()) status = CheckMapName(request->map(), "map");
  if (status.ok()) {
    pose = request->has_pose() ? PoseFromProto(request->pose(), "pose")
                               : absl::InvalidArgumentError("pose: missing");
    status = pose.status();
    if (status.ok()) status = CheckPoseInsideWorld(*pose, "pose");
  }
  if (status.ok()) {
    calibration = request->has_intrinsics()
                      ? IntrinsicsFromProto(request->intrinsics(), "intrinsics", false)
                      : absl::InvalidArgumentError("intrinsics: missing");
    status = calibration.status();
  }
  if (status.ok()) {
    // One render's work is capped: a huge view would hold a device for minutes.
    if (absl::Status s = CheckRenderPixels(calibration->pinhole, state_->config.max_render_pixels);
        !s.ok()) {
      status = absl::Status(s.code(),
                            absl::StrCat("intrinsics: ", s.message(), " (--max-render-pixels)"));
    }
  }
  if (status.ok()) {
    // An answer gRPC could not send is refused before the render, not after seconds of work.
    if (absl::Status s = CheckRenderResponseSize(*request, state_->config.max_message_bytes);
        !s.ok()) {
      status = absl::Status(s.code(),
                            absl::StrCat("intrinsics: ", s.message(), " (--max-message-mb)"));
    }
  }
  if (status.ok()) {
    map = state_->maps->Latest(request->map());
    status = map.status();
  }
  if (!status.ok()) {
    Finish(reactor, "Render", status);
    return reactor;
  }
  state_->workers->Pick(Priority::kInteractive).Post(
      Priority::kInteractive,
      [this, context, reactor, request, response, pose = *pose, k = calibration->pinhole,
       map = *map](Backend* backend, bool stopped) {
        if (absl::Status queued = QueuedCallStatus(stopped, context); !queued.ok()) {
          Finish(reactor, "Render", queued);
          return;
        }
        Finish(reactor, "Render", CatchAllocationFailure("Render", [&]() -> absl::Status {
                 RenderViewOptions options;
                 // Between row tiles: a deadline or a cancellation frees the device within a
                 // tile, not after the whole view.
                 options.cancelled = [context] { return context->IsCancelled(); };
                 PLX_ASSIGN_OR_RETURN(const RenderedView view,
                                      RenderView(*backend, *map.map, pose, k, options));
                 // Encoding a large view takes seconds too; nobody would read it.
                 if (context->IsCancelled()) {
                   return absl::CancelledError("the call was cancelled before its images were "
                                               "encoded");
                 }
                 int64_t rendered = 0;
                 for (float o : view.opacity.data) rendered += o >= kRenderedOpacity;
                 response->set_coverage(static_cast<double>(rendered) /
                                        std::max<int64_t>(1, view.opacity.num_pixels()));
                 response->set_map_version(map.version);
                 state_->metrics->renders++;
                 return RenderedViewToProto(view, request->color_encoding(),
                                            request->depth_encoding(), response);
               }));
      });
  return reactor;
}

grpc::ServerBidiReactor<pb::IntegrateRequest, pb::MappingProgress>* PlenoxdService::Integrate(
    grpc::CallbackServerContext* context) {
  return new IntegrateReactor(state_, context);
}

grpc::ServerBidiReactor<pb::TrackRequest, pb::PoseEstimate>* PlenoxdService::Track(
    grpc::CallbackServerContext* context) {
  return new TrackReactor(state_, context);
}

grpc::ServerBidiReactor<pb::SlamRequest, pb::SlamUpdate>* PlenoxdService::Slam(
    grpc::CallbackServerContext* context) {
  return new SlamReactor(state_, context);
}

grpc::ServerWriteReactor<pb::ExportChunk>* PlenoxdService::Export(
    grpc::CallbackServerContext* context, const pb::ExportRequest* request) {
  return new ExportReactor(state_, context, request);
}

grpc::ServerWriteReactor<pb::JobStatus>* PlenoxdService::WatchJob(
    grpc::CallbackServerContext* context, const pb::WatchJobRequest* request) {
  return new WatchJobReactor(state_, context, request);
}

}  // namespace plx::server
