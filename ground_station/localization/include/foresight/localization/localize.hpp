#pragma once
// Object localization from any number of calibrated camera views (Kim 1996,
// sec. 3), in two steps:
//  1. the multi-view linear algorithm (eq. 7-8): 12 unknowns (the rows of
//     [R | t] of base_T_object), two equations per click and view; the system
//     is rank 11 for a single view (scaling about the camera centre), so the
//     solution is a particular solution plus k times the null-space vector
//     (the right singular vector of the smallest singular value), k from the
//     unit norm of the rotation rows, sign from the points being in front.
//     Object points that are (nearly) coplanar use the 9-unknown form with
//     the third rotation column from the cross product;
//  2. Gauss-Newton (Levenberg-Marquardt damped) on the 6 pose parameters over
//     all views together, on pixel reprojection error.
// Standard deviations from the Jacobian at the solution and the residual
// variance; robust outlier flagging as in calibration.
//
// Not real-time code: allocates, may throw EstimationError.

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/pose.hpp"

namespace foresight::localization {

struct LocalizationOptions {
  int max_iterations = 100;
  calibration::OutlierOptions outliers;
  /// Views to use (camera names); empty: every camera that has points. A
  /// listed view without points is an error.
  std::vector<std::string> views;
  double rank_tolerance = 1e-9;
  /// Optional, per camera name: the calibration's information matrix
  /// (CalibrationResult::information, J^T J in pixels, parameters body
  /// rotation, position, f_px). The cameras listed here are refined together
  /// with the pose, held to their calibration by this prior: the joint
  /// estimate of calibration and localization, whose reported sigma includes
  /// the cameras' uncertainty. Empty: the paper's 6-parameter fit with the
  /// cameras taken as exact.
  std::map<std::string, Eigen::Matrix<double, 7, 7>> camera_information;
  /// The arm model's uncertainty, carried through the cameras: per camera
  /// name, its calibration's response to the arm's link lengths
  /// (CalibrationResult::link_sensitivity, 7 x links, the same links for
  /// every camera), and the links' sd (m). Cameras calibrated on one arm
  /// share its error, so two views' errors do not average out as
  /// independent ones would; the pose's response to the links, D, gives
  /// LocalizationResult::arm_model_covariance = sd^2 D D^T, added to the
  /// covariance (rotation and position). Cameras without a sensitivity count
  /// as exact. 0 or empty: none.
  std::map<std::string, Eigen::MatrixXd> camera_link_sensitivity;
  double arm_link_sigma_m = 0.0;
  /// Optional, per camera name: the camera's own uncertainty (7x7, body
  /// rotation increment rad, position m, f_px; CalibrationResult::
  /// covariance less its arm_model_covariance, in body rotation:
  /// camera_covariance_body_from_rpy). A camera held as calibrated (not in
  /// camera_information) is not exact: its error moves the pose as the
  /// clicks' noise does, and enters the covariance as A C A^T, A the pose's
  /// response to the camera (a "consider" covariance). The pose itself is
  /// the paper's two-step one, unchanged.
  std::map<std::string, Eigen::Matrix<double, 7, 7>> camera_covariance;
};

struct LocalizationResult {
  Pose base_T_object = Pose::Identity();
  /// Covariance of (roll, pitch, yaw [rad], x, y, z [m]) of base_T_object.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  /// The arm model's part of `covariance` (same parameters; zero without
  /// LocalizationOptions::arm_link_sigma_m and camera_link_sensitivity).
  Eigen::Matrix<double, 6, 6> arm_model_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  /// The pose's response to the arm model's link lengths: d(roll, pitch,
  /// yaw, x, y, z) per metre of each link's error (6 x links, the links of
  /// camera_link_sensitivity); arm_model_covariance = arm_link_sigma_m^2 D D^T.
  /// The tool, sent by the same model, moves with the same errors
  /// (contact_check::tip_error_at_hole). Empty without the arm term.
  Eigen::MatrixXd arm_link_sensitivity;
  /// The held cameras' part of `covariance` (LocalizationOptions::camera_covariance).
  Eigen::Matrix<double, 6, 6> held_cameras_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Vector3d sigma_rpy_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d sigma_position_m = Eigen::Vector3d::Zero();
  double rms_px = 0.0;         ///< over inliers, all views
  double max_px = 0.0;
  double linear_rms_px = 0.0;  ///< the linear stage alone
  int iterations = 0;
  int n_points = 0;
  std::vector<std::string> views;       ///< the views used, sorted
  std::vector<calibration::PointResidual> residuals; ///< every point used, input order
  std::vector<int> outliers;            ///< `n` of each flagged point
  bool camera_uncertainty = false;      ///< the joint refinement ran
  std::map<std::string, camera::Camera> refined_cameras;  ///< cameras refined with the pose (joint case)

  Eigen::Vector3d rpy_rad() const;
  Eigen::Vector3d position_m() const { return base_T_object.translation(); }
};

/// Localize the object from its model points (object frame) clicked in
/// calibrated views. Throws EstimationInputError (bad input): a point's
/// camera unknown (names it, the line and the known cameras); a listed view
/// with no points; fewer than 6 points in total or fewer than 4 distinct
/// model points; collinear model points; non-finite numbers; a rank-deficient
/// linear system; points behind their camera at the fitted pose. Throws
/// EstimationError (computation): no linear solution, or the nonlinear fit
/// did not converge (the message gives the iteration count).
LocalizationResult localize_object(const std::vector<calibration::Correspondence>& points,
                                   const std::map<std::string, camera::Camera>& cameras,
                                   const LocalizationOptions& options = {});

/// The linear stage alone (eq. 7-8), on every given point; for tests and
/// benchmarks. Cameras must contain every point's camera.
Pose localize_object_linear(const std::vector<calibration::Correspondence>& points, const std::map<std::string, camera::Camera>& cameras,
                            double rank_tolerance = 1e-9);

}  // namespace foresight::localization
