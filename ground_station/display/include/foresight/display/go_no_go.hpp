#pragma once
// The go/no-go before the insert on the video (issue 30 item 3): where the
// hole may be (the 95% region of its position estimate, projected into the
// image), where the tool tip will be at the end of the approach (the socket's
// rim and axis at the insert's start tag, with the 95% region of the tip's
// error at the hole), green when the insert is a go, red when not, labelled
// "insert: go P=0.997". One drawing for `foresight overlay --check-insert`
// and `foresight display --check-insert` (DisplayState::go_no_go).
//
// The ellipses are first-order projections: a position p ~ N(p0, C) (base
// frame) is seen at the pixel ~ N(project(p0), J C J^T), J = d uv / d p at
// p0; the drawn ellipse is {x : (x - c)^T (J C J^T)^-1 (x - c) <= chi2_2(0.95)
// = 5.991}, the region that holds 95% of the projected position (not the
// outline of the 3-D 95% ellipsoid, which is chi2_3(0.95) = 7.815: 14% larger).
//
// Not real-time code (OpenCV drawing, strings).

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>

#include "foresight/camera/camera.hpp"
#include "foresight/common/pose.hpp"

namespace foresight::display {

/// The chi-square quantile of 2 degrees of freedom: -2 ln(1 - p) (5.991 at
/// p = 0.95). Throws std::invalid_argument for p outside (0, 1).
double chi_square_2dof_quantile(double probability);

/// An ellipse in the image.
struct ImageEllipse {
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_px2 = Eigen::Matrix2d::Zero();  ///< the image covariance it bounds
  double semi_major_px = 0.0, semi_minor_px = 0.0;
  double angle_rad = 0.0;  ///< of the major axis, from +u towards +v (image down), in (-pi/2, pi/2]
};

/// The `probability` ellipse of a 2-D Gaussian N(centre, covariance): semi-axes
/// sqrt(chi2_2(p) * eigenvalue). A covariance that is not symmetric positive
/// semi-definite (within rounding) throws std::invalid_argument.
ImageEllipse gaussian_ellipse(const Eigen::Vector2d& centre_px, const Eigen::Matrix2d& covariance_px2,
                              double probability = 0.95);

/// The image covariance J C J^T of a base-frame position p ~ N(p_base, C)
/// seen through `camera` (J = d uv / d p_base at p_base). Throws
/// std::invalid_argument when p_base is not in front of the camera.
Eigen::Matrix2d project_position_covariance(const camera::Camera& camera, const Eigen::Vector3d& p_base,
                                            const Eigen::Matrix3d& covariance_base);

/// gaussian_ellipse(camera.project(p), project_position_covariance(...), probability).
ImageEllipse project_position_ellipse(const camera::Camera& camera, const Eigen::Vector3d& p_base,
                                      const Eigen::Matrix3d& covariance_base, double probability = 0.95);

/// What the drawing shows: the numbers of session::InsertCheck.
struct GoNoGoMarks {
  Pose base_T_hole = Pose::Identity();  ///< the hole's frame (z along its axis, into the hole)
  Pose base_T_tag = Pose::Identity();   ///< where the approach ends: the tool tip's predicted pose
  Eigen::Matrix3d hole_position_covariance = Eigen::Matrix3d::Zero();  ///< base frame, m^2
  Eigen::Matrix3d tip_position_covariance = Eigen::Matrix3d::Zero();   ///< of the tip relative to the hole, base, m^2
  double socket_diameter_m = 0.028;     ///< the tool's socket: the circle drawn at the tip
  bool go = false;
  double p_success = 0.0;
};

/// What is drawn (in view or not), for the commands' --json.
struct GoNoGoDrawn {
  bool hole_in_front = false, tip_in_front = false;  ///< of the camera
  bool hole_in_view = false, tip_in_view = false;    ///< the centre inside the viewport
  ImageEllipse hole, tip;  ///< valid when in front of the camera
  std::string label;       ///< "insert: go P=0.997"
};

/// The marks' image geometry through `camera` without drawing them.
GoNoGoDrawn project_go_no_go(const camera::Camera& camera, const GoNoGoMarks& marks);

/// "insert: go P=0.997" / "insert: no_go P=0.43": P with 2 decimals below
/// 0.99, 3 above; ">0.999" when it is below 1 but would print as 1.000.
std::string go_no_go_label(bool go, double p_success);

/// The colours, BGR: go (60, 220, 60), no_go (60, 60, 255).
cv::Scalar go_no_go_colour(bool go);

/// Draws the marks on `bgr` (8-bit BGR of the camera's viewport): the hole's
/// 95% ellipse (2 px line) with a cross-hair at its centre, the socket's rim
/// (a circle of socket_diameter_m about the tag's z) and the tool's axis
/// (4 cm back along -z) at base_T_tag, the tip's 95% ellipse (1 px), and the
/// label beside them; all in go_no_go_colour. An ellipse under 1.5 px is drawn
/// with a 1.5 px semi-axis so that it shows (GoNoGoDrawn has its true size).
/// Parts behind the camera are left out; the label too when `label` is false
/// (the display with its text hidden).
GoNoGoDrawn draw_go_no_go(cv::Mat& bgr, const camera::Camera& camera, const GoNoGoMarks& marks, bool label = true);

}  // namespace foresight::display
