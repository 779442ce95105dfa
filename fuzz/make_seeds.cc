// Writes the seed corpus of every harness (fuzz/corpus/<harness>/) with the project's own
// writers, so the seeds are inputs the readers must accept and the fuzzer starts from deep,
// valid states instead of having to discover PNG chunk CRCs or map checksums by chance.
//   plx_fuzz_seeds DIR    (scripts/fuzz.sh --seeds runs it on fuzz/corpus)
// The seeds are small on purpose: a few 8x6 images, maps of at most two bricks with the
// payload cut off (map_file_fuzzer.cc puts it back), three-pose trajectories.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/datasets/dataset.h"
#include "core/formats/calibration_file.h"
#include "core/formats/map_file.h"
#include "core/formats/map_keyframes_codec.h"
#include "core/formats/pose_text.h"
#include "core/formats/trajectory_file.h"
#include "core/io/image_io.h"
#include "plenoxd/v1/plenoxd.pb.h"
#include "proto/frame_codec.h"

namespace {

namespace fs = std::filesystem;
namespace pb = ::plenoxd::v1;

constexpr int kWidth = 8, kHeight = 6;

void Die(const std::string& what) {
  std::fprintf(stderr, "plx_fuzz_seeds: %s\n", what.c_str());
  std::exit(1);
}

template <typename T>
T OrDie(absl::StatusOr<T> value) {
  if (!value.ok()) Die(value.status().ToString());
  return *std::move(value);
}

void OrDie(const absl::Status& status) {
  if (!status.ok()) Die(status.ToString());
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  if (!in) Die("cannot read " + path);
  return s.str();
}

void Write(const fs::path& dir, const std::string& name, const std::string& bytes) {
  fs::create_directories(dir);
  std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) Die("cannot write " + (dir / name).string());
}

// A gradient with some structure, so the codecs emit more than one run.
plx::ColorImage Color() {
  plx::ColorImage image(plx::Image<float>(kWidth, kHeight, 3));
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      float* p = image.pixel(u, v);
      p[0] = u / float(kWidth - 1);
      p[1] = v / float(kHeight - 1);
      p[2] = ((u + v) % 2) * 0.5f;
    }
  }
  return image;
}

plx::DepthImage Depth() {
  plx::DepthImage image(plx::Image<float>(kWidth, kHeight, 1));
  for (int v = 0; v < kHeight; ++v) {
    for (int u = 0; u < kWidth; ++u) {
      *image.pixel(u, v) = (u == 0 && v == 0) ? 0.0f : 1.0f + 0.1f * u;
    }
  }
  return image;
}

plx::SE3 Pose(double t) {
  return plx::SE3(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * t, Eigen::Vector3d(0, 1, 0.2).normalized())),
      Eigen::Vector3d(0.1 * t, -0.2, 1.5 + t));
}

plx::CameraCalibration Calibration() {
  plx::CameraCalibration c;
  c.pinhole = {535.4, 539.2, 320.1, 247.6, 640, 480};
  c.depth_scale = 5000.0;
  c.distortion = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  return c;
}

void ImageSeeds(const fs::path& dir) {
  Write(dir, "color.png", OrDie(plx::EncodeColorImage(Color(), ".png")));
  Write(dir, "color.jpg", OrDie(plx::EncodeColorImage(Color(), ".jpg")));
  Write(dir, "depth.png", OrDie(plx::EncodeDepthImage(Depth(), 5000.0)));
}

// Frames as the CLI sends them (proto/frame_codec.h FrameToProto), in each encoding.
void FrameSeeds(const fs::path& dir) {
  auto frame = [](pb::ColorEncoding color, pb::DepthEncoding depth, bool with_pose) {
    plx::RgbdFrame f;
    f.timestamp = 1.5;
    f.color = Color();
    f.depth = Depth();
    plx::CameraCalibration c;
    c.pinhole = {6.0, 6.0, 4.0, 3.0, kWidth, kHeight};
    c.depth_scale = 5000.0;
    const std::optional<plx::SE3> pose =
        with_pose ? std::optional<plx::SE3>(Pose(1.0)) : std::nullopt;
    return OrDie(plx::FrameToProto(f, c, pose, {color, depth}, "cam0")).SerializeAsString();
  };
  Write(dir, "png_png16_pose", frame(pb::COLOR_ENCODING_PNG, pb::DEPTH_ENCODING_PNG16, true));
  Write(dir, "jpeg_raw", frame(pb::COLOR_ENCODING_JPEG, pb::DEPTH_ENCODING_RAW_U16, false));
  Write(dir, "raw_raw_pose", frame(pb::COLOR_ENCODING_RAW_RGB8, pb::DEPTH_ENCODING_RAW_U16, true));
}

void MapSeeds(const fs::path& dir, const fs::path& scratch) {
  // Whole files (mode 0) only for the empty map: a brick is 57 KB of payload.
  auto saved = [&](const std::vector<plx::BrickCoord>& bricks) {
    plx::PlenoxelMap map(0.02f);
    map.source = "fuzz seed";
    OrDie(map.grid.AllocateBricks(bricks).status());
    const std::string path = (scratch / "seed.plx").string();
    OrDie(plx::SaveMap(map, path));
    return ReadAll(path);
  };
  Write(dir, "empty_whole", std::string(1, '\0') + saved({}));
  // Mode 1: header and brick table; the harness pads the payload and appends the CRC.
  for (const auto& [name, bricks] :
       std::vector<std::pair<std::string, std::vector<plx::BrickCoord>>>{
           {"one_brick", {{0, 0, 0}}}, {"two_bricks", {{1, -1, 2}, {-3, 0, 5}}}}) {
    const std::string file = saved(bricks);
    const size_t keep = 88 + std::string("fuzz seed").size() + 12 * bricks.size();
    Write(dir, name, std::string(1, '\1') + file.substr(0, keep));
  }
  // Format version 2, mode 1: header, brick table and the keyframe section (a keyframe with
  // three keypoints and a 4x3 thumbnail, one without features); the harness pads the payload.
  {
    plx::PlenoxelMap map(0.02f);
    map.source = "fuzz seed";
    OrDie(map.grid.AllocateBricks({{0, 0, 0}}).status());
    plx::MapFileState state;
    state.map_version = 12;
    auto features = std::make_shared<plx::FrameFeatures>();
    for (int i = 0; i < 3; ++i) {
      features->pixels.emplace_back(1.5f + i, 2.5f);
      features->points.emplace_back(0.1f * i, 0.0f, 1.0f);
      plx::OrbDescriptor d{};
      d[0] = static_cast<uint8_t>(i);
      features->descriptors.push_back(d);
    }
    features->thumbnail_width = 4;
    features->thumbnail_height = 3;
    features->thumbnail.assign(12, 0.25f);
    plx::MapKeyframe k;
    k.timestamp = 1.5;
    k.pose = Pose(1.0);
    k.intrinsics = {6.0, 6.0, 4.0, 3.0, kWidth, kHeight};
    k.features = features;
    state.keyframes.push_back(k);
    k.features = nullptr;
    state.keyframes.push_back(k);
    const std::string path = (scratch / "seed_v2.plx").string();
    OrDie(plx::SaveMap(map, state, path));
    const std::string file = ReadAll(path);
    const size_t section = plx::EncodedMapKeyframeBytes(state.keyframes[0]) +
                           plx::EncodedMapKeyframeBytes(state.keyframes[1]);
    const size_t keep = 108 + std::string("fuzz seed").size() + 12 + section;
    Write(dir, "keyframes_v2", std::string(1, '\1') + file.substr(0, keep));
  }
}

void TextSeeds(const fs::path& dir, const fs::path& scratch) {
  const std::string trajectory = (scratch / "trajectory.txt").string();
  OrDie(plx::WriteTumTrajectory(trajectory,
                                {{1.0, Pose(1.0)}, {1.033333, Pose(1.5)}, {1.066667, Pose(2.0)}},
                                "timestamp tx ty tz qx qy qz qw"));
  Write(dir, "trajectory.txt", ReadAll(trajectory));
  Write(dir, "intrinsics.txt", plx::FormatCalibrationFile(Calibration()));
  // ScanNet's intrinsic/intrinsic_depth.txt; the project reads these but never writes them.
  Write(dir, "intrinsic_depth.txt",
        "577.590698 0.000000 318.905426 0.000000\n0.000000 578.729797 242.683609 0.000000\n"
        "0.000000 0.000000 1.000000 0.000000\n0.000000 0.000000 0.000000 1.000000\n");
  Write(dir, "pose_flag", plx::FormatPoseText(Pose(1.0)));
  Write(dir, "intrinsics_flag", "535.4 539.2 320.1 247.6 640 480");
}

void TumSeeds(const fs::path& dir, const fs::path& scratch) {
  // WriteTumDataset names images rgb/<%.6f stamp>.png: stamps 1 and 2 give the files
  // tum_lists_fuzzer.cc creates.
  std::vector<plx::RgbdFrame> frames(2);
  for (int i = 0; i < 2; ++i) {
    frames[i].timestamp = 1.0 + i;
    frames[i].color = Color();
    frames[i].depth = Depth();
    frames[i].ground_truth = Pose(i);
  }
  plx::CameraCalibration c;
  c.pinhole = {6.0, 6.0, 4.0, 3.0, kWidth, kHeight};
  c.depth_scale = 5000.0;
  const plx::InMemoryDataset dataset("seed", c, frames);
  const fs::path seq = scratch / "tum";
  OrDie(plx::WriteTumDataset(dataset, seq.string()));
  const std::string rgb = ReadAll((seq / "rgb.txt").string());
  const std::string depth = ReadAll((seq / "depth.txt").string());
  const std::string assoc = ReadAll((seq / "associations.txt").string());
  const std::string gt = ReadAll((seq / "groundtruth.txt").string());
  const std::string nul(1, '\0');
  Write(dir, "all_lists", rgb + nul + depth + nul + assoc + nul + gt);
  Write(dir, "matched_lists", rgb + nul + depth + nul + nul + gt);
  Write(dir, "associations_only", nul + nul + assoc);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) Die("usage: plx_fuzz_seeds DIR");
  const fs::path out = argv[1];
  const fs::path scratch =
      fs::temp_directory_path() / ("plx_fuzz_seeds_" + std::to_string(getpid()));
  fs::create_directories(scratch);
  ImageSeeds(out / "fuzz_image");
  FrameSeeds(out / "fuzz_frame_proto");
  MapSeeds(out / "fuzz_map_file", scratch);
  TextSeeds(out / "fuzz_text_files", scratch);
  TumSeeds(out / "fuzz_tum_lists", scratch);
  fs::remove_all(scratch);
  return 0;
}
