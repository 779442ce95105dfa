// Rigid transforms. Poses are world_T_camera (camera-to-world); tangent vectors are ordered
// [translation; rotation] and perturb on the right: T * Exp(xi). See DESIGN.md §4.
#pragma once

#include <cmath>
#include <limits>
#include <optional>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace plx {

using Vector6d = Eigen::Matrix<double, 6, 1>;

class SE3 {
 public:
  SE3() : rotation_(Eigen::Quaterniond::Identity()), translation_(Eigen::Vector3d::Zero()) {}
  SE3(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
      : rotation_(rotation.normalized()), translation_(translation) {}
  SE3(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation)
      : rotation_(Eigen::Quaterniond(rotation).normalized()), translation_(translation) {}

  static SE3 Identity() { return SE3(); }
  // Exponential map of xi = [rho; phi] (closed form with the left Jacobian of SO(3)).
  static SE3 Exp(const Vector6d& xi);
  // Inverse of Exp.
  Vector6d Log() const;

  const Eigen::Quaterniond& rotation() const { return rotation_; }
  Eigen::Matrix3d rotation_matrix() const { return rotation_.toRotationMatrix(); }
  const Eigen::Vector3d& translation() const { return translation_; }
  Eigen::Matrix4d matrix() const;

  SE3 Inverse() const;
  SE3 operator*(const SE3& other) const;
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const {
    return rotation_ * point + translation_;
  }

  // True when every component is finite.
  bool IsFinite() const;

 private:
  Eigen::Quaterniond rotation_;
  Eigen::Vector3d translation_;
};

// `q` scaled to unit length, or nullopt when a component is not finite or the norm is below
// `min_norm` (no usable direction). Poses from clients and files are read through this:
// Eigen's normalized() squares the components, so (1e200, 0, 0, 0) came out as a zero
// quaternion (its squared norm overflows to inf) and passed a "norm >= min" check as a pose
// with no rotation at all.
inline std::optional<Eigen::Quaterniond> UnitQuaternion(const Eigen::Quaterniond& q,
                                                        double min_norm) {
  const Eigen::Vector4d& c = q.coeffs();
  if (!c.allFinite()) return std::nullopt;
  const double squared = c.squaredNorm();
  if (std::isfinite(squared) && squared >= std::numeric_limits<double>::min()) {
    // The usual case, computed exactly as normalized() does (same bits as before).
    const double norm = std::sqrt(squared);
    if (norm < min_norm) return std::nullopt;
    return Eigen::Quaterniond(Eigen::Vector4d(c / norm));
  }
  // The squares overflowed or underflowed: divide by the largest component first, which puts
  // the norm in [1, 2].
  const double largest = c.cwiseAbs().maxCoeff();
  if (largest == 0.0) return std::nullopt;
  const Eigen::Vector4d scaled = c / largest;
  const double scaled_norm = scaled.norm();
  if (largest * scaled_norm < min_norm) return std::nullopt;
  return Eigen::Quaterniond(Eigen::Vector4d(scaled / scaled_norm));
}

// Skew-symmetric matrix such that Hat(a) * b = a x b.
Eigen::Matrix3d Hat(const Eigen::Vector3d& v);

// Rotation angle of `a.Inverse() * b` in radians.
double RotationAngleBetween(const SE3& a, const SE3& b);

}  // namespace plx
