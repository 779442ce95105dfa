// plenox --server HOST:PORT track: localise every frame of a dataset in a map on the daemon
// (one Track stream, in lock-step so that no frame is dropped).
#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/common/percentile.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"
#include "clients/plenox/track_output.h"
#include "core/io/atomic_write.h"
#include "core/formats/trajectory_file.h"
#include "core/tracking/tracker.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "track";

}  // namespace

int RunRemoteTrack(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags("plenox track",
                "With --server: tracks every frame of a dataset against map N on the daemon,\n"
                "starting from frame 0's ground-truth pose when the dataset has one, and writes\n"
                "the trajectory in TUM format. Frames go one at a time (the next only after the\n"
                "previous estimate came back), so none is dropped. Times reported: the daemon's\n"
                "latency (frame received to estimate sent) and the round trip seen here (frame\n"
                "sent to estimate read, encoding excluded).");
  AddTrackFlags(flags, "N", "the map on the daemon");
  flags.Add("encoding", "png|raw", "how frames travel: PNG, or raw RGB8 + uint16 (no codec)", "png")
      .Add("timings", "FILE", "also write per-frame times: frame timestamp roundtrip_ms daemon_ms", "");
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  // The options the daemon will apply (it starts from the same TrackerOptionsForMode), so that
  // the summary names what actually ran; only flags the user set go on the wire.
  absl::StatusOr<TrackerOptions> tracker_options = TrackerOptionsFromFlags(flags);
  if (!tracker_options.ok()) return ReportError(kCommand, tracker_options.status(), true);
  const TrackerOptions& options = *tracker_options;
  const pb::TrackOptions wire = TrackOptionsToProto(flags, options);
  absl::StatusOr<WireEncoding> encoding = ParseWireEncoding(flags.GetString("encoding"));
  if (!encoding.ok()) return ReportError(kCommand, encoding.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  const std::string map_name = flags.GetString("map");
  TrackReport report{.mode = flags.GetString("mode"),
                     .rays = options.rays,
                     .iterations = options.iterations,
                     .trajectory = flags.GetString("out")};
  const std::string timings = flags.GetString("timings");
  for (const std::string& path : {report.trajectory, timings}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) return ReportError(kCommand, s);
  }

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport(kCommand, flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  report.frames = dataset->size();
  if (report.frames == 0) {
    return ReportError(kCommand, absl::InvalidArgumentError("the dataset has no frames"));
  }
  const std::optional<SE3> start_pose = dataset->ground_truth(0);

  std::unique_ptr<grpc::ClientContext> context =
      client->NewContext(absl::InfiniteDuration(), map_name);
  std::unique_ptr<grpc::ClientReaderWriter<pb::TrackRequest, pb::PoseEstimate>> stream =
      client->stub().Track(context.get());
  // Ends the stream after a problem: the daemon's status when it has one, else `problem`.
  // A local problem (a frame that does not load) cancels the call; when the daemon ended the
  // stream, its status is already on the way.
  const auto fail = [&](const absl::Status& problem, bool cancel) {
    if (cancel) context->TryCancel();
    const grpc::Status finished = stream->Finish();
    const bool daemon_error =
        !finished.ok() && finished.error_code() != grpc::StatusCode::CANCELLED;
    return ReportError(kCommand, daemon_error ? client->ToStatus(finished) : problem);
  };

  ProgressLine line(!flags.GetSwitch("quiet"));
  std::vector<StampedPose> trajectory;
  std::vector<double> latency_ms;  // frames 1.., as in-process (frame 0 is the start pose)
  std::vector<double> roundtrip_ms;
  absl::Time first_tracked;  // frame 1 loading: frames per second count from here
  int64_t dropped = 0;
  for (int i = 0; i < report.frames; ++i) {
    if (i == 1) first_tracked = absl::Now();
    absl::StatusOr<RgbdFrame> frame = dataset->LoadFrame(i);
    if (!frame.ok()) return fail(frame.status(), /*cancel=*/true);
    pb::TrackRequest request;
    if (i == 0) {
      request.set_map(map_name);
      *request.mutable_options() = wire;
      if (start_pose) PoseToProto(*start_pose, request.mutable_initial_pose());
    }
    // No per-frame prior: the daemon predicts with constant velocity, as in-process tracking.
    absl::StatusOr<pb::Frame> encoded =
        FrameToProto(*frame, dataset->calibration(), /*with_pose=*/false, *encoding);
    if (!encoded.ok()) return fail(encoded.status(), /*cancel=*/true);
    *request.mutable_frame() = std::move(*encoded);
    pb::PoseEstimate estimate;
    const absl::Time sent = absl::Now();
    if (!stream->Write(request) || !stream->Read(&estimate)) {
      return fail(absl::InternalError(absl::StrCat("the daemon ended the Track stream at frame ",
                                                   i, " of ", report.frames)),
                  /*cancel=*/false);
    }
    absl::StatusOr<SE3> pose = PoseFromProto(estimate.pose(), "estimate.pose");
    if (!pose.ok()) return fail(pose.status(), /*cancel=*/true);
    trajectory.push_back({frame->timestamp, *pose});
    if (i > 0) {
      roundtrip_ms.push_back(absl::ToDoubleMilliseconds(absl::Now() - sent));
      latency_ms.push_back(estimate.latency_ms());
      report.lost += estimate.state() == pb::TRACKING_STATE_LOST;
      report.degraded += estimate.state() == pb::TRACKING_STATE_DEGRADED;
    }
    dropped += estimate.dropped();
    line.Update(TrackProgressText({.frame = i + 1,
                                   .frames = report.frames,
                                   .state = TrackingStateText(estimate.state()),
                                   .milliseconds = estimate.latency_ms(),
                                   .valid_rays = static_cast<int>(estimate.valid_rays()),
                                   .rays = options.rays,
                                   .lost = report.lost,
                                   .reason = estimate.reason()}));
  }
  const absl::Time last_tracked = absl::Now();
  stream->WritesDone();
  if (const grpc::Status finished = stream->Finish(); !finished.ok()) {
    return ReportError(kCommand, client->ToStatus(finished));
  }

  // The trajectory first: it is the result; the timings are extra.
  if (absl::Status s = WriteTrackTrajectory(report, trajectory, dataset->name(),
                                            absl::StrCat(map_name, " at ", client->server()));
      !s.ok()) {
    return ReportError(kCommand, s);
  }
  if (!timings.empty()) {
    std::string text = "# frame timestamp roundtrip_ms daemon_ms (frames 1..; 0 is the start)\n";
    for (size_t k = 0; k < roundtrip_ms.size(); ++k) {
      absl::StrAppendFormat(&text, "%d %.6f %.3f %.3f\n", static_cast<int>(k + 1),
                            trajectory[k + 1].timestamp, roundtrip_ms[k], latency_ms[k]);
    }
    if (absl::Status s = WriteFileAtomically(timings, text, "cannot write --timings"); !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  report.ms_per_frame_median = Percentile(latency_ms, 0.5);
  report.ms_per_frame_p95 = Percentile(latency_ms, 0.95);
  report.dropped = dropped;
  report.started_from_ground_truth = start_pose.has_value();
  line.Finish(TrackSummaryText(report, absl::StrCat(" on ", client->server()), ""));
  JsonObject more_times;
  more_times.Add("ms_per_frame_p99", Percentile(latency_ms, 0.99))
      .Add("roundtrip_ms_median", Percentile(roundtrip_ms, 0.5))
      .Add("roundtrip_ms_p99", Percentile(roundtrip_ms, 0.99))
      // Loading and encoding included: what this client achieves end to end.
      .Add("fps", roundtrip_ms.empty() ? 0.0
                                       : roundtrip_ms.size() /
                                             absl::ToDoubleSeconds(last_tracked - first_tracked))
      .Add("encoding", flags.GetString("encoding"));
  PrintTrackResult(report, flags.GetSwitch("json"), more_times,
                   JsonObject().Add("map", map_name).Add("server", client->server()));
  return kExitOk;
}

}  // namespace plx::cli
