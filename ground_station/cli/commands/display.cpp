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
//                     [--health [--health-every N]] [--json]
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

#include <opencv2/highgui.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <thread>
#include <vector>

#include "command.hpp"
#include "foresight/common/format.hpp"
#include "foresight/align/health.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/display/display_frame.hpp"
#include "foresight/display/video_source.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/preview/preview.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"
#include "foresight/render/video_frame.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

using Clock = std::chrono::steady_clock;
constexpr const char* kWindow = "foresight display";

struct DisplayArgs {
  std::string cameras, camera, video, trajectory, joints, joints_deg, object_pose, record, snapshot;
  std::string mode = "solid", gl = "osmesa";
  std::string scene = default_config("scene.yaml");
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double delay_s = 1.0, fps = 15.0, retry_s = 1.0, alpha = 0.45;
  int frames = 0, health_every = 5;
  bool remote = false, headless = false, no_overlay = false, no_text = false, health = false;
  LinkOptions link;
};

int fourcc_for(const std::string& path) {
  auto ends = [&](const std::string& e) {
    if (path.size() < e.size()) return false;
    std::string tail = path.substr(path.size() - e.size());
    for (auto& c : tail) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return tail == e;
  };
  if (ends(".mp4")) return cv::VideoWriter::fourcc('m', 'p', '4', 'v');
  if (ends(".avi")) return cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  if (ends(".webm")) return cv::VideoWriter::fourcc('V', 'P', '8', '0');
  throw InputError(path, "unsupported video extension for --record (use .mp4, .avi or .webm)");
}

int run_display(const DisplayArgs& a) {
  using namespace foresight::render;
  // Options first: bad input is said before any window or GL work.
  if (!(a.fps > 0.0 && a.fps <= 240.0)) throw std::invalid_argument("--fps must be in (0, 240]");
  if (!(a.delay_s >= 0.0) || !std::isfinite(a.delay_s)) throw std::invalid_argument("--delay-s must be >= 0");
  if (!(a.retry_s > 0.0)) throw std::invalid_argument("--retry-s must be positive");
  if (a.frames < 0) throw std::invalid_argument("--frames must be >= 0");
  if (!a.joints.empty() && !a.joints_deg.empty()) throw std::invalid_argument("give only one of --joints, --joints-deg");
  RenderMode mode = parse_render_mode(a.mode);
  const GlBackend backend = parse_gl_backend(a.gl);
  const auto records = load_cameras(a.cameras);
  std::vector<Camera> cameras;
  for (const auto& [name, rec] : records) cameras.push_back(rec.camera);
  std::size_t cam_index = 0;
  while (cam_index < cameras.size() && cameras[cam_index].name != a.camera) ++cam_index;
  if (cam_index == cameras.size()) {
    load_camera(a.cameras, a.camera);  // throws "no camera 'X' (known: ...)"
    throw InputError(a.cameras, "no camera '" + a.camera + "'");
  }
  const RobotModel robot = RobotModel::from_file(a.robot);
  const ObjectModel object = ObjectModel::from_file(a.object);
  std::optional<Trajectory> trajectory;
  if (!a.trajectory.empty()) {
    trajectory = read_trajectory_csv(a.trajectory);
    if (trajectory->joints() != robot.dof())
      throw InputError(a.trajectory, "trajectory has " + std::to_string(trajectory->joints()) + " joints but the arm has " +
                                         std::to_string(robot.dof()));
  }
  Eigen::VectorXd q_static = robot.mid_configuration();
  if (!a.joints.empty()) q_static = parse_joints(a.joints, "--joints", robot);
  if (!a.joints_deg.empty()) q_static = parse_joints(a.joints_deg, "--joints-deg", robot, true);
  std::optional<Pose> base_T_object;
  if (!a.object_pose.empty()) base_T_object = read_object_pose_json(a.object_pose);
  int frames = a.frames;
  if (a.headless && frames == 0) {
    if (!trajectory) throw std::invalid_argument("--headless needs --frames N (or a --trajectory to play through)");
    frames = static_cast<int>(std::ceil((trajectory->duration_s() + a.delay_s) * a.fps)) + 1;
  }
  if (a.headless && a.record.empty() && a.snapshot.empty())
    throw std::invalid_argument("--headless shows nothing: give --record out.mp4 (or --snapshot)");
  const int fourcc = a.record.empty() ? 0 : fourcc_for(a.record);
  if (!a.headless) {
    if (const std::string why = display::x_display_problem(); !why.empty())
      throw InputError("no display available (" + why + "): run with --headless to record without a window (--record out.mp4)");
  }
  const bool synthetic = a.video == "synthetic";
  std::optional<Scene> scene;
  if (synthetic) scene = Scene::from_file(a.scene);

  std::unique_ptr<ground_link::GroundLink> link;
  if (a.remote) link = connect_remote(a.link);

  auto context = GlContext::create(backend);
  display::DisplayComposer composer(*context, robot, &object, base_T_object);
  std::unique_ptr<SyntheticCamera> synth;
  std::unique_ptr<display::CaptureSource> capture;
  if (synthetic) {
    synth = std::make_unique<SyntheticCamera>(*context, robot, object, *scene, cameras[cam_index].viewport);
  } else {
    capture = std::make_unique<display::CaptureSource>(
        a.video, std::chrono::milliseconds(static_cast<long>(std::lround(a.retry_s * 1000.0))));
  }
  cv::VideoWriter writer;
  const cv::Size record_size(cameras[cam_index].viewport.width_px, cameras[cam_index].viewport.height_px);
  if (!a.record.empty()) {
    writer.open(a.record, fourcc, a.fps, record_size);
    if (!writer.isOpened()) throw InputError(a.record, "cannot write video (--record)");
  }
  if (!a.headless) {
    cv::namedWindow(kWindow, cv::WINDOW_AUTOSIZE | cv::WINDOW_GUI_NORMAL);
    cv::moveWindow(kWindow, 0, 0);
  }

  // The `c` key with --remote: the remote's video switch must show the next
  // camera before the overlay uses that camera's calibration (one camera's
  // overlay over another's video would mislead the operator). TAKE_CONTROL,
  // CAMERA select and RELEASE_CONTROL go out at once, in order (the display
  // never waits on the link); the display switches when CAMERA completes. A
  // refusal or no answer is shown and the camera stays.
  struct PendingCamera {
    std::uint64_t id = 0;
    std::size_t index = 0;
    Clock::time_point deadline;
  };
  std::optional<PendingCamera> pending_camera;
  std::string camera_problem;
  int camera_switches = 0;
  display::DisplayState state;
  // Calibration health (--health): the aligner's per-frame score, a monitor per camera shown.
  std::unique_ptr<align::ModelAligner> aligner;
  align::HealthMonitor monitor;
  if (a.health) aligner = std::make_unique<align::ModelAligner>(*context, robot, &object, cameras[cam_index].viewport);
  int health_scored = 0;
  bool camera_moved = false;
  nlohmann::json health_warnings = nlohmann::json::array(), health_last;
  auto switch_camera = [&](std::size_t next) {
    const bool new_viewport = !(cameras[next].viewport == cameras[cam_index].viewport);
    cam_index = next;
    ++camera_switches;
    if (synthetic && new_viewport)
      synth = std::make_unique<SyntheticCamera>(*context, robot, object, *scene, cameras[cam_index].viewport);
    if (aligner && new_viewport)
      aligner = std::make_unique<align::ModelAligner>(*context, robot, &object, cameras[cam_index].viewport);
    monitor = align::HealthMonitor();
    state.health_text.clear();
    state.health_warning = false;
  };

  state.mode = mode;
  state.overlay = !a.no_overlay;
  state.text = !a.no_text;
  state.ghost_alpha = a.alpha;
  std::string last_problem;
  int shown = 0, recorded = 0, video_frames = 0, problems = 0;
  double compose_s = 0.0;
  cv::Mat picture;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / a.fps));
  auto next = Clock::now();
  for (int k = 0; frames == 0 || k < frames; ++k) {
    const Camera& camera = cameras[cam_index];
    const double t_s = (trajectory ? trajectory->time_s.front() : 0.0) + k / a.fps;
    // The arms: telemetry with a remote, the trajectory otherwise.
    state.q_commanded.reset();
    state.controller_text.clear();
    state.fault_text.clear();
    if (link) {
      const auto js = link->joint_state();
      state.q_actual = js ? joints_of(js->value, robot).value_or(q_static) : q_static;
      if (trajectory) state.q_commanded = preview::sample_trajectory(*trajectory, t_s);
      const auto stats = link->delay().stats();
      state.delay_text = stats.count == 0 ? "RTT: no measurement yet"
                                          : "RTT " + fixed(stats.last_rtt_s, 2) + " s (median " + fixed(stats.median_s, 2) +
                                                ", p99 " + fixed(stats.p99_s, 2) + ")" +
                                                (js ? ", joints " + fixed(js->age_s, 2) + " s old" : "");
      if (const auto st = link->status()) {
        state.controller_text = std::string("controller ") + protocol::to_string(st->value.mode);
        if (const std::string queue = queue_text(st->value); !queue.empty())
          state.controller_text += " | " + queue;  // a chain: what runs, what is queued
        if (st->value.stop_category != protocol::StopCategory::None)
          state.fault_text = std::string(protocol::to_string(st->value.stop_category)) + ": " + st->value.stop_reason;
        if (!st->value.fault_text.empty())
          state.fault_text += (state.fault_text.empty() ? "" : "; ") + st->value.fault_text;
      } else {
        state.controller_text = "controller: no status yet";
      }
      if (!link->remote_alive()) state.fault_text = "link: remote silent for " + fixed(link->remote_silence_s(), 1) + " s";
      if (pending_camera) {
        const auto r = link->wait_final(pending_camera->id, std::chrono::nanoseconds(0));
        const std::string& name = cameras[pending_camera->index].name;
        if (r.finished && r.succeeded()) {
          switch_camera(pending_camera->index);
          camera_problem.clear();
          pending_camera.reset();
        } else if (r.finished || Clock::now() > pending_camera->deadline) {
          camera_problem = "camera " + name + " not switched at the remote: " +
                           (r.finished ? std::string(protocol::to_string(r.code)) + ": " + r.reason : "no answer");
          std::cerr << "foresight display: " << camera_problem << "\n";
          pending_camera.reset();
        }
      }
      if (pending_camera) camera_problem = "switching the remote's video to " + cameras[pending_camera->index].name;
      if (!camera_problem.empty()) state.fault_text += (state.fault_text.empty() ? "" : "; ") + camera_problem;
    } else if (trajectory) {
      state.q_commanded = preview::sample_trajectory(*trajectory, t_s);
      state.q_actual = preview::sample_trajectory(*trajectory, t_s - a.delay_s);
      state.delay_text = "delay " + fixed(a.delay_s, 2) + " s (simulated, no remote)";
    } else {
      state.q_actual = q_static;
      state.delay_text = "no remote: the arm at the given joints";
    }
    // The video.
    cv::Mat video;
    std::string problem;
    if (synthetic) {
      video = synth->render(render::scene_camera(*scene, camera.name, a.scene), state.q_actual).image_bgr;
    } else if (capture->read(video, problem)) {
      video = fit_to_viewport(video, a.video, camera, true);
    } else {
      video.release();
    }
    if (!problem.empty()) {
      ++problems;
      if (problem != last_problem) std::cerr << "foresight display: " << problem << "\n";
    } else if (!last_problem.empty()) {
      std::cerr << "foresight display: video source '" << a.video << "' delivers again\n";
    }
    last_problem = problem;
    if (!video.empty()) ++video_frames;
    state.video_problem = problem;
    if (aligner && !video.empty() && (video_frames - 1) % a.health_every == 0) {
      const auto score = aligner->score(camera, {video, state.q_actual}, base_T_object);
      if (score.visible_samples == 0) {
        state.health_text = "calibration: the arm is not in view";
        state.health_warning = false;
      } else {
        const align::HealthVerdict v = monitor.update(score);
        ++health_scored;
        health_last = {{"matched_fraction", score.matched_fraction}, {"score_px", score.score_px}, {"iou", score.iou}};
        if (v.warning && !state.health_warning)
          health_warnings.push_back({{"frame", k}, {"camera", camera.name}, {"reason", v.reason}});
        camera_moved = camera_moved || v.warning;
        state.health_warning = v.warning;
        state.health_text = v.warning ? "CALIBRATION: " + v.reason
                                      : "calibration: " + fixed(100.0 * score.matched_fraction, 0) +
                                            "% of the arm's edges within 1 px, IoU " + fixed(score.iou, 2) +
                                            (v.in_baseline ? " (learning)" : "");
      }
    }
    state.footer = "frame " + std::to_string(k) + "  t " + fixed(t_s, 2) + " s  " + (a.headless ? "recording" : "w s h g mode  o overlay  c camera  q quit");
    const auto c0 = Clock::now();
    picture = composer.compose(camera, video, state);
    compose_s += std::chrono::duration<double>(Clock::now() - c0).count();
    ++shown;
    if (writer.isOpened()) {
      if (picture.size() != record_size) {
        cv::Mat resized;
        cv::resize(picture, resized, record_size, 0, 0, cv::INTER_AREA);
        writer.write(resized);
      } else {
        writer.write(picture);
      }
      ++recorded;
    }
    if (a.headless) {
      // A live source runs at its own pace; the synthetic stream and files as fast as they render.
      if (!synthetic && video.empty()) std::this_thread::sleep_until(next += period);
      continue;
    }
    cv::imshow(kWindow, picture);
    next += period;
    const auto wait_ms = std::chrono::duration_cast<std::chrono::milliseconds>(next - Clock::now()).count();
    if (wait_ms < -1000) next = Clock::now();  // fell behind: do not race to catch up
    const int key = cv::waitKey(static_cast<int>(std::max<long>(1, wait_ms))) ;
    if (key < 0) continue;
    const int c = key & 0xff;
    if (c == 'q' || c == 27) break;
    if (c == 'w') state.mode = RenderMode::Wire;
    if (c == 's') state.mode = RenderMode::Solid;
    if (c == 'h') state.mode = RenderMode::Hidden;
    if (c == 'g') state.mode = RenderMode::Ghost;
    if (c == 'o') state.overlay = !state.overlay;
    if (c == 't') state.text = !state.text;
    if (c == 'c' && cameras.size() > 1) {
      const std::size_t next = (cam_index + 1) % cameras.size();
      if (!link) {
        switch_camera(next);
      } else if (!pending_camera) {
        protocol::CameraCommand select;
        select.camera = cameras[next].name;
        select.action = protocol::CameraAction::Select;
        link->send(protocol::CommandKind::TakeControl, protocol::NoPayload{});
        pending_camera = PendingCamera{link->send(protocol::CommandKind::Camera, select), next,
                                       Clock::now() + link->timeout_for(1.0)};
        link->send(protocol::CommandKind::ReleaseControl, protocol::NoPayload{});
      }
    }
  }
  writer.release();
  if (!a.snapshot.empty() && !picture.empty()) write_image(a.snapshot, picture, "cannot write the snapshot");
  if (!a.headless) cv::destroyAllWindows();
  const int attempts = capture ? capture->open_attempts() : 0;
  if (a.link.json) {
    nlohmann::json j = {{"camera", cameras[cam_index].name},
                        {"video", a.video},
                        {"frames", shown},
                        {"video_frames", video_frames},
                        {"frames_with_video_problem", problems},
                        {"open_attempts", attempts},
                        {"recorded", recorded},
                        {"mode", to_string(state.mode)},
                        {"camera_switches", camera_switches},
                        {"compose_ms_mean", shown > 0 ? 1000.0 * compose_s / shown : 0.0}};
    if (!a.record.empty()) j["record"] = a.record;
    if (aligner)
      j["health"] = {{"scored", health_scored},
                     {"camera_moved", camera_moved},
                     {"warnings", health_warnings},
                     {"last", health_last}};
    if (link) {  // what the last frame showed from the remote
      const auto stats = link->delay().stats();
      j["remote"] = {{"controller", state.controller_text},
                     {"fault", state.fault_text},
                     {"q_actual_rad", std::vector<double>(state.q_actual.data(), state.q_actual.data() + state.q_actual.size())},
                     {"rtt_median_s", stats.count > 0 ? nlohmann::json(stats.median_s) : nlohmann::json(nullptr)},
                     {"alive", link->remote_alive()},
                     {"camera_problem", camera_problem}};
    }
    std::cout << j.dump() << "\n";
  } else {
    std::printf("display: camera %s, video %s: %d frame(s) shown, %d from the source, %d with a video problem",
                cameras[cam_index].name.c_str(), a.video.c_str(), shown, video_frames, problems);
    if (recorded > 0) std::printf("; recorded %d to %s", recorded, a.record.c_str());
    std::printf("; compose %.1f ms/frame\n", shown > 0 ? 1000.0 * compose_s / shown : 0.0);
  }
  if (shown > 0 && video_frames == 0) {
    std::cerr << "foresight display: error: video source '" << a.video << "' never delivered a frame (" << attempts
              << " attempt(s) to open it)\n";
    return kExitFailure;
  }
  return kExitOk;
}

const bool registered = register_command(
    {"display", "live predictive display: video with the calibrated overlay, the delayed and the commanded arm",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<DisplayArgs>();
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
       return [a] { return run_display(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
