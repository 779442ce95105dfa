#include "core/formats/map_keyframes_codec.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"

namespace plx {
namespace {

constexpr uint32_t kHasFeatures = 1u;
constexpr int64_t kBytesPerKeypoint = 2 * 4 + 3 * 4 + static_cast<int64_t>(sizeof(OrbDescriptor));
// A rotation read back must be the unit quaternion the writer wrote: binary64 holds it to
// ~1e-16, so anything further off was not written by SaveMap.
constexpr double kUnitQuaternionTolerance = 1e-9;

static_assert(sizeof(OrbDescriptor) == 32, "the section stores 32-byte ORB descriptors");

// Little-endian fields appended to a string.
class SectionWriter {
 public:
  explicit SectionWriter(std::string* out) : out_(out) {}
  void U32(uint32_t v) { Le(v, 4); }
  void I32(int32_t v) { Le(static_cast<uint32_t>(v), 4); }
  void F32(float v) { Le(std::bit_cast<uint32_t>(v), 4); }
  void F64(double v) { Le(std::bit_cast<uint64_t>(v), 8); }
  void Bytes(const void* data, size_t size) {
    out_->append(static_cast<const char*>(data), size);
  }

 private:
  void Le(uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) out_->push_back(static_cast<char>(v >> (8 * i)));
  }
  std::string* out_;
};

// Little-endian fields read from a span whose length every caller checked first (Has).
class SectionReader {
 public:
  explicit SectionReader(absl::string_view bytes) : bytes_(bytes) {}
  int64_t remaining() const { return static_cast<int64_t>(bytes_.size() - at_); }
  bool Has(int64_t n) const { return n >= 0 && n <= remaining(); }
  uint32_t U32() { return static_cast<uint32_t>(Le(4)); }
  int32_t I32() { return static_cast<int32_t>(U32()); }
  float F32() { return std::bit_cast<float>(U32()); }
  double F64() { return std::bit_cast<double>(Le(8)); }
  void Bytes(void* out, size_t size) {
    std::memcpy(out, bytes_.data() + at_, size);
    at_ += size;
  }

 private:
  uint64_t Le(int bytes) {
    uint64_t v = 0;
    for (int i = 0; i < bytes; ++i) {
      v |= uint64_t{static_cast<uint8_t>(bytes_[at_ + i])} << (8 * i);
    }
    at_ += bytes;
    return v;
  }
  absl::string_view bytes_;
  size_t at_ = 0;
};

bool AllFinite(const float* values, size_t count) {
  for (size_t i = 0; i < count; ++i) {
    if (!std::isfinite(values[i])) return false;
  }
  return true;
}

absl::Status CheckFeatures(const FrameFeatures& f) {
  if (f.pixels.size() != f.points.size() || f.descriptors.size() != f.points.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "features: ", f.pixels.size(), " pixels, ", f.points.size(), " points and ",
        f.descriptors.size(), " descriptors (one of each per keypoint)"));
  }
  for (size_t i = 0; i < f.points.size(); ++i) {
    if (!f.pixels[i].allFinite() || !f.points[i].allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("features: keypoint ", i, " is not finite"));
    }
  }
  if (f.thumbnail_width < 0 || f.thumbnail_height < 0 || f.thumbnail_width > kMaxImageSide ||
      f.thumbnail_height > kMaxImageSide || (f.thumbnail_width == 0) != (f.thumbnail_height == 0)) {
    return absl::InvalidArgumentError(absl::StrCat("features: thumbnail size ", f.thumbnail_width,
                                                   " x ", f.thumbnail_height, " is out of range"));
  }
  if (f.thumbnail.size() !=
      static_cast<size_t>(f.thumbnail_width) * static_cast<size_t>(f.thumbnail_height)) {
    return absl::InvalidArgumentError(absl::StrCat("features: a ", f.thumbnail_width, " x ",
                                                   f.thumbnail_height, " thumbnail with ",
                                                   f.thumbnail.size(), " values"));
  }
  if (!AllFinite(f.thumbnail.data(), f.thumbnail.size())) {
    return absl::InvalidArgumentError("features: the thumbnail is not finite");
  }
  return absl::OkStatus();
}

absl::StatusOr<MapKeyframe> DecodeOne(SectionReader& in) {
  if (!in.Has(kMapKeyframeFixedBytes)) {
    return absl::DataLossError(absl::StrCat("needs at least ", kMapKeyframeFixedBytes,
                                            " bytes, the section has ", in.remaining(), " left"));
  }
  MapKeyframe k;
  k.timestamp = in.F64();
  Eigen::Vector3d translation;
  for (int a = 0; a < 3; ++a) translation[a] = in.F64();
  Eigen::Vector4d q;  // x, y, z, w: Eigen's coefficient order
  for (int a = 0; a < 4; ++a) q[a] = in.F64();
  if (!q.allFinite() || std::abs(q.norm() - 1.0) > kUnitQuaternionTolerance) {
    return absl::DataLossError("the rotation is not a unit quaternion");
  }
  k.pose = SE3(Eigen::Quaterniond(q), translation);
  k.intrinsics.fx = in.F64();
  k.intrinsics.fy = in.F64();
  k.intrinsics.cx = in.F64();
  k.intrinsics.cy = in.F64();
  k.intrinsics.width = in.I32();
  k.intrinsics.height = in.I32();
  const uint32_t flags = in.U32();
  const uint32_t keypoints = in.U32();
  const uint32_t thumbnail_width = in.U32();
  const uint32_t thumbnail_height = in.U32();
  if ((flags & ~kHasFeatures) != 0) {
    return absl::DataLossError(absl::StrCat("unknown flags ", flags));
  }
  const bool has_features = (flags & kHasFeatures) != 0;
  if (!has_features && (keypoints != 0 || thumbnail_width != 0 || thumbnail_height != 0)) {
    return absl::DataLossError("features without the flag that says it has them");
  }
  // Bounded by the bytes that are there before anything is sized from the counts (u32 products
  // fit in int64).
  const int64_t thumbnail_values = int64_t{thumbnail_width} * int64_t{thumbnail_height};
  const int64_t needed = kBytesPerKeypoint * int64_t{keypoints} + 4 * thumbnail_values;
  if (!in.Has(needed)) {
    return absl::DataLossError(absl::StrCat(keypoints, " keypoints and a ", thumbnail_width, " x ",
                                            thumbnail_height, " thumbnail need ", needed,
                                            " bytes, the section has ", in.remaining(), " left"));
  }
  if (flags & kHasFeatures) {
    auto f = std::make_shared<FrameFeatures>();
    f->pixels.resize(keypoints);
    f->points.resize(keypoints);
    f->descriptors.resize(keypoints);
    for (Eigen::Vector2f& p : f->pixels) {
      const float u = in.F32();
      const float v = in.F32();
      p = Eigen::Vector2f(u, v);
    }
    for (Eigen::Vector3f& p : f->points) {
      const float x = in.F32();
      const float y = in.F32();
      const float z = in.F32();
      p = Eigen::Vector3f(x, y, z);
    }
    for (OrbDescriptor& d : f->descriptors) in.Bytes(d.data(), d.size());
    f->thumbnail_width = static_cast<int>(std::min<uint32_t>(thumbnail_width, kMaxImageSide + 1));
    f->thumbnail_height =
        static_cast<int>(std::min<uint32_t>(thumbnail_height, kMaxImageSide + 1));
    f->thumbnail.resize(static_cast<size_t>(thumbnail_values));
    for (float& v : f->thumbnail) v = in.F32();
    k.features = std::move(f);
  }
  if (absl::Status s = CheckStorableKeyframe(k); !s.ok()) {
    return absl::DataLossError(s.message());
  }
  return k;
}

}  // namespace

int64_t EncodedMapKeyframeBytes(const MapKeyframe& keyframe) {
  if (keyframe.features == nullptr) return kMapKeyframeFixedBytes;
  const FrameFeatures& f = *keyframe.features;
  return kMapKeyframeFixedBytes + kBytesPerKeypoint * static_cast<int64_t>(f.points.size()) +
         4 * static_cast<int64_t>(f.thumbnail.size());
}

absl::Status CheckStorableKeyframe(const MapKeyframe& k) {
  if (!std::isfinite(k.timestamp)) {
    return absl::InvalidArgumentError(absl::StrCat("timestamp ", k.timestamp, " is not finite"));
  }
  PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(k.pose, "pose"));
  const PinholeIntrinsics& in = k.intrinsics;
  if (!(std::isfinite(in.fx) && in.fx > 0.0 && std::isfinite(in.fy) && in.fy > 0.0 &&
        std::isfinite(in.cx) && std::isfinite(in.cy))) {
    return absl::InvalidArgumentError(absl::StrCat("intrinsics fx ", in.fx, " fy ", in.fy, " cx ",
                                                   in.cx, " cy ", in.cy,
                                                   ": focal lengths must be positive, all finite"));
  }
  if (in.width < 1 || in.height < 1 || in.width > kMaxImageSide || in.height > kMaxImageSide) {
    return absl::InvalidArgumentError(absl::StrCat("intrinsics: a ", in.width, " x ", in.height,
                                                   " image (sides 1 to ", kMaxImageSide, ")"));
  }
  if (k.features != nullptr) PLX_RETURN_IF_ERROR(CheckFeatures(*k.features));
  return absl::OkStatus();
}

void AppendEncodedMapKeyframe(const MapKeyframe& k, std::string* out) {
  out->reserve(out->size() + static_cast<size_t>(EncodedMapKeyframeBytes(k)));
  SectionWriter w(out);
  w.F64(k.timestamp);
  for (int a = 0; a < 3; ++a) w.F64(k.pose.translation()[a]);
  const Eigen::Vector4d& q = k.pose.rotation().coeffs();  // x, y, z, w
  for (int a = 0; a < 4; ++a) w.F64(q[a]);
  w.F64(k.intrinsics.fx);
  w.F64(k.intrinsics.fy);
  w.F64(k.intrinsics.cx);
  w.F64(k.intrinsics.cy);
  w.I32(k.intrinsics.width);
  w.I32(k.intrinsics.height);
  const FrameFeatures* f = k.features.get();
  w.U32(f != nullptr ? kHasFeatures : 0u);
  w.U32(f != nullptr ? static_cast<uint32_t>(f->points.size()) : 0u);
  w.U32(f != nullptr ? static_cast<uint32_t>(f->thumbnail_width) : 0u);
  w.U32(f != nullptr ? static_cast<uint32_t>(f->thumbnail_height) : 0u);
  if (f == nullptr) return;
  for (const Eigen::Vector2f& p : f->pixels) {
    w.F32(p.x());
    w.F32(p.y());
  }
  for (const Eigen::Vector3f& p : f->points) {
    w.F32(p.x());
    w.F32(p.y());
    w.F32(p.z());
  }
  for (const OrbDescriptor& d : f->descriptors) w.Bytes(d.data(), d.size());
  for (float v : f->thumbnail) w.F32(v);
}

absl::StatusOr<MapKeyframes> DecodeMapKeyframes(absl::string_view section, int64_t count) {
  // Every keyframe takes at least the fixed part: a count the bytes cannot back is corrupt, and
  // nothing is reserved from it before this check.
  if (count < 0 || count > static_cast<int64_t>(section.size()) / kMapKeyframeFixedBytes) {
    return absl::DataLossError(absl::StrCat(count, " keyframes cannot fit in a section of ",
                                            section.size(), " bytes"));
  }
  SectionReader in(section);
  MapKeyframes keyframes;
  keyframes.reserve(static_cast<size_t>(count));
  for (int64_t i = 0; i < count; ++i) {
    absl::StatusOr<MapKeyframe> k = DecodeOne(in);
    if (!k.ok()) {
      return absl::DataLossError(absl::StrCat("keyframe ", i, ": ", k.status().message()));
    }
    keyframes.push_back(*std::move(k));
  }
  if (in.remaining() != 0) {
    return absl::DataLossError(absl::StrCat(count, " keyframes end ", in.remaining(),
                                            " bytes before the section does"));
  }
  return keyframes;
}

}  // namespace plx
