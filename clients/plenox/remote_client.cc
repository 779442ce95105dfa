#include "clients/plenox/remote_client.h"

#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>

#include <grpc/support/log.h>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "clients/plenox/cli_common.h"
#include "core/common/status_macros.h"
#include "proto/slam_codec.h"

namespace plx::cli {
namespace {

// The whole file, or an error naming the flag and the file.
absl::StatusOr<std::string> ReadWholeFile(const std::string& path, const std::string& flag) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return absl::NotFoundError(absl::StrCat(flag, ": cannot read ", path, ": no such file"));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return absl::NotFoundError(
        absl::StrCat(flag, ": cannot read ", path, ": ", std::strerror(errno)));
  }
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// gRPC's own log lines ("E1122 ... Handshake failed ...") would come before plenox's message
// and say the same less clearly; they stay off unless GRPC_VERBOSITY asks for them.
void DropGrpcLog(gpr_log_func_args*) {}

std::chrono::system_clock::time_point DeadlineAfter(absl::Duration d) {
  return std::chrono::system_clock::now() +
         std::chrono::milliseconds(absl::ToInt64Milliseconds(d));
}

}  // namespace

absl::StatusOr<std::unique_ptr<RemoteClient>> RemoteClient::Create(const RemoteOptions& options) {
  if (std::getenv("GRPC_VERBOSITY") == nullptr) gpr_set_log_function(DropGrpcLog);
  std::unique_ptr<RemoteClient> client(new RemoteClient());
  client->server_ = options.server;
  if (!options.token_file.empty()) {
    absl::StatusOr<std::string> token = ReadWholeFile(options.token_file, "--token-file");
    if (!token.ok()) return token.status();
    client->token_ = std::string(absl::StripAsciiWhitespace(*token));
    if (client->token_.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat("--token-file: ", options.token_file, " is empty"));
    }
    // Metadata values must be printable ASCII; gRPC would refuse the call otherwise.
    for (char c : client->token_) {
      if (c < 0x20 || c > 0x7e) {
        return absl::InvalidArgumentError(absl::StrCat(
            "--token-file: the token in ", options.token_file, " must be printable ASCII"));
      }
    }
  }
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  if (!options.tls_ca.empty()) {
    absl::StatusOr<std::string> ca = ReadWholeFile(options.tls_ca, "--tls-ca");
    if (!ca.ok()) return ca.status();
    if (absl::StripAsciiWhitespace(*ca).empty()) {
      return absl::InvalidArgumentError(absl::StrCat("--tls-ca: ", options.tls_ca, " is empty"));
    }
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = *ca;
    credentials = grpc::SslCredentials(ssl);
    client->tls_ = true;
  } else {
    credentials = grpc::InsecureChannelCredentials();
  }
  client->retry_.budget = absl::Seconds(options.retry_seconds);
  if (absl::Status s = ValidateRetryOptions(client->retry_); !s.ok()) return s;
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(kRemoteMaxMessageBytes);
  arguments.SetMaxSendMessageSize(kRemoteMaxMessageBytes);
  // After the daemon went away gRPC reconnects on a backoff of its own (from 1 s up to 120 s by
  // default), and a call made while it waits fails at once: kept within the retry policy's
  // waits, a retried call finds a restarted daemon about max_backoff after it is back.
  arguments.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS,
                   static_cast<int>(absl::ToInt64Milliseconds(client->retry_.initial_backoff)));
  arguments.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS,
                   static_cast<int>(absl::ToInt64Milliseconds(client->retry_.max_backoff)));
  // A lost connection makes the channel resolve the address again, at most once per this
  // (30 s by default), and it waits for that (docs/BENCHMARKS.md, "Failover").
  arguments.SetInt(GRPC_ARG_DNS_MIN_TIME_BETWEEN_RESOLUTIONS_MS,
                   static_cast<int>(absl::ToInt64Milliseconds(client->retry_.max_backoff)));
  client->channel_ = grpc::CreateCustomChannel(options.server, credentials, arguments);
  if (!client->channel_) {
    return absl::InvalidArgumentError(
        absl::StrCat("--server: cannot create a channel to ", options.server));
  }
  client->stub_ = pb::Plenoxd::NewStub(client->channel_);
  client->retry_clock_ = std::make_unique<ChannelWaitClock>(client->channel_);
  return client;
}

void ChannelWaitClock::SleepFor(absl::Duration duration) {
  const absl::Time until = absl::Now() + duration;
  if (channel_->GetState(/*try_to_connect=*/true) != GRPC_CHANNEL_READY) {
    // Returns at once when connected, else when `until` passes.
    if (channel_->WaitForConnected(absl::ToChronoTime(until))) return;
  }
  absl::SleepFor(until - absl::Now());
}

absl::Status RemoteClient::Unreachable(const std::string& why) const {
  return absl::UnavailableError(absl::StrCat(
      "cannot reach ", server_, ": ", why, " (is plenoxd running there",
      tls_ ? ", serving TLS with a certificate --tls-ca trusts?)"
           : "? a daemon serving TLS needs --tls-ca)"));
}

absl::Status RemoteClient::Connect(absl::Duration timeout) {
  const auto deadline = DeadlineAfter(timeout);
  grpc_connectivity_state state = channel_->GetState(/*try_to_connect=*/true);
  while (state != GRPC_CHANNEL_READY) {
    // The first failed attempt is the answer: a refused connection will not be accepted a
    // moment later, and retrying with backoff would only make the user wait.
    if (state == GRPC_CHANNEL_TRANSIENT_FAILURE || state == GRPC_CHANNEL_SHUTDOWN) {
      return Unreachable("the connection failed");
    }
    if (!channel_->WaitForStateChange(state, deadline)) {
      return Unreachable(absl::StrFormat("no connection within %.0f s",
                                         absl::ToDoubleSeconds(timeout)));
    }
    state = channel_->GetState(/*try_to_connect=*/true);
  }
  return absl::OkStatus();
}

std::unique_ptr<grpc::ClientContext> RemoteClient::NewContext(absl::Duration deadline,
                                                             const std::string& map) const {
  auto context = std::make_unique<grpc::ClientContext>();
  if (!map.empty()) context->AddMetadata("x-plenoxd-map", map);
  if (!token_.empty()) context->AddMetadata("authorization", absl::StrCat("Bearer ", token_));
  if (deadline != absl::InfiniteDuration()) context->set_deadline(DeadlineAfter(deadline));
  return context;
}

absl::Status RemoteClient::ToStatus(const grpc::Status& status) const {
  if (status.ok()) return absl::OkStatus();
  const auto code = static_cast<absl::StatusCode>(status.error_code());
  const std::string& message = status.error_message();
  switch (code) {
    case absl::StatusCode::kUnauthenticated:
      return absl::Status(code, absl::StrCat(message, " (UNAUTHENTICATED: ",
                                             token_.empty()
                                                 ? "give the daemon's token with --token-file"
                                                 : "check the token in --token-file",
                                             ")"));
    case absl::StatusCode::kUnavailable:
      return absl::Status(code, absl::StrCat(server_, " is unavailable: ", message,
                                             " (UNAVAILABLE)"));
    case absl::StatusCode::kDeadlineExceeded:
      return absl::Status(code, absl::StrCat(server_, " did not answer in time: ", message,
                                             " (DEADLINE_EXCEEDED)"));
    default:
      return absl::Status(code,
                          absl::StrCat(message, " (", absl::StatusCodeToString(code), ")"));
  }
}

template <typename T>
absl::StatusOr<T> RemoteClient::Retried(bool idempotent,
                                        const std::function<absl::StatusOr<T>()>& call) {
  const absl::Time start = absl::Now();
  int waits = 0;
  absl::StatusOr<T> result = CallWithRetry<T>(
      retry_, idempotent, call, *retry_clock_, [&](const absl::Status& s, int attempt) {
        waits = attempt;
        NoteRetry(s, attempt);
      });
  if (!result.ok() && waits > 0 && result.status().code() == absl::StatusCode::kUnavailable) {
    return absl::Status(result.status().code(),
                        absl::StrFormat("%s; gave up after waiting %.1f s (--retry-seconds %g)",
                                        result.status().message(),
                                        absl::ToDoubleSeconds(absl::Now() - start),
                                        absl::ToDoubleSeconds(retry_.budget)));
  }
  return result;
}

void RemoteClient::NoteRetry(const absl::Status& status, int attempt) const {
  // Once per outage: the user learns why the command pauses, not each attempt.
  if (attempt != 1) return;
  std::cerr << absl::StrFormat("plenox: %s; trying again for up to %g s (--retry-seconds)\n",
                               status.message(), absl::ToDoubleSeconds(retry_.budget));
}

absl::StatusOr<pb::MapInfo> RemoteClient::CreateMap(const std::string& name, float voxel_size) {
  pb::CreateMapRequest request;
  request.set_name(name);
  request.set_voxel_size(voxel_size);
  pb::MapInfo info;
  const auto context = NewContext(kRemoteUnaryDeadline, name);
  if (grpc::Status s = stub_->CreateMap(context.get(), request, &info); !s.ok()) {
    return ToStatus(s);
  }
  return info;
}

absl::StatusOr<pb::MapInfo> RemoteClient::GetMap(const std::string& name) {
  return Retried<pb::MapInfo>(true, [&]() -> absl::StatusOr<pb::MapInfo> {
    pb::GetMapRequest request;
    request.set_name(name);
    pb::MapInfo info;
    const auto context = NewContext(kRemoteUnaryDeadline, name);
    if (grpc::Status s = stub_->GetMap(context.get(), request, &info); !s.ok()) {
      return ToStatus(s);
    }
    return info;
  });
}

absl::Status RemoteClient::Probe(const std::string& map) {
  pb::GetMapRequest request;
  request.set_name(map);
  pb::MapInfo info;
  const auto context = NewContext(kRemoteConnectTimeout, map);
  const grpc::Status s = stub_->GetMap(context.get(), request, &info);
  if (s.ok() || s.error_code() == grpc::StatusCode::NOT_FOUND) return absl::OkStatus();
  return ToStatus(s);
}

absl::StatusOr<std::vector<pb::MapInfo>> RemoteClient::ListMaps() {
  return Retried<std::vector<pb::MapInfo>>(
      true, [&]() -> absl::StatusOr<std::vector<pb::MapInfo>> {
        pb::ListMapsResponse response;
        const auto context = NewContext();
        if (grpc::Status s = stub_->ListMaps(context.get(), pb::ListMapsRequest(), &response);
            !s.ok()) {
          return ToStatus(s);
        }
        return std::vector<pb::MapInfo>(response.maps().begin(), response.maps().end());
      });
}

absl::StatusOr<pb::ServerInfo> RemoteClient::GetServerInfo() {
  return Retried<pb::ServerInfo>(true, [&]() -> absl::StatusOr<pb::ServerInfo> {
    pb::ServerInfo info;
    const auto context = NewContext();
    if (grpc::Status s = stub_->GetServerInfo(context.get(), pb::GetServerInfoRequest(), &info);
        !s.ok()) {
      return ToStatus(s);
    }
    return info;
  });
}

absl::StatusOr<pb::MapInfo> RemoteClient::SaveMap(const std::string& name) {
  return Retried<pb::MapInfo>(true, [&]() -> absl::StatusOr<pb::MapInfo> {
    pb::SaveMapRequest request;
    request.set_name(name);
    pb::MapInfo info;
    const auto context = NewContext(kRemoteFileDeadline, name);
    if (grpc::Status s = stub_->SaveMap(context.get(), request, &info); !s.ok()) {
      return ToStatus(s);
    }
    return info;
  });
}

absl::StatusOr<pb::MapInfo> RemoteClient::LoadMap(const std::string& name) {
  return Retried<pb::MapInfo>(true, [&]() -> absl::StatusOr<pb::MapInfo> {
    pb::LoadMapRequest request;
    request.set_name(name);
    pb::MapInfo info;
    const auto context = NewContext(kRemoteFileDeadline, name);
    if (grpc::Status s = stub_->LoadMap(context.get(), request, &info); !s.ok()) {
      return ToStatus(s);
    }
    return info;
  });
}

absl::StatusOr<pb::RenderResponse> RemoteClient::Render(const pb::RenderRequest& request) {
  return Retried<pb::RenderResponse>(true, [&]() -> absl::StatusOr<pb::RenderResponse> {
    pb::RenderResponse response;
    const auto context = NewContext(kRemoteUnaryDeadline, request.map());
    if (grpc::Status s = stub_->Render(context.get(), request, &response); !s.ok()) {
      return ToStatus(s);
    }
    return response;
  });
}

std::unique_ptr<RemoteClient> ConnectOrReport(const std::string& command,
                                              const RemoteOptions& options, int* exit_code) {
  if (options.server.empty()) {
    *exit_code = ReportError(
        command,
        absl::InvalidArgumentError(absl::StrCat(
            "this command talks to a plenoxd daemon: give --server HOST:PORT before it, e.g. "
            "plenox --server 127.0.0.1:50051 ",
            command, " ...")),
        /*usage_error=*/true);
    return nullptr;
  }
  absl::StatusOr<std::unique_ptr<RemoteClient>> client = RemoteClient::Create(options);
  if (!client.ok()) {
    *exit_code = ReportError(command, client.status(), /*usage_error=*/true);
    return nullptr;
  }
  if (absl::Status s = (*client)->Connect(); !s.ok()) {
    *exit_code = ReportError(command, s);
    return nullptr;
  }
  return std::move(*client);
}

absl::StatusOr<FrameEncoding> ParseWireEncoding(const std::string& text) {
  if (text == "png") return FrameEncoding{pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_PNG16};
  if (text == "raw") return FrameEncoding{pb::COLOR_ENCODING_RAW_RGB8, pb::DEPTH_ENCODING_RAW_U16};
  return absl::InvalidArgumentError(
      absl::StrFormat("--encoding must be png or raw, got \"%s\"", text));
}

void AddWireEncodingFlag(FlagSet& flags) {
  flags.Add("encoding", "png|raw", "how frames travel: PNG, or raw RGB8 + uint16 (no codec)",
            "png");
}

absl::StatusOr<pb::Frame> LoadFrameToProto(const RgbdDataset& dataset, int index, bool with_pose,
                                           const FrameEncoding& encoding) {
  PLX_ASSIGN_OR_RETURN(const RgbdFrame frame, dataset.LoadFrame(index));
  if (with_pose && !frame.ground_truth) {
    return absl::InvalidArgumentError(
        absl::StrFormat("frame at t=%.6f has no ground-truth pose", frame.timestamp));
  }
  return FrameToProto(frame, dataset.calibration(),
                      with_pose ? frame.ground_truth : std::optional<SE3>(), encoding, "plenox");
}

const char* TrackingStateText(pb::TrackingState state) {
  const std::optional<TrackingState> core = TrackingStateFromProto(state);
  return core ? TrackingStateName(*core) : "?";
}

const char* SlamStateText(pb::SlamState state) {
  const std::optional<SlamState> core = SlamStateFromProto(state);
  return core ? SlamStateName(*core) : "?";
}

TrackOptionsFields TrackOptionsFieldsFromFlags(const FlagSet& flags) {
  return {.rays = flags.IsSet("rays"),
          .iterations = flags.IsSet("iterations"),
          .pixels = flags.IsSet("pixels")};
}

}  // namespace plx::cli
