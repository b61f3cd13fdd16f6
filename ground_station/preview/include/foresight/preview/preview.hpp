#pragma once
// The paper's preview and predictive displays (Kim 1996, sec. 4):
//  - preview: the simulated arm moves along a planned trajectory over the
//    quasi-static video frame, at the trajectory's own time (or scaled), as a
//    video file, with a contact sheet of key frames;
//  - predictive frame: the commanded (immediate) arm as a ghost and the
//    delayed actual arm solid, in one labelled picture.
// Both draw through the calibrated camera with foresight::render. Not
// real-time code (allocates, writes files).

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "foresight/camera/camera.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/render/renderer.hpp"
#include "foresight/render/scene_geometry.hpp"

namespace foresight::preview {

/// Joint angles at time t_s (linear between samples; clamped to the ends).
Eigen::VectorXd sample_trajectory(const Trajectory& trajectory, double t_s);

/// The OpenCV VideoWriter fourcc for a video file by its extension (.mp4,
/// .avi, .webm, any case); InputError naming the file otherwise ("unsupported
/// video extension<for_what> (use ...)", e.g. for_what " for --record").
int video_fourcc(const std::string& path, const std::string& for_what = {});

/// What is drawn besides the arm: the task object at its pose, tag triads.
struct OverlayExtras {
  int object_body = -1;                       ///< from render::add_object_body, -1 for none
  Pose base_T_object = Pose::Identity();
  std::vector<Pose> base_T_tags;              ///< axis triads
  double triad_length_m = 0.08;
};

struct PreviewOptions {
  double speed = 1.0;                         ///< > 0; 2 plays twice as fast
  double fps = 30.0;                          ///< video frame rate
  render::RenderMode mode = render::RenderMode::Ghost;
  double ghost_alpha = 0.6;
  /// Solid/ghost colour of the simulated arm, so it stands apart from the
  /// real arm in the video; nullopt keeps the URDF colours.
  std::optional<Eigen::Vector4d> arm_rgba = Eigen::Vector4d(0.45, 0.95, 0.55, 1.0);
  bool tool_path = true;                      ///< the tip's path as a polyline
  int sheet_frames = 6;                       ///< key frames on the contact sheet (>= 2)
  int sheet_columns = 3;
  double sheet_scale = 0.5;                   ///< tile size relative to the viewport
  /// Asked before every video frame; true stops the rendering (Interrupted).
  std::function<bool()> interrupted;
};

/// The rendering was stopped by PreviewOptions::interrupted (the video is
/// incomplete).
class Interrupted : public std::runtime_error {
 public:
  Interrupted() : std::runtime_error("preview interrupted") {}
};

struct PreviewResult {
  int frames = 0;                             ///< video frames written
  double duration_s = 0.0;                   ///< of the trajectory
  double video_duration_s = 0.0;              ///< frames / fps
  std::vector<double> sheet_times_s;          ///< trajectory times of the key frames
  int triangles_per_frame = 0;
};

/// Video frame k shows trajectory time t0 + k * speed / fps; the last frame
/// shows the end. Writes `video_path` (.mp4: mp4v, .avi: MJPG, .webm: VP8)
/// and, when non-empty, the contact sheet PNG `sheet_path`. Throws
/// std::invalid_argument on a joint-count mismatch or bad options, and
/// InputError when an output cannot be written.
PreviewResult render_preview(render::Renderer& renderer, render::ArmGeometry& arm, const camera::Camera& camera,
                             const cv::Mat& background_bgr, const Trajectory& trajectory, const OverlayExtras& extras,
                             const PreviewOptions& options, const std::string& video_path,
                             const std::string& sheet_path);

struct PredictiveOptions {
  double ghost_alpha = 0.45;                  ///< the commanded arm
  Eigen::Vector4d commanded_rgba{0.35, 0.85, 1.0, 1.0};
  bool label = true;
};

/// The predictive display: the actual arm (reported `delay_s` ago) solid,
/// the commanded arm as a ghost over it, labelled with the delay.
cv::Mat predictive_frame(render::Renderer& renderer, render::ArmGeometry& arm, const camera::Camera& camera,
                         const cv::Mat& background_bgr, const Eigen::VectorXd& q_commanded,
                         const Eigen::VectorXd& q_actual, double delay_s, const OverlayExtras& extras,
                         const PredictiveOptions& options = {});

/// Appends the extras (object body and tag triads) to a draw list.
void append_extras(const OverlayExtras& extras, render::DrawList& list);

}  // namespace foresight::preview
