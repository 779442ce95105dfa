// The synthetic room sequence at a test's size, for suites that build it once in
// SetUpTestSuite (generation is deterministic: the same options give the same frames).
#pragma once

#include <memory>

#include <gtest/gtest.h>

#include "core/synthetic/synthetic_sequence.h"

namespace plx::testing {

// The synthetic sequences' camera at `width` x `height` (for views rendered one at a time).
inline PinholeIntrinsics SyntheticCamera(int width, int height) {
  SyntheticOptions o;
  o.width = width;
  o.height = height;
  return SyntheticCalibration(o).pinhole;
}

// `width` x `height`, `frames` frames; depth noise (metres at 1 m) and hole fraction optional.
// Fails the calling test (and returns null) when generation fails.
inline std::unique_ptr<InMemoryDataset> MakeSyntheticRoom(int width, int height, int frames,
                                                          double depth_noise = 0.0,
                                                          double hole_fraction = 0.0) {
  SyntheticOptions o;
  o.width = width;
  o.height = height;
  o.num_frames = frames;
  o.depth_noise = depth_noise;
  o.hole_fraction = hole_fraction;
  absl::StatusOr<InMemoryDataset> dataset = GenerateSyntheticSequence(o);
  EXPECT_TRUE(dataset.ok()) << dataset.status();
  if (!dataset.ok()) return nullptr;
  return std::make_unique<InMemoryDataset>(std::move(*dataset));
}

}  // namespace plx::testing
