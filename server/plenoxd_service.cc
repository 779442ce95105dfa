#include "server/plenoxd_service.h"

#include <algorithm>
#include <cstdint>
#include <functional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"
#include "core/mapping/mapper.h"
#include "core/render/render_view.h"
#include "proto/frame_codec.h"
#include "proto/map_codec.h"
#include "proto/render_codec.h"
#include "proto/render_size.h"
#include "server/export_reactor.h"
#include "server/grpc_status.h"
#include "server/integrate_reactor.h"
#include "server/log.h"
#include "server/slam_reactor.h"
#include "server/track_reactor.h"
#include "server/watch_job_reactor.h"

namespace plx::server {
namespace {

// A map RPC's reply: the map's MapInfo, or the error.
absl::Status StatusToProto(const absl::StatusOr<MapStatus>& status, pb::MapInfo* out) {
  if (status.ok()) *out = MapStatusToProto(*status);
  return status.status();
}

}  // namespace

void PlenoxdService::Finish(grpc::ServerUnaryReactor* reactor, const char* method,
                            const absl::Status& status) {
  if (!status.ok()) {
    state_->metrics->rpc_errors++;
    LogEvent("warning", "rpc",
             {{"method", method},
              {"code", absl::StatusCodeToString(status.code())},
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
    const absl::StatusOr<float> voxel =
        VoxelSizeFromProto(request->voxel_size(), MapperOptions{}.voxel_size, "voxel_size");
    status = voxel.ok() ? StatusToProto(state_->maps->Create(request->name(), *voxel), response)
                        : voxel.status();
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
    for (const MapStatus& s : state_->maps->List()) *response->add_maps() = MapStatusToProto(s);
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
  return MapFileCall(context, "SaveMap", response,
                     [this, name = request->name()] { return state_->maps->Save(name); });
}

grpc::ServerUnaryReactor* PlenoxdService::LoadMap(grpc::CallbackServerContext* context,
                                                  const pb::LoadMapRequest* request,
                                                  pb::MapInfo* response) {
  return MapFileCall(context, "LoadMap", response,
                     [this, name = request->name()] { return state_->maps->Load(name); });
}

grpc::ServerUnaryReactor* PlenoxdService::MapFileCall(
    grpc::CallbackServerContext* context, const char* method, pb::MapInfo* response,
    std::function<absl::StatusOr<MapStatus>()> file_work) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const absl::Status status = CheckCall(*state_, context);
  if (!status.ok()) {
    Finish(reactor, method, status);
    return reactor;
  }
  // Reading or writing hundreds of MB takes a while: off the gRPC thread, on the I/O worker.
  state_->io->Post(Priority::kInteractive, [this, context, reactor, method, response,
                                            file_work = std::move(file_work)](Backend*,
                                                                              bool stopped) {
    absl::Status status = QueuedCallStatus(stopped, context);
    if (status.ok()) {
      status = CatchAllocationFailure(method, [&] { return StatusToProto(file_work(), response); });
    }
    Finish(reactor, method, status);
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
