#pragma once
// Camera calibration with the robot arm as the fixture (Kim 1996, sec. 2 and
// appendices A and B), in two steps:
//  1. the linear least-squares solution (appendix A): the 3x4 camera matrix
//     with one coefficient fixed (the depth term at the points' centroid,
//     the paper's c34/f = -1 after centring), 11 unknowns solved by SVD (no
//     normal equations); the sign chosen so the centroid is in front of the
//     camera; when the view is nearly orthographic (far object) the third
//     rotation row is replaced by the cross product of the first two (the
//     variant with the lower reprojection error is kept);
//  2. Levenberg-Marquardt on the 7 parameters (roll, pitch, yaw and position
//     of base_T_camera, f_px) minimising the pixel reprojection error,
//     started from the linear solution.
// The camera model is the paper's: square pixels, principal point at the
// viewport centre (foresight::camera::Camera, the one projection code path).
// Outlying clicks are flagged robustly (residual above k robust sigmas and a
// pixel floor), named with their residual, and left out of the final fit.
//
// Not real-time code: allocates, may throw EstimationError.

#include <Eigen/Core>
#include <stdexcept>
#include <string>
#include <vector>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/error.hpp"

namespace foresight::calibration {

/// The data cannot determine the estimate: too few points, degenerate
/// geometry (collinear, coplanar, rank deficient), non-finite input, points
/// behind their camera, unknown views. Bad input: the CLI exits 2. what()
/// names the camera or view and the offending points.
class EstimationInputError : public InputError {
 public:
  explicit EstimationInputError(const std::string& message) : InputError(message) {}
};

/// The estimation failed on usable data: the nonlinear fit did not converge,
/// the linear stage found no solution. A computation error: the CLI exits 1.
class EstimationError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

/// Robust outlier rejection shared by calibration and localization.
struct OutlierOptions {
  bool enabled = true;
  /// A point is an outlier when its residual (pixels, 2-D norm) exceeds
  /// max(k_sigma * robust_sigma, floor_px). robust_sigma is the per-axis
  /// sigma from the median residual norm (Rayleigh: median = 1.1774 sigma).
  double k_sigma = 4.0;
  double floor_px = 2.0;
  /// At most this fraction of the points is flagged (the worst first).
  double max_fraction = 0.3;
  /// Flagging rounds, each one refit (the cost stays linear in the points).
  int max_rounds = 8;
};

struct CalibrationOptions {
  int max_iterations = 100;
  OutlierOptions outliers;
  /// Relative singular value below which the linear system counts as rank
  /// deficient (degenerate geometry).
  double rank_tolerance = 1e-9;
  /// The arm model's link-length uncertainty (sd per link length, m; 0: the
  /// model taken as exact). The points of the arm as fixture come from the
  /// nominal arm; one link's error moves every point beyond it alike, the
  /// fit absorbs that into the camera (seen: 3% in f from 2 mm links), and
  /// the residuals cannot show it. With it, the points' link_length
  /// sensitivities (Correspondence::dp_dlinks) carry it into the camera:
  /// CalibrationResult::arm_model_covariance = K (sd^2 I) K^T, K the
  /// camera's response to the link lengths (H^-1 J^T J_links), added to the
  /// covariance. Points without sensitivities count as exact.
  double arm_link_sigma_m = 0.0;
};

/// One point's fit residual: measured minus predicted pixel.
struct PointResidual {
  int n = 0;
  std::string cam;
  int line = 0;
  Eigen::Vector2d r_px = Eigen::Vector2d::Zero();
  double px = 0.0;        ///< |r_px|
  bool outlier = false;   ///< flagged and left out of the final fit
};

struct CalibrationResult {
  camera::Camera camera;                 ///< name, viewport, f_px, base_T_camera
  /// Covariance of (roll, pitch, yaw [rad] of base_T_camera, position x, y, z
  /// [m] of the camera in base, f_px), from the Jacobian at the solution and
  /// the inlier residual variance: s^2 (J^T J)^-1, s^2 = SSR / (2 N - 7)
  /// (with the arm model's uncertainty: see arm_model_covariance).
  Eigen::Matrix<double, 7, 7> covariance = Eigen::Matrix<double, 7, 7>::Zero();
  Eigen::Matrix<double, 7, 1> sigma = Eigen::Matrix<double, 7, 1>::Zero();  ///< sqrt(diag(covariance))
  /// The arm model's part of `covariance` (same parameters; zero without
  /// CalibrationOptions::arm_link_sigma_m). With it, covariance =
  /// s_noise^2 (J^T J)^-1 + this, s_noise^2 the residual variance less the
  /// part the arm's errors are expected to leave in the residuals (>= 0).
  Eigen::Matrix<double, 7, 7> arm_model_covariance = Eigen::Matrix<double, 7, 7>::Zero();
  /// The camera's response to the arm model's link lengths: its parameter
  /// change per metre of each link (7 x links; body rotation increment rad,
  /// position m, f_px, as `information`), K = H^-1 J^T J_links. Cameras
  /// calibrated on one arm share its error, so what they measure together
  /// inherits it correlated (LocalizationOptions::camera_link_sensitivity).
  /// Empty without CalibrationOptions::arm_link_sigma_m.
  Eigen::MatrixXd link_sensitivity;
  double arm_link_sigma_m = 0.0;  ///< CalibrationOptions::arm_link_sigma_m when link_sensitivity is set
  /// J^T J of the inlier reprojection errors (pixels) at the solution, in
  /// the parameters (body-frame rotation increment of base_T_camera [rad],
  /// position [m], f_px): the information the clicks carry about the camera,
  /// before the noise variance. Localization can use it to weigh the
  /// camera's uncertainty (LocalizationOptions::camera_information).
  Eigen::Matrix<double, 7, 7> information = Eigen::Matrix<double, 7, 7>::Zero();
  double residual_variance_px2 = 0.0;  ///< s^2 = SSR / (2 N - 7), per axis
  double rms_px = 0.0;           ///< over inliers
  double max_px = 0.0;           ///< over inliers
  double linear_rms_px = 0.0;    ///< the linear stage alone, over inliers
  bool linear_cross_product = false;  ///< the linear stage used r3 = r1 x r2
  int iterations = 0;            ///< LM iterations of the final fit
  int n_points = 0;              ///< all points given
  std::vector<PointResidual> residuals;  ///< every point, input order
  std::vector<int> outliers;     ///< `n` of each flagged point

  /// rpy (rad) and position (m) of base_T_camera.
  Eigen::Vector3d rpy_rad() const;
  Eigen::Vector3d position_m() const { return camera.base_T_camera.translation(); }
  /// What cameras.yaml stores; `date_utc` in ISO 8601.
  camera::CameraCalibrationInfo info(const std::string& date_utc) const;
};

/// Calibrate one camera from its correspondences (base-frame points). All
/// given points are used (select one camera's rows first). `name` becomes
/// camera.name and appears in error messages.
/// Throws EstimationInputError (bad input): fewer than 6 points; a
/// non-finite coordinate (naming the point and line); collinear or coplanar
/// points (the linear stage needs points off one plane) or an otherwise
/// rank-deficient linear system; points behind the fitted camera. Throws
/// EstimationError (computation): the linear stage found no camera with the
/// points in front; the nonlinear fit did not converge (the message gives
/// the iteration count).
CalibrationResult calibrate_camera(const std::vector<Correspondence>& points, const camera::Viewport& viewport,
                                   const std::string& name, const CalibrationOptions& options = {});

/// The linear stage alone (appendix A): exposed for tests and benchmarks.
/// `cross_product` reports whether r3 = r1 x r2 was kept.
camera::Camera calibrate_camera_linear(const std::vector<Correspondence>& points, const camera::Viewport& viewport,
                               const std::string& name, double rank_tolerance = 1e-9,
                               bool* cross_product = nullptr);

/// Body-frame angular rate per roll/pitch/yaw rate for R = Rz Ry Rx:
/// omega_body = W(rpy) * d(rpy)/dt. Used to express covariances in rpy.
Eigen::Matrix3d rpy_rate_matrix(const Eigen::Vector3d& rpy_rad);

/// A camera's 7x7 covariance (rotation rad, position m, f_px) between the
/// roll/pitch/yaw rotation that cameras.yaml keeps and the body-frame
/// rotation increment the estimators use: C_rpy = T C_body T^T with
/// T = diag(W(rpy)^-1, I), W = rpy_rate_matrix at the camera's rotation.
Eigen::Matrix<double, 7, 7> camera_covariance_rpy_from_body(const Eigen::Matrix<double, 7, 7>& body,
                                                            const Eigen::Matrix3d& base_R_camera);
Eigen::Matrix<double, 7, 7> camera_covariance_body_from_rpy(const Eigen::Matrix<double, 7, 7>& rpy,
                                                            const Eigen::Matrix3d& base_R_camera);

/// Per-axis robust sigma (pixels) from 2-D residual norms.
double robust_sigma_px(std::vector<double> residual_norms_px);

}  // namespace foresight::calibration
