#pragma once
// `foresight display`'s loop: the live predictive display. The video (a V4L2
// device, a network stream, a video file, or `synthetic`: the simulated
// scene's camera) with the calibrated overlay: the delayed actual arm
// (telemetry with a remote; the trajectory's past without one) in the chosen
// render mode, the ORU and its tag frames, the commanded arm running ahead as
// a ghost, the measured round trip, the controller state and any fault; the
// calibration health on demand. Keys in the window: w s h g render mode, o
// overlay, c next camera (with a remote: its video switch first), t text,
// q / Esc quit. Not real-time code: the operator's screen.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "foresight/render/renderer.hpp"
#include "foresight/session/config_path.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::session {

struct DisplaySettings {
  std::string cameras, camera;        ///< cameras.yaml and the camera shown first
  std::string video;                  ///< "synthetic", a device, a stream URL or a video file
  std::string trajectory;             ///< the commanded arm (and without a remote the actual one, delay_s behind)
  std::string joints, joints_deg;     ///< the arm without remote or trajectory
  std::string object_pose;            ///< localize JSON: the ORU and its tags drawn
  std::string record, snapshot;       ///< what is shown as a video; the last frame as a PNG
  std::string mode = "solid", gl = "osmesa";
  std::string scene = default_config("scene.yaml");
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  std::string ground = default_config("ground.yaml");  ///< its contact_check section (check_insert)
  double delay_s = 1.0, fps = 15.0, retry_s = 1.0, alpha = 0.45;
  int frames = 0;                     ///< 0: until q (headless: the trajectory's length)
  int health_every = 5;
  bool remote = false, headless = false, no_overlay = false, no_text = false, health = false;
  /// The insert's go/no-go drawn with the overlay (display/go_no_go.hpp):
  /// needs object_pose with its covariance.
  bool check_insert = false;
  LinkOptions link;                   ///< with `remote`
};

/// What the display showed, for the command's summary.
struct DisplaySummary {
  std::string camera;                 ///< shown last
  int shown = 0, video_frames = 0, frames_with_video_problem = 0, open_attempts = 0, recorded = 0;
  render::RenderMode mode = render::RenderMode::Solid;
  int camera_switches = 0;
  double compose_ms_mean = 0.0;
  /// With health: {scored, camera_moved, warnings[{frame, camera, reason}], last{matched_fraction, score_px, iou}}.
  nlohmann::json health;
  /// With a remote, what the last frame showed: {controller, fault,
  /// q_actual_rad, rtt_median_s (null before a measurement), alive, camera_problem}.
  nlohmann::json remote;
  /// With check_insert: {verdict, p_success, label, hole{in_view, ellipse95}, tip{...}}
  /// through the camera shown last; null otherwise.
  nlohmann::json insert_check;
};

/// Checks the settings (bad input before any window or GL work:
/// std::invalid_argument / InputError naming the option or file), connects
/// the remote when asked, and shows frames until q, `frames` or the end.
DisplaySummary run_display(const DisplaySettings& settings);

}  // namespace foresight::session
