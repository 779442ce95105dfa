#include "server/secret_files.h"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <sys/stat.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "server/log.h"

namespace plx::server {
namespace {

// Secrets are small; the bound keeps a mistaken path (a device, a huge file) from being read
// into memory whole.
constexpr size_t kMaxSecretFileBytes = 1 << 20;

absl::StatusOr<std::string> ReadSmallFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot read the file"));
  std::string bytes(kMaxSecretFileBytes + 1, '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (in.bad()) return absl::NotFoundError(absl::StrCat(path, ": cannot read the file"));
  bytes.resize(static_cast<size_t>(in.gcount()));
  if (bytes.size() > kMaxSecretFileBytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": larger than ", kMaxSecretFileBytes, " bytes, not a key file"));
  }
  return bytes;
}

// The reason OpenSSL gave for its last failure (its error queue is per thread), then cleared.
std::string OpenSslReason() {
  const unsigned long code = ERR_peek_last_error();
  std::string reason = "unknown reason";
  if (code != 0) {
    const char* text = ERR_reason_error_string(code);
    if (text != nullptr) reason = text;
  }
  ERR_clear_error();
  return reason;
}

struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct PkeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
using BioPtr = std::unique_ptr<BIO, BioFree>;

BioPtr MemoryBio(const std::string& text) {
  return BioPtr(BIO_new_mem_buf(text.data(), static_cast<int>(text.size())));
}

// Without a callback OpenSSL would prompt on the terminal for an encrypted key's passphrase;
// the daemon has none to give, so such a key is an error.
int NoPassphrase(char*, int, int, void*) { return 0; }

}  // namespace

absl::StatusOr<std::string> ReadAuthTokenFile(const std::string& path) {
  absl::StatusOr<std::string> text = ReadSmallFile(path);
  if (!text.ok()) return text.status();
  struct stat st {};
  if (stat(path.c_str(), &st) == 0 && (st.st_mode & (S_IRGRP | S_IROTH)) != 0) {
    LogEvent("warning", "token_file_readable",
             {{"file", path},
              {"mode", absl::StrFormat("%04o", st.st_mode & 07777)},
              {"message", "group or others can read the bearer token; chmod 600 the file"}});
  }
  const std::string token(absl::StripAsciiWhitespace(*text));
  if (token.empty()) return absl::InvalidArgumentError(absl::StrCat(path, ": the file is empty"));
  for (size_t i = 0; i < token.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(token[i]);
    if (c <= 0x20 || c >= 0x7F) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s: the token must be printable ASCII without spaces; character %d (after trimming) "
          "is 0x%02x",
          path, i + 1, c));
    }
  }
  return token;
}

absl::Status CheckTlsPem(const TlsPem& pem, const std::string& cert_name,
                         const std::string& key_name) {
  ERR_clear_error();
  BioPtr cert_bio = MemoryBio(pem.cert_pem);
  std::unique_ptr<X509, X509Free> leaf(
      cert_bio ? PEM_read_bio_X509(cert_bio.get(), nullptr, NoPassphrase, nullptr) : nullptr);
  if (!leaf) {
    return absl::InvalidArgumentError(
        absl::StrCat(cert_name, ": not a PEM certificate (", OpenSslReason(), ")"));
  }
  BioPtr key_bio = MemoryBio(pem.key_pem);
  std::unique_ptr<EVP_PKEY, PkeyFree> key(
      key_bio ? PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr) : nullptr);
  if (!key) {
    return absl::InvalidArgumentError(
        absl::StrCat(key_name, ": not an unencrypted PEM private key (", OpenSslReason(), ")"));
  }
  if (X509_check_private_key(leaf.get(), key.get()) != 1) {
    ERR_clear_error();
    return absl::InvalidArgumentError(
        absl::StrCat(key_name, ": the key does not belong to the certificate in ", cert_name));
  }
  return absl::OkStatus();
}

absl::StatusOr<TlsPem> ReadTlsFiles(const std::string& cert_path, const std::string& key_path) {
  TlsPem pem;
  absl::StatusOr<std::string> cert = ReadSmallFile(cert_path);
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = ReadSmallFile(key_path);
  if (!key.ok()) return key.status();
  pem.cert_pem = *std::move(cert);
  pem.key_pem = *std::move(key);
  if (absl::Status s = CheckTlsPem(pem, cert_path, key_path); !s.ok()) return s;
  return pem;
}

}  // namespace plx::server
