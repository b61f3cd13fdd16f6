#pragma once
// Clicked correspondences: a 3-D point and the pixel the operator clicked for
// it in one camera's view. Read from the points CSV (docs/estimation.md):
//
//   n,cam,x,y,z,u,v                       x, y, z in metres in the frame being
//                                         solved against (robot base for
//                                         calibrate, object frame for localize)
//   n,cam,link,lx,ly,lz,q1,...,qN,u,v     a point on an arm link (link frame,
//                                         metres) clicked with the arm at
//                                         joint angles q (radians): the robot
//                                         arm as the calibration fixture
//
// One header line (either form); under the link-form header a row may use
// either form, under the base-form header only the base form (a row is of the
// link form when its third field is not a number). Blank lines and
// lines starting with '#' are skipped. u, v are screen pixels (origin at the
// top-left corner, v down; pixel centres at i + 0.5).
//
// Set-up code: allocates, throws InputError with the file and line.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"

namespace foresight::calibration {

struct Correspondence {
  int n = 0;                ///< the point number (`n` column)
  std::string cam;          ///< camera (view) name
  Eigen::Vector3d p_m = Eigen::Vector3d::Zero();  ///< the 3-D point (base or object frame)
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
  int line = 0;             ///< 1-based line in the CSV (0: not from a file)
  std::string link;         ///< arm link for link-form rows, empty otherwise
  /// Link-form rows: how p_m moves per metre of each arm link length
  /// (LinkPointResolver::link_length_sensitivity, 3 x chain segments); empty
  /// for x,y,z rows (a point taken as exact).
  Eigen::Matrix3Xd dp_dlinks;
};

/// Turns a point given on an arm link at joint angles q into base
/// coordinates (the robot arm as fixture). RobotLinkPoints (robot_points.hpp)
/// implements it with the URDF model and forward kinematics.
class LinkPointResolver {
 public:
  virtual ~LinkPointResolver() = default;
  virtual int dof() const = 0;
  /// True when `link` names a link of the arm.
  virtual bool has_link(const std::string& link) const = 0;
  /// Comma-separated link names, for error messages.
  virtual std::string link_list() const = 0;
  /// Why the joint angles `q` cannot be a pose of the arm (a joint beyond its
  /// limits by more than limits::kJointLimitMargin_rad), nullopt when they can.
  virtual std::optional<std::string> joints_out_of_range(const Eigen::VectorXd& q) const {
    (void)q;
    return std::nullopt;
  }
  /// base_T_link(q) * p_link.
  virtual Eigen::Vector3d to_base(const std::string& link, const Eigen::Vector3d& p_link,
                                  const Eigen::VectorXd& q) const = 0;
  /// How to_base(link, p_link, q) moves per metre of each of the arm's link
  /// lengths (3 x M); empty (the default) when the resolver does not know.
  virtual Eigen::Matrix3Xd link_length_sensitivity(const std::string& link, const Eigen::Vector3d& p_link,
                                                   const Eigen::VectorXd& q) const {
    (void)link, (void)p_link, (void)q;
    return {};
  }
};

/// Parse CSV text; `source` names the file in errors. Link-form rows need
/// `robot` (nullptr: such a row is an error naming its line). Throws
/// InputError("source", line, ...) on: a missing or wrong header, a row with
/// the wrong number of fields, a field that is not a number, a non-finite
/// number, an unknown link, the wrong number of joint angles (in the header
/// or the row), joint angles beyond the arm's limits (joints_out_of_range), a
/// point number that does not fit an int, an empty camera name, more than
/// limits::kMaxPointRows rows; and InputError(source, "no points") for a file
/// without data rows.
std::vector<Correspondence> parse_correspondences_csv(const std::string& text, const std::string& source,
                                                      const LinkPointResolver* robot = nullptr);
/// Read a file (InputError when it cannot be opened), then as above.
std::vector<Correspondence> read_correspondences_csv(const std::string& path,
                                                     const LinkPointResolver* robot = nullptr);

/// Refuses a click outside the viewport (0 <= u <= width, 0 <= v <= height,
/// each widened by limits::kViewportMarginFraction of the larger side):
/// InputError "<source>:<line>: point n=N: pixel (u, v) is outside the WxH
/// viewport of camera 'C'". `source` names the points file.
void check_in_viewport(const std::vector<Correspondence>& points, const camera::Viewport& viewport,
                       const std::string& source);

/// The rows whose camera is `cam`, in file order.
std::vector<Correspondence> select_camera(const std::vector<Correspondence>& points, const std::string& cam);

/// CSV text of base-frame (or object-frame) points, full precision; the
/// inverse of parse_correspondences_csv for x,y,z rows.
std::string to_csv(const std::vector<Correspondence>& points);

}  // namespace foresight::calibration
