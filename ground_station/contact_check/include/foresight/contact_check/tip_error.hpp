#pragma once
// Uncertainty where the tool meets the task (issue 30 item 1): the error of
// the tool tip relative to the hole at the end of the approach, propagated
// from the object pose's covariance (the cameras' calibration, the clicks,
// the arm model: localization::LocalizationResult) and the arm's own
// positioning error (its link lengths, its joint encoders).
//
// Error vector, everywhere here: e = (theta_x, theta_y, theta_z, x, y, z) of
// hole_T_tip, the tool-tip frame in the hole's frame (z along the hole axis
// into the object, origin at the entrance): the rotation vector of its
// rotation [rad] and its translation [m]. x, y are the lateral error, z the
// axial one, |(theta_x, theta_y)| the tilt of the tool axis to the hole axis.
//
// The arm model's link-length error moves the estimate and the tool the same
// way (the cameras were calibrated with the arm as the fixture): the two
// enter correlated, through one sensitivity per link (docs/estimation.md
// "Go/no-go before contact"). Set-up code: allocates, throws.

#include <Eigen/Core>
#include <optional>
#include <string>

#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight::contact_check {

using Vector6 = Eigen::Matrix<double, 6, 1>;
using Matrix6 = Eigen::Matrix<double, 6, 6>;

/// The object pose and what is known about its error.
struct ObjectEstimate {
  Pose base_T_object = Pose::Identity();
  /// Covariance of (roll, pitch, yaw [rad], x, y, z [m]) of base_T_object,
  /// every term included (the localize/align --json "covariance").
  Matrix6 covariance = Matrix6::Zero();
  /// d(roll, pitch, yaw, x, y, z of the estimate) / d(link length error),
  /// one column per RobotModel::offset_segments() link; empty when the
  /// cameras carry no arm-model term. Its part of `covariance` is
  /// arm_link_sigma_m^2 D D^T.
  Eigen::MatrixXd arm_link_sensitivity;
  double arm_link_sigma_m = 0.0;
};

/// The arm's own positioning error.
struct ArmUncertainty {
  double link_sigma_m = 0.0;       ///< each offset link's length, 1 sigma
  double encoder_sigma_rad = 0.0;  ///< each joint's position, 1 sigma
};

/// A pose's error in its own frame, as the covariance of e (above).
struct LocalCovariance {
  Vector6 mean = Vector6::Zero();
  Matrix6 covariance = Matrix6::Zero();
};

/// The covariance of a tag frame's pose in the robot base, in the object
/// pose's parameters (roll, pitch, yaw, x, y, z of base_T_tag), by the
/// Jacobian of base_T_object * object_T_tag: the localize/align --json
/// per-tag "covariance".
Matrix6 tag_covariance_base(const Pose& base_T_object, const Matrix6& covariance, const Pose& object_T_tag);

/// The tool tip's error in the tag frame when the arm is commanded to
/// base_T_tag (joints by IK on `robot`, the ground's model): link lengths
/// and encoders, uncorrelated with the estimate (its own part only).
/// Throws std::runtime_error when IK cannot reach the tag.
struct ToolTip {
  Eigen::VectorXd q;           ///< the approach joints
  Matrix6 covariance = Matrix6::Zero();  ///< e of tag_T_tip
  Eigen::MatrixXd link_sensitivity;      ///< d e / d link error (6 x offset links)
};
ToolTip tool_tip_uncertainty(const RobotModel& robot, const Pose& base_T_tag, const ArmUncertainty& arm);

/// The tip's error relative to the hole (object_T_hole, the object's hole
/// frame) when the arm is sent to the tag object_T_tag of the estimated
/// object: mean = the tag's planned offset from the hole; covariance = the
/// estimate's (through the hole and the tag) plus the tool's, the arm-model
/// terms of both combined with their correlation.
LocalCovariance tip_error_at_hole(const ObjectEstimate& estimate, const Pose& object_T_hole, const Pose& object_T_tag,
                                  const ToolTip& tool, const ArmUncertainty& arm);

/// e of a pose error: rotation vector and translation of T.
Vector6 pose_error_vector(const Pose& T);

}  // namespace foresight::contact_check
