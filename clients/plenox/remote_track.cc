// plenox --server HOST:PORT track: localise every frame of a dataset in a map on the daemon
// (one Track stream, in lock-step so that no frame is dropped).
#include "absl/strings/str_cat.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/frame_stream.h"
#include "clients/plenox/remote_client.h"
#include "clients/plenox/track_output.h"
#include "core/common/percentile.h"
#include "core/common/status_macros.h"
#include "core/formats/trajectory_file.h"
#include "core/io/atomic_write.h"
#include "core/tracking/tracker.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "track";

FlagSet RemoteTrackFlags() {
  FlagSet flags("plenox track",
                "With --server: tracks every frame of a dataset against map N on the daemon,\n"
                "starting from frame 0's ground-truth pose when the dataset has one, and writes\n"
                "the trajectory in TUM format. Frames go one at a time (the next only after the\n"
                "previous estimate came back), so none is dropped. Times reported: the daemon's\n"
                "latency (frame received to estimate sent) and the round trip seen here (frame\n"
                "sent to estimate read, encoding excluded).");
  AddTrackFlags(flags, "N", "the map on the daemon");
  AddWireEncodingFlag(flags);
  flags.Add("timings", "FILE", "also write per-frame times: frame timestamp roundtrip_ms daemon_ms",
            "");
  AddJsonAndQuietSwitches(flags);
  return flags;
}

// One Track stream over a dataset and what came back.
struct TrackStream {
  RemoteClient* client = nullptr;
  const RgbdDataset* dataset;
  std::string map_name;
  pb::TrackOptions wire;
  FrameEncoding encoding;
  std::optional<SE3> start_pose;
  int rays = 0;

  std::vector<StampedPose> trajectory{};
  absl::Time first_tracked{};  // frame 1 loading: frames per second count from here
  FrameStreamResult result{};
};

// Streams every frame (the first with the map, the options and the start pose) and collects the
// estimates into `s` and `report`; the error to report when the stream did not track them all.
absl::Status StreamFrames(TrackStream& s, ProgressLine& line, TrackReport& report) {
  std::unique_ptr<grpc::ClientContext> context =
      s.client->NewContext(absl::InfiniteDuration(), s.map_name);
  auto stream = s.client->stub().Track(context.get());
  FrameStream<pb::TrackRequest, pb::PoseEstimate> frames(
      stream.get(), [&] { context->TryCancel(); }, FramePacing::LockStep(), "an estimate");
  int64_t dropped = 0;
  s.result = frames.Run(report.frames, {
      .request = [&](int i) -> absl::StatusOr<pb::TrackRequest> {
        if (i == 1) s.first_tracked = absl::Now();
        // No per-frame prior: the daemon predicts with constant velocity, as in-process.
        return TrackingStreamRequest<pb::TrackRequest>(*s.dataset, i, s.encoding, s.map_name,
                                                       s.wire, s.start_pose);
      },
      .answers = [](const pb::PoseEstimate& e) -> std::optional<FrameAnswer> {
        return FrameAnswer{e.timestamp(), e.latency_ms()};
      },
      .on_reply = [&](const pb::PoseEstimate& estimate, FrameRecord* record) -> absl::Status {
        absl::StatusOr<SE3> pose = PoseFromProto(estimate.pose(), "estimate.pose");
        if (!pose.ok()) return pose.status();
        s.trajectory.push_back({record->timestamp, *pose});
        if (record->index > 0) {  // frame 0 is the start pose, as in-process
          report.lost += estimate.state() == pb::TRACKING_STATE_LOST;
          report.degraded += estimate.state() == pb::TRACKING_STATE_DEGRADED;
        }
        dropped += estimate.dropped();
        line.Update(TrackProgressText({.frame = record->index + 1,
                                       .frames = report.frames,
                                       .state = TrackingStateText(estimate.state()),
                                       .milliseconds = estimate.latency_ms(),
                                       .valid_rays = static_cast<int>(estimate.valid_rays()),
                                       .rays = s.rays,
                                       .lost = report.lost,
                                       .reason = estimate.reason()}));
        return absl::OkStatus();
      },
  });
  report.dropped = dropped;
  const FrameStreamResult& r = s.result;
  const int tracked = static_cast<int>(r.records.size());
  if (r.local.ok() && r.problem.ok() && tracked == report.frames) {
    return s.client->ToStatus(r.finished);
  }
  // The daemon's status when it has one; else the local problem, or that the stream ended.
  if (!r.finished.ok() && r.finished.error_code() != grpc::StatusCode::CANCELLED) {
    return s.client->ToStatus(r.finished);
  }
  if (!r.local.ok()) return r.local;
  if (!r.problem.ok()) return r.problem;
  return absl::InternalError(absl::StrCat("the daemon ended the Track stream at frame ", tracked,
                                          " of ", report.frames));
}

// The trajectory first (it is the result; the timings are extra), then the summary.
absl::Status WriteAndPrint(const FlagSet& flags, const TrackStream& s, ProgressLine& line,
                           TrackReport& report) {
  PLX_RETURN_IF_ERROR(WriteTrackTrajectory(report, s.trajectory, s.dataset->name(),
                                           absl::StrCat(s.map_name, " at ", s.client->server())));
  const std::vector<FrameRecord>& records = s.result.records;  // frames 1..: 0 is the start
  if (const std::string timings = flags.GetString("timings"); !timings.empty()) {
    PLX_RETURN_IF_ERROR(WriteFileAtomically(
        timings,
        FrameTimingsText("# frame timestamp roundtrip_ms daemon_ms (frames 1..; 0 is the start)\n",
                         records, 1),
        "cannot write --timings"));
  }
  const std::vector<double> latency_ms = DaemonMs(records, 1);
  const std::vector<double> roundtrip_ms = RoundtripMs(records, 1);
  report.ms_per_frame_median = Percentile(latency_ms, 0.5);
  report.ms_per_frame_p95 = Percentile(latency_ms, 0.95);
  report.started_from_ground_truth = s.start_pose.has_value();
  line.Finish(TrackSummaryText(report, absl::StrCat(" on ", s.client->server()), ""));
  const double seconds = absl::ToDoubleSeconds(s.result.last_answer - s.first_tracked);
  JsonObject more_times;
  more_times.Add("ms_per_frame_p99", Percentile(latency_ms, 0.99))
      .Add("roundtrip_ms_median", Percentile(roundtrip_ms, 0.5))
      .Add("roundtrip_ms_p99", Percentile(roundtrip_ms, 0.99))
      // Loading and encoding included: what this client achieves end to end.
      .Add("fps", roundtrip_ms.empty() ? 0.0 : roundtrip_ms.size() / seconds)
      .Add("encoding", flags.GetString("encoding"));
  PrintTrackResult(report, flags.GetSwitch("json"), more_times,
                   JsonObject().Add("map", s.map_name).Add("server", s.client->server()));
  return absl::OkStatus();
}

}  // namespace

int RunRemoteTrack(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags = RemoteTrackFlags();
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  // The options the daemon will apply (it starts from the same TrackerOptionsForMode), so that
  // the summary names what actually ran; only flags the user set go on the wire.
  absl::StatusOr<TrackerOptions> options = TrackerOptionsFromFlags(flags);
  if (!options.ok()) return ReportError(kCommand, options.status(), true);
  absl::StatusOr<FrameEncoding> encoding = ParseWireEncoding(flags.GetString("encoding"));
  if (!encoding.ok()) return ReportError(kCommand, encoding.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  TrackReport report{.mode = flags.GetString("mode"),
                     .rays = options->rays,
                     .iterations = options->iterations,
                     .trajectory = flags.GetString("out")};
  for (const std::string& path : {report.trajectory, flags.GetString("timings")}) {
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
  TrackStream stream{.client = client.get(),
                     .dataset = dataset.get(),
                     .map_name = flags.GetString("map"),
                     .wire = TrackOptionsToProto(*options, TrackOptionsFieldsFromFlags(flags)),
                     .encoding = *encoding,
                     .start_pose = dataset->ground_truth(0),
                     .rays = options->rays};
  ProgressLine line(!flags.GetSwitch("quiet"));
  if (absl::Status s = StreamFrames(stream, line, report); !s.ok()) {
    return ReportError(kCommand, s);
  }
  if (absl::Status s = WriteAndPrint(flags, stream, line, report); !s.ok()) {
    return ReportError(kCommand, s);
  }
  return kExitOk;
}

}  // namespace plx::cli
