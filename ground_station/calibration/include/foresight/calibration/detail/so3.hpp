#pragma once
// Rotation increments for the Gauss-Newton / Levenberg-Marquardt steps of
// calibration and localization (internal).

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace foresight::detail {

/// The cross-product matrix: skew(v) * x = v x x.
inline Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

/// The rotation by the angle |w| about w / |w| (exponential map of so(3)).
inline Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  if (a < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

}  // namespace foresight::detail
