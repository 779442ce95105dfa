// Bad input on every path: each call is answered with the right code and a message naming the
// offending field, and afterwards the daemon is healthy, no lease or stream slot is held, and
// the bystander map "b" serves exactly what it served before.
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tests/image_bytes.h"
#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

constexpr absl::Duration kBadCallTimeout = absl::Seconds(20);

// Writes `requests` (stopping at the first failed write), half-closes, reads to the end.
template <typename Request, typename Response, typename Stream>
grpc::Status Drive(Stream& stream, const std::vector<Request>& requests, int* responses) {
  for (const Request& r : requests) {
    if (!stream->Write(r)) break;
  }
  stream->WritesDone();
  Response response;
  int n = 0;
  while (stream->Read(&response)) ++n;
  if (responses != nullptr) *responses = n;
  return stream->Finish();
}

grpc::Status TrackStatus(pb::Plenoxd::Stub& stub, const std::vector<pb::TrackRequest>& requests,
                         int* estimates = nullptr) {
  grpc::ClientContext context;
  Prepare(&context, "", kBadCallTimeout);
  auto stream = stub.Track(&context);
  return Drive<pb::TrackRequest, pb::PoseEstimate>(stream, requests, estimates);
}

grpc::Status IntegrateStatus(pb::Plenoxd::Stub& stub,
                             const std::vector<pb::IntegrateRequest>& requests) {
  grpc::ClientContext context;
  Prepare(&context, "", kBadCallTimeout);
  auto stream = stub.Integrate(&context);
  return Drive<pb::IntegrateRequest, pb::MappingProgress>(stream, requests, nullptr);
}

pb::TrackRequest TrackStart(const std::string& map, const pb::Frame& frame) {
  pb::TrackRequest r;
  r.set_map(map);
  *r.mutable_options() = FastTrackOptions();
  *r.mutable_initial_pose() = ToProto(GroundTruth(0));
  *r.mutable_frame() = frame;
  return r;
}

pb::IntegrateRequest IntegrateStart(const std::string& map, const pb::Frame* frame) {
  pb::IntegrateRequest r;
  r.set_map(map);
  *r.mutable_options() = SmallIntegrateOptions();
  if (frame != nullptr) *r.mutable_frame() = *frame;
  return r;
}

pb::IntegrateRequest IntegrateFrame(const pb::Frame& frame) {
  pb::IntegrateRequest r;
  *r.mutable_frame() = frame;
  return r;
}

std::string DepthPngOfSize(int width, int height) {
  absl::StatusOr<std::string> png = EncodeDepthImage(DepthImage(width, height, 1, 1.5f), 5000.0);
  EXPECT_TRUE(png.ok()) << png.status();
  return png.ok() ? *png : "";
}

std::string ColorPngOfSize(int width, int height) {
  absl::StatusOr<std::string> png = EncodeColorImage(ColorImage(width, height, 3, 0.5f), ".png");
  EXPECT_TRUE(png.ok()) << png.status();
  return png.ok() ? *png : "";
}

pb::Pose NanPose() {
  pb::Pose p = ToProto(GroundTruth(0));
  p.set_tx(std::nan(""));
  return p;
}

pb::Pose ZeroQuaternionPose() {
  pb::Pose p = ToProto(GroundTruth(0));
  p.set_qx(0);
  p.set_qy(0);
  p.set_qz(0);
  p.set_qw(0);
  return p;
}

#define EXPECT_CODE_AND_FIELD(status, code, field)                                      \
  do {                                                                                 \
    const grpc::Status s_ = (status);                                                  \
    EXPECT_EQ(s_.error_code(), grpc::StatusCode::code) << Describe(s_);                \
    EXPECT_NE(s_.error_message().find(field), std::string::npos)                       \
        << "the message should name \"" << (field) << "\": " << s_.error_message();    \
  } while (0)

class BadInputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    absl::StatusOr<std::unique_ptr<TestDaemon>> d = StartWithMaps({"a", "b"});
    ASSERT_TRUE(d.ok()) << d.status();
    d_ = std::move(*d);
    ASSERT_TRUE(Render(stub(), RenderRequestAt("b", 10), &b_before_).ok());
    ASSERT_TRUE(GetMap(stub(), "a", &a_before_).ok());
  }

  // After every test: healthy, nothing held, "b" unchanged, "a" still renders.
  void TearDown() override {
    if (!d_) return;
    EXPECT_EQ(HealthCheck(*d_->health), kServing);
    EXPECT_TRUE(WaitFor([&] { return d_->daemon->state().metrics->active_streams.load() == 0; }))
        << "stream slots leaked: " << d_->daemon->state().metrics->active_streams.load();
    for (const char* name : {"a", "b"}) {
      EXPECT_TRUE(WaitFor([&] {
        pb::MapInfo info;
        return GetMap(stub(), name, &info).ok() && !info.mapping();
      })) << "map " << name << " still has a writer";
    }
    pb::RenderResponse b_after;
    ASSERT_TRUE(Render(stub(), RenderRequestAt("b", 10), &b_after).ok());
    EXPECT_EQ(b_after.map_version(), b_before_.map_version());
    EXPECT_EQ(b_after.color(), b_before_.color());
    EXPECT_EQ(b_after.depth(), b_before_.depth());
    pb::RenderResponse a_after;
    EXPECT_TRUE(Render(stub(), RenderRequestAt("a", 10), &a_after).ok());
    EXPECT_GT(a_after.coverage(), 0.9);
  }

  pb::Plenoxd::Stub& stub() { return *d_->stub; }

  std::unique_ptr<TestDaemon> d_;
  pb::RenderResponse b_before_;
  pb::MapInfo a_before_;
};

TEST_F(BadInputTest, TrackUndecodableColourNamesFrameColor) {
  pb::Frame f = EncodeFrame(0, false);
  f.set_color("definitely not a PNG");
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", f)}), INVALID_ARGUMENT, "frame.color");
}

TEST_F(BadInputTest, TrackBadFrameMidStreamEndsTheStream) {
  std::vector<pb::TrackRequest> requests = {TrackStart("a", EncodeFrame(0, false))};
  pb::TrackRequest good, bad;
  *good.mutable_frame() = EncodeFrame(1, false);
  *bad.mutable_frame() = EncodeFrame(2, false);
  bad.mutable_frame()->set_color(std::string(500, '\x7f'));
  requests.push_back(good);
  requests.push_back(bad);
  int estimates = 0;
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), requests, &estimates), INVALID_ARGUMENT, "frame.color");
  EXPECT_LE(estimates, 2);
}

TEST_F(BadInputTest, TrackImageSizesMustMatchTheIntrinsics) {
  pb::Frame depth = EncodeFrame(0, false);
  depth.set_depth(DepthPngOfSize(kWidth / 2, kHeight / 2));
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", depth)}), INVALID_ARGUMENT,
                        "frame.depth");
  pb::Frame color = EncodeFrame(0, false);
  color.set_color(ColorPngOfSize(kWidth + 1, kHeight));
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", color)}), INVALID_ARGUMENT,
                        "frame.color");
  pb::Frame raw = EncodeFrame(0, false);
  raw.set_color_encoding(pb::COLOR_ENCODING_RAW_RGB8);
  raw.set_color(std::string(kWidth * kHeight * 3 - 1, '\0'));
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", raw)}), INVALID_ARGUMENT,
                        "frame.color");
  pb::Frame raw_depth = EncodeFrame(0, false);
  raw_depth.set_depth_encoding(pb::DEPTH_ENCODING_RAW_U16);
  raw_depth.set_depth(std::string(kWidth * kHeight, '\0'));
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", raw_depth)}), INVALID_ARGUMENT,
                        "frame.depth");
}

// Decompression bombs: a PNG of a few dozen bytes declaring 16384x16384 is refused from its
// header, before any image of the call is decoded, whether it disagrees with the intrinsics
// (INVALID_ARGUMENT) or agrees with intrinsics over the pixel limit (RESOURCE_EXHAUSTED).
TEST_F(BadInputTest, ImageBombsAreRefusedBeforeDecoding) {
  const std::string bomb = plx::testing::PngDeclaring(16384, 16384);
  const std::string depth_bomb = plx::testing::PngDeclaring(16384, 16384, 0, 16);
  const int64_t decoded_before = ImageBuffersDecoded();
  const absl::Time start = absl::Now();

  pb::Frame colour = EncodeFrame(0, false);
  colour.set_color(bomb);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", colour)}), INVALID_ARGUMENT,
                        "frame.color: image is 16384x16384 (PNG header), the intrinsics say");
  pb::Frame depth = EncodeFrame(0, false);
  depth.set_depth(depth_bomb);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", depth)}), INVALID_ARGUMENT,
                        "frame.depth: image is 16384x16384");
  pb::Frame keyframe = EncodeFrame(5, true);
  keyframe.set_color(bomb);
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &keyframe)}),
                        INVALID_ARGUMENT, "frame[0].color: image is 16384x16384");
  // The intrinsics agree with the bomb: 268 million pixels, over the default limit (4K UHD).
  pb::Frame matching = EncodeFrame(0, false);
  matching.mutable_intrinsics()->set_width(16384);
  matching.mutable_intrinsics()->set_height(16384);
  matching.set_color(bomb);
  matching.set_depth(depth_bomb);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", matching)}), RESOURCE_EXHAUSTED,
                        "frame.intrinsics: a 16384x16384 frame is over the limit of 8294400");
  pb::Frame matching_keyframe = matching;
  *matching_keyframe.mutable_pose() = ToProto(GroundTruth(5));
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &matching_keyframe)}),
                        RESOURCE_EXHAUSTED, "--max-frame-pixels");

  EXPECT_EQ(ImageBuffersDecoded(), decoded_before) << "an image of a refused frame was decoded";
  EXPECT_LT(absl::Now() - start, absl::Seconds(10));
}

// Bytes that are no PNG or JPEG at all never reach a codec either (OpenCV would read a BMP).
TEST_F(BadInputTest, OnlyPngAndJpegAreDecoded) {
  pb::Frame f = EncodeFrame(0, false);
  std::vector<uint8_t> bmp;
  ASSERT_TRUE(cv::imencode(".bmp", cv::Mat(kHeight, kWidth, CV_8UC3, cv::Scalar(1, 2, 3)), bmp));
  f.set_color(std::string(bmp.begin(), bmp.end()));
  const int64_t decoded_before = ImageBuffersDecoded();
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", f)}), INVALID_ARGUMENT,
                        "frame.color: not a PNG or JPEG");
  EXPECT_EQ(ImageBuffersDecoded(), decoded_before);
}

// A good header over corrupt data passes the checks on arrival and fails where the frame is
// decoded, in the stream's task: the stream still ends INVALID_ARGUMENT naming the field.
TEST_F(BadInputTest, CorruptDataBehindAGoodHeaderFailsNamingTheField) {
  const std::string truncated = plx::testing::PngDeclaring(kWidth, kHeight);
  pb::Frame f = EncodeFrame(0, false);
  f.set_color(truncated);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", f)}), INVALID_ARGUMENT,
                        "frame.color: cannot decode");
  pb::Frame k = EncodeFrame(5, true);
  k.set_depth(plx::testing::PngDeclaring(kWidth, kHeight, 0, 16));
  const pb::Frame good = EncodeFrame(15, true);
  EXPECT_CODE_AND_FIELD(
      IntegrateStatus(stub(), {IntegrateStart("a", &good), IntegrateFrame(k)}), INVALID_ARGUMENT,
      "frame[1].depth: cannot decode");
}

TEST_F(BadInputTest, TrackBadIntrinsicsAndEncodingsNameTheField) {
  pb::Frame none = EncodeFrame(0, false);
  none.clear_intrinsics();
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", none)}), INVALID_ARGUMENT,
                        "frame.intrinsics");
  pb::Frame scale = EncodeFrame(0, false);
  scale.mutable_intrinsics()->set_depth_scale(0);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", scale)}), INVALID_ARGUMENT,
                        "frame.intrinsics");
  pb::Frame fx = EncodeFrame(0, false);
  fx.mutable_intrinsics()->set_fx(std::nan(""));
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", fx)}), INVALID_ARGUMENT,
                        "frame.intrinsics");
  pb::Frame encoding = EncodeFrame(0, false);
  encoding.set_color_encoding(pb::COLOR_ENCODING_UNSPECIFIED);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", encoding)}), INVALID_ARGUMENT,
                        "frame.color_encoding");
  pb::Frame depth_encoding = EncodeFrame(0, false);
  depth_encoding.set_depth_encoding(pb::DEPTH_ENCODING_UNSPECIFIED);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", depth_encoding)}), INVALID_ARGUMENT,
                        "frame.depth_encoding");
  pb::Frame time = EncodeFrame(0, false);
  time.set_timestamp(INFINITY);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("a", time)}), INVALID_ARGUMENT,
                        "frame.timestamp");
}

TEST_F(BadInputTest, TrackNonFinitePosesNameThePose) {
  pb::TrackRequest initial = TrackStart("a", EncodeFrame(0, false));
  *initial.mutable_initial_pose() = NanPose();
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {initial}), INVALID_ARGUMENT, "initial_pose.tx");
  pb::TrackRequest zero = TrackStart("a", EncodeFrame(0, false));
  *zero.mutable_initial_pose() = ZeroQuaternionPose();
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {zero}), INVALID_ARGUMENT, "initial_pose");
  // A frame's pose is an optional prior for tracking, but must still be a pose.
  pb::TrackRequest prior = TrackStart("a", EncodeFrame(0, false));
  *prior.mutable_frame()->mutable_pose() = NanPose();
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {prior}), INVALID_ARGUMENT, "frame.pose");
}

TEST_F(BadInputTest, TrackMapMustExistAndBeNamed) {
  EXPECT_EQ(TrackStatus(stub(), {TrackStart("missing", EncodeFrame(0, false))}).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("", EncodeFrame(0, false))}),
                        INVALID_ARGUMENT, "map");
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {TrackStart("../a", EncodeFrame(0, false))}),
                        INVALID_ARGUMENT, "map");
  // Closed before the first message: nothing names the map.
  EXPECT_EQ(TrackStatus(stub(), {}).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(BadInputTest, TrackBadOptionsNameOptions) {
  pb::TrackRequest r = TrackStart("a", EncodeFrame(0, false));
  r.mutable_options()->set_rays(3);
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {r}), INVALID_ARGUMENT, "options");
  // An enum number the daemon does not know is refused, not taken as the default mode.
  pb::TrackRequest mode = TrackStart("a", EncodeFrame(0, false));
  mode.mutable_options()->set_mode(static_cast<pb::TrackOptions::Mode>(99));
  EXPECT_CODE_AND_FIELD(TrackStatus(stub(), {mode}), INVALID_ARGUMENT,
                        "options.mode: unknown mode 99");
}

// Negative and non-finite options are refused, not replaced by the default (0 is the default).
TEST_F(BadInputTest, IntegrateMaxDepthMustBeFiniteAndNotNegative) {
  const pb::Frame f = EncodeFrame(5, true);
  for (float bad : {-1.0f, std::nanf(""), INFINITY}) {
    pb::IntegrateRequest r = IntegrateStart("a", &f);
    r.mutable_options()->set_max_depth(bad);
    SCOPED_TRACE(bad);
    EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {r}), INVALID_ARGUMENT, "options.max_depth");
  }
  pb::MapInfo a;
  ASSERT_TRUE(GetMap(stub(), "a", &a).ok());
  EXPECT_EQ(a.version(), a_before_.version());
}

TEST_F(BadInputTest, ExportMinDensityMustBeFiniteAndNotNegative) {
  for (float bad : {-1.0f, std::nanf(""), INFINITY}) {
    grpc::ClientContext context;
    Prepare(&context, "", kBadCallTimeout);
    pb::ExportRequest request;
    request.set_map("a");
    request.set_min_density(bad);
    auto reader = stub().Export(&context, request);
    pb::ExportChunk chunk;
    EXPECT_FALSE(reader->Read(&chunk)) << bad;
    SCOPED_TRACE(bad);
    EXPECT_CODE_AND_FIELD(reader->Finish(), INVALID_ARGUMENT, "min_density");
  }
}

TEST_F(BadInputTest, IntegrateUndecodableColourNamesTheKeyframe) {
  pb::Frame f = EncodeFrame(5, true);
  f.set_color("\x89PNG but not really");
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &f)}), INVALID_ARGUMENT,
                        "frame[0].color");
  // The second keyframe of a stream is frame[1].
  const pb::Frame good = EncodeFrame(5, true);
  EXPECT_CODE_AND_FIELD(
      IntegrateStatus(stub(), {IntegrateStart("a", &good), IntegrateFrame(f)}), INVALID_ARGUMENT,
      "frame[1].color");
}

TEST_F(BadInputTest, IntegrateDepthSizeMustMatchTheIntrinsics) {
  pb::Frame f = EncodeFrame(5, true);
  f.set_depth(DepthPngOfSize(kWidth, kHeight - 1));
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", nullptr), IntegrateFrame(f)}),
                        INVALID_ARGUMENT, "frame[0].depth");
}

TEST_F(BadInputTest, IntegrateKeyframesNeedAFinitePose) {
  const pb::Frame no_pose = EncodeFrame(5, false);
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &no_pose)}), INVALID_ARGUMENT,
                        "frame[0].pose");
  pb::Frame nan = EncodeFrame(5, true);
  *nan.mutable_pose() = NanPose();
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &nan)}), INVALID_ARGUMENT,
                        "frame[0].pose.tx");
  pb::Frame zero = EncodeFrame(5, true);
  *zero.mutable_pose() = ZeroQuaternionPose();
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &zero)}), INVALID_ARGUMENT,
                        "frame[0].pose");
  // None of the rejected streams published anything.
  pb::MapInfo a;
  ASSERT_TRUE(GetMap(stub(), "a", &a).ok());
  EXPECT_EQ(a.version(), a_before_.version());
}

TEST_F(BadInputTest, IntegrateMapMustExistAndStayTheSame) {
  const pb::Frame f = EncodeFrame(5, true);
  EXPECT_EQ(IntegrateStatus(stub(), {IntegrateStart("missing", &f)}).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("", &f)}), INVALID_ARGUMENT, "map");
  pb::IntegrateRequest other = IntegrateFrame(EncodeFrame(15, true));
  other.set_map("b");
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &f), other}), INVALID_ARGUMENT,
                        "map");
  pb::IntegrateRequest options = IntegrateStart("a", &f);
  options.mutable_options()->set_iterations_per_keyframe(1000000);
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {options}), INVALID_ARGUMENT,
                        "options.iterations_per_keyframe");
}

TEST_F(BadInputTest, IntegrateEmptyStreamIsInvalidArgument) {
  // The client half-closes at once: no message names a map.
  const grpc::Status s = IntegrateStatus(stub(), {});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << Describe(s);
}

TEST_F(BadInputTest, RenderChecksPoseIntrinsicsAndMap) {
  pb::RenderResponse r;
  pb::RenderRequest nan = RenderRequestAt("a", 10);
  *nan.mutable_pose() = NanPose();
  EXPECT_CODE_AND_FIELD(Render(stub(), nan, &r), INVALID_ARGUMENT, "pose.tx");
  pb::RenderRequest zero = RenderRequestAt("a", 10);
  *zero.mutable_pose() = ZeroQuaternionPose();
  EXPECT_CODE_AND_FIELD(Render(stub(), zero, &r), INVALID_ARGUMENT, "pose");
  pb::RenderRequest no_pose = RenderRequestAt("a", 10);
  no_pose.clear_pose();
  EXPECT_CODE_AND_FIELD(Render(stub(), no_pose, &r), INVALID_ARGUMENT, "pose");
  pb::RenderRequest no_k = RenderRequestAt("a", 10);
  no_k.clear_intrinsics();
  EXPECT_CODE_AND_FIELD(Render(stub(), no_k, &r), INVALID_ARGUMENT, "intrinsics");
  pb::RenderRequest empty = RenderRequestAt("a", 10);
  empty.mutable_intrinsics()->set_width(0);
  EXPECT_CODE_AND_FIELD(Render(stub(), empty, &r), INVALID_ARGUMENT, "intrinsics");
  pb::RenderRequest huge = RenderRequestAt("a", 10);
  huge.mutable_intrinsics()->set_width(100000);
  huge.mutable_intrinsics()->set_height(100000);
  EXPECT_CODE_AND_FIELD(Render(stub(), huge, &r), INVALID_ARGUMENT, "intrinsics");
  EXPECT_EQ(Render(stub(), RenderRequestAt("missing", 10), &r).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_CODE_AND_FIELD(Render(stub(), RenderRequestAt("", 10), &r), INVALID_ARGUMENT, "map");
}

TEST_F(BadInputTest, ExportAndWatchJobOfUnknownThingsAreNotFound) {
  std::string bytes;
  EXPECT_EQ(Export(stub(), "missing", &bytes).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(bytes.empty());
  grpc::ClientContext context;
  Prepare(&context, "", kBadCallTimeout);
  pb::WatchJobRequest request;
  request.set_job_id("integrate-999");
  auto reader = stub().WatchJob(&context, request);
  pb::JobStatus status;
  EXPECT_FALSE(reader->Read(&status));
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
}

// One writer per map: while a job maps "a", a second Integrate, DeleteMap and LoadMap of "a"
// are FAILED_PRECONDITION; the first job is not disturbed and ends OK.
TEST_F(BadInputTest, SecondWriterIsFailedPrecondition) {
  grpc::ClientContext context;
  Prepare(&context);
  auto first = stub().Integrate(&context);
  const pb::Frame f = EncodeFrame(5, true);
  ASSERT_TRUE(first->Write(IntegrateStart("a", &f)));
  pb::MappingProgress progress;
  ASSERT_TRUE(first->Read(&progress));  // the lease is held once the job reports

  const pb::Frame g = EncodeFrame(15, true);
  EXPECT_CODE_AND_FIELD(IntegrateStatus(stub(), {IntegrateStart("a", &g)}), FAILED_PRECONDITION,
                        "\"a\"");
  {
    grpc::ClientContext c;
    Prepare(&c);
    pb::DeleteMapRequest del;
    del.set_name("a");
    pb::DeleteMapResponse r;
    EXPECT_EQ(stub().DeleteMap(&c, del, &r).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  }
  {
    grpc::ClientContext c;
    Prepare(&c);
    pb::LoadMapRequest load;
    load.set_name("a");
    pb::MapInfo r;
    EXPECT_EQ(stub().LoadMap(&c, load, &r).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  }
  // Another map can be mapped meanwhile.
  const IntegrateResult other = Integrate(stub(), "b", {});
  EXPECT_TRUE(other.status.ok()) << Describe(other.status);

  first->WritesDone();
  while (first->Read(&progress)) {
  }
  const grpc::Status s = first->Finish();
  EXPECT_TRUE(s.ok()) << Describe(s);
  EXPECT_TRUE(progress.done());
}

// A client that abandons its streams: the stream objects, context and channel are destroyed
// without WritesDone or Finish.
TEST_F(BadInputTest, AbandonedStreamsLeaveNothingBehind) {
  {
    std::shared_ptr<grpc::Channel> channel = MakeChannel(d_->daemon->port());
    std::unique_ptr<pb::Plenoxd::Stub> stub = pb::Plenoxd::NewStub(channel);
    grpc::ClientContext track_context, integrate_context;
    Prepare(&track_context);
    Prepare(&integrate_context);
    auto track = stub->Track(&track_context);
    auto integrate = stub->Integrate(&integrate_context);
    ASSERT_TRUE(track->Write(TrackStart("a", EncodeFrame(0, false))));
    pb::PoseEstimate estimate;
    ASSERT_TRUE(track->Read(&estimate));
    const pb::Frame f = EncodeFrame(5, true);
    ASSERT_TRUE(integrate->Write(IntegrateStart("a", &f)));
    pb::MappingProgress progress;
    ASSERT_TRUE(integrate->Read(&progress));
    pb::TrackRequest next;
    *next.mutable_frame() = EncodeFrame(1, false);
    track->Write(next);
    // Gone: streams, contexts and the channel go out of scope here.
  }
  // TearDown checks that the lease and the stream slots come back; a new writer gets "a".
  EXPECT_TRUE(WaitFor([&] {
    pb::MapInfo info;
    return GetMap(stub(), "a", &info).ok() && !info.mapping();
  }));
  const IntegrateResult again = Integrate(stub(), "a", {25});
  EXPECT_TRUE(again.status.ok()) << Describe(again.status);
}

// A client whose connection dies (TCP reset through a proxy) in the middle of a Track and an
// Integrate stream.
TEST_F(BadInputTest, VanishedConnectionLeavesNothingBehind) {
  TcpProxy proxy(d_->daemon->port());
  std::shared_ptr<grpc::Channel> channel = MakeChannel(proxy.port());
  std::unique_ptr<pb::Plenoxd::Stub> via_proxy = pb::Plenoxd::NewStub(channel);
  grpc::ClientContext track_context, integrate_context;
  Prepare(&track_context);
  Prepare(&integrate_context);
  auto track = via_proxy->Track(&track_context);
  auto integrate = via_proxy->Integrate(&integrate_context);
  ASSERT_TRUE(track->Write(TrackStart("a", EncodeFrame(0, false))));
  pb::PoseEstimate estimate;
  ASSERT_TRUE(track->Read(&estimate));
  const pb::Frame f = EncodeFrame(5, true);
  ASSERT_TRUE(integrate->Write(IntegrateStart("a", &f)));
  pb::MappingProgress progress;
  ASSERT_TRUE(integrate->Read(&progress));
  pb::MapInfo info;
  ASSERT_TRUE(GetMap(stub(), "a", &info).ok());
  EXPECT_TRUE(info.mapping());
  EXPECT_EQ(proxy.connections(), 1);

  proxy.CutAll();
  while (track->Read(&estimate)) {
  }
  while (integrate->Read(&progress)) {
  }
  EXPECT_FALSE(track->Finish().ok());
  EXPECT_FALSE(integrate->Finish().ok());

  EXPECT_TRUE(WaitFor([&] {
    pb::MapInfo i;
    return GetMap(stub(), "a", &i).ok() && !i.mapping();
  })) << "the lease of a vanished client's Integrate was not released";
  const IntegrateResult again = Integrate(stub(), "a", {25});
  EXPECT_TRUE(again.status.ok()) << Describe(again.status);
}

}  // namespace
}  // namespace plx::server::testing
