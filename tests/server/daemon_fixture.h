// Shared helpers for the daemon's integration tests: an in-process Daemon on a free loopback
// port with a temporary data directory, channels with 64 MiB message limits, synthetic RGB-D
// frames encoded as the wire's pb::Frame (PNG colour, PNG16 depth), a small map built through
// the Integrate stream, a raw HTTP GET for /metrics and a TCP proxy whose connections can be cut
// (a client that vanishes without closing its streams).
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "core/datasets/dataset.h"
#include "core/io/image_io.h"
#include "core/synthetic/synthetic_sequence.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "plenoxd/v1/plenoxd.grpc.pb.h"
#include "proto/pose_codec.h"
#include "server/daemon.h"
#include "tests/loopback_http.h"
#include "tests/test_util.h"

namespace plx::server::testing {

namespace pb = ::plenoxd::v1;
using HealthStub = ::grpc::health::v1::Health::Stub;

// Every test RPC gets a deadline, so a daemon that hangs fails the test instead of the run.
inline constexpr absl::Duration kRpcTimeout = absl::Seconds(60);
inline constexpr int kMaxMessageBytes = 64 << 20;

// The synthetic room at a size that maps and tracks in well under a second per keyframe.
inline constexpr int kWidth = 128;
inline constexpr int kHeight = 96;
inline constexpr int kFrames = 30;
inline constexpr float kVoxel = 0.04f;
inline const std::vector<int> kKeyframes = {0, 10, 20};

// Options of the test maps' Integrate streams: few iterations, enough for centimetre tracking.
inline pb::IntegrateOptions SmallIntegrateOptions() {
  pb::IntegrateOptions o;
  o.set_iterations_per_keyframe(30);
  o.set_rays_per_iteration(2048);
  return o;
}

// Tracking options of the tests: fewer rays than the default, still millimetre-accurate here.
inline pb::TrackOptions FastTrackOptions(uint32_t rays = 1024) {
  pb::TrackOptions o;
  o.set_rays(rays);
  return o;
}

// ---------------------------------------------------------------------------------------------
// Data.

inline const InMemoryDataset& Room() {
  static const InMemoryDataset* dataset = [] {
    SyntheticOptions o;
    o.width = kWidth;
    o.height = kHeight;
    o.num_frames = kFrames;
    absl::StatusOr<InMemoryDataset> d = GenerateSyntheticSequence(o);
    if (!d.ok()) {
      ADD_FAILURE() << "GenerateSyntheticSequence: " << d.status();
      return new InMemoryDataset("empty", CameraCalibration(), {});
    }
    return new InMemoryDataset(std::move(*d));
  }();
  return *dataset;
}

inline SE3 GroundTruth(int index) { return *Room().frames()[index].ground_truth; }

// The daemon's own pose codec (proto/pose_codec.h), as the CLI uses it.
inline pb::Pose ToProto(const SE3& pose) {
  pb::Pose p;
  PoseToProto(pose, &p);
  return p;
}

// A pose the daemon sent; a malformed one fails the test and reads as the identity.
inline SE3 FromProto(const pb::Pose& p) {
  absl::StatusOr<SE3> pose = PoseFromProto(p, "pose");
  EXPECT_TRUE(pose.ok()) << pose.status();
  return pose.ok() ? *pose : SE3();
}

inline pb::Intrinsics RoomIntrinsics() {
  const CameraCalibration& c = Room().calibration();
  pb::Intrinsics k;
  k.set_fx(c.pinhole.fx);
  k.set_fy(c.pinhole.fy);
  k.set_cx(c.pinhole.cx);
  k.set_cy(c.pinhole.cy);
  k.set_width(static_cast<uint32_t>(c.pinhole.width));
  k.set_height(static_cast<uint32_t>(c.pinhole.height));
  k.set_depth_scale(c.depth_scale);
  return k;
}

// Frame `index` of the room as the wire carries it: PNG colour, PNG16 depth at the sequence's
// depth scale; with its ground-truth pose when `with_pose` (Integrate), without for Track.
// Encoded once per index and cached (PNG encoding is the slow part of the helpers).
inline pb::Frame EncodeFrame(int index, bool with_pose) {
  static std::mutex mutex;
  static std::vector<pb::Frame> cache;
  pb::Frame frame;
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (cache.empty()) cache.resize(Room().frames().size());
    pb::Frame& cached = cache.at(static_cast<size_t>(index));
    if (cached.color().empty()) {
      const RgbdFrame& f = Room().frames()[index];
      absl::StatusOr<std::string> color = EncodeColorImage(f.color, ".png");
      absl::StatusOr<std::string> depth =
          EncodeDepthImage(f.depth, Room().calibration().depth_scale);
      EXPECT_TRUE(color.ok()) << color.status();
      EXPECT_TRUE(depth.ok()) << depth.status();
      if (color.ok() && depth.ok()) {
        cached.set_camera_id("synthetic");
        cached.set_timestamp(f.timestamp);
        *cached.mutable_intrinsics() = RoomIntrinsics();
        cached.set_color(*color);
        cached.set_color_encoding(pb::COLOR_ENCODING_PNG);
        cached.set_depth(*depth);
        cached.set_depth_encoding(pb::DEPTH_ENCODING_PNG16);
      }
    }
    frame = cached;
  }
  if (with_pose) *frame.mutable_pose() = ToProto(GroundTruth(index));
  return frame;
}

// ---------------------------------------------------------------------------------------------
// Calls.

inline void Prepare(grpc::ClientContext* context, const std::string& token = "",
                    absl::Duration timeout = kRpcTimeout) {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(absl::ToInt64Milliseconds(timeout)));
  if (!token.empty()) context->AddMetadata("authorization", "Bearer " + token);
}

inline std::string Describe(const grpc::Status& s) {
  return absl::StrCat("code ", static_cast<int>(s.error_code()), ": ", s.error_message());
}

// A channel of its own (local subchannel pool), with 64 MiB messages both ways.
inline std::shared_ptr<grpc::Channel> MakeChannel(int port) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(absl::StrCat("127.0.0.1:", port),
                                   grpc::InsecureChannelCredentials(), args);
}

// Polls `condition` every 10 ms until it holds or `timeout` passes.
inline bool WaitFor(const std::function<bool()>& condition,
                    absl::Duration timeout = absl::Seconds(20)) {
  const absl::Time end = absl::Now() + timeout;
  while (!condition()) {
    if (absl::Now() > end) return false;
    absl::SleepFor(absl::Milliseconds(10));
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// The daemon.

inline DaemonOptions TestDaemonOptions(const std::string& data_dir) {
  DaemonOptions o;
  o.listen = "127.0.0.1:0";
  o.data_dir = data_dir;
  o.threads = 2;
  return o;
}

// A running daemon and a client for it. Drains (1 s grace) when destroyed, before its channel
// goes away.
struct TestDaemon {
  std::string data_dir;
  std::string token;
  std::unique_ptr<Daemon> daemon;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<pb::Plenoxd::Stub> stub;
  std::unique_ptr<HealthStub> health;

  ~TestDaemon() {
    if (daemon) daemon->Drain(absl::Seconds(1)).IgnoreError();
  }
};

inline absl::StatusOr<std::unique_ptr<TestDaemon>> StartTestDaemon(const DaemonOptions& options) {
  absl::StatusOr<std::unique_ptr<Daemon>> daemon = Daemon::Start(options);
  if (!daemon.ok()) return daemon.status();
  auto t = std::make_unique<TestDaemon>();
  t->data_dir = options.data_dir;
  t->token = options.auth_token;
  t->daemon = std::move(*daemon);
  t->channel = MakeChannel(t->daemon->port());
  t->stub = pb::Plenoxd::NewStub(t->channel);
  t->health = ::grpc::health::v1::Health::NewStub(t->channel);
  return t;
}

// grpc.health.v1.Health/Check for the whole server (service ""): the serving status, or -1 when
// the call itself failed (`status` then says why).
inline int HealthCheck(HealthStub& health, grpc::Status* status = nullptr) {
  grpc::ClientContext context;
  Prepare(&context, "", absl::Seconds(10));
  ::grpc::health::v1::HealthCheckRequest request;
  ::grpc::health::v1::HealthCheckResponse response;
  const grpc::Status s = health.Check(&context, request, &response);
  if (status != nullptr) *status = s;
  return s.ok() ? static_cast<int>(response.status()) : -1;
}
inline constexpr int kServing = ::grpc::health::v1::HealthCheckResponse::SERVING;

// ---------------------------------------------------------------------------------------------
// Unary helpers; `token` is sent as a bearer token when not empty.

inline grpc::Status CreateMap(pb::Plenoxd::Stub& stub, const std::string& name,
                              float voxel = kVoxel, pb::MapInfo* info = nullptr,
                              const std::string& token = "") {
  grpc::ClientContext context;
  Prepare(&context, token);
  pb::CreateMapRequest request;
  request.set_name(name);
  request.set_voxel_size(voxel);
  pb::MapInfo response;
  const grpc::Status s = stub.CreateMap(&context, request, &response);
  if (info != nullptr) *info = response;
  return s;
}

inline grpc::Status GetMap(pb::Plenoxd::Stub& stub, const std::string& name, pb::MapInfo* info,
                           const std::string& token = "") {
  grpc::ClientContext context;
  Prepare(&context, token);
  pb::GetMapRequest request;
  request.set_name(name);
  return stub.GetMap(&context, request, info);
}

inline grpc::Status SaveMap(pb::Plenoxd::Stub& stub, const std::string& name,
                            pb::MapInfo* info = nullptr, const std::string& token = "") {
  grpc::ClientContext context;
  Prepare(&context, token);
  pb::SaveMapRequest request;
  request.set_name(name);
  pb::MapInfo response;
  const grpc::Status s = stub.SaveMap(&context, request, &response);
  if (info != nullptr) *info = response;
  return s;
}

inline pb::RenderRequest RenderRequestAt(const std::string& map, int frame_index) {
  pb::RenderRequest request;
  request.set_map(map);
  *request.mutable_pose() = ToProto(GroundTruth(frame_index));
  *request.mutable_intrinsics() = RoomIntrinsics();
  request.set_color_encoding(pb::COLOR_ENCODING_PNG);
  request.set_depth_encoding(pb::DEPTH_ENCODING_PNG16);
  return request;
}

inline grpc::Status Render(pb::Plenoxd::Stub& stub, const pb::RenderRequest& request,
                           pb::RenderResponse* response, const std::string& token = "") {
  grpc::ClientContext context;
  Prepare(&context, token);
  return stub.Render(&context, request, response);
}

// The whole Export stream concatenated; `chunks` counts the messages.
inline grpc::Status Export(pb::Plenoxd::Stub& stub, const pb::ExportRequest& request,
                           std::string* bytes, int* chunks = nullptr,
                           const std::string& token = "") {
  grpc::ClientContext context;
  Prepare(&context, token);
  std::unique_ptr<grpc::ClientReader<pb::ExportChunk>> reader = stub.Export(&context, request);
  pb::ExportChunk chunk;
  int n = 0;
  bool last_seen = false;
  while (reader->Read(&chunk)) {
    EXPECT_FALSE(last_seen) << "a chunk after the one marked last";
    EXPECT_EQ(chunk.offset(), bytes->size()) << "chunk " << n;
    bytes->append(chunk.data());
    last_seen = chunk.last();
    ++n;
  }
  if (chunks != nullptr) *chunks = n;
  const grpc::Status s = reader->Finish();
  if (s.ok()) {
    EXPECT_TRUE(last_seen) << "no chunk marked last";
  }
  return s;
}

// The same for the point cloud of `map` with the default threshold.
inline grpc::Status Export(pb::Plenoxd::Stub& stub, const std::string& map, std::string* bytes,
                           int* chunks = nullptr, const std::string& token = "") {
  pb::ExportRequest request;
  request.set_map(map);
  return Export(stub, request, bytes, chunks, token);
}

// ---------------------------------------------------------------------------------------------
// Streams.

struct IntegrateResult {
  grpc::Status status;
  std::vector<pb::MappingProgress> progress;
  std::string job_id;
};

// One Integrate stream: the first message names the map and carries `options`, then one
// keyframe (with its ground-truth pose) per message; half-closes and reads to the end.
inline IntegrateResult Integrate(pb::Plenoxd::Stub& stub, const std::string& map,
                                 const std::vector<int>& keyframes,
                                 const pb::IntegrateOptions& options = SmallIntegrateOptions(),
                                 const std::string& token = "") {
  IntegrateResult result;
  grpc::ClientContext context;
  Prepare(&context, token);
  auto stream = stub.Integrate(&context);
  pb::IntegrateRequest first;
  first.set_map(map);
  *first.mutable_options() = options;
  bool writing = stream->Write(first);
  for (int index : keyframes) {
    if (!writing) break;
    pb::IntegrateRequest request;
    *request.mutable_frame() = EncodeFrame(index, true);
    writing = stream->Write(request);
  }
  stream->WritesDone();
  pb::MappingProgress progress;
  while (stream->Read(&progress)) {
    if (result.job_id.empty()) result.job_id = progress.job_id();
    result.progress.push_back(progress);
  }
  result.status = stream->Finish();
  return result;
}

// CreateMap + Integrate of the room's three keyframes; fails the test on any error.
inline void BuildSmallMap(pb::Plenoxd::Stub& stub, const std::string& name) {
  const grpc::Status created = CreateMap(stub, name);
  ASSERT_TRUE(created.ok()) << Describe(created);
  const IntegrateResult r = Integrate(stub, name, kKeyframes);
  ASSERT_TRUE(r.status.ok()) << Describe(r.status);
  ASSERT_FALSE(r.progress.empty());
  ASSERT_TRUE(r.progress.back().done());
  ASSERT_EQ(r.progress.back().keyframes_integrated(), kKeyframes.size());
}

// The path of a saved map of the room's keyframes, built once per process (a daemon is started
// for it, the map integrated and saved). Tests that only need a map to read link it into their
// data directory as "<name>.plx" before starting their daemon, which loads it.
inline const std::string& CachedRoomMapFile() {
  static const std::string* path = [] {
    auto* out = new std::string();
    const std::string dir = plx::testing::MakeTempDir("plx_srv_cache");
    absl::StatusOr<std::unique_ptr<TestDaemon>> d = StartTestDaemon(TestDaemonOptions(dir));
    if (!d.ok()) {
      ADD_FAILURE() << "daemon for the cached map: " << d.status();
      return out;
    }
    BuildSmallMap(*(*d)->stub, "room");
    const grpc::Status saved = SaveMap(*(*d)->stub, "room");
    EXPECT_TRUE(saved.ok()) << Describe(saved);
    (*d)->daemon->Drain(absl::Seconds(1)).IgnoreError();
    const std::filesystem::path file = std::filesystem::path(dir) / "room.plx";
    if (std::filesystem::exists(file)) {
      *out = file.string();
    } else {
      ADD_FAILURE() << "no room.plx written";
    }
    return out;
  }();
  return *path;
}

// Puts the cached room map into `data_dir` as each of `names` (hard links: the file is ~50 MB).
inline void SeedMaps(const std::string& data_dir, const std::vector<std::string>& names) {
  const std::string& source = CachedRoomMapFile();
  ASSERT_FALSE(source.empty());
  for (const std::string& name : names) {
    const std::filesystem::path target = std::filesystem::path(data_dir) / (name + ".plx");
    std::error_code ec;
    std::filesystem::create_hard_link(source, target, ec);
    if (ec) std::filesystem::copy_file(source, target, ec);
    ASSERT_FALSE(ec) << target << ": " << ec.message();
  }
}

// A fresh daemon whose data directory holds the cached room map under each of `names`.
inline absl::StatusOr<std::unique_ptr<TestDaemon>> StartWithMaps(
    const std::vector<std::string>& names, DaemonOptions options = TestDaemonOptions("")) {
  if (options.data_dir.empty()) options.data_dir = plx::testing::MakeTempDir("plx_srv");
  SeedMaps(options.data_dir, names);
  return StartTestDaemon(options);
}

struct TrackResult {
  grpc::Status status;
  std::vector<pb::PoseEstimate> estimates;
};

// A lock-step Track stream over `frames`: the first message names the map and starts at the
// ground truth of frames[0] (initial_pose); each frame is written only after the previous
// estimate arrived. `between` runs after each estimate (pacing, checks).
inline TrackResult TrackLockStep(pb::Plenoxd::Stub& stub, const std::string& map,
                                 const std::vector<int>& frames,
                                 const pb::TrackOptions& options = FastTrackOptions(),
                                 const std::string& token = "",
                                 const std::function<void(int)>& between = nullptr) {
  TrackResult result;
  grpc::ClientContext context;
  Prepare(&context, token);
  auto stream = stub.Track(&context);
  for (size_t i = 0; i < frames.size(); ++i) {
    pb::TrackRequest request;
    if (i == 0) {
      request.set_map(map);
      *request.mutable_options() = options;
      *request.mutable_initial_pose() = ToProto(GroundTruth(frames[0]));
    }
    *request.mutable_frame() = EncodeFrame(frames[i], false);
    // Timestamps increase even when a frame index repeats (ping-pong sequences).
    request.mutable_frame()->set_timestamp(static_cast<double>(i) / 30.0);
    if (!stream->Write(request)) break;
    pb::PoseEstimate estimate;
    if (!stream->Read(&estimate)) break;
    result.estimates.push_back(estimate);
    if (between) between(static_cast<int>(i));
  }
  stream->WritesDone();
  pb::PoseEstimate extra;
  while (stream->Read(&extra)) result.estimates.push_back(extra);
  result.status = stream->Finish();
  return result;
}

// Root mean square of the translation errors of `estimates` against the ground truth of
// `frames` (same order, no alignment: the stream started at the true pose).
inline double TranslationRmse(const std::vector<pb::PoseEstimate>& estimates,
                              const std::vector<int>& frames) {
  double sum = 0.0;
  const size_t n = std::min(estimates.size(), frames.size());
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d =
        FromProto(estimates[i].pose()).translation() - GroundTruth(frames[i]).translation();
    sum += d.squaredNorm();
  }
  return n == 0 ? INFINITY : std::sqrt(sum / n);
}

// ---------------------------------------------------------------------------------------------
// HTTP and TCP.

// Raw HTTP over loopback: tests/loopback_http.h.
using plx::testing::ConnectLoopback;
using plx::testing::ConnectLoopbackFrom;
using plx::testing::HttpAnswer;
using plx::testing::HttpExchange;
using plx::testing::HttpGet;
using plx::testing::HttpGetAnswer;
using plx::testing::ParseHttpAnswer;
using plx::testing::SendAll;
using plx::testing::Sockets;

// A loopback TCP proxy to 127.0.0.1:`target_port`. CutAll() drops every connection at once
// (both sockets closed): to the daemon, its client has vanished without a word.
class TcpProxy {
 public:
  explicit TcpProxy(int target_port) : target_port_(target_port) {
    listen_fd_ = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = 0;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (listen_fd_ < 0 || bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
        listen(listen_fd_, 8) != 0) {
      ADD_FAILURE() << "proxy: cannot listen: " << std::strerror(errno);
      return;
    }
    socklen_t len = sizeof(addr);
    getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    thread_ = std::thread([this] { Loop(); });
  }
  ~TcpProxy() {
    stopping_ = true;
    if (thread_.joinable()) thread_.join();
    CloseAllLocked();
    if (listen_fd_ >= 0) close(listen_fd_);
  }

  int port() const { return port_; }
  int connections() {
    std::lock_guard<std::mutex> lock(mutex_);
    return accepted_;
  }
  void CutAll() {
    std::lock_guard<std::mutex> lock(mutex_);
    CloseAllLocked();
  }

 private:
  void CloseAllLocked() {
    for (auto& [a, b] : pairs_) {
      // RST rather than FIN: the peer learns at once that the connection is gone.
      linger hard{1, 0};
      setsockopt(a, SOL_SOCKET, SO_LINGER, &hard, sizeof(hard));
      setsockopt(b, SOL_SOCKET, SO_LINGER, &hard, sizeof(hard));
      close(a);
      close(b);
    }
    pairs_.clear();
  }

  static bool Forward(int from, int to) {
    char buffer[65536];
    const ssize_t n = recv(from, buffer, sizeof(buffer), 0);
    if (n <= 0) return false;
    ssize_t sent = 0;
    while (sent < n) {
      const ssize_t k = send(to, buffer + sent, static_cast<size_t>(n - sent), MSG_NOSIGNAL);
      if (k <= 0) return false;
      sent += k;
    }
    return true;
  }

  void Loop() {
    while (!stopping_) {
      std::vector<pollfd> fds;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        fds.push_back({listen_fd_, POLLIN, 0});
        for (const auto& [a, b] : pairs_) {
          fds.push_back({a, POLLIN, 0});
          fds.push_back({b, POLLIN, 0});
        }
      }
      if (poll(fds.data(), fds.size(), 20) <= 0) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      if (fds[0].revents & POLLIN) {
        const int client = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
        if (client >= 0) {
          const int upstream = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
          sockaddr_in addr{};
          addr.sin_family = AF_INET;
          addr.sin_port = htons(static_cast<uint16_t>(target_port_));
          addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
          if (upstream >= 0 &&
              connect(upstream, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) {
            pairs_.emplace_back(client, upstream);
            ++accepted_;
          } else {
            close(client);
            if (upstream >= 0) close(upstream);
          }
        }
      }
      // Only pairs that were polled (CutAll may have closed them meanwhile: then skip).
      for (size_t i = 1; i + 1 < fds.size(); i += 2) {
        const int a = fds[i].fd, b = fds[i + 1].fd;
        auto it = std::find(pairs_.begin(), pairs_.end(), std::make_pair(a, b));
        if (it == pairs_.end()) continue;
        bool alive = true;
        if (fds[i].revents & (POLLIN | POLLHUP | POLLERR)) alive = Forward(a, b);
        if (alive && (fds[i + 1].revents & (POLLIN | POLLHUP | POLLERR))) alive = Forward(b, a);
        if (!alive) {
          close(a);
          close(b);
          pairs_.erase(it);
        }
      }
    }
  }

  int target_port_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::vector<std::pair<int, int>> pairs_;
  int accepted_ = 0;
  std::thread thread_;
};

}  // namespace plx::server::testing
