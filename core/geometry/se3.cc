#include "core/geometry/se3.h"

#include <cmath>

namespace plx {
namespace {

// Left Jacobian of SO(3) and its inverse; small-angle branches use Taylor series.
Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d K = Hat(phi);
  if (theta < 1e-6) return Eigen::Matrix3d::Identity() + 0.5 * K + K * K / 6.0;
  const double t2 = theta * theta;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(theta)) / t2 * K +
         (theta - std::sin(theta)) / (t2 * theta) * K * K;
}

Eigen::Matrix3d InverseLeftJacobianSO3(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d K = Hat(phi);
  if (theta < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * K + K * K / 12.0;
  const double t2 = theta * theta;
  const double coeff = (1.0 / t2) - (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta));
  return Eigen::Matrix3d::Identity() - 0.5 * K + coeff * K * K;
}

}  // namespace

Eigen::Matrix3d Hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

SE3 SE3::Exp(const Vector6d& xi) {
  const Eigen::Vector3d rho = xi.head<3>();
  const Eigen::Vector3d phi = xi.tail<3>();
  const double theta = phi.norm();
  Eigen::Quaterniond q;
  if (theta < 1e-12) {
    q = Eigen::Quaterniond(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z());
  } else {
    q = Eigen::Quaterniond(Eigen::AngleAxisd(theta, phi / theta));
  }
  return SE3(q, LeftJacobianSO3(phi) * rho);
}

Vector6d SE3::Log() const {
  Eigen::AngleAxisd aa(rotation_);
  double angle = aa.angle();
  Eigen::Vector3d axis = aa.axis();
  if (angle > M_PI) {  // keep the angle in [0, pi]
    angle = 2.0 * M_PI - angle;
    axis = -axis;
  }
  const Eigen::Vector3d phi = angle * axis;
  Vector6d xi;
  xi.head<3>() = InverseLeftJacobianSO3(phi) * translation_;
  xi.tail<3>() = phi;
  return xi;
}

Eigen::Matrix4d SE3::matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rotation_matrix();
  m.topRightCorner<3, 1>() = translation_;
  return m;
}

SE3 SE3::Inverse() const {
  const Eigen::Quaterniond inv = rotation_.conjugate();
  return SE3(inv, -(inv * translation_));
}

SE3 SE3::operator*(const SE3& other) const {
  return SE3(rotation_ * other.rotation_, rotation_ * other.translation_ + translation_);
}

bool SE3::IsFinite() const {
  return rotation_.coeffs().allFinite() && translation_.allFinite();
}

double RotationAngleBetween(const SE3& a, const SE3& b) {
  const Eigen::Quaterniond d = a.rotation().conjugate() * b.rotation();
  const double w = std::min(1.0, std::abs(d.w()));
  return 2.0 * std::acos(w);
}

}  // namespace plx
