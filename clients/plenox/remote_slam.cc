// plenox --server HOST:PORT slam: online SLAM of a dataset's frames on the daemon (one Slam
// stream into map N): the same trajectory, summary and JSON as in-process `plenox slam`, plus
// the round trip seen here.
//
// A failover (the daemon killed or restarted, the map reloaded from its last snapshot by the
// new one, here or on another replica behind the same address) does not end the run: the
// stream that broke with UNAVAILABLE is replaced by a new one into the same map, within
// --retry-seconds, which gives no start pose of its own but the last pose tracked in the map
// as the hint: the camera relocalises against the map's saved keyframes (their features first)
// and the poses go on in the map's frame. Frames are treated as a camera's: those whose update
// never came back (the one in flight in lock-step) and, with --realtime, those due while no
// stream was open, are lost, not sent again later (stale by then, and the new stream finds
// its place from the next frame anyway); the summary and the JSON count them
// (frames_lost_in_failover) with the reconnects and the time from the break to the first
// frame tracked again (failover_resume_s).
#include <algorithm>
#include <cmath>
#include <iostream>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "app/retry_policy.h"
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
  bool quiet = false;  // --quiet: no progress line (failover notices are still printed)

  std::vector<StampedPose> trajectory{};  // in the main map's frame (PosesInMainMap) at the end
  std::vector<StampedPose> corrected{};   // and moved by the corrections (FollowCorrections)
  std::vector<SlamFrameResult> given{};   // each update's pose with its segment, as given
  std::vector<SlamCorrection> corrections{};  // the loop-closure corrections the stream sent
  pb::SlamMapping mapping{};  // as of the last update (the done message's at the end)
  bool done = false;
  absl::Time done_at{};
  int corrections_after_last_frame = 0;  // of `corrections`, those the done messages carried
  FrameStreamResult result{};  // records: each update's frame, times and state [keyframe]

  // Failovers: each stream's first result in `given` and first correction (segments and
  // corrections are numbered per stream, so each stream's poses are put in its map's frame
  // on their own); the reconnects, the frames lost, and the longest time from a stream
  // breaking to the first frame tracked on its replacement (NaN: no reconnect).
  std::vector<size_t> stream_given{};
  std::vector<size_t> stream_corrections{};
  int reconnects = 0;
  int frames_lost = 0;
  double resume_s = std::nan("");
  // The last pose tracked in the map (segment 0, not LOST or WAITING): a new stream's hint.
  std::optional<SE3> last_in_map{};
  std::optional<absl::Time> broke_at{};  // set until a frame is tracked after a reconnect
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
  const bool tracked = update.state() == pb::SLAM_STATE_OK ||
                       update.state() == pb::SLAM_STATE_DEGRADED ||
                       update.state() == pb::SLAM_STATE_RELOCALISED;
  if (tracked && update.segment() == 0) s.last_in_map = *pose;
  if (tracked && s.broke_at) {
    const double resume_s = absl::ToDoubleSeconds(absl::Now() - *s.broke_at);
    s.resume_s = std::isnan(s.resume_s) ? resume_s : std::max(s.resume_s, resume_s);
    s.broke_at.reset();
  }
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

// A failover notice on a line of its own. Printed with --quiet too: it is an event the run's
// numbers depend on, not progress (as the --save warning).
void Notice(const SlamStream& s, ProgressLine& line, const std::string& text) {
  if (s.quiet) {
    std::cerr << text << "\n";
  } else {
    line.Finish(text);
  }
}

// Request of dataset frame `index`; `opens`: the stream's first, with the map, the options and
// `start` (none: the daemon starts at the identity, or relocalises in a map with content).
absl::StatusOr<pb::SlamRequest> SlamRequestAt(const SlamStream& s, int index, bool opens,
                                              const std::optional<SE3>& start) {
  PLX_ASSIGN_OR_RETURN(pb::SlamRequest request,
                       TrackingStreamRequest<pb::SlamRequest>(*s.dataset, index, s.encoding,
                                                              s.map_name, s.wire, start));
  if (opens && index != 0) {
    request.set_map(s.map_name);
    *request.mutable_options() = s.wire;
    if (start) PoseToProto(*start, request.mutable_initial_pose());
  }
  return request;
}

// One Slam stream over frames first..frames-1, one at a time or at their timestamps; the
// updates go into `s` and `report` as they come, the records' indices are the dataset's.
FrameStreamResult RunStream(SlamStream& s, int first, const std::optional<SE3>& start,
                            SlamReport& report, ProgressLine& line) {
  std::unique_ptr<grpc::ClientContext> context =
      s.client->NewContext(absl::InfiniteDuration(), s.map_name);
  auto stream = s.client->stub().Slam(context.get());
  // Lock-step: the next frame goes once this one's update is back, so the round trip is the
  // daemon's work and not a queue's; --realtime: the sensor's clock, as in-process.
  FrameStream<pb::SlamRequest, pb::SlamUpdate> frames(
      stream.get(), [&] { context->TryCancel(); },
      s.realtime ? FramePacing::Realtime(s.speed) : FramePacing::LockStep(), "an update");
  return frames.Run(report.frames - first, {
      .request = [&](int k) { return SlamRequestAt(s, first + k, k == 0, start); },
      .timestamp = [&](int k) { return s.dataset->timestamp(first + k); },
      .answers = [](const pb::SlamUpdate& u) -> std::optional<FrameAnswer> {
        if (u.done()) return std::nullopt;
        return FrameAnswer{u.timestamp(), u.latency_ms()};
      },
      .on_reply = [&](const pb::SlamUpdate& update, FrameRecord* record) -> absl::Status {
        s.mapping = update.mapping();
        if (record != nullptr) {
          record->index += first;
          return TakeUpdate(update, *record, s, report, line);
        }
        s.done = true;
        s.done_at = absl::Now();
        // The corrections the map made after the last frame (its finishing mapping): the
        // corrected trajectory follows them like those the frames' updates carried.
        for (const pb::SlamCorrection& after : update.corrections_after()) {
          PLX_ASSIGN_OR_RETURN(SlamCorrection correction, SlamCorrectionFromProto(after));
          s.corrections.push_back(std::move(correction));
          ++s.corrections_after_last_frame;
        }
        return absl::OkStatus();
      },
  });
}

// The first frame to send after a reconnect, from `next` (the frame after the last one sent):
// with --realtime the newest frame due by now on the run's clock (a live camera's frames
// captured while disconnected are gone), else `next` itself (the replay waited).
int ResumeFrame(const SlamStream& s, int next, int frames) {
  if (!s.realtime || next >= frames) return next;
  const FramePacing pacing = FramePacing::Realtime(s.speed);
  const double t0 = s.dataset->timestamp(0);
  const absl::Time now = absl::Now();
  int k = next;
  while (k + 1 < frames &&
         pacing.Due(s.result.started, t0, s.dataset->timestamp(k + 1)) <= now) {
    ++k;
  }
  return k;
}

// Waits for the daemon (or its replacement) to answer at the address, under the retry
// policy's backoff begun when the stream broke; the failure to report when it does not.
absl::Status AwaitDaemon(SlamStream& s, Backoff& backoff, absl::Status failure) {
  while (true) {
    if (!backoff.Wait()) {
      return absl::Status(failure.code(),
                          absl::StrFormat("%s; no daemon answered within %.1f s "
                                          "(--retry-seconds %g)",
                                          failure.message(),
                                          absl::ToDoubleSeconds(backoff.elapsed()),
                                          absl::ToDoubleSeconds(s.client->retry().budget)));
    }
    failure = s.client->Probe(s.map_name);
    if (failure.ok()) return absl::OkStatus();
    if (!IsRetryable(failure, /*idempotent=*/true)) return failure;
  }
}

// Streams the frames (the first with the map, the options and the start pose) and collects the
// updates; a stream cut by a failover is replaced (see the top of this file). The error to
// report when it went wrong.
absl::Status StreamFrames(SlamStream& s, SlamReport& report, ProgressLine& line) {
  Backoff backoff(s.client->retry(), s.client->retry_clock());
  std::optional<SE3> start = s.start_pose;
  int first = 0;
  while (true) {
    s.stream_given.push_back(s.given.size());
    s.stream_corrections.push_back(s.corrections.size());
    const int dropped_before = report.dropped;
    FrameStreamResult r = RunStream(s, first, start, report, line);
    const int answered = static_cast<int>(r.records.size());
    const int sent = r.sent;
    if (first == 0) {
      s.result = std::move(r);
    } else {
      s.result.sent += r.sent;
      s.result.records.insert(s.result.records.end(), r.records.begin(), r.records.end());
      if (answered > 0) s.result.last_answer = r.last_answer;
      s.result.local = r.local;
      s.result.problem = r.problem;
      s.result.finished = r.finished;
    }
    const FrameStreamResult& last = s.result;  // this stream's statuses and `sent` count
    if (!last.local.ok() || !last.problem.ok()) {
      line.Finish("slam cancelled");
      return !last.local.ok() ? last.local : last.problem;
    }
    if (last.finished.ok()) {
      if (!s.done) {
        return absl::InternalError("the daemon ended the Slam stream without its done message");
      }
      return absl::OkStatus();
    }
    const absl::Status failure = s.client->ToStatus(last.finished);
    // Only a daemon that went away is waited for: a stream it refused or ended with another
    // code would be refused again (app/retry_policy.h).
    if (!IsRetryable(failure, /*idempotent=*/true) ||
        s.client->retry().budget <= absl::ZeroDuration()) {
      line.Finish("slam failed");
      return failure;
    }
    // Frames written and neither answered nor reported dropped by the daemon are lost.
    const int lost = sent - answered - (report.dropped - dropped_before);
    s.frames_lost += std::max(lost, 0);
    const int next = first + sent;
    if (next >= report.frames) {
      // Every frame was sent: nothing to reconnect for. The poses that came back are the
      // result; the mapping job that would have sent the done message died with the daemon.
      Notice(s, line, absl::StrFormat(
          "slam: the daemon went away after the last frame was sent (%s), before its mapping "
          "job finished: the map has what its last snapshot saved",
          failure.message()));
      s.done_at = absl::Now();
      return absl::OkStatus();
    }
    if (!s.broke_at) s.broke_at = absl::Now();
    backoff.Start();
    Notice(s, line, absl::StrFormat(
        "slam: the stream broke with %d of %d frames sent (%s); reconnecting for up to %g s "
        "(--retry-seconds)",
        next, report.frames, failure.message(), absl::ToDoubleSeconds(s.client->retry().budget)));
    PLX_RETURN_IF_ERROR(AwaitDaemon(s, backoff, failure));
    const int resume = ResumeFrame(s, next, report.frames);
    s.frames_lost += resume - next;
    ++s.reconnects;
    Notice(s, line, absl::StrFormat(
        "slam: reconnected after %.1f s, going on from frame %d (%d frame(s) lost so far); "
        "relocalising in map \"%s\"",
        absl::ToDoubleSeconds(absl::Now() - *s.broke_at), resume, s.frames_lost, s.map_name));
    // No start pose of its own: a map with content places the camera by its keyframes; the
    // last pose tracked in it is where the dense attempts begin when the features find
    // nothing (and where a map lost altogether starts again).
    start = s.last_in_map;
    first = resume;
  }
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
  report.corrections_in_place = static_cast<int>(s.mapping.corrections_in_place());
  const double roundtrip_median = Percentile(roundtrip_ms, 0.5);
  const double roundtrip_p95 = Percentile(roundtrip_ms, 0.95);
  std::string failover;
  if (s.reconnects > 0) {
    failover = absl::StrFormat("; %d reconnect(s), %d frame(s) lost in the failover", s.reconnects,
                               s.frames_lost);
    if (!std::isnan(s.resume_s)) {
      absl::StrAppendFormat(&failover, ", tracking again %.1f s after the stream broke",
                            s.resume_s);
    }
  } else if (s.frames_lost > 0) {
    failover = absl::StrFormat("; %d frame(s) lost when the daemon went away", s.frames_lost);
  }
  std::string summary = SlamSummaryText(
      report, absl::StrFormat(" [%s, map \"%s\"; round trip median %.1f ms, p95 %.1f ms%s]",
                              s.client->server(), s.map_name, roundtrip_median, roundtrip_p95,
                              failover));
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
      .AddBool("saved", saved.has_value())
      .Add("reconnects", s.reconnects)
      .Add("frames_lost_in_failover", s.frames_lost)
      .Add("failover_resume_s", s.resume_s)
      .Add("corrections_received", static_cast<int64_t>(s.corrections.size()))
      .Add("corrections_after_last_frame", s.corrections_after_last_frame);
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
                    .speed = options->speed,
                    .quiet = flags.GetSwitch("quiet")};
  report.started_from_ground_truth = stream.start_pose.has_value();

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  stream.client = client.get();
  ProgressLine line(!flags.GetSwitch("quiet"));
  if (absl::Status s = StreamFrames(stream, report, line); !s.ok()) return ReportError(kCommand, s);
  // Each stream's results on their own (a failover's new stream numbers its segments and
  // corrections afresh): a segment's poses, once it joined the map, in the map's frame
  // (docs/SLAM.md), and each pose moved by the corrections after it, as the stream sent them
  // (the daemon's final keyframe poses are not sent).
  stream.stream_given.push_back(stream.given.size());
  stream.stream_corrections.push_back(stream.corrections.size());
  stream.trajectory.clear();  // TakeUpdate's poses as given
  for (size_t i = 0; i + 1 < stream.stream_given.size(); ++i) {
    const std::vector<SlamFrameResult> given(stream.given.begin() + stream.stream_given[i],
                                             stream.given.begin() + stream.stream_given[i + 1]);
    const std::vector<SlamCorrection> corrections(
        stream.corrections.begin() + stream.stream_corrections[i],
        stream.corrections.begin() + stream.stream_corrections[i + 1]);
    for (const StampedPose& p : PosesInMainMap(given)) stream.trajectory.push_back(p);
    for (const StampedPose& p : FollowCorrections(given, corrections)) {
      stream.corrected.push_back(p);
    }
  }
  absl::StatusOr<std::optional<pb::MapInfo>> saved = WriteAndSave(flags, stream, report);
  if (!saved.ok()) return ReportError(kCommand, saved.status());
  ScoreSlamTrajectory(*dataset, stream.trajectory, stream.corrected, *rpe_delta, &report);
  PrintRemoteSlamResult(flags, *options, stream, *saved, report, line);
  return kExitOk;
}

}  // namespace plx::cli
