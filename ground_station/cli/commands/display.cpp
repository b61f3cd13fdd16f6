// foresight display: the live predictive display. The video (a V4L2 device,
// a network stream, a video file, or `synthetic`: the simulated scene's
// camera) with the calibrated overlay: the delayed actual arm (telemetry with
// --remote; the trajectory's past without one) in the chosen render mode, the
// ORU and its tag frames (--object-pose), the commanded arm running ahead as a
// ghost, the measured round trip, the controller state and any fault.
//
//   foresight display --cameras cameras.yaml --camera NAME --video SOURCE
//                     [--trajectory traj.csv] [--joints q | --joints-deg q] [--delay-s D]
//                     [--remote [--domain N] [--connect-timeout S]]
//                     [--object-pose localize.json] [--mode wire|solid|hidden|ghost] [--no-overlay] [--no-text]
//                     [--record out.mp4] [--headless] [--frames N] [--fps F] [--retry-s S]
//                     [--snapshot shown.png] [--scene scene.yaml] [--gl osmesa|egl]
//                     [--health [--health-every N]] [--check-insert [--ground ground.yaml]] [--json]
//
// Keys: w s h g render mode (wire, solid, hidden-line, ghost), o overlay on/off,
// c next camera (of cameras.yaml; with --remote the remote's video switch is
// asked first and the display follows once it has switched), t text on/off,
// q / Esc quit.
// Without --remote, frame k shows trajectory time k / fps: the commanded arm
// at that time, the actual (and the synthetic video's) arm --delay-s earlier.
// A video source that cannot be opened or stops is said on stderr and on the
// picture, and retried every --retry-s. Exit: 0 ok, 2 bad input (also: no
// display and no --headless), 1 the video source never delivered a frame or
// the remote did not answer. --json: frames, video_frames, recorded, mode,
// camera_switches, compose_ms_mean, ...; with --remote also remote{controller,
// fault, q_actual_rad, rtt_median_s (null before a measurement), alive,
// camera_problem}: what the last frame showed.
// --health: calibration health on the picture (as `foresight health`): every
// N-th video frame is scored against the shown arm (the reported one with
// --remote): the share of the arm's model edges within 1 px of the video's,
// the silhouette IoU, and a red warning when the camera has moved or zoomed
// (align::HealthMonitor; its baseline restarts when the camera changes).
// --json then has health{scored, camera_moved, warnings[{frame, camera,
// reason}], last{matched_fraction, score_px, iou}}.
// --check-insert: the insert's go/no-go with the overlay (needs --object-pose
// with its covariance, as localize/align --json write it): the hole's 95%
// ellipse and the tool tip at insert_start with its own, green go / red no_go,
// "insert: go P=0.997" beside them (docs/display.md). --json then has
// insert_check{verdict, p_success, label, hole{in_view, ellipse95}, tip{...}}.

#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/session/display_loop.hpp"
#include "link_options.hpp"

namespace foresight::cli {
namespace {

int show(const session::DisplaySettings& a) {
  const session::DisplaySummary s = session::run_display(a);
  if (a.link.json) {
    nlohmann::json j = {{"camera", s.camera},
                        {"video", a.video},
                        {"frames", s.shown},
                        {"video_frames", s.video_frames},
                        {"frames_with_video_problem", s.frames_with_video_problem},
                        {"open_attempts", s.open_attempts},
                        {"recorded", s.recorded},
                        {"mode", render::to_string(s.mode)},
                        {"camera_switches", s.camera_switches},
                        {"compose_ms_mean", s.compose_ms_mean}};
    if (!a.record.empty()) j["record"] = a.record;
    if (!s.health.is_null()) j["health"] = s.health;
    if (!s.remote.is_null()) j["remote"] = s.remote;
    if (!s.insert_check.is_null()) j["insert_check"] = s.insert_check;
    std::cout << j.dump() << "\n";
  } else {
    std::printf("display: camera %s, video %s: %d frame(s) shown, %d from the source, %d with a video problem",
                s.camera.c_str(), a.video.c_str(), s.shown, s.video_frames, s.frames_with_video_problem);
    if (s.recorded > 0) std::printf("; recorded %d to %s", s.recorded, a.record.c_str());
    std::printf("; compose %.1f ms/frame\n", s.compose_ms_mean);
  }
  if (s.shown > 0 && s.video_frames == 0) {
    std::cerr << "foresight display: error: video source '" << a.video << "' never delivered a frame ("
              << s.open_attempts << " attempt(s) to open it)\n";
    return kExitFailure;
  }
  return kExitOk;
}

const bool registered = register_command(
    {"display", "live predictive display: video with the calibrated overlay, the delayed and the commanded arm",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<session::DisplaySettings>();
       sub.add_option("--cameras", a->cameras, "cameras.yaml from `foresight calibrate`")->required();
       sub.add_option("--camera", a->camera, "camera name in cameras.yaml")->required();
       sub.add_option("--video", a->video,
                      "video source: synthetic (the simulated scene's camera), a device (0, /dev/video0), a stream "
                      "URL or a video file")
           ->required();
       sub.add_option("--trajectory", a->trajectory, "trajectory CSV: the commanded arm (and, without --remote, the actual arm --delay-s behind)");
       sub.add_option("--joints", a->joints, "the arm without remote or trajectory, q1,...,qN (rad)");
       sub.add_option("--joints-deg", a->joints_deg, "the same in degrees");
       sub.add_option("--delay-s", a->delay_s, "simulated delay of the actual arm without --remote, seconds")
           ->capture_default_str();
       sub.add_flag("--remote", a->remote, "the actual arm, round trip, controller state and faults from foresight-remote over DDS");
       add_link_options(sub, a->link, false);
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json`: draw the ORU and its tag frames");
       sub.add_flag("--check-insert", a->check_insert,
                    "draw the insert's go/no-go: the hole's 95% ellipse and the tool tip at insert_start, green go / red no_go "
                    "(needs --object-pose with its covariance)");
       sub.add_option("--ground", a->ground, "ground.yaml (its contact_check section, for --check-insert)")->capture_default_str();
       sub.add_option("--mode", a->mode, "render mode of the actual arm: wire | solid | hidden | ghost")->capture_default_str();
       sub.add_option("--alpha", a->alpha, "ghost opacity")->capture_default_str();
       sub.add_flag("--no-overlay", a->no_overlay, "start with the overlay off (key o)");
       sub.add_flag("--no-text", a->no_text, "start with the text off (key t)");
       sub.add_option("--record", a->record, "record what is shown (.mp4, .avi, .webm)");
       sub.add_flag("--headless", a->headless, "no window (needs no X server): record only");
       sub.add_option("--frames", a->frames, "stop after N frames (0: until q; headless: the trajectory's length)");
       sub.add_option("--fps", a->fps, "frame rate shown and recorded")->capture_default_str();
       sub.add_option("--retry-s", a->retry_s, "seconds between attempts to reopen a failed video source")->capture_default_str();
       sub.add_option("--snapshot", a->snapshot, "write the last shown frame (PNG) at exit");
       sub.add_option("--scene", a->scene, "the simulated work site for --video synthetic")->capture_default_str();
       sub.add_option("--gl", a->gl, "GL back end: osmesa | egl")->capture_default_str();
       sub.add_flag("--health", a->health,
                    "calibration health on the picture: the arm's model edges against the video, a warning when the "
                    "camera has moved or zoomed");
       sub.add_option("--health-every", a->health_every, "with --health: score every N-th video frame")
           ->check(check::PositiveNumber)
           ->capture_default_str();
       sub.add_option("--robot", a->robot, "robot URDF")->capture_default_str();
       sub.add_option("--object", a->object, "task object model")->capture_default_str();
       return [a] { return show(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
