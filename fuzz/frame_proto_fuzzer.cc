// A Track/Integrate frame off the wire: the bytes are parsed as a plenoxd.v1.Frame (what gRPC
// hands the reactors), checked on the "gRPC thread" (CheckFrame: intrinsics, pixel limit,
// timestamp, encodings, raw byte counts, image headers, pose) and decoded as a device worker
// does (DecodeCheckedFrame), all from proto/frame_codec.h.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "fuzz/fuzz_util.h"
#include "proto/frame_codec.h"

namespace {

namespace pb = ::plenoxd::v1;

// Stands in for --max-frame-pixels: small, so that a PNG declaring a large frame is refused
// before decoding rather than decoded for seconds (the check is the same at any limit).
constexpr int64_t kMaxFramePixels = int64_t{1} << 16;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  pb::Frame frame;
  if (!frame.ParseFromArray(data, static_cast<int>(size))) return 0;
  const bool has_pose = frame.has_pose();

  // Integrate requires a pose on every frame; Track takes one as an optional prior. The two
  // must agree on everything else.
  const absl::StatusOr<plx::CheckedFrame> with_pose =
      plx::CheckFrame(frame, "frame[0]", /*require_pose=*/true, kMaxFramePixels);
  absl::StatusOr<plx::CheckedFrame> checked =
      plx::CheckFrame(frame, "frame", /*require_pose=*/false, kMaxFramePixels);
  if (!checked.ok()) {
    PLX_FUZZ_CHECK(!with_pose.ok(), "require_pose accepted what the optional check refused");
    return 0;
  }
  PLX_FUZZ_CHECK(with_pose.ok() == has_pose, "require_pose disagrees with has_pose()");
  PLX_FUZZ_CHECK(checked->client_pose.has_value() == has_pose, "pose lost or invented");
  if (checked->client_pose) {
    const double norm = checked->client_pose->rotation().norm();
    PLX_FUZZ_CHECK(std::abs(norm - 1.0) < 1e-9, "client pose rotation is not a unit quaternion");
  }
  const int w = checked->calibration.pinhole.width, h = checked->calibration.pinhole.height;
  PLX_FUZZ_CHECK(w > 0 && h > 0 && int64_t{w} * h <= kMaxFramePixels, "size passed unchecked");

  const absl::StatusOr<plx::DecodedFrame> decoded =
      plx::DecodeCheckedFrame(*std::move(checked));
  if (!decoded.ok()) return 0;
  const plx::RgbdFrame& f = decoded->frame;
  PLX_FUZZ_CHECK(f.color.width == w && f.color.height == h && f.color.channels == 3,
                 "decoded colour does not match the intrinsics");
  PLX_FUZZ_CHECK(f.depth.width == w && f.depth.height == h && f.depth.channels == 1,
                 "decoded depth does not match the intrinsics");
  PLX_FUZZ_CHECK(f.color.data.size() == size_t(w) * h * 3, "colour buffer size");
  PLX_FUZZ_CHECK(f.depth.data.size() == size_t(w) * h, "depth buffer size");
  for (float v : f.color.data) PLX_FUZZ_CHECK(v >= 0.0f && v <= 1.0f, "colour outside [0, 1]");
  // +inf is allowed: a tiny depth_scale puts samples beyond every max_depth, and every consumer
  // drops depths over its max_depth. NaN would pass a "z <= 0 || z > max" test.
  for (float z : f.depth.data) PLX_FUZZ_CHECK(!std::isnan(z) && z >= 0.0f, "bad depth value");
  return 0;
}
