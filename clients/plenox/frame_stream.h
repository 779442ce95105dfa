// The frames-in side of the remote CLI's bidirectional calls (Track, Integrate, Slam): one helper
// that sends a sequence of frames on a stream and reads the daemon's replies on a reader thread,
// as clients/python's _FrameStream does for the Python client.
//
//   - Pacing: lock-step (the next frame goes once the previous one's reply is back), realtime
//     (frame k goes (t_k - t_0) / speed after the first, whatever the replies do) or flow
//     control (as fast as the stream takes them).
//   - Replies that answer a frame are matched to the frames sent, in order, by timestamp (a
//     frame without a reply was dropped by the daemon), and each answered frame gets a latency
//     record: the round trip seen here (frame written to reply read; loading and encoding
//     excluded) and the daemon's own latency.
//   - Cancellation: a request that cannot be made (a frame that does not load), a reply that
//     makes no sense, or Cancel() from another thread stops sending and cancels the call; the
//     call is always finished, and the result says what stopped it.
//
// The commands keep what is theirs (requests, what a reply means, progress lines, reports) in
// the callbacks; the helper knows nothing about datasets. Only built with PLX_WITH_SERVER.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <grpcpp/support/sync_stream.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"

namespace plx::cli {

// How frames go out.
struct FramePacing {
  enum class Kind {
    kLockStep,     // one at a time: nothing waits on the daemon, so a round trip is its work
    kRealtime,     // at the frames' timestamps, scaled by `speed` (the daemon may drop frames)
    kFlowControl,  // as fast as the stream takes them (the daemon's backpressure)
  };
  Kind kind = Kind::kLockStep;
  double speed = 1.0;  // kRealtime: 2 = twice as fast as recorded

  static FramePacing LockStep() { return {Kind::kLockStep, 1.0}; }
  static FramePacing Realtime(double speed) { return {Kind::kRealtime, speed}; }
  static FramePacing FlowControl() { return {Kind::kFlowControl, 1.0}; }

  // When a frame stamped `t` is due on a stream whose first frame (stamped `t0`) went at
  // `start`: start + (t - t0) / speed for kRealtime, `start` (no wait) otherwise.
  absl::Time Due(absl::Time start, double t0, double t) const;
};

// One frame sent and, once answered, its latency record.
struct FrameRecord {
  int index = 0;              // the frame's position in the stream (0 = the first sent)
  double timestamp = 0.0;     // the frame's
  absl::Time sent_at;         // when it was written (loading and encoding done)
  double roundtrip_ms = 0.0;  // written to its reply read, here
  double daemon_ms = 0.0;     // received to reply sent, as the daemon measured
  std::string note{};         // the command's (e.g. the reply's state), for timings files
};

// What a reply says about the frame it answers.
struct FrameAnswer {
  double timestamp = 0.0;  // of the frame answered
  double daemon_ms = 0.0;  // the daemon's latency for it
};

// The round trips and the daemon's latencies of records[first..].
std::vector<double> RoundtripMs(const std::vector<FrameRecord>& records, size_t first = 0);
std::vector<double> DaemonMs(const std::vector<FrameRecord>& records, size_t first = 0);

// A timings file: `header` (one comment line, with its newline), then one line per record from
// `first` on: "index timestamp roundtrip_ms daemon_ms[ note]".
std::string FrameTimingsText(const std::string& header, const std::vector<FrameRecord>& records,
                             size_t first = 0);

// How a stream ended.
struct FrameStreamResult {
  absl::Status local;     // a request that could not be made, or Cancel(): the call was cancelled
  absl::Status problem;   // a reply that made no sense (or on_reply refused): cancelled too
  grpc::Status finished;  // the call's own status (CANCELLED after either of the above)
  int sent = 0;           // frames written
  std::vector<FrameRecord> records;  // the answered frames, in the order sent
  absl::Time started;                // before the first frame was loaded
  absl::Time last_answer;            // the last answer read (`started` when none came)
};

template <typename Request, typename Reply>
class FrameStream {
 public:
  using Stream = grpc::ClientReaderWriterInterface<Request, Reply>;

  struct Callbacks {
    // The request of frame k (0-based; the first carries the call's options). Called on the
    // calling thread; an error stops sending and cancels the call. Required.
    std::function<absl::StatusOr<Request>(int k)> request{};
    // The timestamp of frame k before it is loaded. Required with realtime pacing.
    std::function<double(int k)> timestamp{};
    // The frame a reply answers, or nullopt for one that answers none (progress, a done
    // message). Unset: no reply answers a frame (lock-step then waits for nothing).
    std::function<std::optional<FrameAnswer>(const Reply&)> answers{};
    // Every reply, on the reader thread; `record` is the answered frame's record (filled in but
    // for `note`), nullptr for a reply that answers none. An error cancels the call. Optional.
    std::function<absl::Status(const Reply&, FrameRecord* record)> on_reply{};
    // After frame k was written, on the calling thread. Optional.
    std::function<void(int k)> on_sent{};
  };

  // `cancel` cancels the call (ClientContext::TryCancel). `reply_name` names a reply in the
  // error about one that answers no frame sent ("an update").
  FrameStream(Stream* stream, std::function<void()> cancel, FramePacing pacing,
              std::string reply_name)
      : stream_(stream),
        cancel_(std::move(cancel)),
        pacing_(pacing),
        reply_name_(std::move(reply_name)) {}

  // Sends frames 0..frames-1, then half-closes, waits for the daemon to end the call and
  // finishes it. Callbacks run with the stream's lock held (on_reply, on_sent): state they share
  // needs no lock of its own, and they must not call Cancel().
  FrameStreamResult Run(int frames, Callbacks callbacks);

  // Stops sending and cancels the call, from any thread (e.g. a signal watcher); Run's result
  // then has `local` Cancelled with `why`.
  void Cancel(const std::string& why) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (result_.local.ok()) result_.local = absl::CancelledError(why);
      changed_.notify_all();
    }
    cancel_();
  }

 private:
  void ReadReplies();
  // Under the lock: the reader has a reply for the frame stamped `answer.timestamp`.
  FrameRecord* Match(const FrameAnswer& answer, absl::Time now);
  // Under the lock: whether sending should stop (the stream ended or something went wrong).
  bool Stopped() const { return ended_ || !result_.local.ok() || !result_.problem.ok(); }

  Stream* stream_;
  std::function<void()> cancel_;
  FramePacing pacing_;
  std::string reply_name_;
  Callbacks callbacks_;

  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<FrameRecord> sent_;  // every frame written
  size_t matched_ = 0;             // sent_ before this one are answered or were dropped
  bool ended_ = false;             // the reader has nothing more to read
  FrameStreamResult result_;
};

template <typename Request, typename Reply>
FrameStreamResult FrameStream<Request, Reply>::Run(int frames, Callbacks callbacks) {
  callbacks_ = std::move(callbacks);
  result_.started = result_.last_answer = absl::Now();
  // Replies are read on their own thread: with realtime pacing frames go out whatever the daemon
  // is doing, and after the last frame a final message can take as long as the daemon needs.
  std::thread reader([this] { ReadReplies(); });
  const bool lock_step = pacing_.kind == FramePacing::Kind::kLockStep && callbacks_.answers;
  double t0 = 0.0;
  bool open = true;  // false: the daemon ended the stream (Finish says why) or we stopped
  for (int k = 0; k < frames && open; ++k) {
    if (pacing_.kind == FramePacing::Kind::kRealtime) {
      const double t = callbacks_.timestamp(k);
      if (k == 0) t0 = t;
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait_until(lock, absl::ToChronoTime(pacing_.Due(result_.started, t0, t)),
                          [&] { return Stopped(); });
      if (Stopped()) break;
    }
    absl::StatusOr<Request> request = callbacks_.request(k);
    std::unique_lock<std::mutex> lock(mutex_);
    if (!request.ok()) {
      if (result_.local.ok()) result_.local = request.status();
      break;
    }
    if (Stopped()) break;
    sent_.push_back(
        {.index = k, .timestamp = request->frame().timestamp(), .sent_at = absl::Now()});
    lock.unlock();
    open = stream_->Write(*request);
    lock.lock();
    if (!open) break;
    ++result_.sent;
    if (callbacks_.on_sent) callbacks_.on_sent(k);
    if (lock_step) {
      changed_.wait(lock, [&] { return Stopped() || matched_ >= sent_.size(); });
      open = !Stopped();
    }
  }
  bool cancelled;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    cancelled = !result_.local.ok();
  }
  if (cancelled) {
    cancel_();
  } else if (open) {
    stream_->WritesDone();
  }
  reader.join();
  result_.finished = stream_->Finish();
  return std::move(result_);
}

template <typename Request, typename Reply>
void FrameStream<Request, Reply>::ReadReplies() {
  Reply reply;
  while (stream_->Read(&reply)) {
    const absl::Time now = absl::Now();
    std::lock_guard<std::mutex> lock(mutex_);
    FrameRecord* record = nullptr;
    if (callbacks_.answers) {
      if (const std::optional<FrameAnswer> answer = callbacks_.answers(reply)) {
        record = Match(*answer, now);
        if (record == nullptr) break;
      }
    }
    if (callbacks_.on_reply) {
      if (absl::Status s = callbacks_.on_reply(reply, record); !s.ok()) {
        result_.problem = std::move(s);
        cancel_();
        break;
      }
    }
    changed_.notify_all();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ended_ = true;
  changed_.notify_all();
}

template <typename Request, typename Reply>
FrameRecord* FrameStream<Request, Reply>::Match(const FrameAnswer& answer, absl::Time now) {
  // Replies come in the order the frames went; frames without one were dropped.
  size_t at = matched_;
  while (at < sent_.size() && sent_[at].timestamp != answer.timestamp) ++at;
  if (at == sent_.size()) {
    result_.problem = absl::InternalError(
        absl::StrFormat("the daemon sent %s for t=%.6f, a frame not sent (or answered twice)",
                        reply_name_, answer.timestamp));
    cancel_();
    return nullptr;
  }
  matched_ = at + 1;
  FrameRecord record = sent_[at];
  record.roundtrip_ms = absl::ToDoubleMilliseconds(now - record.sent_at);
  record.daemon_ms = answer.daemon_ms;
  result_.records.push_back(std::move(record));
  result_.last_answer = now;
  return &result_.records.back();
}

}  // namespace plx::cli
