#pragma once
// The camera projection with its derivatives: one module for calibration
// (the camera's 7 parameters), localization (the object pose, and the
// cameras in the joint refinement) and the accuracy study's Cramer-Rao bound.
// The model is Camera's (camera.hpp): u = W/2 + f x/z, v = H/2 + f y/z in the
// camera frame (x right, y down, z forward).
//
// Parameter increments, as every estimator here steps them:
//  - a rotation R by a body-frame rotation vector theta: R exp([theta]x);
//  - a position (camera centre, object origin) in base by adding to it;
//  - the focal length f_px by adding to it.
// Not real-time code (plain inline Eigen, no allocation).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

#include "foresight/camera/camera.hpp"

namespace foresight::camera {

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

/// The inverse right Jacobian of SO(3) at the rotation vector phi:
/// d log(exp([phi]x) exp([d]x)) / dd at d = 0.
inline Eigen::Matrix3d right_jacobian_inverse_so3(const Eigen::Vector3d& phi) {
  const double t = phi.norm();
  const Eigen::Matrix3d S = skew(phi);
  if (t < 1e-6) return Eigen::Matrix3d::Identity() + 0.5 * S + (1.0 / 12.0) * S * S;
  return Eigen::Matrix3d::Identity() + 0.5 * S +
         (1.0 / (t * t) - (1.0 + std::cos(t)) / (2.0 * t * std::sin(t))) * S * S;
}

/// A base-frame point seen through a camera, and the derivatives of its pixel.
struct Projection {
  Eigen::Vector3d p_camera = Eigen::Vector3d::Zero();
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
  /// d uv / d p_base.
  Eigen::Matrix<double, 2, 3> d_point = Eigen::Matrix<double, 2, 3>::Zero();
  /// d uv / d (theta (body rotation of base_R_camera), camera position in base, f_px).
  Eigen::Matrix<double, 2, 7> d_camera = Eigen::Matrix<double, 2, 7>::Zero();
};

/// The pixel of p_base through the camera base_R_camera, position_m (its
/// centre in base), f_px, principal point pp_px, with both Jacobians. The
/// point must be in front (z > 0).
inline Projection project_with_jacobians(const Eigen::Matrix3d& base_R_camera, const Eigen::Vector3d& position_m,
                                         double f_px, const Eigen::Vector2d& pp_px, const Eigen::Vector3d& p_base) {
  Projection out;
  const Eigen::Matrix3d Rt = base_R_camera.transpose();
  out.p_camera = Rt * (p_base - position_m);
  const double iz = 1.0 / out.p_camera.z();
  const Eigen::Vector2d xy(out.p_camera.x() * iz, out.p_camera.y() * iz);
  out.uv_px = pp_px + f_px * xy;
  Eigen::Matrix<double, 2, 3> d_pc;  // d uv / d p_camera
  d_pc << f_px * iz, 0.0, -f_px * xy.x() * iz, 0.0, f_px * iz, -f_px * xy.y() * iz;
  out.d_point = d_pc * Rt;
  out.d_camera.leftCols<3>() = d_pc * skew(out.p_camera);  // p_camera = exp(-[theta]x) R^T (p - c)
  out.d_camera.middleCols<3>(3) = -out.d_point;
  out.d_camera.col(6) = xy;
  return out;
}

inline Projection project_with_jacobians(const Camera& camera, const Eigen::Vector3d& p_base) {
  return project_with_jacobians(camera.base_T_camera.linear(), camera.base_T_camera.translation(), camera.f_px,
                                camera.principal_point(), p_base);
}

/// d uv / d (theta, t) of a point p_object fixed in an object at base_R_object
/// (theta its body rotation, t its origin in base), from the projection's d_point.
inline Eigen::Matrix<double, 2, 6> object_pose_jacobian(const Projection& p, const Eigen::Matrix3d& base_R_object,
                                                        const Eigen::Vector3d& p_object) {
  Eigen::Matrix<double, 2, 6> J;
  J.leftCols<3>() = -p.d_point * base_R_object * skew(p_object);
  J.rightCols<3>() = p.d_point;
  return J;
}

}  // namespace foresight::camera
