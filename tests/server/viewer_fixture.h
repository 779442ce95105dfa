// Helpers of the web viewer's tests (HTTP requests: tests/loopback_http.h): a daemon with the
// viewer on, and a Slam stream kept open while a test looks at the viewer.
#pragma once

#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {

// A render query from frame `index`'s true pose, percent-encoded.
inline std::string RenderQuery(const std::string& map, int index, int width, int height,
                        const std::string& image) {
  const SE3 pose = GroundTruth(index);
  const Eigen::Vector3d& t = pose.translation();
  const Eigen::Quaterniond& q = pose.rotation();
  return absl::StrCat("/viewer/api/render?map=", map, "&pose=", t.x(), "%2C", t.y(), "%2C", t.z(),
                      "%2C", q.x(), "%2C", q.y(), "%2C", q.z(), "%2C", q.w(),
                      "&width=", width, "&height=", height, "&fov=50&image=", image);
}

// Options of a daemon with the viewer on a free HTTP port.
inline DaemonOptions ViewerDaemonOptions(const std::string& prefix) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir(prefix));
  o.metrics_port = 0;
  o.viewer = true;
  return o;
}

// Whether Debian's libjs-three is installed (the viewer needs it to start).
inline bool HaveThreeJs() {
  return std::filesystem::exists(std::string(web::kDefaultThreeJsDir) + "/three.min.js");
}

#define PLX_SKIP_WITHOUT_THREE_JS()                                                        \
  if (!HaveThreeJs()) {                                                                    \
    GTEST_SKIP() << "Debian's libjs-three is not installed (/usr/share/javascript/three); " \
                    "scripts/install_deps.sh installs it";                                 \
  }

// A lock-step Slam stream on the room's frames that stays open until Close: Advance(n) sends
// frames and waits for their updates, so a test can look at a live stream in between.
class OpenSlamStream {
 public:
  OpenSlamStream(pb::Plenoxd::Stub& stub, const std::string& map, const pb::SlamOptions& options,
                 const std::string& token = "") {
    Prepare(&context_, token, absl::Seconds(300));
    stream_ = stub.Slam(&context_);
    pb::SlamRequest first;
    first.set_map(map);
    *first.mutable_options() = options;
    *first.mutable_initial_pose() = ToProto(GroundTruth(0));
    ok_ = stream_->Write(first);
  }
  ~OpenSlamStream() { Close(); }

  // Sends the next `frames` room frames one at a time, each after the previous update arrived;
  // false when the stream broke. Past the room's last frame the camera walks back and forth
  // along its path (time stamps keep increasing), so a stream can go on as long as a test
  // needs.
  bool Advance(int frames) {
    for (int i = 0; i < frames && ok_; ++i, ++next_) {
      const int period = 2 * (kFrames - 1);
      const int phase = next_ % period;
      pb::SlamRequest request;
      *request.mutable_frame() = EncodeFrame(phase < kFrames ? phase : period - phase, false);
      request.mutable_frame()->set_timestamp(next_ / 30.0);
      pb::SlamUpdate update;
      ok_ = stream_->Write(request) && stream_->Read(&update);
      if (ok_) keyframes_ += update.keyframe();
    }
    return ok_;
  }

  int frames_sent() const { return next_; }
  int keyframes() const { return keyframes_; }

  // Half-closes and reads to the end; the stream's status.
  grpc::Status Close() {
    if (closed_) return status_;
    closed_ = true;
    stream_->WritesDone();
    pb::SlamUpdate update;
    while (stream_->Read(&update)) {
    }
    status_ = stream_->Finish();
    return status_;
  }

 private:
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<pb::SlamRequest, pb::SlamUpdate>> stream_;
  bool ok_ = false;
  bool closed_ = false;
  grpc::Status status_;
  int next_ = 0;
  int keyframes_ = 0;
};

// The room's Slam options of the tests: small and quick (as tests/server/slam_stream_test.cc).
inline pb::SlamOptions ViewerSlamOptions() {
  pb::SlamOptions o;
  o.set_voxel_size(kVoxel);
  *o.mutable_tracking() = FastTrackOptions();
  o.set_iterations_per_keyframe(30);
  o.set_rays_per_iteration(2048);
  return o;
}

}  // namespace plx::server::testing
