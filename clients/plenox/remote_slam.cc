// plenox --server HOST:PORT slam: online SLAM of a dataset's frames on the daemon (one Slam
// stream into map N): the same trajectory, summary and JSON as in-process `plenox slam`, plus
// the round trip seen here.
#include <algorithm>
#include <iostream>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/frame_stream.h"
#include "clients/plenox/remote_client.h"
#include "clients/plenox/slam_output.h"
#include "core/common/percentile.h"
#include "core/common/status_macros.h"
#include "core/formats/trajectory_file.h"
#include "core/io/atomic_write.h"
#include "core/slam/map_segment_poses.h"
#include "proto/slam_codec.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "slam";

// In-process flags that would mean something else, or nothing, on a daemon.
const std::vector<UnavailableFlag>& InProcessOnlyFlags() {
  static const std::vector<UnavailableFlag> flags = {
      {"map-out",
       "the map stays on the daemon: --save writes it to the daemon's data directory (then "
       "`plenox --server ... export` writes a PLY)"},
      {"keyframes-out",
       "the daemon does not send the keyframes' refined poses (each update says whether its "
       "frame became a keyframe)"},
      {"loops-out",
       "the daemon does not send the loop edges (the viewer draws them; the stream's "
       "corrections say how the keyframes moved)"},
      {"window", "the daemon's mapping job sets its own mapping window"},
      {"refine-window", "the daemon's mapping job sets its own keyframe refinement"},
      {"mapping-nice", "the daemon's mapping job runs at the daemon's priority"},
      {"new-segment-after", "the daemon's SLAM starts map segments at its default"},
      {"backend", "the daemon computes on its own devices (plenoxd --backend, --gpus)"},
      {"device", "the daemon computes on its own devices (plenoxd --backend, --gpus)"},
      {"threads", "the daemon computes with its own threads (plenoxd --threads)"},
      {"no-odometry", "the daemon's SLAM always runs its whole front-end (they are switches to "
                      "measure it in-process)"},
      {"no-feature-relocalisation",
       "the daemon's SLAM always runs its whole front-end (they are switches to measure it "
       "in-process)"},
  };
  return flags;
}

// The settings the user chose with flags: only those go on the wire (SlamOptionsToProto), so
// that an existing map's voxel size or a running mapping job's budget is not contradicted by a
// default nobody chose.
SlamOptionsFields SlamOptionsFieldsFromFlags(const FlagSet& flags) {
  return {.voxel_size = flags.IsSet("voxel-size"),
          .tracking = TrackOptionsFieldsFromFlags(flags),
          .kf_translation = flags.IsSet("kf-translation"),
          .kf_rotation = flags.IsSet("kf-rotation"),
          .kf_unmapped_fraction = flags.IsSet("kf-unmapped"),
          .kf_interval = flags.IsSet("kf-interval"),
          .iterations_per_keyframe = flags.IsSet("iterations-per-keyframe"),
          .max_pending_keyframes = flags.IsSet("max-pending-keyframes"),
          .loop_closure = flags.IsSet("no-loop-closure")};
}

FlagSet RemoteSlamFlags() {
  FlagSet flags("plenox slam",
                "With --server: online RGB-D SLAM on the daemon. Streams every frame of a dataset\n"
                "(no poses) into map N, which is created when it does not exist, bootstrapped\n"
                "when it is empty and extended when it has content, and writes the poses the\n"
                "daemon sends back as a TUM trajectory. Starts at frame 0's "
                "ground-truth pose when\n"
                "the dataset has one (and is then scored against it), else at the identity.\n"
                "Frames go one at a time (the next after the previous update came back), or at\n"
                "their timestamps with --realtime, where the daemon keeps the newest (latest\n"
                "wins). Ends when the daemon has processed every frame and, for the last stream\n"
                "on the map, its mapping job has finished; --save then writes the map to the\n"
                "daemon's data directory. Times reported: the daemon's latency (frame received\n"
                "to update sent) and the round trip seen here (frame sent to update read,\n"
                "encoding excluded). Not here (the daemon decides them): --map-out,\n"
                "--keyframes-out, --loops-out, --window, --refine-window, --mapping-nice,\n"
                "--new-segment-after, --backend, --device, --threads, --no-odometry,\n"
                "--no-feature-relocalisation.");
  AddDatasetFlags(flags);
  flags.Add("name", "N", "the map on the daemon (1-64 characters of [A-Za-z0-9_.-])", std::nullopt,
            true);
  AddSlamFlags(flags,
               "voxel edge in metres of a new map (for an existing map, its own or nothing)");
  AddWireEncodingFlag(flags);
  flags.Add("timings", "FILE",
            "also write per-frame times: frame timestamp roundtrip_ms daemon_ms state [keyframe]",
            "");
  flags.AddSwitch("save", "after the last update, write the map to the daemon's data directory");
  AddJsonAndQuietSwitches(flags);
  return flags;
}

// One Slam stream over a dataset and what came back (counters go into `report`).
struct SlamStream {
  RemoteClient* client = nullptr;
  const RgbdDataset* dataset;
  std::string map_name;
  pb::SlamOptions wire;
  FrameEncoding encoding;
  std::optional<SE3> start_pose;
  bool realtime = false;
  double speed = 1.0;

  std::vector<StampedPose> trajectory{};  // in the main map's frame (PosesInMainMap) at the end
  std::vector<StampedPose> corrected{};   // and moved by the corrections (FollowCorrections)
  std::vector<SlamFrameResult> given{};   // each update's pose with its segment, as given
  std::vector<SlamCorrection> corrections{};  // the loop-closure corrections the stream sent
  pb::SlamMapping mapping{};  // as of the last update (the done message's at the end)
  bool done = false;
  absl::Time done_at{};
  FrameStreamResult result{};  // records: each update's frame, times and state [keyframe]
};

// Counts an update into `report` and shows it; its frame is `record`.
absl::Status TakeUpdate(const pb::SlamUpdate& update, FrameRecord& record, SlamStream& s,
                        SlamReport& report, ProgressLine& line) {
  absl::StatusOr<SE3> pose = PoseFromProto(update.pose(), "update.pose");
  if (!pose.ok()) return pose.status();
  s.trajectory.push_back({update.timestamp(), *pose});
  SlamFrameResult& given = s.given.emplace_back();
  given.timestamp = update.timestamp();
  given.pose = *pose;
  given.segment = static_cast<int>(update.segment());
  given.correction_generation = static_cast<int>(update.correction_generation());
  if (update.has_correction()) {
    absl::StatusOr<SlamCorrection> correction = SlamCorrectionFromProto(update.correction());
    if (!correction.ok()) return correction.status();
    s.corrections.push_back(*std::move(correction));
  }
  if (update.has_main_t_segment()) {
    absl::StatusOr<SE3> joined = PoseFromProto(update.main_t_segment(), "update.main_T_segment");
    if (!joined.ok()) return joined.status();
    given.main_T_segment = *joined;
    ++report.segments_joined;
  }
  report.segments += update.new_segment();
  record.note = absl::StrCat(SlamStateText(update.state()), update.keyframe() ? " keyframe" : "");
  report.keyframes += update.keyframe();
  report.dropped += static_cast<int>(update.dropped());
  switch (update.state()) {
    case pb::SLAM_STATE_OK: ++report.ok; break;
    case pb::SLAM_STATE_DEGRADED: ++report.degraded; break;
    case pb::SLAM_STATE_LOST: ++report.lost; break;
    case pb::SLAM_STATE_RELOCALISED: ++report.relocalised; break;
    case pb::SLAM_STATE_WAITING: ++report.waiting; break;
    default: break;
  }
  line.Update(SlamProgressText(record.index + 1, report.frames, SlamStateText(update.state()),
                               update.latency_ms(), report.keyframes, report.lost,
                               update.state() == pb::SLAM_STATE_OK ? "" : update.reason()));
  return absl::OkStatus();
}

// Streams the frames (the first with the map, the options and the start pose), one at a time
// or at their timestamps, and collects the updates; the error to report when it went wrong.
absl::Status StreamFrames(SlamStream& s, SlamReport& report, ProgressLine& line) {
  std::unique_ptr<grpc::ClientContext> context =
      s.client->NewContext(absl::InfiniteDuration(), s.map_name);
  auto stream = s.client->stub().Slam(context.get());
  // Lock-step: the next frame goes once this one's update is back, so the round trip is the
  // daemon's work and not a queue's; --realtime: the sensor's clock, as in-process.
  FrameStream<pb::SlamRequest, pb::SlamUpdate> frames(
      stream.get(), [&] { context->TryCancel(); },
      s.realtime ? FramePacing::Realtime(s.speed) : FramePacing::LockStep(), "an update");
  s.result = frames.Run(report.frames, {
      .request = [&](int i) -> absl::StatusOr<pb::SlamRequest> {
        return TrackingStreamRequest<pb::SlamRequest>(*s.dataset, i, s.encoding, s.map_name,
                                                      s.wire, s.start_pose);
      },
      .timestamp = [&](int i) { return s.dataset->timestamp(i); },
      .answers = [](const pb::SlamUpdate& u) -> std::optional<FrameAnswer> {
        if (u.done()) return std::nullopt;
        return FrameAnswer{u.timestamp(), u.latency_ms()};
      },
      .on_reply = [&](const pb::SlamUpdate& update, FrameRecord* record) -> absl::Status {
        s.mapping = update.mapping();
        if (record != nullptr) return TakeUpdate(update, *record, s, report, line);
        s.done = true;
        s.done_at = absl::Now();
        return absl::OkStatus();
      },
  });
  const FrameStreamResult& r = s.result;
  if (!r.local.ok() || !r.problem.ok()) {
    line.Finish("slam cancelled");
    return !r.local.ok() ? r.local : r.problem;
  }
  if (!r.finished.ok()) {
    line.Finish("slam failed");
    return s.client->ToStatus(r.finished);
  }
  if (!s.done) {
    return absl::InternalError("the daemon ended the Slam stream without its done message");
  }
  return absl::OkStatus();
}

// The trajectory, then the timings (it is the result, the timings are extra), then --save.
absl::StatusOr<std::optional<pb::MapInfo>> WriteAndSave(const FlagSet& flags, const SlamStream& s,
                                                        const SlamReport& report) {
  const std::string where = absl::StrCat(" on map ", s.map_name, " at ", s.client->server());
  const std::string header =
      SlamTrajectoryHeader(s.dataset->name(), where, report.started_from_ground_truth);
  PLX_RETURN_IF_ERROR(WriteTumTrajectory(report.trajectory, s.trajectory, header));
  if (!report.corrected_trajectory.empty()) {
    PLX_RETURN_IF_ERROR(WriteTumTrajectory(report.corrected_trajectory, s.corrected,
                                           absl::StrCat(header, ", in the map's final frame")));
  }
  if (const std::string timings = flags.GetString("timings"); !timings.empty()) {
    PLX_RETURN_IF_ERROR(WriteFileAtomically(
        timings,
        FrameTimingsText("# frame timestamp roundtrip_ms daemon_ms state [keyframe]\n",
                         s.result.records),
        "cannot write --timings"));
  }
  if (!flags.GetSwitch("save")) return std::nullopt;
  if (!s.mapping.finished()) {
    // Another stream still maps into it: the file has the keyframes mapped so far.
    std::cerr << absl::StrFormat(
        "plenox slam: other streams still map \"%s\" (%d in all): --save writes what is "
        "mapped so far\n",
        s.map_name, s.mapping.streams());
  }
  PLX_ASSIGN_OR_RETURN(pb::MapInfo info, s.client->SaveMap(s.map_name));
  return info;
}

// The summary line(s), then the result on stdout.
void PrintRemoteSlamResult(const FlagSet& flags, const SlamDatasetOptions& options,
                           const SlamStream& s, const std::optional<pb::MapInfo>& saved,
                           SlamReport& report, ProgressLine& line) {
  const std::vector<double> daemon_ms = DaemonMs(s.result.records);
  const std::vector<double> roundtrip_ms = RoundtripMs(s.result.records);
  report.processed = static_cast<int>(s.trajectory.size());
  report.ms_per_frame_median = Percentile(daemon_ms, 0.5);
  report.ms_per_frame_p95 = Percentile(daemon_ms, 0.95);
  report.wall_s = absl::ToDoubleSeconds(s.done_at - s.result.started);
  report.mapping_iterations = static_cast<int>(s.mapping.iterations());
  report.map_mb = s.mapping.map_bytes() / 1e6;
  report.loops_accepted = static_cast<int>(s.mapping.loops_accepted());
  report.loops_rejected = static_cast<int>(s.mapping.loops_rejected());
  report.corrections = static_cast<int>(s.mapping.corrections());
  const double roundtrip_median = Percentile(roundtrip_ms, 0.5);
  const double roundtrip_p95 = Percentile(roundtrip_ms, 0.95);
  std::string summary = SlamSummaryText(
      report, absl::StrFormat(" [%s, map \"%s\"; round trip median %.1f ms, p95 %.1f ms]",
                              s.client->server(), s.map_name, roundtrip_median, roundtrip_p95));
  if (saved) {
    absl::StrAppendFormat(&summary,
                          "\nslam: saved \"%s\" in the daemon's data directory: version %d, "
                          "%d keyframes, %.1f MB",
                          s.map_name, saved->version(), saved->keyframes(),
                          saved->memory_bytes() / 1e6);
  }
  line.Finish(summary);
  JsonObject more;
  more.Add("roundtrip_ms_median", roundtrip_median)
      .Add("roundtrip_ms_p95", roundtrip_p95)
      .Add("roundtrip_ms_p99", Percentile(roundtrip_ms, 0.99))
      .Add("ms_per_frame_p99", Percentile(daemon_ms, 0.99))
      .Add("encoding", flags.GetString("encoding"))
      .AddBool("deterministic", options.slam.deterministic)
      .AddBool("realtime", options.realtime)
      .Add("map", s.map_name)
      .Add("server", s.client->server())
      .Add("map_keyframes", static_cast<int64_t>(s.mapping.keyframes()))
      .Add("map_version", static_cast<int64_t>(s.mapping.map_version()))
      .AddBool("mapping_finished", s.mapping.finished())
      .AddBool("saved", saved.has_value());
  PrintSlamResult(report, flags.GetSwitch("json"), more);
}

}  // namespace

int RunRemoteSlam(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags = RemoteSlamFlags();
  int exit_code = 0;
  if (absl::Status s = RefuseUnavailableFlags(args, InProcessOnlyFlags()); !s.ok()) {
    return ReportError(kCommand, s, true);
  }
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<SlamDatasetOptions> options = SlamOptionsFromFlags(flags);
  if (!options.ok()) return ReportError(kCommand, options.status(), true);
  absl::StatusOr<FrameEncoding> encoding = ParseWireEncoding(flags.GetString("encoding"));
  if (!encoding.ok()) return ReportError(kCommand, encoding.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  absl::StatusOr<double> rpe_delta = RpeDeltaFromFlags(flags);
  if (!rpe_delta.ok()) return ReportError(kCommand, rpe_delta.status(), true);
  SlamReport report;
  report.trajectory = flags.GetString("out");
  report.corrected_trajectory = flags.GetString("corrected-out");
  for (const std::string& path :
       {report.trajectory, report.corrected_trajectory, flags.GetString("timings")}) {
    if (path.empty()) continue;
    if (absl::Status s = CheckOutputDirectory(path); !s.ok()) return ReportError(kCommand, s);
  }

  // The dataset is checked before the daemon is asked for anything: nothing is created on it
  // for frames that cannot be mapped.
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport(kCommand, flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  if (absl::Status s = CheckSlamDataset(*dataset); !s.ok()) return ReportError(kCommand, s);
  report.frames = SlamFrameCount(*dataset, *options);
  SlamStream stream{.dataset = dataset.get(),
                    .map_name = flags.GetString("name"),
                    .wire = SlamOptionsToProto(options->slam, options->realtime,
                                               SlamOptionsFieldsFromFlags(flags)),
                    .encoding = *encoding,
                    .start_pose = dataset->ground_truth(0),
                    .realtime = options->realtime,
                    .speed = options->speed};
  report.started_from_ground_truth = stream.start_pose.has_value();

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  stream.client = client.get();
  ProgressLine line(!flags.GetSwitch("quiet"));
  if (absl::Status s = StreamFrames(stream, report, line); !s.ok()) return ReportError(kCommand, s);
  // A segment's poses, once it joined the map, in the map's frame (docs/SLAM.md).
  stream.trajectory = PosesInMainMap(stream.given);
  // Each pose moved by the corrections after it, as the stream sent them (the daemon's final
  // keyframe poses are not sent).
  stream.corrected = FollowCorrections(stream.given, stream.corrections);
  absl::StatusOr<std::optional<pb::MapInfo>> saved = WriteAndSave(flags, stream, report);
  if (!saved.ok()) return ReportError(kCommand, saved.status());
  ScoreSlamTrajectory(*dataset, stream.trajectory, stream.corrected, *rpe_delta, &report);
  PrintRemoteSlamResult(flags, *options, stream, *saved, report, line);
  return kExitOk;
}

}  // namespace plx::cli
