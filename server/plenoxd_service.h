// The plenoxd.v1.Plenoxd service on gRPC's callback API. Handlers only check the call,
// convert, call core (on a device worker for anything heavy) and map the status. The streams
// live in their own reactors: track_reactor.h, integrate_reactor.h and slam_reactor.h (over
// stream_reactor.h), export_reactor.h and watch_job_reactor.h.
#pragma once

#include <functional>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"
#include "core/grid/map_status.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "server/daemon_state.h"

namespace plx::server {

class PlenoxdService final : public plenoxd::v1::Plenoxd::CallbackService {
 public:
  explicit PlenoxdService(DaemonState* state) : state_(state) {}

  grpc::ServerUnaryReactor* CreateMap(grpc::CallbackServerContext* context,
                                      const plenoxd::v1::CreateMapRequest* request,
                                      plenoxd::v1::MapInfo* response) override;
  grpc::ServerUnaryReactor* GetMap(grpc::CallbackServerContext* context,
                                   const plenoxd::v1::GetMapRequest* request,
                                   plenoxd::v1::MapInfo* response) override;
  grpc::ServerUnaryReactor* ListMaps(grpc::CallbackServerContext* context,
                                     const plenoxd::v1::ListMapsRequest* request,
                                     plenoxd::v1::ListMapsResponse* response) override;
  grpc::ServerUnaryReactor* DeleteMap(grpc::CallbackServerContext* context,
                                      const plenoxd::v1::DeleteMapRequest* request,
                                      plenoxd::v1::DeleteMapResponse* response) override;
  grpc::ServerUnaryReactor* SaveMap(grpc::CallbackServerContext* context,
                                    const plenoxd::v1::SaveMapRequest* request,
                                    plenoxd::v1::MapInfo* response) override;
  grpc::ServerUnaryReactor* LoadMap(grpc::CallbackServerContext* context,
                                    const plenoxd::v1::LoadMapRequest* request,
                                    plenoxd::v1::MapInfo* response) override;
  grpc::ServerUnaryReactor* Render(grpc::CallbackServerContext* context,
                                   const plenoxd::v1::RenderRequest* request,
                                   plenoxd::v1::RenderResponse* response) override;
  grpc::ServerBidiReactor<plenoxd::v1::IntegrateRequest, plenoxd::v1::MappingProgress>* Integrate(
      grpc::CallbackServerContext* context) override;
  grpc::ServerBidiReactor<plenoxd::v1::TrackRequest, plenoxd::v1::PoseEstimate>* Track(
      grpc::CallbackServerContext* context) override;
  grpc::ServerBidiReactor<plenoxd::v1::SlamRequest, plenoxd::v1::SlamUpdate>* Slam(
      grpc::CallbackServerContext* context) override;
  grpc::ServerWriteReactor<plenoxd::v1::ExportChunk>* Export(
      grpc::CallbackServerContext* context, const plenoxd::v1::ExportRequest* request) override;
  grpc::ServerWriteReactor<plenoxd::v1::JobStatus>* WatchJob(
      grpc::CallbackServerContext* context, const plenoxd::v1::WatchJobRequest* request) override;
  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* context,
                                          const plenoxd::v1::GetServerInfoRequest* request,
                                          plenoxd::v1::ServerInfo* response) override;

 private:
  // Finishes `reactor` with `status`, counting errors and logging the call.
  void Finish(grpc::ServerUnaryReactor* reactor, const char* method, const absl::Status& status);
  // SaveMap and LoadMap: checks the call, then runs `file_work` (the map store's Save or Load)
  // on the I/O worker and answers with the map's MapInfo. `method` names the call in logs.
  grpc::ServerUnaryReactor* MapFileCall(grpc::CallbackServerContext* context, const char* method,
                                        plenoxd::v1::MapInfo* response,
                                        std::function<absl::StatusOr<MapStatus>()> file_work);

  DaemonState* state_;
};

}  // namespace plx::server
