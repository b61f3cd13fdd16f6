#include "foresight/contact_check/tip_error.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "foresight/common/kinematics.hpp"

namespace foresight::contact_check {

namespace {

using Params = Vector6;  // roll, pitch, yaw, x, y, z

Params params_of(const Pose& T) {
  Params p;
  p << rpy_from_rotation(T.linear()), T.translation();
  return p;
}

Pose pose_of(const Params& p) { return make_pose(p.tail<3>(), p.head<3>()); }

/// a - b with the angles wrapped to (-pi, pi].
Params params_difference(const Params& a, const Params& b) {
  Params d = a - b;
  for (int i = 0; i < 3; ++i) d[i] = std::remainder(d[i], 2.0 * std::numbers::pi);
  return d;
}

/// exp of e (rotation vector, translation) as a pose.
Pose pose_from_error(const Vector6& e) {
  Pose T = Pose::Identity();
  const double angle = e.head<3>().norm();
  if (angle > 0.0) T.linear() = Eigen::AngleAxisd(angle, e.head<3>() / angle).toRotationMatrix();
  T.translation() = e.tail<3>();
  return T;
}

/// The 6 x 6 central-difference Jacobian of f (a 6-vector of a 6-vector) at 0.
template <typename F>
Matrix6 jacobian_at_zero(F&& f, double h) {
  Matrix6 J;
  for (int i = 0; i < 6; ++i) {
    Vector6 d = Vector6::Zero();
    d[i] = h;
    J.col(i) = (f(d) - f(-d)) / (2.0 * h);
  }
  return J;
}

constexpr double kStep = 1e-6;

/// The nearest positive semi-definite matrix (eigenvalues clamped at 0).
Matrix6 clamp_psd(const Matrix6& C) {
  const Eigen::SelfAdjointEigenSolver<Matrix6> eig(0.5 * (C + C.transpose()));
  return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() * eig.eigenvectors().transpose();
}

}  // namespace

Vector6 pose_error_vector(const Pose& T) {
  const Eigen::AngleAxisd aa(T.linear());
  Vector6 e;
  e << aa.angle() * aa.axis(), T.translation();
  return e;
}

Matrix6 tag_covariance_base(const Pose& base_T_object, const Matrix6& covariance, const Pose& object_T_tag) {
  const Params p0 = params_of(base_T_object);
  const Params t0 = params_of(base_T_object * object_T_tag);
  const Matrix6 J = jacobian_at_zero(
      [&](const Vector6& d) { return params_difference(params_of(pose_of(p0 + d) * object_T_tag), t0); }, kStep);
  return J * covariance * J.transpose();
}

ToolTip tool_tip_uncertainty(const RobotModel& robot, const Pose& base_T_tag, const ArmUncertainty& arm) {
  KinematicsWorkspace ws{robot};
  IkOptions opt;
  opt.centre_joints = true;
  const IkResult ik = inverse_kinematics(robot, ws, base_T_tag, robot.mid_configuration(), opt);
  if (!ik.success)
    throw std::runtime_error("the arm cannot reach the tag (IK: " + std::to_string(ik.position_error_m * 1e3) + " mm off)");
  ToolTip tip;
  tip.q = ik.q;
  const Pose tip0 = forward_kinematics(robot, ws, tip.q);
  // Encoders: each joint's error moves the tip by the Jacobian's column.
  const Eigen::Index n = tip.q.size();
  Eigen::MatrixXd Jq(6, n);
  for (Eigen::Index j = 0; j < n; ++j) {
    Eigen::VectorXd qp = tip.q, qm = tip.q;
    qp[j] += kStep;
    qm[j] -= kStep;
    const Pose Tp = forward_kinematics(robot, ws, qp), Tm = forward_kinematics(robot, ws, qm);
    Jq.col(j) = (pose_error_vector(tip0.inverse() * Tp) - pose_error_vector(tip0.inverse() * Tm)) / (2.0 * kStep);
  }
  tip.covariance = arm.encoder_sigma_rad * arm.encoder_sigma_rad * Jq * Jq.transpose();
  // Links: the true arm's tip at the same joints, per metre of each link's error.
  const std::vector<int> links = robot.offset_segments();
  tip.link_sensitivity.resize(6, static_cast<Eigen::Index>(links.size()));
  constexpr double kLinkStep = 1e-4;
  for (std::size_t k = 0; k < links.size(); ++k) {
    std::vector<double> delta(static_cast<std::size_t>(robot.segment_count()), 0.0);
    delta[static_cast<std::size_t>(links[k])] = kLinkStep;
    const RobotModel longer = robot.with_link_lengths_changed(delta);
    KinematicsWorkspace wl{longer};
    tip.link_sensitivity.col(static_cast<Eigen::Index>(k)) =
        pose_error_vector(tip0.inverse() * forward_kinematics(longer, wl, tip.q)) / kLinkStep;
  }
  tip.covariance += arm.link_sigma_m * arm.link_sigma_m * tip.link_sensitivity * tip.link_sensitivity.transpose();
  return tip;
}

LocalCovariance tip_error_at_hole(const ObjectEstimate& est, const Pose& object_T_hole, const Pose& object_T_tag,
                                  const ToolTip& tool, const ArmUncertainty& arm) {
  const Params p0 = params_of(est.base_T_object);
  const Pose base_T_tip = est.base_T_object * object_T_tag;  // where the arm is sent
  LocalCovariance out;
  out.mean = pose_error_vector(object_T_hole.inverse() * object_T_tag);
  // G: the estimate's error eps (estimate = truth + eps) moves the true hole
  // by -eps, and so the tip relative to it.
  const Matrix6 G = jacobian_at_zero(
      [&](const Vector6& d) { return pose_error_vector((pose_of(p0 - d) * object_T_hole).inverse() * base_T_tip); }, kStep);
  // T: the tool's own error xi (tag_T_tip) as seen from the hole.
  const Pose hole_T_tag = object_T_hole.inverse() * object_T_tag;
  const Matrix6 T = jacobian_at_zero([&](const Vector6& d) { return pose_error_vector(hole_T_tag * pose_from_error(d)); }, kStep);
  const Eigen::Index links = tool.link_sensitivity.cols();
  const bool correlated = est.arm_link_sensitivity.size() > 0;
  if (correlated && est.arm_link_sensitivity.cols() != links)
    throw std::invalid_argument("the object pose's arm_link_sensitivity has " + std::to_string(est.arm_link_sensitivity.cols()) +
                                " links, the robot model " + std::to_string(links));
  Matrix6 tool_own = tool.covariance;  // less its links' part: the encoders'
  if (links > 0) tool_own -= arm.link_sigma_m * arm.link_sigma_m * tool.link_sensitivity * tool.link_sensitivity.transpose();
  if (!correlated) {
    out.covariance = G * est.covariance * G.transpose() + T * tool.covariance * T.transpose();
  } else {
    // One link error delta moves both: the estimate by D delta, the tip by
    // D_tip delta; e gets (G D + T D_tip) delta.
    const double var = est.arm_link_sigma_m * est.arm_link_sigma_m;
    const Matrix6 est_own = clamp_psd(est.covariance - var * est.arm_link_sensitivity * est.arm_link_sensitivity.transpose());
    const Eigen::MatrixXd D = G * est.arm_link_sensitivity + T * tool.link_sensitivity;
    out.covariance = G * est_own * G.transpose() + T * tool_own * T.transpose() + var * D * D.transpose();
  }
  out.covariance = clamp_psd(out.covariance);
  return out;
}

}  // namespace foresight::contact_check
