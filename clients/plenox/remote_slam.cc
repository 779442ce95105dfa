// plenox --server HOST:PORT slam: online SLAM of a dataset's frames on the daemon (one Slam
// stream into map N): the same trajectory, summary and JSON as in-process `plenox slam`, plus
// the round trip seen here.
#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <iostream>
#include <mutex>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/remote_client.h"
#include "clients/plenox/slam_output.h"
#include "core/common/percentile.h"
#include "core/formats/trajectory_file.h"
#include "core/io/atomic_write.h"

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
      {"window", "the daemon's mapping job sets its own mapping window"},
      {"refine-window", "the daemon's mapping job sets its own keyframe refinement"},
      {"mapping-nice", "the daemon's mapping job runs at the daemon's priority"},
      {"backend", "the daemon computes on its own devices (plenoxd --backend, --gpus)"},
      {"device", "the daemon computes on its own devices (plenoxd --backend, --gpus)"},
      {"threads", "the daemon computes with its own threads (plenoxd --threads)"},
  };
  return flags;
}

// The options on the wire. Only what the user set is sent (0 = the daemon's default, which is
// DefaultSlamOptions' too), so that an existing map's voxel size or a running mapping job's
// budget is not contradicted by a value nobody chose; the replay switches always are.
pb::SlamOptions SlamOptionsToProto(const FlagSet& flags, const SlamDatasetOptions& options) {
  const SlamOptions& s = options.slam;
  pb::SlamOptions wire;
  if (flags.IsSet("voxel-size")) wire.set_voxel_size(s.mapping.mapper.voxel_size);
  *wire.mutable_tracking() = TrackOptionsToProto(flags, s.tracker);
  if (flags.IsSet("kf-translation")) {
    wire.set_kf_translation_m(static_cast<float>(s.keyframes.max_translation_m));
  }
  if (flags.IsSet("kf-rotation")) {
    wire.set_kf_rotation_deg(static_cast<float>(s.keyframes.max_rotation_rad * 180.0 / M_PI));
  }
  if (flags.IsSet("kf-unmapped")) {
    wire.set_kf_unmapped_fraction(static_cast<float>(s.keyframes.max_unmapped_fraction));
  }
  if (flags.IsSet("kf-interval")) {
    wire.set_kf_interval_s(static_cast<float>(s.keyframes.max_interval_s));
  }
  if (flags.IsSet("iterations-per-keyframe")) {
    wire.set_iterations_per_keyframe(static_cast<uint32_t>(s.mapping.iterations_per_keyframe));
  }
  if (flags.IsSet("max-pending-keyframes")) {
    wire.set_max_pending_keyframes(static_cast<uint32_t>(s.max_pending_keyframes));
  }
  wire.set_realtime(options.realtime);
  wire.set_deterministic(s.deterministic);
  return wire;
}

// A frame on its way: which one, and when it went (encoding excluded).
struct SentFrame {
  int index = 0;
  double timestamp = 0.0;
  absl::Time at;
};

// What the reader thread gathers from the daemon's updates; guarded by Exchange::mutex.
struct Received {
  std::vector<StampedPose> trajectory;
  std::vector<double> daemon_ms;     // frame received to update sent, as the daemon measured
  std::vector<double> roundtrip_ms;  // frame sent to update read, here
  std::vector<int> frame_index;      // the dataset's index of each update's frame
  std::vector<std::string> state;    // each update's state (SlamStateText) and keyframe mark
  int keyframes = 0;                 // this stream's
  int ok = 0, degraded = 0, lost = 0, relocalised = 0, waiting = 0;
  int dropped = 0;
  bool done = false;
  pb::SlamMapping mapping;  // as of the last update (the done message's at the end)
  absl::Time done_at;
  absl::Status problem;     // an update that makes no sense (cancels the call)
  bool ended = false;       // the stream has nothing more to read
};

// The state the sender (this thread) and the reader thread share.
struct Exchange {
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<SentFrame> sent;
  size_t matched = 0;  // sent frames before this one are answered or were dropped
  Received received;
};

}  // namespace

int RunRemoteSlam(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags("plenox slam",
                "With --server: online RGB-D SLAM on the daemon. Streams every frame of a dataset\n"
                "(no poses) into map N, which is created when it does not exist, bootstrapped\n"
                "when it is empty and extended when it has content, and writes the poses the\n"
                "daemon sends back as a TUM trajectory. Starts at frame 0's ground-truth pose when\n"
                "the dataset has one (and is then scored against it), else at the identity.\n"
                "Frames go one at a time (the next after the previous update came back), or at\n"
                "their timestamps with --realtime, where the daemon keeps the newest (latest\n"
                "wins). Ends when the daemon has processed every frame and, for the last stream\n"
                "on the map, its mapping job has finished; --save then writes the map to the\n"
                "daemon's data directory. Times reported: the daemon's latency (frame received\n"
                "to update sent) and the round trip seen here (frame sent to update read,\n"
                "encoding excluded). Not here (the daemon decides them): --map-out,\n"
                "--keyframes-out, --window, --refine-window, --mapping-nice, --backend,\n"
                "--device, --threads.");
  AddDatasetFlags(flags);
  flags.Add("name", "N", "the map on the daemon (1-64 characters of [A-Za-z0-9_.-])", std::nullopt,
            true);
  AddSlamFlags(flags, "voxel edge in metres of a new map (for an existing map, its own or nothing)");
  flags.Add("encoding", "png|raw", "how frames travel: PNG, or raw RGB8 + uint16 (no codec)", "png")
      .Add("timings", "FILE",
           "also write per-frame times: frame timestamp roundtrip_ms daemon_ms state [keyframe]",
           "")
      .AddSwitch("save", "after the last update, write the map to the daemon's data directory");
  AddJsonAndQuietSwitches(flags);
  int exit_code = 0;
  if (absl::Status s = RefuseUnavailableFlags(args, InProcessOnlyFlags()); !s.ok()) {
    return ReportError(kCommand, s, true);
  }
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;

  absl::StatusOr<SlamDatasetOptions> options = SlamOptionsFromFlags(flags);
  if (!options.ok()) return ReportError(kCommand, options.status(), true);
  absl::StatusOr<WireEncoding> encoding = ParseWireEncoding(flags.GetString("encoding"));
  if (!encoding.ok()) return ReportError(kCommand, encoding.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  absl::StatusOr<double> rpe_delta = RpeDeltaFromFlags(flags);
  if (!rpe_delta.ok()) return ReportError(kCommand, rpe_delta.status(), true);
  const pb::SlamOptions wire = SlamOptionsToProto(flags, *options);
  const std::string map_name = flags.GetString("name");
  SlamReport report;
  report.trajectory = flags.GetString("out");
  const std::string timings = flags.GetString("timings");
  for (const std::string& path : {report.trajectory, timings}) {
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
  const std::optional<SE3> start_pose = dataset->ground_truth(0);
  report.started_from_ground_truth = start_pose.has_value();

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  std::unique_ptr<grpc::ClientContext> context =
      client->NewContext(absl::InfiniteDuration(), map_name);
  std::unique_ptr<grpc::ClientReaderWriter<pb::SlamRequest, pb::SlamUpdate>> stream =
      client->stub().Slam(context.get());

  ProgressLine line(!flags.GetSwitch("quiet"));
  Exchange exchange;
  // Updates are read on their own thread: with --realtime frames go out at their timestamps
  // whatever the daemon is doing, and after the last frame the done message can take as long
  // as the mapping job has left.
  std::thread reader([&] {
    pb::SlamUpdate update;
    while (stream->Read(&update)) {
      const absl::Time now = absl::Now();
      std::lock_guard<std::mutex> lock(exchange.mutex);
      Received& r = exchange.received;
      r.mapping = update.mapping();
      if (update.done()) {
        r.done = true;
        r.done_at = now;
        continue;
      }
      // Updates come in the order the frames went; frames without one were dropped.
      std::vector<SentFrame>& sent = exchange.sent;
      size_t at = exchange.matched;
      while (at < sent.size() && sent[at].timestamp != update.timestamp()) ++at;
      absl::StatusOr<SE3> pose = PoseFromProto(update.pose(), "update.pose");
      if (at == sent.size() || !pose.ok()) {
        r.problem = !pose.ok() ? pose.status()
                               : absl::InternalError(absl::StrFormat(
                                     "the daemon sent an update for t=%.6f, a frame not sent "
                                     "(or answered twice)",
                                     update.timestamp()));
        context->TryCancel();
        break;
      }
      exchange.matched = at + 1;
      r.trajectory.push_back({update.timestamp(), *pose});
      r.daemon_ms.push_back(update.latency_ms());
      r.roundtrip_ms.push_back(absl::ToDoubleMilliseconds(now - sent[at].at));
      r.frame_index.push_back(sent[at].index);
      r.state.push_back(
          absl::StrCat(SlamStateText(update.state()), update.keyframe() ? " keyframe" : ""));
      r.keyframes += update.keyframe();
      r.dropped += static_cast<int>(update.dropped());
      switch (update.state()) {
        case pb::SLAM_STATE_OK: ++r.ok; break;
        case pb::SLAM_STATE_DEGRADED: ++r.degraded; break;
        case pb::SLAM_STATE_LOST: ++r.lost; break;
        case pb::SLAM_STATE_RELOCALISED: ++r.relocalised; break;
        case pb::SLAM_STATE_WAITING: ++r.waiting; break;
        default: break;
      }
      line.Update(SlamProgressText(sent[at].index + 1, report.frames,
                                   SlamStateText(update.state()), update.latency_ms(),
                                   r.keyframes, r.lost,
                                   update.state() == pb::SLAM_STATE_OK ? "" : update.reason()));
      exchange.changed.notify_all();
    }
    std::lock_guard<std::mutex> lock(exchange.mutex);
    exchange.received.ended = true;
    exchange.changed.notify_all();
  });

  const absl::Time wall_start = absl::Now();
  const double t0 = dataset->timestamp(0);
  absl::Status local = absl::OkStatus();  // a frame that does not load here
  bool stream_open = true;
  for (int i = 0; i < report.frames && stream_open; ++i) {
    if (options->realtime) {
      // The sensor's clock, as in-process: frame i is due (t_i - t_0) / speed after the start.
      const absl::Time due =
          wall_start + absl::Seconds((dataset->timestamp(i) - t0) / options->speed);
      absl::SleepFor(due - absl::Now());
    }
    absl::StatusOr<pb::Frame> encoded =
        LoadFrameToProto(*dataset, i, /*with_pose=*/false, *encoding);
    if (!encoded.ok()) {
      local = encoded.status();
      break;
    }
    pb::SlamRequest request;
    if (i == 0) {
      request.set_map(map_name);
      *request.mutable_options() = wire;
      if (start_pose) PoseToProto(*start_pose, request.mutable_initial_pose());
    }
    *request.mutable_frame() = std::move(*encoded);
    {
      std::lock_guard<std::mutex> lock(exchange.mutex);
      exchange.sent.push_back({i, request.frame().timestamp(), absl::Now()});
    }
    // false: the daemon ended the stream (an error); Finish says why.
    stream_open = stream->Write(request);
    if (stream_open && !options->realtime) {
      // Lock-step: the next frame goes once this one's update is back, so the round trip is
      // the daemon's work and not a queue's.
      std::unique_lock<std::mutex> lock(exchange.mutex);
      exchange.changed.wait(lock, [&] {
        const Received& r = exchange.received;
        return r.ended || !r.problem.ok() || exchange.matched >= exchange.sent.size();
      });
      stream_open = !exchange.received.ended && exchange.received.problem.ok();
    }
  }
  if (!local.ok()) {
    context->TryCancel();
  } else if (stream_open) {
    stream->WritesDone();
  }
  reader.join();
  const grpc::Status finished = stream->Finish();
  const Received& received = exchange.received;
  if (!local.ok()) {
    line.Finish("slam cancelled");
    return ReportError(kCommand, local);
  }
  if (!received.problem.ok()) {
    line.Finish("slam cancelled");
    return ReportError(kCommand, received.problem);
  }
  if (!finished.ok()) {
    line.Finish("slam failed");
    return ReportError(kCommand, client->ToStatus(finished));
  }
  if (!received.done) {
    return ReportError(kCommand, absl::InternalError(
                                     "the daemon ended the Slam stream without its done message"));
  }

  const std::string where = absl::StrCat(" on map ", map_name, " at ", client->server());
  if (absl::Status s = WriteTumTrajectory(
          report.trajectory, received.trajectory,
          SlamTrajectoryHeader(dataset->name(), where, report.started_from_ground_truth));
      !s.ok()) {
    return ReportError(kCommand, s);
  }
  if (!timings.empty()) {  // after the trajectory: it is the result, the timings are extra
    std::string text = "# frame timestamp roundtrip_ms daemon_ms state [keyframe]\n";
    for (size_t k = 0; k < received.trajectory.size(); ++k) {
      absl::StrAppendFormat(&text, "%d %.6f %.3f %.3f %s\n", received.frame_index[k],
                            received.trajectory[k].timestamp, received.roundtrip_ms[k],
                            received.daemon_ms[k], received.state[k]);
    }
    if (absl::Status s = WriteFileAtomically(timings, text, "cannot write --timings"); !s.ok()) {
      return ReportError(kCommand, s);
    }
  }
  const pb::SlamMapping& mapping = received.mapping;
  std::optional<pb::MapInfo> saved;
  if (flags.GetSwitch("save")) {
    if (!mapping.finished()) {
      // Another stream still maps into it: the file has the keyframes mapped so far.
      std::cerr << absl::StrFormat(
          "plenox slam: other streams still map \"%s\" (%d in all): --save writes what is "
          "mapped so far\n",
          map_name, mapping.streams());
    }
    absl::StatusOr<pb::MapInfo> info = client->SaveMap(map_name);
    if (!info.ok()) return ReportError(kCommand, info.status());
    saved = *info;
  }

  report.processed = static_cast<int>(received.trajectory.size());
  report.dropped = received.dropped;
  report.keyframes = received.keyframes;
  report.ok = received.ok;
  report.degraded = received.degraded;
  report.lost = received.lost;
  report.relocalised = received.relocalised;
  report.waiting = received.waiting;
  report.ms_per_frame_median = Percentile(received.daemon_ms, 0.5);
  report.ms_per_frame_p95 = Percentile(received.daemon_ms, 0.95);
  report.wall_s = absl::ToDoubleSeconds(received.done_at - wall_start);
  report.mapping_iterations = static_cast<int>(mapping.iterations());
  report.map_mb = mapping.map_bytes() / 1e6;
  ScoreSlamTrajectory(*dataset, received.trajectory, *rpe_delta, &report);
  const double roundtrip_median = Percentile(received.roundtrip_ms, 0.5);
  const double roundtrip_p95 = Percentile(received.roundtrip_ms, 0.95);
  std::string summary = SlamSummaryText(
      report, absl::StrFormat(" [%s, map \"%s\"; round trip median %.1f ms, p95 %.1f ms]",
                              client->server(), map_name, roundtrip_median, roundtrip_p95));
  if (saved) {
    absl::StrAppendFormat(&summary,
                          "\nslam: saved \"%s\" in the daemon's data directory: version %d, "
                          "%d keyframes, %.1f MB",
                          map_name, saved->version(), saved->keyframes(),
                          saved->memory_bytes() / 1e6);
  }
  line.Finish(summary);
  JsonObject more;
  more.Add("roundtrip_ms_median", roundtrip_median)
      .Add("roundtrip_ms_p95", roundtrip_p95)
      .Add("roundtrip_ms_p99", Percentile(received.roundtrip_ms, 0.99))
      .Add("ms_per_frame_p99", Percentile(received.daemon_ms, 0.99))
      .Add("encoding", flags.GetString("encoding"))
      .AddBool("deterministic", options->slam.deterministic)
      .AddBool("realtime", options->realtime)
      .Add("map", map_name)
      .Add("server", client->server())
      .Add("map_keyframes", static_cast<int64_t>(mapping.keyframes()))
      .Add("map_version", static_cast<int64_t>(mapping.map_version()))
      .AddBool("mapping_finished", mapping.finished())
      .AddBool("saved", saved.has_value());
  PrintSlamResult(report, flags.GetSwitch("json"), more);
  return kExitOk;
}

}  // namespace plx::cli
