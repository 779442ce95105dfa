// The token and TLS files (server/secret_files.h): bad ones are reported as themselves, naming
// the file, before any server starts.
#include "server/secret_files.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;

std::string WriteFile(const std::string& dir, const std::string& name, const std::string& text,
                      mode_t mode = 0600) {
  const std::string path = dir + "/" + name;
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
  chmod(path.c_str(), mode);
  return path;
}

TEST(AuthTokenFileTest, TrimsTheEndsAndRefusesWhitespaceOrControlsInside) {
  const std::string dir = plx::testing::MakeTempDir("plx_token");
  absl::StatusOr<std::string> token = ReadAuthTokenFile(WriteFile(dir, "ok", "  s3cret-token\n"));
  ASSERT_TRUE(token.ok()) << token.status();
  EXPECT_EQ(*token, "s3cret-token");

  for (const std::string& bad :
       {std::string("two words\n"), std::string("tab\tinside"), std::string("nul\0x", 5),
        std::string("bell\x07"), std::string("line\nbreak\n"), std::string("caf\xc3\xa9")}) {
    const std::string path = WriteFile(dir, "bad", bad);
    const absl::StatusOr<std::string> r = ReadAuthTokenFile(path);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), AllOf(HasSubstr(path), HasSubstr("printable ASCII")));
  }
  const std::string empty = WriteFile(dir, "empty", " \n");
  EXPECT_THAT(ReadAuthTokenFile(empty).status().message(),
              AllOf(HasSubstr(empty), HasSubstr("empty")));
  EXPECT_THAT(ReadAuthTokenFile(dir + "/missing").status().message(), HasSubstr(dir + "/missing"));
}

TEST(AuthTokenFileTest, WarnsWhenGroupOrOthersCanReadIt) {
  const std::string dir = plx::testing::MakeTempDir("plx_token_mode");
  const std::string open_file = WriteFile(dir, "open", "tok\n", 0644);
  ::testing::internal::CaptureStderr();
  EXPECT_TRUE(ReadAuthTokenFile(open_file).ok());
  const std::string warned = ::testing::internal::GetCapturedStderr();
  EXPECT_THAT(warned, AllOf(HasSubstr("level=warning"), HasSubstr("event=token_file_readable"),
                            HasSubstr(open_file), HasSubstr("mode=0644"), Not(HasSubstr("tok\n"))));

  const std::string private_file = WriteFile(dir, "private", "tok\n", 0600);
  ::testing::internal::CaptureStderr();
  EXPECT_TRUE(ReadAuthTokenFile(private_file).ok());
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

// A throwaway EC key and self-signed certificate from the openssl command (as the CLI's TLS test
// makes them); empty when the command is missing or fails.
bool MakeCertificate(const std::string& dir, const std::string& name) {
  if (!std::filesystem::exists("/usr/bin/openssl")) return false;
  const std::string command = absl::StrCat(
      "/usr/bin/openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes "
      "-keyout ",
      dir, "/", name, ".key -out ", dir, "/", name,
      ".crt -subj /CN=localhost -days 1 > /dev/null 2>&1");
  return std::system(command.c_str()) == 0;
}

TEST(TlsFilesTest, BadCertificateOrKeyFilesAreNamed) {
  const std::string dir = plx::testing::MakeTempDir("plx_tls");
  if (!MakeCertificate(dir, "a") || !MakeCertificate(dir, "b")) {
    GTEST_SKIP() << "needs /usr/bin/openssl to make certificates";
  }
  const std::string cert = dir + "/a.crt", key = dir + "/a.key", other_key = dir + "/b.key";
  absl::StatusOr<TlsPem> good = ReadTlsFiles(cert, key);
  ASSERT_TRUE(good.ok()) << good.status();
  EXPECT_THAT(good->cert_pem, HasSubstr("BEGIN CERTIFICATE"));

  const std::string garbage = WriteFile(dir, "garbage.pem", "-----BEGIN CERTIFICATE-----\nzz\n");
  const struct {
    std::string cert, key, names, says;
  } cases[] = {
      {dir + "/none.crt", key, dir + "/none.crt", "cannot read"},
      {cert, dir + "/none.key", dir + "/none.key", "cannot read"},
      {garbage, key, garbage, "not a PEM certificate"},
      {key, key, key, "not a PEM certificate"},
      {cert, cert, cert, "not an unencrypted PEM private key"},
      {cert, garbage, garbage, "not an unencrypted PEM private key"},
      {cert, other_key, other_key, "does not belong to the certificate in " + cert},
  };
  for (const auto& c : cases) {
    const absl::StatusOr<TlsPem> r = ReadTlsFiles(c.cert, c.key);
    ASSERT_FALSE(r.ok()) << c.cert << " " << c.key;
    EXPECT_THAT(r.status().message(), AllOf(HasSubstr(c.names + ": "), HasSubstr(c.says)))
        << c.cert << " " << c.key;
  }
}

// Daemon::Start with a certificate gRPC cannot use says so, not "address in use".
TEST(TlsFilesTest, DaemonStartReportsABadCertificateAsSuch) {
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_tls_daemon"));
  o.tls_cert_pem = "not a certificate";
  o.tls_key_pem = "not a key";
  const absl::StatusOr<std::unique_ptr<Daemon>> d = Daemon::Start(o);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument) << d.status();
  EXPECT_THAT(d.status().message(),
              AllOf(HasSubstr("TLS certificate: not a PEM certificate"), Not(HasSubstr("in use"))));
}

}  // namespace
}  // namespace plx::server::testing
