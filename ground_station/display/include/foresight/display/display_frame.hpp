#pragma once
// The operator display's picture (`foresight display`), composed without a
// window so it can be recorded headless and tested: the video frame, the
// delayed actual arm from telemetry drawn in the current render mode (with
// the ORU and its tag frames), the commanded/previewed arm as a ghost running
// ahead, and the text the operator needs: the measured round trip, the
// controller state, any fault, the camera, mode and overlay state, and the
// video source's trouble when it has any.
//
// Not real-time code: renders with OpenGL, allocates per frame.

#include <Eigen/Core>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/display/go_no_go.hpp"
#include "foresight/render/gl_context.hpp"
#include "foresight/render/renderer.hpp"

namespace foresight::display {

/// What one displayed frame shows besides the video.
struct DisplayState {
  Eigen::VectorXd q_actual;                  ///< delayed actual joints (telemetry), rad
  std::optional<Eigen::VectorXd> q_commanded;  ///< the ghost running ahead; none: not drawn
  render::RenderMode mode = render::RenderMode::Solid;  ///< of the actual arm and the ORU
  bool overlay = true;                       ///< false: the video (and text) only
  double ghost_alpha = 0.45;
  std::string delay_text;                    ///< e.g. "RTT 0.62 s (median 0.60, p99 0.71)"
  std::string controller_text;               ///< e.g. "controller RUNNING"
  std::string fault_text;                    ///< empty: no fault (drawn red otherwise)
  /// Calibration health (`display --health`), e.g. "calibration: 76% of the
  /// arm's edges within 1 px, IoU 0.93"; drawn red when health_warning.
  std::string health_text;
  bool health_warning = false;
  std::string video_problem;                 ///< empty: video fine (drawn red, centred otherwise)
  std::string footer;                        ///< e.g. "frame 12  t 0.40 s"
  /// The insert's go/no-go (`display --check-insert`): drawn with the overlay
  /// (draw_go_no_go, go_no_go.hpp), its label only with the text; none: not drawn.
  std::optional<GoNoGoMarks> go_no_go;
  bool text = true;                          ///< draw the text at all
};

struct DisplayColours {
  Eigen::Vector4d actual_rgba{1.0, 0.62, 0.18, 1.0};   ///< solid/ghost modes: apart from the real arm's grey
  Eigen::Vector4d actual_wire_rgba{0.2, 1.0, 0.3, 1.0};
  Eigen::Vector4d commanded_rgba{0.35, 0.85, 1.0, 1.0};
};

class DisplayComposer {
 public:
  /// Set-up: the arm (and optionally the ORU at base_T_object with the triads
  /// of its tag frames) for cameras of any viewport (one renderer per
  /// viewport, made on first use). The models must outlive the composer.
  DisplayComposer(render::GlContext& context, const RobotModel& robot, const ObjectModel* object,
                  std::optional<Pose> base_T_object, DisplayColours colours = {});
  ~DisplayComposer();
  DisplayComposer(const DisplayComposer&) = delete;
  DisplayComposer& operator=(const DisplayComposer&) = delete;

  /// The displayed picture for `camera`: `video_bgr` (8-bit BGR of the
  /// camera's viewport; empty = black) with the overlay and text. Throws
  /// std::invalid_argument on a wrong joint count or video size.
  cv::Mat compose(const camera::Camera& camera, const cv::Mat& video_bgr, const DisplayState& state);

  /// The actual arm's overlay silhouette alone (255 where drawn) at q:
  /// what a test compares with the synthetic camera's truth.
  cv::Mat arm_silhouette(const camera::Camera& camera, const Eigen::VectorXd& q);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Draws a line of text with a dark box behind it (top-left at `at`); returns the next line's y.
int put_text_line(cv::Mat& img, const std::string& text, cv::Point at, const cv::Scalar& colour, double scale = 0.5);

}  // namespace foresight::display
