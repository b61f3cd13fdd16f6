#pragma once
// The paper's operator-interactive data entry, without a window: the state
// machine behind `foresight click`. The operator picks a model point (in the
// model window), then clicks where it appears in the image (the image
// window); each pair becomes one row of the points CSV (calibrate/localize).
// Delete-last, clear-all, and a zoomed view of the image for precise clicks
// (ZoomView maps window pixels to image pixels and back).
//
// Pixel convention (correspondence.hpp): u right, v down, origin at the
// image's top-left corner, pixel centres at i + 0.5. A click on window pixel
// (x, y) is the centre of that pixel mapped through the zoom.
//
// Set-up/UI code, not real-time: allocates, never throws from the event
// methods (their outcome is returned).

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight::display {

/// A selectable model point: where it is in the frame the fit solves
/// against (robot base for calibrate, object frame for localize).
struct ModelPoint {
  std::string label;                          ///< e.g. "link3" or the ORU point's name
  Eigen::Vector3d p_m = Eigen::Vector3d::Zero();
};

/// The arm's selectable points at joint angles q: each link's origin and the
/// centres of its visual shapes, in base coordinates, closer than 3 cm to an
/// earlier one dropped (the features the simulated operator clicks too).
std::vector<ModelPoint> arm_model_points(const RobotModel& model, const Eigen::VectorXd& q);
/// The object's model points (object frame), in the order of oru.yaml.
std::vector<ModelPoint> object_model_points(const ObjectModel& object);

/// A camera that sees every point: looking at their centroid from
/// `view_direction` (from the centroid towards the eye), far enough that the
/// points fill about 70 % of the smaller image side.
camera::Camera model_view_camera(const std::vector<ModelPoint>& points, const camera::Viewport& viewport,
                         const Eigen::Vector3d& view_direction, const Eigen::Vector3d& up);

/// The model window's camera of `foresight click`: the arm (base frame, z
/// up) seen from the front right above; the ORU (object frame: z into the
/// hole, y down) seen from in front of its face, a little from the side.
camera::Camera default_model_view(const std::vector<ModelPoint>& points, const camera::Viewport& viewport, bool arm);

/// Index of the projected point nearest to `uv_px` within `radius_px`, -1 if none.
int nearest_point(const std::vector<Eigen::Vector2d>& projected_px, const Eigen::Vector2d& uv_px, double radius_px);

/// A window showing part of an image magnified: window pixel (x, y) shows
/// image point origin + (x + 0.5, y + 0.5) / zoom. The window has the
/// image's size; zoom >= 1 and the shown part stays inside the image.
class ZoomView {
 public:
  explicit ZoomView(cv::Size image_size) : size_(image_size) {}
  /// Continuous image coordinates of the centre of window pixel (x, y).
  Eigen::Vector2d to_image(int x, int y) const;
  /// Window coordinates (continuous) of an image point.
  Eigen::Vector2d to_window(const Eigen::Vector2d& uv_px) const;
  /// Multiplies the zoom by `factor` keeping image point `uv_px` under the
  /// same window position; zoom clamped to [1, max_zoom].
  void zoom_at(const Eigen::Vector2d& uv_px, double factor);
  void reset();
  double zoom() const { return zoom_; }
  Eigen::Vector2d origin_px() const { return origin_; }
  /// The window's picture of `image` (same size; nearest-neighbour when zoomed
  /// so pixels stay visible).
  cv::Mat render(const cv::Mat& image) const;
  static constexpr double max_zoom = 16.0;

 private:
  void clamp();
  cv::Size size_;
  double zoom_ = 1.0;
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();
};

class ClickSession {
 public:
  enum class State { AwaitModelPoint, AwaitImagePoint };
  enum class Outcome { Added, NoModelPoint, OutsideImage };

  /// `camera` is the cam column; `image_size` bounds the image clicks.
  ClickSession(std::string camera, std::vector<ModelPoint> model_points, cv::Size image_size);

  /// Keeps rows read from an existing file (appending): numbering continues after their largest n.
  void set_existing_rows(std::vector<calibration::Correspondence> rows);

  /// Selects model point `index` (then the next image click pairs with it).
  /// False (state unchanged) when out of range.
  bool select_model_point(int index);
  /// An image click at continuous pixel coordinates. Outside the image
  /// (u not in [0, width), v not in [0, height)): ignored, OutsideImage.
  /// No model point selected: NoModelPoint. Otherwise the row is added and
  /// the session waits for the next model point.
  Outcome click_image(const Eigen::Vector2d& uv_px);
  /// Removes the last row of this session (rows read from a file stay);
  /// false when there is none. Also cancels a pending model-point selection first.
  bool delete_last();
  /// Removes every row of this session and any pending selection.
  void clear();

  State state() const { return selected_ < 0 ? State::AwaitModelPoint : State::AwaitImagePoint; }
  int selected() const { return selected_; }
  const std::vector<ModelPoint>& model_points() const { return model_points_; }
  /// Existing rows then this session's, in order.
  std::vector<calibration::Correspondence> rows() const;
  /// This session's rows only.
  const std::vector<calibration::Correspondence>& session_rows() const { return rows_; }
  /// Model-point index of each session row.
  const std::vector<int>& session_model_index() const { return row_point_; }
  /// The points CSV (n,cam,x,y,z,u,v; foresight::calibration::to_csv) of rows().
  std::string csv() const;
  const std::string& camera() const { return camera_; }

 private:
  std::string camera_;
  std::vector<ModelPoint> model_points_;
  cv::Size image_size_;
  std::vector<calibration::Correspondence> existing_, rows_;
  std::vector<int> row_point_;
  int selected_ = -1;
  int next_n_ = 1;
};

}  // namespace foresight::display
