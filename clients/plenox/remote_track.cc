// plenox --server HOST:PORT track: localise every frame of a dataset in a map on the daemon
// (one Track stream, in lock-step so that no frame is dropped).
#include <algorithm>
#include <cmath>
#include <iostream>

#include "absl/strings/str_cat.h"
#include "core/common/percentile.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"
#include "core/io/atomic_write.h"
#include "core/io/trajectory_file.h"
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
  flags.Add("map", "N", "the map on the daemon", std::nullopt, true);
  AddDatasetFlags(flags);
  flags.Add("out", "TRAJ.txt", "trajectory to write", std::nullopt, true);
  AddTrackerFlags(flags);
  flags.Add("encoding", "png|raw", "how frames travel: PNG, or raw RGB8 + uint16 (no codec)", "png")
      .Add("timings", "FILE", "also write per-frame times: frame timestamp roundtrip_ms daemon_ms", "")
      .AddSwitch("json", "print a JSON summary on the last line of stdout")
      .AddSwitch("quiet", "no progress on stderr");
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  // The options the daemon will apply (it starts from the same TrackerOptionsForMode), so that
  // the summary names what actually ran; only flags the user set go on the wire.
  absl::StatusOr<TrackerOptions> tracker_options = TrackerOptionsFromFlags(flags);
  if (!tracker_options.ok()) return ReportError(kCommand, tracker_options.status(), true);
  const TrackerOptions& options = *tracker_options;
  const std::string mode = flags.GetString("mode");
  pb::TrackOptions wire;
  wire.set_mode(options.mode == TrackingMode::kAdam ? pb::TrackOptions::MODE_ADAM
                                                    : pb::TrackOptions::MODE_GAUSS_NEWTON);
  if (flags.IsSet("rays")) wire.set_rays(static_cast<uint32_t>(options.rays));
  if (flags.IsSet("iterations")) wire.set_iterations(static_cast<uint32_t>(options.iterations));
  absl::StatusOr<WireEncoding> encoding = ParseWireEncoding(flags.GetString("encoding"));
  if (!encoding.ok()) return ReportError(kCommand, encoding.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  const std::string map_name = flags.GetString("map");
  const std::string out = flags.GetString("out");
  if (absl::Status s = CheckOutputDirectory(out); !s.ok()) return ReportError(kCommand, s);
  const std::string timings = flags.GetString("timings");
  if (!timings.empty()) {
    if (absl::Status s = CheckOutputDirectory(timings); !s.ok()) return ReportError(kCommand, s);
  }

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  absl::StatusOr<std::unique_ptr<RgbdDataset>> opened =
      OpenDatasetFromFlags(flags, *dataset_options);
  if (!opened.ok()) return ReportError(kCommand, opened.status());
  const RgbdDataset& dataset = **opened;
  const int total = dataset.size();
  if (total == 0) {
    return ReportError(kCommand, absl::InvalidArgumentError("the dataset has no frames"));
  }
  const std::optional<SE3> start_pose = dataset.ground_truth(0);

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
  int lost = 0, degraded = 0;
  int64_t dropped = 0;
  for (int i = 0; i < total; ++i) {
    if (i == 1) first_tracked = absl::Now();
    absl::StatusOr<RgbdFrame> frame = dataset.LoadFrame(i);
    if (!frame.ok()) return fail(frame.status(), /*cancel=*/true);
    pb::TrackRequest request;
    if (i == 0) {
      request.set_map(map_name);
      *request.mutable_options() = wire;
      if (start_pose) PoseToProto(*start_pose, request.mutable_initial_pose());
    }
    // No per-frame prior: the daemon predicts with constant velocity, as in-process tracking.
    absl::StatusOr<pb::Frame> encoded =
        FrameToProto(*frame, dataset.calibration(), /*with_pose=*/false, *encoding);
    if (!encoded.ok()) return fail(encoded.status(), /*cancel=*/true);
    *request.mutable_frame() = std::move(*encoded);
    pb::PoseEstimate estimate;
    const absl::Time sent = absl::Now();
    if (!stream->Write(request) || !stream->Read(&estimate)) {
      return fail(absl::InternalError(
          absl::StrCat("the daemon ended the Track stream at frame ", i, " of ", total)),
                  /*cancel=*/false);
    }
    absl::StatusOr<SE3> pose = PoseFromProto(estimate.pose(), "estimate.pose");
    if (!pose.ok()) return fail(pose.status(), /*cancel=*/true);
    trajectory.push_back({frame->timestamp, *pose});
    if (i > 0) {
      roundtrip_ms.push_back(absl::ToDoubleMilliseconds(absl::Now() - sent));
      latency_ms.push_back(estimate.latency_ms());
      lost += estimate.state() == pb::TRACKING_STATE_LOST;
      degraded += estimate.state() == pb::TRACKING_STATE_DEGRADED;
    }
    dropped += estimate.dropped();
    line.Update(absl::StrFormat("tracking %d/%d  %s  %.0f ms  rays %d/%d  lost %d%s%s", i + 1,
                                total, TrackingStateText(estimate.state()), estimate.latency_ms(),
                                estimate.valid_rays(), options.rays, lost,
                                estimate.reason().empty() ? "" : "  ", estimate.reason()));
  }
  const absl::Time last_tracked = absl::Now();
  stream->WritesDone();
  if (const grpc::Status finished = stream->Finish(); !finished.ok()) {
    return ReportError(kCommand, client->ToStatus(finished));
  }

  // The trajectory first: it is the result; the timings are extra.
  if (absl::Status s = WriteTumTrajectory(
          out, trajectory,
          absl::StrFormat("plenox track: %s on map %s at %s (mode %s)", dataset.name(), map_name,
                          client->server(), mode));
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
  const double median = Percentile(latency_ms, 0.5), p95 = Percentile(latency_ms, 0.95);
  line.Finish(absl::StrFormat(
      "tracked %d frames on %s: median %.1f ms, p95 %.1f ms per frame, %d lost, %d degraded%s",
      total, client->server(), median, p95, lost, degraded,
      start_pose ? "" : " (no ground truth: started at the identity)"));
  if (flags.GetSwitch("json")) {
    JsonObject json;
    json.Add("frames", total)
        .Add("ms_per_frame_median", median)
        .Add("ms_per_frame_p95", p95)
        .Add("ms_per_frame_p99", Percentile(latency_ms, 0.99))
        .Add("roundtrip_ms_median", Percentile(roundtrip_ms, 0.5))
        .Add("roundtrip_ms_p99", Percentile(roundtrip_ms, 0.99))
        // Loading and encoding included: what this client achieves end to end.
        .Add("fps", roundtrip_ms.empty() ? 0.0
                                         : roundtrip_ms.size() /
                                               absl::ToDoubleSeconds(last_tracked - first_tracked))
        .Add("encoding", flags.GetString("encoding"))
        .Add("lost", lost)
        .Add("degraded", degraded)
        .Add("dropped", dropped)
        .Add("mode", mode)
        .Add("rays", options.rays)
        .Add("iterations", options.iterations)
        .Add("trajectory", out)
        .Add("map", map_name)
        .Add("server", client->server());
    std::cout << json.str() << "\n";
  } else {
    std::cout << absl::StrFormat("wrote %s (%d poses)\n", out, total);
  }
  return kExitOk;
}

}  // namespace plx::cli
