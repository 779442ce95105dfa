// The remote CLI's frame-streaming helper (clients/plenox/frame_stream.h) over a fake stream
// that answers on the spot: pacing, matching replies to frames (with drops), latency records,
// cancellation. The commands that use it are tested against a real daemon in remote_*_test.cc.
#ifdef PLX_WITH_SERVER

#include "clients/plenox/frame_stream.h"

#include <cmath>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "plenoxd/v1/plenoxd.grpc.pb.h"

namespace plx::cli {
namespace {

namespace pb = ::plenoxd::v1;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

// A Track stream whose daemon is `answer`: the replies to each request, queued when it is
// written. Records how many replies were still unread when each frame was written.
class FakeTrackStream
    : public grpc::ClientReaderWriterInterface<pb::TrackRequest, pb::PoseEstimate> {
 public:
  explicit FakeTrackStream(
      std::function<std::vector<pb::PoseEstimate>(const pb::TrackRequest&)> answer)
      : answer_(std::move(answer)) {}

  bool Write(const pb::TrackRequest& request, grpc::WriteOptions) override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (cancelled_ || writes_done_) return false;
    unread_at_write.push_back(static_cast<int>(replies_.size()));
    for (pb::PoseEstimate& reply : answer_(request)) replies_.push_back(std::move(reply));
    changed_.notify_all();
    return true;
  }
  bool Read(pb::PoseEstimate* reply) override {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] { return cancelled_ || writes_done_ || !replies_.empty(); });
    if (cancelled_ || replies_.empty()) return false;
    *reply = std::move(replies_.front());
    replies_.pop_front();
    return true;
  }
  bool WritesDone() override {
    std::lock_guard<std::mutex> lock(mutex_);
    writes_done_ = true;
    changed_.notify_all();
    return true;
  }
  grpc::Status Finish() override {
    std::lock_guard<std::mutex> lock(mutex_);
    return cancelled_ ? grpc::Status(grpc::StatusCode::CANCELLED, "cancelled") : grpc::Status::OK;
  }
  bool NextMessageSize(uint32_t* size) override {
    *size = 0;
    return true;
  }
  void WaitForInitialMetadata() override {}

  void Cancel() {
    std::lock_guard<std::mutex> lock(mutex_);
    cancelled_ = true;
    changed_.notify_all();
  }

  std::vector<int> unread_at_write;

 private:
  std::function<std::vector<pb::PoseEstimate>(const pb::TrackRequest&)> answer_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<pb::PoseEstimate> replies_;
  bool cancelled_ = false;
  bool writes_done_ = false;
};

pb::PoseEstimate Estimate(double timestamp, double latency_ms) {
  pb::PoseEstimate estimate;
  estimate.set_timestamp(timestamp);
  estimate.set_latency_ms(latency_ms);
  return estimate;
}

// Frame k is stamped 10 + k / 10.
double Stamp(int k) { return 10.0 + 0.1 * k; }

using TrackFrames = FrameStream<pb::TrackRequest, pb::PoseEstimate>;

TrackFrames::Callbacks Callbacks(int fail_at = -1) {
  return {
      .request = [fail_at](int k) -> absl::StatusOr<pb::TrackRequest> {
        if (k == fail_at) return absl::NotFoundError("frame does not load");
        pb::TrackRequest request;
        request.mutable_frame()->set_timestamp(Stamp(k));
        return request;
      },
      .timestamp = Stamp,
      .answers = [](const pb::PoseEstimate& e) -> std::optional<FrameAnswer> {
        return FrameAnswer{e.timestamp(), e.latency_ms()};
      },
  };
}

TEST(FrameStreamTest, LockStepSendsEachFrameAfterThePreviousReplyAndRecordsLatencies) {
  FakeTrackStream stream([](const pb::TrackRequest& r) {
    return std::vector<pb::PoseEstimate>{Estimate(r.frame().timestamp(), 2.5)};
  });
  TrackFrames frames(
      &stream, [&] { stream.Cancel(); }, FramePacing::LockStep(), "an estimate");
  int replies = 0;
  TrackFrames::Callbacks callbacks = Callbacks();
  callbacks.on_reply = [&](const pb::PoseEstimate&, FrameRecord* record) {
    EXPECT_NE(record, nullptr);
    record->note = "OK";
    ++replies;
    return absl::OkStatus();
  };
  const FrameStreamResult result = frames.Run(4, callbacks);
  EXPECT_TRUE(result.local.ok());
  EXPECT_TRUE(result.problem.ok());
  EXPECT_TRUE(result.finished.ok());
  EXPECT_EQ(result.sent, 4);
  EXPECT_EQ(replies, 4);
  EXPECT_THAT(stream.unread_at_write, ElementsAre(0, 0, 0, 0));  // none waited unread
  ASSERT_EQ(result.records.size(), 4u);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(result.records[k].index, k);
    EXPECT_EQ(result.records[k].timestamp, Stamp(k));
    EXPECT_EQ(result.records[k].daemon_ms, 2.5);
    EXPECT_GE(result.records[k].roundtrip_ms, 0.0);
  }
  EXPECT_GE(result.last_answer, result.started);
  EXPECT_THAT(DaemonMs(result.records, 2), ElementsAre(2.5, 2.5));
  EXPECT_EQ(RoundtripMs(result.records, 1).size(), 3u);
}

TEST(FrameStreamTest, FramesWithoutAReplyWereDroppedAndOtherRepliesAnswerNone) {
  // Odd frames are dropped; every reply is followed by one that answers no frame (latency < 0).
  FakeTrackStream stream([](const pb::TrackRequest& r) {
    const double t = r.frame().timestamp();
    if (static_cast<int>(std::lround((t - 10.0) * 10)) % 2 == 1)
      return std::vector<pb::PoseEstimate>{};
    return std::vector<pb::PoseEstimate>{Estimate(t, 1.0), Estimate(0.0, -1.0)};
  });
  TrackFrames frames(
      &stream, [&] { stream.Cancel(); }, FramePacing::FlowControl(), "an estimate");
  TrackFrames::Callbacks callbacks = Callbacks();
  callbacks.answers = [](const pb::PoseEstimate& e) -> std::optional<FrameAnswer> {
    if (e.latency_ms() < 0) return std::nullopt;
    return FrameAnswer{e.timestamp(), e.latency_ms()};
  };
  int others = 0;
  std::vector<int> sent;
  callbacks.on_reply = [&](const pb::PoseEstimate&, FrameRecord* record) {
    others += record == nullptr;
    return absl::OkStatus();
  };
  callbacks.on_sent = [&](int k) { sent.push_back(k); };
  const FrameStreamResult result = frames.Run(5, callbacks);
  EXPECT_TRUE(result.finished.ok());
  EXPECT_TRUE(result.problem.ok());
  EXPECT_THAT(sent, ElementsAre(0, 1, 2, 3, 4));
  EXPECT_EQ(others, 3);
  std::vector<int> answered;
  for (const FrameRecord& r : result.records) answered.push_back(r.index);
  EXPECT_THAT(answered, ElementsAre(0, 2, 4));
  EXPECT_EQ(FrameTimingsText("# h\n", result.records, 2).substr(0, 16), "# h\n4 10.400000 ");
}

TEST(FrameStreamTest, AReplyForAFrameNotSentCancelsTheCall) {
  FakeTrackStream stream(
      [](const pb::TrackRequest&) { return std::vector<pb::PoseEstimate>{Estimate(99.0, 1.0)}; });
  TrackFrames frames(
      &stream, [&] { stream.Cancel(); }, FramePacing::LockStep(), "an estimate");
  const FrameStreamResult result = frames.Run(3, Callbacks());
  EXPECT_THAT(result.problem.message(),
              HasSubstr("the daemon sent an estimate for t=99.000000, a frame not sent"));
  EXPECT_EQ(result.finished.error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_EQ(result.sent, 1);
  EXPECT_TRUE(result.records.empty());
}

TEST(FrameStreamTest, ARequestThatCannotBeMadeStopsSendingAndCancelsTheCall) {
  FakeTrackStream stream([](const pb::TrackRequest& r) {
    return std::vector<pb::PoseEstimate>{Estimate(r.frame().timestamp(), 1.0)};
  });
  TrackFrames frames(
      &stream, [&] { stream.Cancel(); }, FramePacing::LockStep(), "an estimate");
  const FrameStreamResult result = frames.Run(5, Callbacks(/*fail_at=*/2));
  EXPECT_EQ(result.local, absl::NotFoundError("frame does not load"));
  EXPECT_EQ(result.finished.error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_EQ(result.sent, 2);
  EXPECT_EQ(result.records.size(), 2u);
}

TEST(FrameStreamTest, RealtimeSendsAtTheFramesTimestamps) {
  const absl::Time start = absl::FromUnixSeconds(1000);
  EXPECT_EQ(FramePacing::Realtime(2.0).Due(start, 10.0, 12.0), start + absl::Seconds(1));
  EXPECT_EQ(FramePacing::LockStep().Due(start, 10.0, 12.0), start);
  EXPECT_EQ(FramePacing::FlowControl().Due(start, 10.0, 12.0), start);

  FakeTrackStream stream([](const pb::TrackRequest& r) {
    return std::vector<pb::PoseEstimate>{Estimate(r.frame().timestamp(), 1.0)};
  });
  // Frames 0.1 s apart at speed 4: the last of 5 goes 0.1 s after the first.
  TrackFrames frames(
      &stream, [&] { stream.Cancel(); }, FramePacing::Realtime(4.0), "an estimate");
  const FrameStreamResult result = frames.Run(5, Callbacks());
  ASSERT_EQ(result.records.size(), 5u);
  const absl::Duration spread = result.records[4].sent_at - result.records[0].sent_at;
  EXPECT_GE(spread, absl::Milliseconds(95));
  EXPECT_LT(spread, absl::Seconds(2));
}

}  // namespace
}  // namespace plx::cli

#endif  // PLX_WITH_SERVER
