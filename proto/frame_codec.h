// plenoxd.v1 Frame and Intrinsics <-> core's frames and calibrations. From the wire (the
// daemon): every check on a client's frame lives here and names the field it rejects (e.g.
// "frame.intrinsics.fx"), so handlers only convert, call core and map the status. To the wire
// (the CLI, the fuzzers' seeds): a frame's images encoded as PNG, JPEG or raw bytes.
// (Render responses: proto/render_codec.h; maps: proto/map_codec.h; poses: proto/pose_codec.h.)
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "proto/pose_codec.h"
#include "proto/wire.h"

namespace plx {

void IntrinsicsToProto(const PinholeIntrinsics& k, double depth_scale, pb::Intrinsics* out);

// With require_depth_scale, depth_scale must be positive (incoming depth images).
absl::StatusOr<CameraCalibration> IntrinsicsFromProto(const pb::Intrinsics& intrinsics,
                                                      const std::string& field,
                                                      bool require_depth_scale);

// A frame whose cheap checks passed on the gRPC thread: intrinsics, timestamp and pose, the
// encodings, raw byte counts, and the PNG/JPEG headers against the intrinsics and the pixel
// limit. Its images are still encoded: DecodeCheckedFrame decodes them in the stream's task on
// a device worker, so no gRPC callback thread ever runs a codec, and a frame that latest-wins
// tracking drops is never decoded.
struct CheckedFrame {
  pb::Frame frame;    // the wire frame (images encoded)
  std::string field;  // names the frame in errors: "frame", "frame[3]"
  CameraCalibration calibration;
  // The pose the client sent with the frame (world_T_camera), if any: the pose prior for
  // Track, the keyframe's pose for Integrate (where CheckFrame requires it).
  std::optional<SE3> client_pose;
};

struct DecodedFrame {
  RgbdFrame frame;  // colour in [0,1], depth in metres; no ground truth (a client sends none)
  CameraCalibration calibration;
  std::string camera_id;
  std::optional<SE3> client_pose;
};

// Checks a frame without decoding it (see CheckedFrame). `require_pose`: Integrate needs one on
// every frame. Frames over `max_pixels` (the intrinsics' width x height) are
// RESOURCE_EXHAUSTED; every other failure is INVALID_ARGUMENT naming the field.
absl::StatusOr<CheckedFrame> CheckFrame(pb::Frame frame, const std::string& field,
                                        bool require_pose, int64_t max_pixels);

// How a frame's images travel: colour as PNG, JPEG (lossy, smallest) or raw RGB8; depth as
// 16-bit PNG or raw little-endian uint16, both in units of the calibration's depth_scale.
struct FrameEncoding {
  pb::ColorEncoding color = pb::COLOR_ENCODING_PNG;
  pb::DepthEncoding depth = pb::DEPTH_ENCODING_PNG16;
};

// `frame` as a Frame message that CheckFrame accepts: its timestamp, the calibration's
// intrinsics and depth_scale, the images in `encoding`, `camera_id`, and `pose` when given.
// INVALID_ARGUMENT for an encoding other than the ones above; the image codec's errors.
absl::StatusOr<pb::Frame> FrameToProto(const RgbdFrame& frame, const CameraCalibration& calibration,
                                       const std::optional<SE3>& pose,
                                       const FrameEncoding& encoding, const std::string& camera_id);

// Decodes a checked frame's images (INVALID_ARGUMENT naming the field when the data behind a
// good header is corrupt; RESOURCE_EXHAUSTED when memory runs out).
absl::StatusOr<DecodedFrame> DecodeCheckedFrame(CheckedFrame checked);

}  // namespace plx
