// The gRPC side of `plenox --server HOST:PORT <command>`: the channel to a plenoxd daemon
// (64 MiB messages both ways, TLS with --tls-ca, the bearer token from --token-file on every
// call), a short connect check so an unreachable daemon is reported at once, deadlines on unary
// calls, and grpc::Status -> absl::Status so that commands report the daemon's own message
// ("plenox map: no map named "x" (NOT_FOUND)") through ReportError with exit code 1. gRPC's own
// log lines are dropped unless GRPC_VERBOSITY is set (e.g. GRPC_VERBOSITY=debug to debug TLS).
// Once connected, a daemon that goes away (restarted, failed over to another replica) is waited
// for: the unary calls that are safe to repeat are retried on UNAVAILABLE with backoff for up to
// --retry-seconds (app/retry_policy.h), and `slam` reconnects its stream (remote_slam.cc).
//
// Only built with PLX_WITH_SERVER (clients/plenox/CMakeLists.txt).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "app/flags.h"
#include "app/retry_policy.h"
#include "clients/plenox/commands.h"
#include "core/datasets/dataset.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/tracking/tracker.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "proto/frame_codec.h"
#include "proto/pose_codec.h"
#include "proto/track_codec.h"

namespace plx::cli {

namespace pb = ::plenoxd::v1;

// The largest message sent or accepted (the daemon's default limit too).
inline constexpr int kRemoteMaxMessageBytes = 64 << 20;
// How long Connect waits for a daemon that neither accepts nor refuses the connection.
inline constexpr absl::Duration kRemoteConnectTimeout = absl::Seconds(5);
// Deadline of unary calls; save and load (hundreds of MB to or from disk) get longer.
inline constexpr absl::Duration kRemoteUnaryDeadline = absl::Seconds(60);
inline constexpr absl::Duration kRemoteFileDeadline = absl::Seconds(600);

class RemoteClient {
 public:
  // Reads --token-file (trimmed; must be non-empty printable ASCII) and --tls-ca and creates
  // the channel; nothing goes over the network yet. Errors are the user's (a file that is
  // missing or empty) and are reported as usage errors.
  static absl::StatusOr<std::unique_ptr<RemoteClient>> Create(const RemoteOptions& options);

  // Connects to the daemon. Unavailable "cannot reach HOST:PORT: ..." when the connection is
  // refused or fails (also a TLS handshake that fails), or nothing answers within `timeout`.
  absl::Status Connect(absl::Duration timeout = kRemoteConnectTimeout);

  pb::Plenoxd::Stub& stub() { return *stub_; }
  const std::string& server() const { return server_; }
  // --retry-seconds as a policy (budget 0: no retries).
  const RetryOptions& retry() const { return retry_; }
  // The clock the retry waits run on (ChannelWaitClock): real time, with a wait cut short by
  // the channel (re)connecting.
  RetryClock& retry_clock() { return *retry_clock_; }

  // One GetMap of `map` with a short deadline and no retry, for a stream that waits for its
  // daemon under a backoff of its own: OK when a daemon answered, with the map or without it
  // (NOT_FOUND: a Slam stream then starts it again); else the failure (UNAVAILABLE while
  // nothing serves the address).
  absl::Status Probe(const std::string& map);

  // A context for one call: the bearer token when there is one, a deadline unless `deadline`
  // is infinite (streams), and the map's name as "x-plenoxd-map" metadata when the call is about
  // one map, which a proxy in front of several daemons hashes on (deploy/k8s/envoy.yaml).
  std::unique_ptr<grpc::ClientContext> NewContext(absl::Duration deadline = kRemoteUnaryDeadline,
                                                  const std::string& map = "") const;

  // The daemon's status as an absl::Status with the same code: the daemon's message with the
  // code's name appended, "(UNAUTHENTICATED: ...)" with a hint about --token-file, and
  // UNAVAILABLE / DEADLINE_EXCEEDED naming the server.
  absl::Status ToStatus(const grpc::Status& status) const;

  // Unary calls (kRemoteUnaryDeadline; save and load kRemoteFileDeadline). All but CreateMap
  // are retried on UNAVAILABLE (reads; SaveMap writes the same file again, LoadMap reads it
  // again); CreateMap is not: done before the connection was lost, it would fail with
  // ALREADY_EXISTS when repeated.
  absl::StatusOr<pb::MapInfo> CreateMap(const std::string& name, float voxel_size);
  absl::StatusOr<pb::MapInfo> GetMap(const std::string& name);
  absl::StatusOr<std::vector<pb::MapInfo>> ListMaps();
  absl::StatusOr<pb::MapInfo> SaveMap(const std::string& name);
  absl::StatusOr<pb::MapInfo> LoadMap(const std::string& name);
  absl::StatusOr<pb::RenderResponse> Render(const pb::RenderRequest& request);
  absl::StatusOr<pb::ServerInfo> GetServerInfo();

 private:
  RemoteClient() = default;
  absl::Status Unreachable(const std::string& why) const;
  // `call` under the retry policy when `idempotent`; says on stderr that it waits, once per
  // outage, and when it gave up.
  template <typename T>
  absl::StatusOr<T> Retried(bool idempotent, const std::function<absl::StatusOr<T>()>& call);
  void NoteRetry(const absl::Status& status, int attempt) const;

  std::string server_;
  std::string token_;
  bool tls_ = false;
  RetryOptions retry_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Plenoxd::Stub> stub_;
  std::unique_ptr<RetryClock> retry_clock_;
};

// Real time for the retry waits, except that a wait while `channel` is not connected watches
// it and ends as soon as it is. gRPC learns whether its connection attempts succeed only while
// something polls the channel: between a call that failed and the next, nothing does but its
// backup poller, every 5 s, so a daemon back after 1.5 s was found after 7 (docs/BENCHMARKS.md,
// "Failover"). A channel already connected (a proxy in front answered UNAVAILABLE for the
// daemon behind it) gets the plain sleep, so the backoff still paces the attempts.
class ChannelWaitClock final : public RetryClock {
 public:
  explicit ChannelWaitClock(std::shared_ptr<grpc::Channel> channel)
      : channel_(std::move(channel)) {}
  absl::Time Now() override { return absl::Now(); }
  void SleepFor(absl::Duration duration) override;

 private:
  std::shared_ptr<grpc::Channel> channel_;
};

// For the commands: checks that --server was given, creates the client and connects. On an
// error it prints it ("plenox <command>: ...") and returns nullptr with *exit_code set: usage
// (2) without --server or with an unreadable --token-file / --tls-ca, failure (1) when the
// daemon cannot be reached.
std::unique_ptr<RemoteClient> ConnectOrReport(const std::string& command,
                                              const RemoteOptions& options, int* exit_code);

// Wire conversions are proto/'s codecs, shared with the daemon (poses: pose_codec.h; frames and
// intrinsics: frame_codec.h; options: track_codec.h, slam_codec.h, integrate_codec.h); what is
// here is the flags' side of them.

// --encoding png|raw: how frames travel, PNG (colour 8-bit, depth 16-bit; small on the wire,
// costs an encode here and a decode on the daemon) or raw (RAW_RGB8 + RAW_U16; 1.5 MB at
// 640x480, no codec).
absl::StatusOr<FrameEncoding> ParseWireEncoding(const std::string& text);
// Declares that flag (default png) for the commands that stream frames with a pose to estimate.
void AddWireEncodingFlag(FlagSet& flags);

// Frame `index` of `dataset` as a Frame message (FrameToProto with the dataset's calibration,
// camera id "plenox"), with the frame's ground-truth pose when `with_pose` (InvalidArgument when
// it has none); a frame that does not load is its error.
absl::StatusOr<pb::Frame> LoadFrameToProto(const RgbdDataset& dataset, int index, bool with_pose,
                                           const FrameEncoding& encoding = FrameEncoding());

// Request `index` of a Track or Slam stream: frame `index` of `dataset` without its pose (the
// daemon estimates it), the first also with the map, the options and the start pose (none: the
// daemon starts at the identity).
template <typename Request, typename Options>
absl::StatusOr<Request> TrackingStreamRequest(const RgbdDataset& dataset, int index,
                                              const FrameEncoding& encoding, const std::string& map,
                                              const Options& options,
                                              const std::optional<SE3>& start_pose) {
  absl::StatusOr<pb::Frame> frame = LoadFrameToProto(dataset, index, /*with_pose=*/false, encoding);
  if (!frame.ok()) return frame.status();
  Request request;
  if (index == 0) {
    request.set_map(map);
    *request.mutable_options() = options;
    if (start_pose) PoseToProto(*start_pose, request.mutable_initial_pose());
  }
  *request.mutable_frame() = *std::move(frame);
  return request;
}

// The name of a TrackingState for progress lines ("OK", "DEGRADED", "LOST").
const char* TrackingStateText(pb::TrackingState state);
// The same for a SlamState ("OK", "DEGRADED", "LOST", "RELOCALISED", "WAITING"), as in-process
// SLAM names them.
const char* SlamStateText(pb::SlamState state);

// Which tracker settings the user chose with --rays/--iterations/--pixels (AddTrackerFlags):
// only those go on the wire (TrackOptionsToProto; the others are the daemon's defaults for the
// mode, which are TrackerOptionsForMode's too).
TrackOptionsFields TrackOptionsFieldsFromFlags(const FlagSet& flags);

}  // namespace plx::cli
