#pragma once
// The Monte Carlo accuracy study after the paper's Tables 1-3: a synthetic
// multi-camera scene (config/scene.yaml), calibration clicks on the robot arm
// and localization clicks on the object model, Gaussian pixel noise. Each
// trial re-runs every camera calibration from its noisy arm clicks, then
// localizes the object with every combination of views, and the two peers
// (OpenCV solvePnP for single views, triangulate-then-align for two or more)
// on identical clicks. Beside it the Cramer-Rao lower bound of the same
// geometry and noise: the joint bound (calibration and localization clicks,
// every camera's 7 parameters and the pose unknown) and the bound with the
// cameras known exactly.
//
// Errors are expressed in the object frame (for the ORU: z along the hole
// axis): position error R_true^T (t_est - t_true), rotation error the
// rotation vector of R_true^T R_est. Not real-time code.

#include <Eigen/Core>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"

namespace foresight::localization {

/// A point fixed on an arm link that an operator can click in a camera
/// image: a link origin or the centre of one of its visual shapes.
struct ArmFeature {
  int link = 0;                                    ///< index in RobotModel::links()
  Eigen::Vector3d p_link = Eigen::Vector3d::Zero();  ///< in the link frame
  Eigen::Vector3d p_base = Eigen::Vector3d::Zero();  ///< FK(q) * p_link
  int pose = 0;                                    ///< index of its arm pose (StudySetup::arm_q)
};

struct StudyView {
  camera::Camera truth;
  std::vector<Eigen::Vector3d> calibration_points_base;  ///< arm points seen by this camera (exact)
  /// The arm features behind calibration_points_base, one each, when the
  /// points come from the arm (choose_calibration_points); empty otherwise.
  std::vector<ArmFeature> calibration_features;
  std::vector<Eigen::Vector3d> object_points;            ///< model points (object frame) seen by this camera
};

struct StudySetup {
  std::vector<StudyView> views;  ///< the paper's order: view 1..V
  Pose base_T_object = Pose::Identity();
  std::vector<Eigen::VectorXd> arm_q;  ///< the calibration arm poses (choose_calibration_points)
};

/// Cameras from the scene (in file order) and, per camera, the arm points in
/// front of it and inside its view, and the object's model points that are
/// visible: in front, inside the view, and on a face turned toward the
/// camera (points with object z <= 0, the exposed front of the ORU, seen
/// from the front side; points deeper in the panel are hidden).
StudySetup make_study_setup(const Scene& scene, const ObjectModel& object,
                            const std::vector<Eigen::Vector3d>& arm_points_base);

/// One arm pose of the calibration: joint angles and the distinct features
/// (at least 3 cm apart) the arm shows there.
struct ArmCalibrationPose {
  Eigen::VectorXd q;
  std::vector<ArmFeature> features;
};

/// The arm as the calibration fixture: four arm poses with the tool in front
/// of the work site at different places and heights (by IK), and the
/// features at each. Throws std::runtime_error when IK reaches fewer than two.
std::vector<ArmCalibrationPose> arm_calibration_poses(const RobotModel& model);

/// The features of `pose` that `camera` sees (in front, inside the view), at
/// most `max_count` spread evenly over them, as an operator clicks 6-8 a pose.
std::vector<ArmFeature> visible_features(const camera::Camera& camera, const ArmCalibrationPose& pose, int max_count = 8);

/// Sets every view's calibration points (and features) to the visible
/// features of every pose, and setup.arm_q to the poses' joint angles.
void choose_calibration_points(StudySetup& setup, const std::vector<ArmCalibrationPose>& poses);

/// Per-axis statistics of pose errors: order x, y, z (m), theta x, y, z
/// (rad), in the object frame.
struct ErrorStats {
  int n = 0;  ///< trials that produced an estimate
  Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 1> sd = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 1> rms = Eigen::Matrix<double, 6, 1>::Zero();
  /// The paper's 95% errors: alignment |mu_xy| + 2 sigma_xy with
  /// sigma_xy = sqrt(sigma_x^2 + sigma_y^2); depth |mu_z| + 2 sigma_z (m).
  double alignment95_m = 0.0;
  double depth95_m = 0.0;
  double position_rmse_m = 0.0;  ///< sqrt(mean |dp|^2)
  double rotation_rmse_rad = 0.0;
};

/// Error (x, y, z, theta) of an estimate in the true object frame, the
/// order of ErrorStats.
Eigen::Matrix<double, 6, 1> pose_error(const Pose& est, const Pose& truth);

/// Sums of pose errors over trials -> ErrorStats (Bessel-corrected sd).
struct ErrorAccumulator {
  int n = 0;
  Eigen::Matrix<double, 6, 1> sum = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 1> sum_sq = Eigen::Matrix<double, 6, 1>::Zero();
  void add(const Eigen::Matrix<double, 6, 1>& e);
  ErrorStats stats() const;
};

/// "1+2+4": 0-based view indices written 1-based, as the paper.
std::string view_combination_label(const std::vector<int>& views);

/// The simulated clicks of one view in a trial (the accuracy study's and the
/// alignment study's): calibration click i pairs the believed 3-D point
/// believed_base[i] with the true camera's projection of true_base[i] plus
/// click noise; the object clicks pair the view's object model points with
/// their true projections (the object at base_T_object) plus noise. The
/// noise is drawn in that order, u then v per click.
struct ViewClicks {
  std::vector<calibration::Correspondence> calibration, object;
};
ViewClicks simulate_view_clicks(const StudyView& view, const std::vector<Eigen::Vector3d>& believed_base,
                                const std::vector<Eigen::Vector3d>& true_base, const Pose& base_T_object,
                                const std::function<double()>& noise);

/// The arm as the fixture, per view and calibration point: the point's
/// response to the arm model's link lengths at its arm pose (the nominal
/// arm `robot`'s; calibration::Correspondence::dp_dlinks), for a calibration
/// that carries the arm model's uncertainty (CalibrationOptions::
/// arm_link_sigma_m). Needs a setup from choose_calibration_points.
std::vector<std::vector<Eigen::Matrix3Xd>> calibration_link_sensitivities(const StudySetup& setup, const RobotModel& robot);

/// One trial's click calibration of some views (the alignment study's and
/// `eval insertion`'s): the clicks show the true arm `true_arm` at the
/// setup's calibration poses, the believed points are the nominal arm's
/// (the view's calibration_points_base); each camera calibrated from them
/// with `options`, with the points' link sensitivities (`dp_dlinks`, from
/// calibration_link_sensitivities; ignored when empty). Noise is drawn view
/// by view in `views`' order as simulate_view_clicks draws it.
struct ClickCalibration {
  std::map<std::string, camera::Camera> cameras;
  /// Per camera, body rotation (calibration::camera_covariance_body_from_rpy):
  /// the whole covariance, and its noise part (less the arm model's).
  std::map<std::string, Eigen::Matrix<double, 7, 7>> covariance, noise_covariance;
  std::map<std::string, Eigen::Matrix<double, 7, 7>> information;
  std::map<std::string, Eigen::MatrixXd> link_sensitivity;  ///< CalibrationResult::link_sensitivity
  std::map<std::string, double> rms_px;
  std::vector<calibration::Correspondence> object;  ///< the object's clicks of every view
};
/// Throws the calibration's Error (input or computation) when a camera's
/// calibration fails; the views after it are not clicked.
ClickCalibration calibrate_from_arm_clicks(const StudySetup& setup, const std::vector<int>& views, const RobotModel& true_arm,
                                           const std::vector<std::vector<Eigen::Matrix3Xd>>& dp_dlinks,
                                           const calibration::CalibrationOptions& options,
                                           const std::function<double()>& noise);

struct ComboStats {
  std::vector<int> views;  ///< 0-based view indices
  std::string label;       ///< "1+2+4" (1-based, as the paper)
  ErrorStats ours;         ///< calibrate, then localize (linear + Gauss-Newton), the paper's method
  /// The same, with the calibrations' information as camera priors: pose and
  /// cameras refined together (LocalizationOptions::camera_information).
  ErrorStats ours_joint;
  int joint_failures = 0;
  ErrorStats pnp_iterative;   ///< single views only
  ErrorStats pnp_sqpnp;       ///< single views only
  ErrorStats triangulation;   ///< two or more views
  int failures = 0;           ///< trials where our localization threw
  /// Cramer-Rao standard deviations (same order as ErrorStats).
  Eigen::Matrix<double, 6, 1> crlb_sd = Eigen::Matrix<double, 6, 1>::Zero();              ///< joint
  Eigen::Matrix<double, 6, 1> crlb_known_cameras_sd = Eigen::Matrix<double, 6, 1>::Zero(); ///< cameras exact
  double crlb_position_m = 0.0;    ///< sqrt(trace) of the joint bound's position block
  double crlb_rotation_rad = 0.0;
  double crlb_alignment95_m = 0.0; ///< 2 sqrt(var_x + var_y) of the joint bound
  double crlb_depth95_m = 0.0;     ///< 2 sigma_z of the joint bound
};

struct StudyOptions {
  int trials = 1000;
  double noise_px = 1.0;
  unsigned seed = 1;
  /// Arm-model error: each trial, the length of every non-zero link offset
  /// of `robot` is off by a Gaussian of this standard deviation (m), and
  /// the calibration takes its arm points from that wrong model (FK of the
  /// erroneous arm at the clicked poses) while the clicks show the true arm.
  /// 0: the arm model is exact (the study's default). Needs `robot` and a
  /// setup from choose_calibration_points. The click noise is drawn exactly
  /// as without it (same seed: the same clicks).
  double arm_link_error_m = 0.0;
  const RobotModel* robot = nullptr;
  /// Called after each trial with (done, total); for a progress bar.
  std::function<void(int, int)> progress;
};

struct StudyResult {
  std::vector<std::string> view_names;
  std::vector<int> calibration_points;  ///< per view
  std::vector<int> object_points;       ///< per view
  std::vector<double> calibration_rms_px;  ///< mean over trials, per view
  std::vector<ComboStats> combos;          ///< all non-empty view subsets, by size then index
  int trials = 0;
  double noise_px = 0.0;
  double arm_link_error_m = 0.0;
  int calibration_failures = 0;  ///< trials skipped because a calibration threw
};

/// Throws EstimationInputError when a view sees fewer than 6 arm points;
/// InputError when arm_link_error_m > 0 without a robot or arm features.
StudyResult run_accuracy_study(const StudySetup& setup, const StudyOptions& options);

/// Mean and sample standard deviation of a quantity over several runs.
struct Spread {
  int n = 0;
  double mean = 0.0;
  double sd = 0.0;
};
Spread spread_of(const std::vector<double>& values);

/// The accuracy study repeated with seeds options.seed, options.seed + 1,
/// ... (`seeds` runs): the Monte Carlo spread of every statistic.
std::vector<StudyResult> run_accuracy_study_seeds(const StudySetup& setup, const StudyOptions& options, int seeds);

/// The joint Cramer-Rao covariance (object frame, order x, y, z, theta) for
/// the given views, and the one with the cameras known exactly.
void cramer_rao_bound(const StudySetup& setup, const std::vector<int>& views, double noise_px,
                      Eigen::Matrix<double, 6, 6>& joint, Eigen::Matrix<double, 6, 6>& known_cameras);

}  // namespace foresight::localization
