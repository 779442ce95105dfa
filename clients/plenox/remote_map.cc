// plenox --server HOST:PORT map: map a dataset's keyframes with their ground-truth poses into a
// map on the daemon (CreateMap, then one Integrate stream).
#include <chrono>
#include <cmath>
#include <iostream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/plenox/cli_common.h"
#include "clients/plenox/commands.h"
#include "clients/plenox/frame_stream.h"
#include "clients/plenox/map_flags.h"
#include "clients/plenox/remote_client.h"
#include "core/eval/map_metrics.h"
#include "core/mapping/mapping_session.h"
#include "proto/integrate_codec.h"

namespace plx::cli {
namespace {

constexpr char kCommand[] = "map";

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// What the progress line shows; written by the sender and the progress reader.
struct MappingState {
  int sent = 0;
  int total = 0;
  bool have_progress = false;
  pb::MappingProgress last;
  // From the last message that reported an optimisation step (the final one may not).
  double train_psnr = 0.0, train_depth_l1_m = 0.0;
};

std::string ProgressText(const std::string& name, int iterations_per_keyframe,
                         const MappingState& s) {
  std::string text = absl::StrFormat("mapping \"%s\": sent %d/%d keyframes", name, s.sent, s.total);
  if (s.have_progress) {
    const pb::MappingProgress& p = s.last;
    absl::StrAppendFormat(&text, ", integrated %d, iteration %d/%d", p.keyframes_integrated(),
                          p.iterations(), iterations_per_keyframe * p.keyframes_integrated());
    if (s.train_psnr > 0.0) {
      absl::StrAppendFormat(&text, ", PSNR %.2f dB, depth L1 %.2f cm", s.train_psnr,
                            100.0 * s.train_depth_l1_m);
    }
    absl::StrAppendFormat(&text, ", version %d, %.1f s", p.map_version(), p.elapsed_s());
  }
  return text;
}

FlagSet RemoteMapFlags() {
  FlagSet flags("plenox map",
                "With --server: maps every K-th frame of a dataset, with its ground-truth pose,\n"
                "into map N on the daemon. Creates N (or keeps mapping into it when it exists),\n"
                "streams the keyframes (colour PNG, 16-bit depth PNG) and waits until the\n"
                "daemon has spent the optimisation budget and published the final version.");
  AddDatasetFlags(flags);
  flags.Add("name", "N", "the map on the daemon (1-64 characters of [A-Za-z0-9_.-])", std::nullopt,
            true);
  AddEveryFlag(flags, "K");
  AddVoxelSizeFlag(flags, "voxel edge in metres of a new map (an existing map keeps its own)");
  flags.Add("iterations-per-keyframe", "N", "optimisation iterations per keyframe",
            absl::StrCat(kDefaultIterationsPerKeyframe));
  AddBatchAndMaxDepthFlags(flags);
  AddJsonAndQuietSwitches(flags);
  return flags;
}

// The keyframes of `dataset`, each with a ground-truth pose, or why there are none to map.
absl::StatusOr<std::vector<int>> MappableKeyframes(const RgbdDataset& dataset, int every) {
  std::vector<int> keyframes = KeyframeIndices(dataset.size(), every);
  if (keyframes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(dataset.name(), " has no frames to map"));
  }
  for (int index : keyframes) {
    if (!dataset.ground_truth(index)) {
      return absl::FailedPreconditionError(absl::StrCat(
          "frame ", index, " (t=", dataset.timestamp(index),
          ") has no ground-truth pose; mapping with known poses needs one for every keyframe"));
    }
  }
  return keyframes;
}

// Creates the map, or says that mapping goes into the existing one; whether it was created.
absl::StatusOr<bool> CreateOrReuseMap(RemoteClient& client, const std::string& name,
                                      double voxel_size, bool voxel_size_set) {
  absl::StatusOr<pb::MapInfo> info = client.CreateMap(name, static_cast<float>(voxel_size));
  if (info.ok()) return true;
  if (info.status().code() != absl::StatusCode::kAlreadyExists) return info.status();
  info = client.GetMap(name);
  if (!info.ok()) return info.status();
  std::cerr << absl::StrFormat(
      "plenox map: map \"%s\" already exists on %s (voxel size %g m, %d keyframes, version %d): "
      "mapping into it%s\n",
      name, client.server(), info->voxel_size(), info->keyframes(), info->version(),
      voxel_size_set ? "; --voxel-size does not apply to it" : "");
  return false;
}

// Streams the keyframes (the first with the options) on one Integrate stream, the daemon's
// progress on the progress line; the final state, or the error to report.
absl::StatusOr<MappingState> StreamKeyframes(RemoteClient& client, const RgbdDataset& dataset,
                                             const std::string& name,
                                             const std::vector<int>& keyframes,
                                             const pb::IntegrateOptions& options,
                                             ProgressLine& line) {
  std::unique_ptr<grpc::ClientContext> context = client.NewContext(absl::InfiniteDuration(), name);
  auto stream = client.stub().Integrate(context.get());
  // Progress keeps flowing while the sender waits for the daemon to take the next keyframe.
  FrameStream<pb::IntegrateRequest, pb::MappingProgress> frames(
      stream.get(), [&] { context->TryCancel(); }, FramePacing::FlowControl(), "progress");
  MappingState state;  // guarded by the stream's lock, as `line` is
  state.total = static_cast<int>(keyframes.size());
  bool done = false;
  const int iterations = static_cast<int>(options.iterations_per_keyframe());
  const FrameStreamResult result = frames.Run(state.total, {
      .request = [&](int k) -> absl::StatusOr<pb::IntegrateRequest> {
        absl::StatusOr<pb::Frame> frame =
            LoadFrameToProto(dataset, keyframes[k], /*with_pose=*/true);
        if (!frame.ok()) return frame.status();
        pb::IntegrateRequest request;
        if (k == 0) {
          request.set_map(name);
          *request.mutable_options() = options;
        }
        *request.mutable_frame() = std::move(*frame);
        return request;
      },
      .on_reply = [&](const pb::MappingProgress& progress, FrameRecord*) {
        state.last = progress;
        state.have_progress = true;
        if (progress.train_psnr() > 0.0) {
          state.train_psnr = progress.train_psnr();
          state.train_depth_l1_m = progress.train_depth_l1_m();
        }
        done = done || progress.done();
        line.Update(ProgressText(name, iterations, state));
        return absl::OkStatus();
      },
      .on_sent = [&](int) {
        ++state.sent;
        line.Update(ProgressText(name, iterations, state));
      },
  });
  if (!result.local.ok()) {
    line.Finish("mapping cancelled");
    return result.local;
  }
  if (!result.finished.ok()) {
    line.Finish("mapping failed");
    return client.ToStatus(result.finished);
  }
  if (!done) {
    return absl::InternalError("the daemon ended the Integrate stream before mapping was done");
  }
  return state;
}

// The summary line, then the result on stdout (with --json an object).
void PrintMapResult(const std::string& name, const std::string& server, bool created,
                    const MappingState& state, const pb::MapInfo& info, double seconds, bool json,
                    ProgressLine& line) {
  const pb::MappingProgress& last = state.last;
  const double map_mb = info.memory_bytes() / 1e6;
  // The training error is shown only when the daemon reported one.
  const bool have_error = state.train_psnr > 0.0;
  line.Finish(absl::StrFormat(
      "mapped %d keyframes into \"%s\" on %s: %d iterations%s, version %d, %.1f s",
      last.keyframes_integrated(), name, server, last.iterations(),
      have_error ? absl::StrFormat(", last batch PSNR %.2f dB, depth L1 %.2f cm", state.train_psnr,
                                   100.0 * state.train_depth_l1_m)
                 : "",
      last.map_version(), seconds));
  if (!json) {
    std::cout << absl::StrFormat(
        "mapped \"%s\" on %s: %d keyframes, %d bricks, %.1f MB, version %d, %.1f s\n", name,
        server, last.keyframes_integrated(), info.bricks(), map_mb, last.map_version(), seconds);
    return;
  }
  JsonObject out;
  out.Add("map", name)
      .Add("server", server)
      .Add("created", created ? 1 : 0)
      .Add("keyframes", static_cast<int64_t>(last.keyframes_integrated()))
      .Add("iterations", static_cast<int64_t>(last.iterations()))
      .Add("map_version", static_cast<int64_t>(last.map_version()))
      .Add("bricks", static_cast<int64_t>(info.bricks()))
      .Add("map_mb", map_mb)
      .Add("map_keyframes", static_cast<int64_t>(info.keyframes()))
      .Add("train_psnr", have_error ? state.train_psnr : std::nan(""))  // null: not reported
      .Add("train_depth_l1_m", have_error ? state.train_depth_l1_m : std::nan(""))
      .Add("seconds", seconds)
      .Add("seconds_server", last.elapsed_s());
  std::cout << out.str() << "\n";
}

}  // namespace

int RunRemoteMap(const RemoteOptions& remote, const std::vector<std::string>& args) {
  FlagSet flags = RemoteMapFlags();
  int exit_code = 0;
  if (!ParseFlagsOrExit(flags, args, &exit_code)) return exit_code;
  absl::StatusOr<int> every = EveryFromFlags(flags);
  if (!every.ok()) return ReportError(kCommand, every.status(), true);
  absl::StatusOr<double> voxel = VoxelSizeFromFlags(flags);
  if (!voxel.ok()) return ReportError(kCommand, voxel.status(), true);
  absl::StatusOr<int> iterations =
      flags.GetInt("iterations-per-keyframe", 1, kMaxIterationsPerKeyframe);
  if (!iterations.ok()) return ReportError(kCommand, iterations.status(), true);
  absl::StatusOr<int> batch = BatchFromFlags(flags);
  if (!batch.ok()) return ReportError(kCommand, batch.status(), true);
  absl::StatusOr<double> max_depth = MaxDepthFromFlags(flags);
  if (!max_depth.ok()) return ReportError(kCommand, max_depth.status(), true);
  absl::StatusOr<DatasetOptions> dataset_options = DatasetOptionsFromFlags(flags);
  if (!dataset_options.ok()) return ReportError(kCommand, dataset_options.status(), true);
  const std::string name = flags.GetString("name");
  MappingSessionOptions mapping;
  mapping.iterations_per_keyframe = *iterations;
  mapping.mapper.batch_size = *batch;
  mapping.mapper.allocation.max_depth = static_cast<float>(*max_depth);
  const pb::IntegrateOptions options = IntegrateOptionsToProto(mapping);

  std::unique_ptr<RemoteClient> client = ConnectOrReport(kCommand, remote, &exit_code);
  if (!client) return exit_code;
  // Everything local is checked before the daemon is asked to create anything.
  std::unique_ptr<RgbdDataset> dataset =
      OpenDatasetOrReport(kCommand, flags, *dataset_options, &exit_code);
  if (!dataset) return exit_code;
  absl::StatusOr<std::vector<int>> keyframes = MappableKeyframes(*dataset, *every);
  if (!keyframes.ok()) return ReportError(kCommand, keyframes.status());
  absl::StatusOr<bool> created =
      CreateOrReuseMap(*client, name, *voxel, flags.IsSet("voxel-size"));
  if (!created.ok()) return ReportError(kCommand, created.status());

  const auto start = std::chrono::steady_clock::now();
  ProgressLine line(!flags.GetSwitch("quiet"));
  absl::StatusOr<MappingState> state =
      StreamKeyframes(*client, *dataset, name, *keyframes, options, line);
  if (!state.ok()) return ReportError(kCommand, state.status());
  const double seconds = SecondsSince(start);
  absl::StatusOr<pb::MapInfo> info = client->GetMap(name);
  if (!info.ok()) return ReportError(kCommand, info.status());
  PrintMapResult(name, client->server(), *created, *state, *info, seconds,
                 flags.GetSwitch("json"), line);
  return kExitOk;
}

}  // namespace plx::cli
