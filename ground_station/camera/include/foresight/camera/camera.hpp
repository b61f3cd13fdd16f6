#pragma once
// The calibrated camera: one projection code path for calibration,
// localization, the synthetic camera and the OpenGL overlays.
//
// Conventions (named once, here):
//  - Camera frame `camera`: x right, y down, z forward along the optical axis
//    (the OpenCV convention). base_T_camera maps camera coordinates to base.
//  - Pixels: continuous (u, v), origin at the top-left corner of the image,
//    u right, v down; pixel (i, j) covers [i, i+1) x [j, j+1), its centre is at
//    (i + 0.5, j + 0.5).
//  - Model (the paper's default): pinhole, square pixels, principal point at
//    the viewport centre (W/2, H/2), one focal length f_px in pixels:
//        u = W/2 + f_px * x/z,   v = H/2 + f_px * y/z.
//  - OpenGL eye frame (the paper's fig. 3, looking down -z, y up) is
//    eye_T_camera = diag(1, -1, -1); gl_projection()/gl_view() derive from it
//    here and nowhere else.

#include <Eigen/Core>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "foresight/common/pose.hpp"

namespace foresight::camera {

struct Viewport {
  int width_px = 646;   ///< the paper's NTSC window
  int height_px = 486;
  bool operator==(const Viewport&) const = default;
};

/// Parse "646x486"; throws std::invalid_argument naming the text.
Viewport parse_viewport(const std::string& text);

struct Camera {
  std::string name;
  Viewport viewport;
  double f_px = 700.0;
  Pose base_T_camera = Pose::Identity();

  /// Point in the camera frame.
  Eigen::Vector3d to_camera(const Eigen::Vector3d& p_base) const { return base_T_camera.inverse() * p_base; }
  /// Pixel of a point given in the camera frame (z must be > 0).
  Eigen::Vector2d project_camera(const Eigen::Vector3d& p_camera) const;
  /// Pixel of a point given in the base frame.
  Eigen::Vector2d project(const Eigen::Vector3d& p_base) const { return project_camera(to_camera(p_base)); }
  /// True when the point lies in front of the camera (z > 0 in camera frame).
  bool in_front(const Eigen::Vector3d& p_base) const { return to_camera(p_base).z() > 0.0; }
  /// True when the pixel lies inside the viewport.
  bool in_view(const Eigen::Vector2d& uv) const;
  /// Vertical field of view, radians: 2 atan(H / (2 f_px)).
  double fovy_rad() const;
  Eigen::Vector2d principal_point() const { return {viewport.width_px / 2.0, viewport.height_px / 2.0}; }

  /// OpenGL projection (column-major convention, as glLoadMatrix expects once
  /// stored column-major) for the viewport, near/far in metres. Maps camera
  /// rays to the same pixel as project() (with the bottom-up GL viewport).
  Eigen::Matrix4d gl_projection(double near_m, double far_m) const;
  /// OpenGL view matrix: eye_T_base (eye frame looks down -z, y up).
  Eigen::Matrix4d gl_view() const;

  /// A camera at `position` looking at `target`, `up` appearing up in the image.
  static Camera look_at(const std::string& name, const Viewport& vp, double f_px, const Eigen::Vector3d& position_m,
                        const Eigen::Vector3d& target_m, const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());
};

/// What a calibration adds to a camera in cameras.yaml.
struct CameraCalibrationInfo {
  Eigen::Matrix<double, 7, 7> covariance = Eigen::Matrix<double, 7, 7>::Zero();  ///< (roll,pitch,yaw rad; x,y,z m; f_px)
  double rms_px = 0.0;
  double max_px = 0.0;
  int n_points = 0;
  std::vector<int> outliers;  ///< point numbers (the `n` column)
  std::string date;           ///< ISO 8601, UTC
  /// With the arm model's uncertainty (`calibrate --arm-link-sigma`): the
  /// links' sd (m) and the camera's response to the link lengths (7 x links,
  /// the covariance's parameters per metre of each link; its arm part is
  /// sd^2 K K^T). Cameras calibrated on one arm share its error; localization
  /// carries it correlated. Empty: none.
  double arm_link_sigma_m = 0.0;
  Eigen::MatrixXd arm_link_sensitivity;
};

struct CameraRecord {
  Camera camera;
  std::optional<CameraCalibrationInfo> calibration;
};

/// cameras.yaml: a map from camera name to {viewport: [W, H], f_px,
/// base_T_camera: 4x4 rows, fovy_deg, calibration: {covariance (7x7 rows),
/// rms_px, max_px, n_points, outliers, date[, arm_link_sigma_m,
/// arm_link_sensitivity (7 rows of one number per link)]}}. Throws InputError naming the
/// file and camera/key on any problem.
std::map<std::string, CameraRecord> load_cameras(const std::string& path);
/// Write all cameras (sorted by name). Throws InputError when not writable.
void save_cameras(const std::string& path, const std::map<std::string, CameraRecord>& cameras);

}  // namespace foresight::camera
