// Every Render's work is bounded: the view size is capped (--max-render-pixels), a render whose
// call was cancelled while it waited in a worker's queue never starts, and one cancelled while
// it runs (deadline, client gone) stops between row tiles. An 8192^2 render used to hold the
// only worker for 127 s after its client's 3 s deadline; a Track stream waited all that time.
#include <atomic>
#include <chrono>
#include <random>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "core/io/image_io.h"
#include "proto/render_size.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

pb::RenderRequest RenderOfSize(int width, int height) {
  pb::RenderRequest request = RenderRequestAt("room", 10);
  pb::Intrinsics* k = request.mutable_intrinsics();
  // The same field of view at the new size.
  k->set_fx(k->fx() * width / kWidth);
  k->set_fy(k->fy() * height / kHeight);
  k->set_cx(k->cx() * width / kWidth);
  k->set_cy(k->cy() * height / kHeight);
  k->set_width(static_cast<uint32_t>(width));
  k->set_height(static_cast<uint32_t>(height));
  return request;
}

// Holds a worker busy until released (or destroyed, so a failing test never leaves the
// daemon's drain waiting on it).
class BlockedWorker {
 public:
  explicit BlockedWorker(DeviceWorker& worker) {
    worker.Post(Priority::kInteractive, [this](Backend*, bool) {
      running_ = true;
      while (!released_) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    });
    WaitFor([this] { return running_.load(); });
  }
  ~BlockedWorker() { Release(); }
  void Release() { released_ = true; }

 private:
  std::atomic<bool> running_{false}, released_{false};
};

TEST(RenderBoundsTest, ViewsOverThePixelLimitAreRefusedNamingTheLimit) {
  EXPECT_GE(DaemonOptions().max_render_pixels, int64_t{3840} * 2160) << "the default covers 4K";
  DaemonOptions o = TestDaemonOptions("");
  o.max_render_pixels = 5000;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::RenderResponse response;
  const grpc::Status refused = Render(*d.stub, RenderOfSize(128, 96), &response);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(refused);
  EXPECT_EQ(refused.error_message(),
            "intrinsics: 128 x 96 = 12288 pixels, over the limit of 5000 pixels per render "
            "(--max-render-pixels)");
  const grpc::Status ok = Render(*d.stub, RenderOfSize(64, 48), &response);
  EXPECT_TRUE(ok.ok()) << Describe(ok);
  EXPECT_EQ(response.width(), 64u);
}

TEST(RenderBoundsTest, ARenderCancelledWhileQueuedNeverRuns) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"});
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  // Renders go to the CPU's interactive worker (the mapping worker takes none).
  DeviceWorker& worker = d.daemon->state().workers->Pick(Priority::kInteractive);
  BlockedWorker blocked(worker);

  grpc::ClientContext context;
  Prepare(&context, "", absl::Milliseconds(300));
  pb::RenderResponse response;
  const grpc::Status late = d.stub->Render(&context, RenderRequestAt("room", 10), &response);
  EXPECT_EQ(late.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << Describe(late);
  // The server's own timer for the same deadline fires independently of the client's.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  blocked.Release();
  ASSERT_TRUE(WaitFor([&] { return worker.queue_depth() == 0; }));
  EXPECT_EQ(d.daemon->state().metrics->renders.load(), 0) << "the abandoned render ran";

  const grpc::Status ok = Render(*d.stub, RenderRequestAt("room", 10), &response);
  EXPECT_TRUE(ok.ok()) << Describe(ok);
  EXPECT_EQ(d.daemon->state().metrics->renders.load(), 1);
}

// A 4096 x 3072 render takes about 28 s on two CPU threads; its client's deadline passes after
// 1 s. The worker stops within a row tile, so the next call on it is served at once instead of
// waiting for the whole view. Raw images (63 MB) fit the 64 MiB message limit; PNGs' worst case
// would not, and the render would be refused before it starts.
TEST(RenderBoundsTest, ARenderPastItsDeadlineStopsBetweenTiles) {
  DaemonOptions o = TestDaemonOptions("");
  o.max_render_pixels = 4096 * 3072;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  {
    grpc::ClientContext context;
    Prepare(&context, "", absl::Seconds(1));
    pb::RenderResponse response;
    pb::RenderRequest request = RenderOfSize(4096, 3072);
    request.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
    request.set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
    const grpc::Status late = d.stub->Render(&context, request, &response);
    EXPECT_EQ(late.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED) << Describe(late);
  }
  grpc::ClientContext context;
  Prepare(&context, "", absl::Seconds(5));
  pb::RenderResponse response;
  const grpc::Status next = d.stub->Render(&context, RenderRequestAt("room", 10), &response);
  EXPECT_TRUE(next.ok()) << Describe(next) << " (the worker was still rendering the large view)";
  EXPECT_EQ(d.daemon->state().metrics->renders.load(), 1);
}

// A response gRPC could not send used to be found out after the render (seconds of a worker for
// a large view); now the request's size and encodings refuse it first, naming the size and the
// flag.
TEST(RenderBoundsTest, ARenderWhoseAnswerCannotBeSentIsRefusedBeforeRendering) {
  DaemonOptions o = TestDaemonOptions("");
  o.max_message_bytes = 900 << 10;
  absl::StatusOr<std::unique_ptr<TestDaemon>> started = StartWithMaps({"room"}, o);
  ASSERT_TRUE(started.ok()) << started.status();
  TestDaemon& d = **started;
  pb::RenderRequest request = RenderOfSize(512, 384);  // raw: 512 * 384 * 5 = 960 KiB
  request.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
  request.set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
  pb::RenderResponse response;
  const grpc::Status refused = Render(*d.stub, request, &response);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(refused);
  EXPECT_EQ(refused.error_message(),
            absl::StrCat("intrinsics: a 512 x 384 render with RAW_RGB8 colour and RAW_U16 depth "
                         "may take up to ",
                         RenderResponseBytesBound(512, 384, pb::COLOR_ENCODING_RAW_RGB8,
                                                  pb::DEPTH_ENCODING_RAW_U16),
                         " bytes, over the largest message of ", 900 << 10,
                         " bytes (--max-message-mb)"));
  // Refused before the worker saw it: no render ran (the counter counts renders done).
  EXPECT_EQ(d.daemon->state().metrics->renders.load(), 0);
  EXPECT_EQ(d.daemon->state().workers->Pick(Priority::kInteractive).queue_depth(), 0);

  request = RenderOfSize(256, 192);
  request.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
  request.set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
  const grpc::Status ok = Render(*d.stub, request, &response);
  EXPECT_TRUE(ok.ok()) << Describe(ok);
  EXPECT_EQ(d.daemon->state().metrics->renders.load(), 1);
}

// The bound the refusal uses is a worst case: images of noise, which no codec compresses, still
// encode within it (PNG and PNG16; JPEG colour beside raw depth).
TEST(RenderBoundsTest, TheResponseBoundHoldsForIncompressibleImages) {
  constexpr int kW = 301, kH = 203;  // not multiples of the codecs' blocks
  std::mt19937 random(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  ColorImage color(kW, kH, 3);
  for (float& c : color.data) c = unit(random);
  DepthImage depth(kW, kH, 1);
  for (float& z : depth.data) z = 65.0f * unit(random);
  absl::StatusOr<std::string> png = EncodeColorImage(color, ".png");
  absl::StatusOr<std::string> jpeg = EncodeColorImage(color, ".jpg");
  absl::StatusOr<std::string> png16 = EncodeDepthImage(depth, 1000.0);
  ASSERT_TRUE(png.ok() && jpeg.ok() && png16.ok());
  const int64_t pngs = static_cast<int64_t>(png->size() + png16->size());
  EXPECT_LE(pngs,
            RenderResponseBytesBound(kW, kH, pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_PNG16));
  EXPECT_LE(static_cast<int64_t>(jpeg->size()) + 2 * kW * kH,
            RenderResponseBytesBound(kW, kH, pb::COLOR_ENCODING_JPEG, pb::DEPTH_ENCODING_RAW_U16));
  // Noise is the worst case in earnest: the PNGs are not much smaller than the raw images.
  EXPECT_GT(pngs, 4 * kW * kH);
}

}  // namespace
}  // namespace plx::server::testing
