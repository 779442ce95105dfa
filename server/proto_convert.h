// Wire <-> engine conversions. Every check on client input lives here and names the field it
// rejects (e.g. "frame.intrinsics.fx"), so handlers only convert, call core and map the status.
#pragma once

#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "core/geometry/intrinsics.h"
#include "core/geometry/rgbd_frame.h"
#include "core/geometry/se3.h"
#include "core/render/render_view.h"
#include "plenoxd/v1/plenoxd.pb.h"
#include "proto/pose_codec.h"

namespace plx::server {

namespace pb = ::plenoxd::v1;

// Poses: PoseFromProto / PoseToProto (proto/pose_codec.h, shared with the CLI).

// With require_depth_scale, depth_scale must be positive (incoming depth images).
absl::StatusOr<CameraCalibration> IntrinsicsFromProto(const pb::Intrinsics& intrinsics,
                                                      const std::string& field,
                                                      bool require_depth_scale);

struct DecodedFrame {
  RgbdFrame frame;  // colour in [0,1], depth in metres; no ground truth (a client sends none)
  CameraCalibration calibration;
  std::string camera_id;
  // The pose the client sent with the frame (world_T_camera), if any: the pose prior for
  // Track, the keyframe's pose for Integrate (where FrameFromProto requires it).
  std::optional<SE3> client_pose;
};

// Decodes and checks a frame: intrinsics, encodings, image sizes against the intrinsics, pose
// finite. `require_pose`: Integrate needs one on every frame.
absl::StatusOr<DecodedFrame> FrameFromProto(const pb::Frame& frame, const std::string& field,
                                            bool require_pose);

// Encodes a rendered view for a RenderResponse.
absl::Status RenderedViewToProto(const RenderedView& view, pb::ColorEncoding color_encoding,
                                 pb::DepthEncoding depth_encoding, pb::RenderResponse* out);

// Valid map names: 1-64 characters of [A-Za-z0-9_.-], not starting with '.'.
absl::Status CheckMapName(const std::string& name, const std::string& field);

}  // namespace plx::server
