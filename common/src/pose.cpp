#include "foresight/common/pose.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

namespace foresight {

Eigen::Matrix3d rotation_from_rpy(const Eigen::Vector3d& rpy) {
  return (Eigen::AngleAxisd(rpy[2], Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(rpy[1], Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy[0], Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d rpy_from_rotation(const Eigen::Matrix3d& R) {
  const double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  const double cp = std::sqrt(R(0, 0) * R(0, 0) + R(1, 0) * R(1, 0));
  if (cp < 1e-9) {  // gimbal lock: roll and yaw share one axis
    return {0.0, pitch, std::atan2(-R(0, 1), R(1, 1))};
  }
  return {std::atan2(R(2, 1), R(2, 2)), pitch, std::atan2(R(1, 0), R(0, 0))};
}

Pose make_pose(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy) {
  Pose T = Pose::Identity();
  T.linear() = rotation_from_rpy(rpy);
  T.translation() = xyz;
  return T;
}

double rotation_distance(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  // Via the quaternion: acos of the trace loses precision near zero.
  const Eigen::Quaterniond d(Ra.transpose() * Rb);
  return 2.0 * std::atan2(d.vec().norm(), std::abs(d.w()));
}

Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& M) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

}  // namespace foresight
