#include "core/datasets/dataset.h"

#include <cmath>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::HasSubstr;

TEST(DatasetFormatTest, ParsesAndNamesFormats) {
  for (DatasetFormat format : {DatasetFormat::kAuto, DatasetFormat::kTum, DatasetFormat::kReplica,
                               DatasetFormat::kScanNet}) {
    auto parsed = ParseDatasetFormat(DatasetFormatName(format));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, format);
  }
  EXPECT_EQ(*ParseDatasetFormat("ScanNet"), DatasetFormat::kScanNet);
  auto unknown = ParseDatasetFormat("kitti");
  ASSERT_FALSE(unknown.ok());
  EXPECT_THAT(unknown.status().message(), HasSubstr("kitti"));
  EXPECT_THAT(unknown.status().message(), HasSubstr("tum, replica or scannet"));
}

// Frames at 30 Hz: random colour, random depth with about 20% holes, ground truth on all but
// frame 1 (given with qw < 0 on purpose).
InMemoryDataset MakeSyntheticDataset(int frames, int width, int height, double depth_scale) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::uniform_real_distribution<float> metres(0.3f, 6.0f);
  CameraCalibration calibration;
  calibration.pinhole = PinholeIntrinsics{50, 52, width / 2.0, height / 2.0, width, height};
  calibration.depth_scale = depth_scale;
  std::vector<RgbdFrame> list;
  for (int i = 0; i < frames; ++i) {
    RgbdFrame frame;
    frame.timestamp = 100.0 + i / 30.0;
    frame.color = ColorImage(width, height, 3);
    for (float& c : frame.color.data) c = unit(rng);
    frame.depth = DepthImage(width, height, 1);
    for (float& z : frame.depth.data) z = unit(rng) < 0.2f ? 0.0f : metres(rng);
    if (i != 1) {
      const Eigen::Quaterniond q(-0.5, 0.5 + 0.1 * i, -0.5, 0.5);  // w < 0
      frame.ground_truth = SE3(q, Eigen::Vector3d(i, -2.0 * i, 0.25));
    }
    list.push_back(std::move(frame));
  }
  return InMemoryDataset("synthetic", calibration, std::move(list));
}

TEST(WriteTumDatasetTest, RoundTripReproducesFrames) {
  const InMemoryDataset source = MakeSyntheticDataset(4, 16, 12, 5000);
  const std::string dir = testing::MakeTempDir("write_tum") + "/nested/out";
  ASSERT_TRUE(WriteTumDataset(source, dir).ok());

  auto read = OpenDataset(dir);
  ASSERT_TRUE(read.ok()) << read.status();
  const RgbdDataset& d = **read;
  ASSERT_EQ(d.size(), source.size());
  EXPECT_EQ(d.calibration(), source.calibration());
  for (int i = 0; i < source.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_NEAR(d.timestamp(i), source.timestamp(i), 5e-7);
    auto frame = d.LoadFrame(i);
    ASSERT_TRUE(frame.ok()) << frame.status();
    const RgbdFrame& want = source.frames()[i];
    ASSERT_EQ(frame->color.data.size(), want.color.data.size());
    for (size_t j = 0; j < want.color.data.size(); ++j) {
      ASSERT_NEAR(frame->color.data[j], want.color.data[j], 0.5f / 255.0f + 1e-6f);
    }
    ASSERT_EQ(frame->depth.data.size(), want.depth.data.size());
    for (size_t j = 0; j < want.depth.data.size(); ++j) {
      if (want.depth.data[j] == 0.0f) {
        ASSERT_EQ(frame->depth.data[j], 0.0f);
      } else {
        ASSERT_NEAR(frame->depth.data[j], want.depth.data[j], 0.5 / 5000 + 1e-6);
      }
    }
    EXPECT_EQ(d.ground_truth(i).has_value(), want.ground_truth.has_value());
    if (want.ground_truth.has_value() && d.ground_truth(i).has_value()) {
      EXPECT_NEAR((d.ground_truth(i)->translation() - want.ground_truth->translation()).norm(), 0,
                  1e-12);
      EXPECT_NEAR(RotationAngleBetween(*d.ground_truth(i), *want.ground_truth), 0, 1e-6);
    }
  }

  // groundtruth.txt: 3 poses, quaternions written with qw >= 0.
  const std::string text = testing::ReadTextFile(dir + "/groundtruth.txt");
  int poses = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n', absl::SkipEmpty())) {
    if (line[0] == '#') continue;
    const std::vector<std::string> fields = absl::StrSplit(line, ' ');
    ASSERT_EQ(fields.size(), 8u) << line;
    double qw = -1;
    ASSERT_TRUE(absl::SimpleAtod(fields[7], &qw));
    EXPECT_GE(qw, 0.0) << line;
    ++poses;
  }
  EXPECT_EQ(poses, 3);
  for (const char* name : {"rgb.txt", "depth.txt", "associations.txt", "intrinsics.txt"}) {
    EXPECT_TRUE(std::filesystem::is_regular_file(dir + "/" + name)) << name;
  }
  EXPECT_TRUE(std::filesystem::is_regular_file(dir + "/rgb/100.033333.png"));
}

TEST(WriteTumDatasetTest, DepthBeyondSixteenBitsIsClamped) {
  InMemoryDataset source = MakeSyntheticDataset(1, 4, 4, 5000);
  std::vector<RgbdFrame> frames = source.frames();
  frames[0].depth.data[5] = 20.0f;  // 100000 units at scale 5000
  const InMemoryDataset far("far", source.calibration(), frames);
  const std::string dir = testing::MakeTempDir("write_tum_clamp");
  ASSERT_TRUE(WriteTumDataset(far, dir).ok());
  auto read = OpenDataset(dir);
  ASSERT_TRUE(read.ok()) << read.status();
  auto frame = (*read)->LoadFrame(0);
  ASSERT_TRUE(frame.ok());
  EXPECT_FLOAT_EQ(frame->depth.data[5], 65535 / 5000.0f);
}

TEST(WriteTumDatasetTest, RejectsWhatCannotBeWritten) {
  const InMemoryDataset source = MakeSyntheticDataset(2, 4, 4, 1000);
  std::vector<RgbdFrame> frames = source.frames();
  frames[1].timestamp = frames[0].timestamp + 1e-8;  // same name to the microsecond
  auto same_stamp = WriteTumDataset(InMemoryDataset("dup", source.calibration(), frames),
                                    testing::MakeTempDir("write_tum_dup"));
  EXPECT_THAT(same_stamp.message(), HasSubstr("same timestamp"));

  frames = source.frames();
  frames[1].depth = DepthImage(3, 4, 1);
  auto wrong_size = WriteTumDataset(InMemoryDataset("size", source.calibration(), frames),
                                    testing::MakeTempDir("write_tum_size"));
  EXPECT_THAT(wrong_size.message(), HasSubstr("frame 1"));

  auto empty = WriteTumDataset(InMemoryDataset("empty", source.calibration(), {}),
                               testing::MakeTempDir("write_tum_empty"));
  EXPECT_FALSE(empty.ok());

  // A regular file where the directory should go.
  const std::string blocker = testing::MakeTempDir("write_tum_blocked") + "/file";
  testing::WriteTextFile(blocker, "x");
  EXPECT_FALSE(WriteTumDataset(source, blocker).ok());
}

TEST(OpenDatasetTest, DetectsTumAndExplainsUnknownLayouts) {
  const std::string dir = testing::MakeTempDir("open_detect");
  ASSERT_TRUE(WriteTumDataset(MakeSyntheticDataset(2, 4, 4, 1000), dir).ok());
  auto tum = OpenDataset(dir);
  ASSERT_TRUE(tum.ok()) << tum.status();
  EXPECT_EQ((*tum)->size(), 2);

  // Naming the wrong layout fails instead of guessing.
  DatasetOptions replica;
  replica.format = DatasetFormat::kReplica;
  EXPECT_FALSE(OpenDataset(dir, replica).ok());

  const std::string empty = testing::MakeTempDir("open_unknown");
  auto unknown = OpenDataset(empty);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(unknown.status().message(), HasSubstr("rgb.txt"));
  EXPECT_THAT(unknown.status().message(), HasSubstr("associations.txt"));
  EXPECT_THAT(unknown.status().message(), HasSubstr("traj.txt"));
  EXPECT_THAT(unknown.status().message(), HasSubstr("color/ depth/ pose/"));

  auto missing = OpenDataset("/nonexistent/plx/sequence");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("/nonexistent/plx/sequence"));
}

TEST(WriteTumDatasetTest, RealTeddyFramesRoundTripExactly) {
  const std::string source_dir = testing::SharedSequence("tum_fr3_teddy");
  if (source_dir.empty()) GTEST_SKIP() << "shared data tum_fr3_teddy not found";
  auto source = OpenDataset(source_dir);
  ASSERT_TRUE(source.ok()) << source.status();
  std::vector<RgbdFrame> frames;
  for (int i : {0, 50}) {
    auto frame = (*source)->LoadFrame(i);
    ASSERT_TRUE(frame.ok()) << frame.status();
    frames.push_back(*std::move(frame));
  }
  const InMemoryDataset subset("teddy_subset", (*source)->calibration(), frames);
  const std::string dir = testing::MakeTempDir("write_tum_teddy");
  ASSERT_TRUE(WriteTumDataset(subset, dir).ok());
  auto read = OpenDataset(dir);
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ((*read)->size(), 2);
  for (int i = 0; i < 2; ++i) {
    auto frame = (*read)->LoadFrame(i);
    ASSERT_TRUE(frame.ok());
    // 8-bit colour and 16-bit depth written back at the same scale are lossless.
    EXPECT_EQ(frame->color.data, frames[i].color.data);
    EXPECT_EQ(frame->depth.data, frames[i].depth.data);
    EXPECT_EQ(frame->timestamp, frames[i].timestamp);
    ASSERT_TRUE((*read)->ground_truth(i).has_value());
    EXPECT_NEAR(
        (frame->ground_truth->translation() - frames[i].ground_truth->translation()).norm(), 0,
        1e-12);
  }
}

}  // namespace
}  // namespace plx
