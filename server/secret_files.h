// The daemon's secrets on disk: the bearer-token file and the TLS certificate and key. They are
// read and checked before anything starts, so a bad file is reported as itself, naming the
// file, instead of surfacing later as a server that "cannot listen".
#pragma once

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace plx::server {

// The token in `path`. Leading and trailing whitespace (the usual final newline) is trimmed;
// what is left must be non-empty printable ASCII with no space inside, the only thing a client
// can send in an "authorization" header. Logs a warning (token_file_readable) when group or
// others may read the file. Errors name the file but never echo the token.
absl::StatusOr<std::string> ReadAuthTokenFile(const std::string& path);

struct TlsPem {
  std::string cert_pem;  // certificate chain, leaf first
  std::string key_pem;   // the leaf's private key, unencrypted
};

// Reads both files and checks them with CheckTlsPem; errors name the file at fault.
absl::StatusOr<TlsPem> ReadTlsFiles(const std::string& cert_path, const std::string& key_path);

// Parses the PEM text as gRPC will: at least one X.509 certificate, an unencrypted private
// key, and the key belonging to the first certificate. InvalidArgumentError "<cert_name>: ..."
// or "<key_name>: ..." naming the part at fault.
absl::Status CheckTlsPem(const TlsPem& pem, const std::string& cert_name,
                         const std::string& key_name);

}  // namespace plx::server
