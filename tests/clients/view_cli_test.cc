// `plenox view MAP.plx`: starts, prints the page's URL, serves the map list, the points, the
// mesh and renders of the file's map, and stops cleanly (exit 0) on SIGINT, as Ctrl-C sends it. Its
// usage errors and a missing three.js end it at once with a message.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tests/clients/cli_runner.h"
#include "tests/ply_mesh_reader.h"
#include "tests/test_util.h"

namespace plx::testing {
namespace {

namespace fs = std::filesystem;

bool HaveThreeJs() { return fs::exists("/usr/share/javascript/three/three.min.js"); }

// GET `path` from 127.0.0.1:`port` over HTTP/1.0: the whole response, or empty.
std::string HttpGet(int port, const std::string& path) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return "";
  timeval tv{10, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string response;
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) {
    const std::string request = "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) ==
        static_cast<ssize_t>(request.size())) {
      char buffer[4096];
      for (ssize_t n; (n = ::recv(fd, buffer, sizeof(buffer), 0)) > 0;) response.append(buffer, n);
    }
  }
  ::close(fd);
  return response;
}

// `plenox view` as a background process, its stdout in a file.
class ViewProcess {
 public:
  ViewProcess(const std::string& dir, const std::vector<std::string>& args)
      : out_(dir + "/view.out") {
    std::vector<std::string> storage = {kPlenoxBinary, "view"};
    storage.insert(storage.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& s : storage) argv.push_back(s.data());
    argv.push_back(nullptr);
    pid_ = ::fork();
    if (pid_ == 0) {
      ::setpgid(0, 0);
      const int out = ::open(out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      const int in = ::open("/dev/null", O_RDONLY);
      if (out < 0 || in < 0 || ::dup2(in, 0) < 0 || ::dup2(out, 1) < 0 || ::dup2(out, 2) < 0) {
        ::_exit(127);
      }
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
  }
  ~ViewProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }

  // The port of the printed URL, or -1 when none came within `seconds` (or the process ended).
  int WaitForPort(double seconds) {
    const std::string marker = "at http://127.0.0.1:";
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
    while (std::chrono::steady_clock::now() < deadline && pid_ > 0) {
      const std::string out = Output();
      const size_t at = out.find(marker);
      if (at != std::string::npos && out.find('\n', at) != std::string::npos) {
        return std::atoi(out.c_str() + at + marker.size());
      }
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }

  // Sends `signal` and waits up to `seconds`: the exit code, -1 when killed at the deadline.
  int Stop(int signal, double seconds) {
    if (pid_ <= 0) return exit_code_;
    ::kill(pid_, signal);
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) return -1;  // the destructor kills it
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

  std::string Output() const { return ReadFileToString(out_); }

 private:
  std::string out_;
  pid_t pid_ = -1;
  int exit_code_ = -1;
};

class ViewCliTest : public ::testing::Test {
 protected:
  // A tiny map of the synthetic room, made once.
  static void SetUpTestSuite() {
    root_ = new std::string(MakeTempDir("plenox_view"));
    map_ = new std::string(*root_ + "/tiny.plx");
    setup_ = new CommandResult(RunPlenox(
        {"synth", "--out", *root_ + "/dataset", "--frames", "12", "--width", "48", "--height",
         "36"}));
    if (setup_->exit_code == 0) {
      *setup_ = RunPlenox({"map", "--dataset", *root_ + "/dataset", "--out", *map_,
                           "--iterations", "1", "--voxel-size", "0.08", "--threads", "2",
                           "--quiet"});
    }
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(*root_, ec);
    delete setup_;
    delete map_;
    delete root_;
  }
  void SetUp() override { ASSERT_EQ(setup_->exit_code, 0) << setup_->Describe(); }

  static std::string* root_;
  static std::string* map_;
  static CommandResult* setup_;
};
std::string* ViewCliTest::root_ = nullptr;
std::string* ViewCliTest::map_ = nullptr;
CommandResult* ViewCliTest::setup_ = nullptr;

TEST_F(ViewCliTest, ServesTheMapUntilInterrupted) {
  if (!HaveThreeJs()) GTEST_SKIP() << "Debian's libjs-three is not installed";
  ViewProcess view(*root_, {*map_, "--port", "0", "--backend", "cpu", "--threads", "2"});
  const int port = view.WaitForPort(30);
  ASSERT_GT(port, 0) << view.Output();
  EXPECT_NE(view.Output().find("/viewer/ (Ctrl-C stops)"), std::string::npos) << view.Output();

  const std::string maps = HttpGet(port, "/viewer/api/maps");
  EXPECT_EQ(maps.rfind("HTTP/1.1 200", 0), 0u) << maps;
  EXPECT_NE(maps.find("\"name\":\"tiny\""), std::string::npos) << maps;
  EXPECT_NE(maps.find("\"title\":\"plenox view "), std::string::npos) << maps;
  const std::string page = HttpGet(port, "/viewer/");
  EXPECT_EQ(page.rfind("HTTP/1.1 200", 0), 0u);
  EXPECT_NE(page.find("/viewer/viewer.js"), std::string::npos);
  const std::string points = HttpGet(port, "/viewer/api/points?map=tiny");
  EXPECT_EQ(points.rfind("HTTP/1.1 200", 0), 0u) << points.substr(0, 300);
  EXPECT_NE(points.find("\r\n\r\nply\n"), std::string::npos);
  const std::string render = HttpGet(
      port, "/viewer/api/render?map=tiny&pose=0%2C0%2C1%2C0%2C0%2C0%2C1&width=32&height=24&fov=60");
  EXPECT_EQ(render.rfind("HTTP/1.1 200", 0), 0u) << render.substr(0, 300);
  EXPECT_NE(render.find("Content-Type: image/png"), std::string::npos);
  EXPECT_EQ(HttpGet(port, "/viewer/api/points?map=other").rfind("HTTP/1.1 404", 0), 0u);
  // The mesh, made on this process's backend.
  const std::string mesh = HttpGet(port, "/viewer/api/mesh?map=tiny");
  ASSERT_EQ(mesh.rfind("HTTP/1.1 200", 0), 0u) << mesh.substr(0, 300);
  const size_t mesh_body = mesh.find("\r\n\r\n");
  ASSERT_NE(mesh_body, std::string::npos);
  absl::StatusOr<PlyMeshFile> read = ReadPlyMesh(mesh.substr(mesh_body + 4));
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_GT(read->mesh.num_triangles(), 10);
  EXPECT_EQ(HttpGet(port, "/viewer/api/mesh?map=other").rfind("HTTP/1.1 404", 0), 0u);
  // No SLAM without a daemon: an empty camera list.
  EXPECT_NE(HttpGet(port, "/viewer/api/trajectory?map=tiny").find("\"cameras\":[]"),
            std::string::npos);

  EXPECT_EQ(view.Stop(SIGINT, 10), 0) << view.Output();
  EXPECT_NE(view.Output().find("plenox view: stopping"), std::string::npos) << view.Output();
  EXPECT_TRUE(HttpGet(port, "/viewer/api/maps").empty()) << "still serving after SIGINT";
}

TEST_F(ViewCliTest, UsageErrorsAndAMissingThreeJsEndAtOnce) {
  CommandResult r = RunPlenox({"view"});
  EXPECT_EQ(r.exit_code, 2) << r.Describe();
  EXPECT_NE(r.err.find("plenox view MAP.plx"), std::string::npos) << r.Describe();
  r = RunPlenox({"view", *map_, "--port", "70000"});
  EXPECT_EQ(r.exit_code, 2) << r.Describe();
  r = RunPlenox({"view", *root_ + "/missing.plx"});
  EXPECT_NE(r.exit_code, 0) << r.Describe();
  const std::string empty = MakeTempDir("plenox_view_no_three");
  r = RunPlenox({"view", *map_, "--viewer-three-dir", empty});
  EXPECT_EQ(r.exit_code, 1) << r.Describe();
  EXPECT_NE(r.err.find("libjs-three"), std::string::npos) << r.Describe();
  std::error_code ec;
  fs::remove_all(empty, ec);
  r = RunPlenox({"--server", "127.0.0.1:1", "view", *map_});
  EXPECT_EQ(r.exit_code, 2) << r.Describe();
  EXPECT_NE(r.err.find("in-process only"), std::string::npos) << r.Describe();
}

#ifdef PLENOXD_BINARY
// plenoxd's side of the viewer's flags: documented, and a viewer it cannot serve stops it at once.
TEST(PlenoxdViewerFlagsTest, ViewerNeedsTheHttpPortAndThreeJs) {
  CommandResult r = RunCommand(PLENOXD_BINARY, {"--help"});
  EXPECT_EQ(r.exit_code, 0) << r.Describe();
  EXPECT_NE(r.out.find("--viewer "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--viewer-three-dir"), std::string::npos) << r.out;
  r = RunCommand(PLENOXD_BINARY, {"--listen", "127.0.0.1:0", "--viewer"});
  EXPECT_EQ(r.exit_code, 2) << r.Describe();
  EXPECT_NE(r.err.find("--metrics-port"), std::string::npos) << r.Describe();
  const std::string empty = MakeTempDir("plenoxd_no_three");
  r = RunCommand(PLENOXD_BINARY, {"--listen", "127.0.0.1:0", "--metrics-port", "0", "--viewer",
                                  "--viewer-three-dir", empty});
  EXPECT_EQ(r.exit_code, 1) << r.Describe();
  EXPECT_NE(r.err.find("libjs-three"), std::string::npos) << r.Describe();
  std::error_code ec;
  fs::remove_all(empty, ec);
}
#endif

}  // namespace
}  // namespace plx::testing
