// The keyframe section of a version-2 map file (core/formats/map_file.h): the map's keyframes
// (core/formats/map_keyframe.h) one after the other, in order. Every number is little-endian,
// each field written on its own; floats are IEEE-754 binary32 (f32) or binary64 (f64).
//
//   size      field
//   8         f64  timestamp, seconds
//   24        f64  pose translation x, y, z (world_T_camera, metres)
//   32        f64  pose rotation, unit quaternion x, y, z, w
//   32        f64  intrinsics fx, fy, cx, cy
//   8         i32  intrinsics width, height
//   4         u32  flags: bit 0 set = the keyframe has features (other bits 0)
//   4         u32  M = keypoints
//   8         u32  thumbnail width TW, height TH
//   8 M       f32  each keypoint's pixel u, v
//   12 M      f32  each keypoint's point x, y, z in the keyframe's camera (metres)
//   32 M      u8   each keypoint's ORB descriptor
//   4 TW TH   f32  the thumbnail, row-major
//
// A keyframe is 120 + 52 M + 4 TW TH bytes: 31 KB for 500 keypoints and a 40x30 thumbnail. One
// without features has flags 0 and M = TW = TH = 0.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/formats/map_keyframe.h"

namespace plx {

// The bytes of a keyframe without features.
inline constexpr int64_t kMapKeyframeFixedBytes = 120;

// What the section needs for `keyframe`.
int64_t EncodedMapKeyframeBytes(const MapKeyframe& keyframe);

// What a keyframe must satisfy to be stored, checked on both sides (the writer refuses what the
// reader would): finite timestamp, a pose inside the world extent, positive finite focal
// lengths, image sides in [1, kMaxImageSide], keypoint arrays of one length with finite values,
// a finite thumbnail of its stated size. InvalidArgument; the message names no keyframe.
absl::Status CheckStorableKeyframe(const MapKeyframe& keyframe);

// Appends `keyframe`'s bytes (CheckStorableKeyframe first; not repeated here).
void AppendEncodedMapKeyframe(const MapKeyframe& keyframe, std::string* out);

// Exactly `count` keyframes from exactly `section`'s bytes. DataLoss "keyframe <i>: ..." for
// anything a writer would not have written: a size that does not add up, a non-unit rotation,
// a failed CheckStorableKeyframe. No allocation exceeds what `section`'s length can back.
absl::StatusOr<MapKeyframes> DecodeMapKeyframes(absl::string_view section, int64_t count);

}  // namespace plx
