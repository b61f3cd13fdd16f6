// `foresight display`'s loop (display_loop.hpp).
#include "foresight/session/display_loop.hpp"

#include <opencv2/highgui.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>
#include <thread>
#include <vector>

#include "foresight/align/health.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/format.hpp"
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
#include "go_no_go_marks.hpp"

namespace foresight::session {

namespace {

using Clock = std::chrono::steady_clock;
constexpr const char* kWindow = "foresight display";

/// The loop's inputs, checked and loaded (nothing opened yet).
struct Inputs {
  std::vector<camera::Camera> cameras;
  std::size_t first_camera = 0;
  RobotModel robot;
  ObjectModel object;
  std::optional<Trajectory> trajectory;
  Eigen::VectorXd q_static;
  std::optional<Pose> base_T_object;
  int frames = 0;
  int fourcc = 0;
  std::optional<Scene> scene;  ///< --video synthetic
  std::optional<display::GoNoGoMarks> go_no_go;  ///< --check-insert
};

Inputs check_and_load(const DisplaySettings& a) {
  using namespace foresight::render;
  if (!(a.fps > 0.0 && a.fps <= 240.0)) throw std::invalid_argument("--fps must be in (0, 240]");
  if (!(a.delay_s >= 0.0) || !std::isfinite(a.delay_s)) throw std::invalid_argument("--delay-s must be >= 0");
  if (!(a.retry_s > 0.0)) throw std::invalid_argument("--retry-s must be positive");
  if (a.frames < 0) throw std::invalid_argument("--frames must be >= 0");
  if (!a.joints.empty() && !a.joints_deg.empty()) throw std::invalid_argument("give only one of --joints, --joints-deg");
  parse_render_mode(a.mode);
  parse_gl_backend(a.gl);
  const auto records = camera::load_cameras(a.cameras);
  std::vector<camera::Camera> cameras;
  for (const auto& [name, rec] : records) cameras.push_back(rec.camera);
  std::size_t cam_index = 0;
  while (cam_index < cameras.size() && cameras[cam_index].name != a.camera) ++cam_index;
  if (cam_index == cameras.size()) {
    load_camera(a.cameras, a.camera);  // throws "no camera 'X' (known: ...)"
    throw InputError(a.cameras, "no camera '" + a.camera + "'");
  }
  Inputs in{std::move(cameras), cam_index, RobotModel::from_file(a.robot), ObjectModel::from_file(a.object),
            std::nullopt, {}, std::nullopt, a.frames, 0, std::nullopt, std::nullopt};
  if (!a.trajectory.empty()) {
    in.trajectory = read_trajectory_csv(a.trajectory);
    if (in.trajectory->joints() != in.robot.dof())
      throw InputError(a.trajectory, "trajectory has " + std::to_string(in.trajectory->joints()) +
                                         " joints but the arm has " + std::to_string(in.robot.dof()));
  }
  in.q_static = in.robot.mid_configuration();
  if (!a.joints.empty()) in.q_static = parse_joints(a.joints, "--joints", in.robot);
  if (!a.joints_deg.empty()) in.q_static = parse_joints(a.joints_deg, "--joints-deg", in.robot, true);
  if (!a.object_pose.empty()) in.base_T_object = localization::read_object_pose_json(a.object_pose);
  if (a.check_insert) {
    if (a.object_pose.empty())
      throw std::invalid_argument("--check-insert needs --object-pose (the object pose with its covariance)");
    in.go_no_go = load_go_no_go_marks(a.object_pose, a.object, a.robot, a.ground);
  }
  if (a.headless && in.frames == 0) {
    if (!in.trajectory) throw std::invalid_argument("--headless needs --frames N (or a --trajectory to play through)");
    in.frames = static_cast<int>(std::ceil((in.trajectory->duration_s() + a.delay_s) * a.fps)) + 1;
  }
  if (a.headless && a.record.empty() && a.snapshot.empty())
    throw std::invalid_argument("--headless shows nothing: give --record out.mp4 (or --snapshot)");
  in.fourcc = a.record.empty() ? 0 : preview::video_fourcc(a.record, " for --record");
  if (!a.headless) {
    if (const std::string why = display::x_display_problem(); !why.empty())
      throw InputError("no display available (" + why + "): run with --headless to record without a window (--record out.mp4)");
  }
  if (a.video == "synthetic") in.scene = Scene::from_file(a.scene);
  return in;
}

class DisplayLoop {
 public:
  DisplayLoop(const DisplaySettings& a, Inputs in, std::unique_ptr<ground_link::GroundLink> link)
      : a_(a),
        in_(std::move(in)),
        link_(std::move(link)),
        cam_index_(in_.first_camera),
        context_(render::GlContext::create(render::parse_gl_backend(a.gl))),
        composer_(*context_, in_.robot, &in_.object, in_.base_T_object),
        record_size_(in_.cameras[cam_index_].viewport.width_px, in_.cameras[cam_index_].viewport.height_px) {
    if (in_.scene) {
      synth_ = std::make_unique<render::SyntheticCamera>(*context_, in_.robot, in_.object, *in_.scene,
                                                         in_.cameras[cam_index_].viewport);
    } else {
      capture_ = std::make_unique<display::CaptureSource>(
          a.video, std::chrono::milliseconds(static_cast<long>(std::lround(a.retry_s * 1000.0))));
    }
    if (!a.record.empty()) {
      writer_.open(a.record, in_.fourcc, a.fps, record_size_);
      if (!writer_.isOpened()) throw InputError(a.record, "cannot write video (--record)");
    }
    if (!a.headless) {
      cv::namedWindow(kWindow, cv::WINDOW_AUTOSIZE | cv::WINDOW_GUI_NORMAL);
      cv::moveWindow(kWindow, 0, 0);
    }
    if (a.health)
      aligner_ = std::make_unique<align::ModelAligner>(*context_, in_.robot, &in_.object, in_.cameras[cam_index_].viewport);
    state_.mode = render::parse_render_mode(a.mode);
    state_.overlay = !a.no_overlay;
    state_.text = !a.no_text;
    state_.ghost_alpha = a.alpha;
    state_.go_no_go = in_.go_no_go;
  }

  DisplaySummary run() {
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / a_.fps));
    auto next = Clock::now();
    for (int k = 0; in_.frames == 0 || k < in_.frames; ++k) {
      const camera::Camera& camera = in_.cameras[cam_index_];
      const double t_s = (in_.trajectory ? in_.trajectory->time_s.front() : 0.0) + k / a_.fps;
      update_arms(t_s);
      const cv::Mat video = read_video(camera);
      if (aligner_ && !video.empty() && (video_frames_ - 1) % a_.health_every == 0) score_health(k, camera, video);
      state_.footer = "frame " + std::to_string(k) + "  t " + fixed(t_s, 2) + " s  " +
                      (a_.headless ? "recording" : "w s h g mode  o overlay  c camera  q quit");
      show_and_record(camera, video);
      if (a_.headless) {
        // A live source runs at its own pace; the synthetic stream and files as fast as they render.
        if (!in_.scene && video.empty()) std::this_thread::sleep_until(next += period);
        continue;
      }
      cv::imshow(kWindow, picture_);
      next += period;
      const auto wait_ms = std::chrono::duration_cast<std::chrono::milliseconds>(next - Clock::now()).count();
      if (wait_ms < -1000) next = Clock::now();  // fell behind: do not race to catch up
      const int key = cv::waitKey(static_cast<int>(std::max<long>(1, wait_ms)));
      if (key >= 0 && !on_key(key & 0xff)) break;
    }
    writer_.release();
    if (!a_.snapshot.empty() && !picture_.empty()) render::write_image(a_.snapshot, picture_, "cannot write the snapshot");
    if (!a_.headless) cv::destroyAllWindows();
    return summary();
  }

 private:
  /// The arms: telemetry with a remote, the trajectory otherwise.
  void update_arms(double t_s) {
    state_.q_commanded.reset();
    state_.controller_text.clear();
    state_.fault_text.clear();
    if (link_) {
      const auto js = link_->joint_state();
      state_.q_actual = js ? joints_of(js->value, in_.robot).value_or(in_.q_static) : in_.q_static;
      if (in_.trajectory) state_.q_commanded = preview::sample_trajectory(*in_.trajectory, t_s);
      const auto stats = link_->delay().stats();
      state_.delay_text = stats.count == 0 ? "RTT: no measurement yet"
                                           : "RTT " + fixed(stats.last_rtt_s, 2) + " s (median " + fixed(stats.median_s, 2) +
                                                 ", p99 " + fixed(stats.p99_s, 2) + ")" +
                                                 (js ? ", joints " + fixed(js->age_s, 2) + " s old" : "");
      if (const auto st = link_->status()) {
        state_.controller_text = std::string("controller ") + protocol::to_string(st->value.mode);
        if (const std::string queue = queue_text(st->value); !queue.empty())
          state_.controller_text += " | " + queue;  // a chain: what runs, what is queued
        if (st->value.stop_category != protocol::StopCategory::None)
          state_.fault_text = std::string(protocol::to_string(st->value.stop_category)) + ": " + st->value.stop_reason;
        if (!st->value.fault_text.empty())
          state_.fault_text += (state_.fault_text.empty() ? "" : "; ") + st->value.fault_text;
      } else {
        state_.controller_text = "controller: no status yet";
      }
      if (!link_->remote_alive()) state_.fault_text = "link: remote silent for " + fixed(link_->remote_silence_s(), 1) + " s";
      follow_remote_camera();
    } else if (in_.trajectory) {
      state_.q_commanded = preview::sample_trajectory(*in_.trajectory, t_s);
      state_.q_actual = preview::sample_trajectory(*in_.trajectory, t_s - a_.delay_s);
      state_.delay_text = "delay " + fixed(a_.delay_s, 2) + " s (simulated, no remote)";
    } else {
      state_.q_actual = in_.q_static;
      state_.delay_text = "no remote: the arm at the given joints";
    }
  }

  /// The `c` key with a remote: the remote's video switch must show the next
  /// camera before the overlay uses that camera's calibration (one camera's
  /// overlay over another's video would mislead the operator). TAKE_CONTROL,
  /// CAMERA select and RELEASE_CONTROL go out at once, in order (the display
  /// never waits on the link); the display switches when CAMERA completes. A
  /// refusal or no answer is shown and the camera stays.
  void ask_remote_camera(std::size_t next) {
    protocol::CameraCommand select;
    select.camera = in_.cameras[next].name;
    select.action = protocol::CameraAction::Select;
    link_->send(protocol::CommandKind::TakeControl, protocol::NoPayload{});
    pending_camera_ = PendingCamera{link_->send(protocol::CommandKind::Camera, select), next,
                                    Clock::now() + link_->timeout_for(1.0)};
    link_->send(protocol::CommandKind::ReleaseControl, protocol::NoPayload{});
  }

  void follow_remote_camera() {
    if (pending_camera_) {
      const auto r = link_->wait_final(pending_camera_->id, std::chrono::nanoseconds(0));
      const std::string& name = in_.cameras[pending_camera_->index].name;
      if (r.finished && r.succeeded()) {
        switch_camera(pending_camera_->index);
        camera_problem_.clear();
        pending_camera_.reset();
      } else if (r.finished || Clock::now() > pending_camera_->deadline) {
        camera_problem_ = "camera " + name + " not switched at the remote: " +
                          (r.finished ? std::string(protocol::to_string(r.code)) + ": " + r.reason : "no answer");
        std::cerr << "foresight display: " << camera_problem_ << "\n";
        pending_camera_.reset();
      }
    }
    if (pending_camera_) camera_problem_ = "switching the remote's video to " + in_.cameras[pending_camera_->index].name;
    if (!camera_problem_.empty()) state_.fault_text += (state_.fault_text.empty() ? "" : "; ") + camera_problem_;
  }

  void switch_camera(std::size_t next) {
    const bool new_viewport = !(in_.cameras[next].viewport == in_.cameras[cam_index_].viewport);
    cam_index_ = next;
    ++camera_switches_;
    if (synth_ && new_viewport)
      synth_ = std::make_unique<render::SyntheticCamera>(*context_, in_.robot, in_.object, *in_.scene,
                                                         in_.cameras[cam_index_].viewport);
    if (aligner_ && new_viewport)
      aligner_ = std::make_unique<align::ModelAligner>(*context_, in_.robot, &in_.object, in_.cameras[cam_index_].viewport);
    monitor_ = align::HealthMonitor();
    state_.health_text.clear();
    state_.health_warning = false;
  }

  /// The video frame (empty when the source has none now); a problem is said
  /// on stderr once, and when the source delivers again.
  cv::Mat read_video(const camera::Camera& camera) {
    cv::Mat video;
    std::string problem;
    if (synth_) {
      video = synth_->render(render::scene_camera(*in_.scene, camera.name, a_.scene), state_.q_actual).image_bgr;
    } else if (capture_->read(video, problem)) {
      video = render::fit_to_viewport(video, a_.video, camera, true);
    } else {
      video.release();
    }
    if (!problem.empty()) {
      ++problems_;
      if (problem != last_problem_) std::cerr << "foresight display: " << problem << "\n";
    } else if (!last_problem_.empty()) {
      std::cerr << "foresight display: video source '" << a_.video << "' delivers again\n";
    }
    last_problem_ = problem;
    if (!video.empty()) ++video_frames_;
    state_.video_problem = problem;
    return video;
  }

  /// Calibration health: the aligner's score of the shown arm against the video.
  void score_health(int k, const camera::Camera& camera, const cv::Mat& video) {
    const auto score = aligner_->score(camera, {video, state_.q_actual}, in_.base_T_object);
    if (score.visible_samples == 0) {
      state_.health_text = "calibration: the arm is not in view";
      state_.health_warning = false;
      return;
    }
    const align::HealthVerdict v = monitor_.update(score);
    ++health_scored_;
    health_last_ = {{"matched_fraction", score.matched_fraction}, {"score_px", score.score_px}, {"iou", score.iou}};
    if (v.warning && !state_.health_warning)
      health_warnings_.push_back({{"frame", k}, {"camera", camera.name}, {"reason", v.reason}});
    camera_moved_ = camera_moved_ || v.warning;
    state_.health_warning = v.warning;
    state_.health_text = v.warning ? "CALIBRATION: " + v.reason
                                   : "calibration: " + fixed(100.0 * score.matched_fraction, 0) +
                                         "% of the arm's edges within 1 px, IoU " + fixed(score.iou, 2) +
                                         (v.in_baseline ? " (learning)" : "");
  }

  void show_and_record(const camera::Camera& camera, const cv::Mat& video) {
    const auto c0 = Clock::now();
    picture_ = composer_.compose(camera, video, state_);
    compose_s_ += std::chrono::duration<double>(Clock::now() - c0).count();
    ++shown_;
    if (!writer_.isOpened()) return;
    if (picture_.size() != record_size_) {
      cv::Mat resized;
      cv::resize(picture_, resized, record_size_, 0, 0, cv::INTER_AREA);
      writer_.write(resized);
    } else {
      writer_.write(picture_);
    }
    ++recorded_;
  }

  /// A key in the window; false to quit.
  bool on_key(int c) {
    using render::RenderMode;
    if (c == 'q' || c == 27) return false;
    if (c == 'w') state_.mode = RenderMode::Wire;
    if (c == 's') state_.mode = RenderMode::Solid;
    if (c == 'h') state_.mode = RenderMode::Hidden;
    if (c == 'g') state_.mode = RenderMode::Ghost;
    if (c == 'o') state_.overlay = !state_.overlay;
    if (c == 't') state_.text = !state_.text;
    if (c == 'c' && in_.cameras.size() > 1) {
      const std::size_t next = (cam_index_ + 1) % in_.cameras.size();
      if (!link_) switch_camera(next);
      else if (!pending_camera_) ask_remote_camera(next);
    }
    return true;
  }

  DisplaySummary summary() const {
    DisplaySummary s;
    s.camera = in_.cameras[cam_index_].name;
    s.shown = shown_;
    s.video_frames = video_frames_;
    s.frames_with_video_problem = problems_;
    s.open_attempts = capture_ ? capture_->open_attempts() : 0;
    s.recorded = recorded_;
    s.mode = state_.mode;
    s.camera_switches = camera_switches_;
    s.compose_ms_mean = shown_ > 0 ? 1000.0 * compose_s_ / shown_ : 0.0;
    if (aligner_)
      s.health = {{"scored", health_scored_},
                  {"camera_moved", camera_moved_},
                  {"warnings", health_warnings_},
                  {"last", health_last_}};
    if (in_.go_no_go)
      s.insert_check = go_no_go_json(*in_.go_no_go, display::project_go_no_go(in_.cameras[cam_index_], *in_.go_no_go));
    if (link_) {
      const auto stats = link_->delay().stats();
      s.remote = {{"controller", state_.controller_text},
                  {"fault", state_.fault_text},
                  {"q_actual_rad", std::vector<double>(state_.q_actual.data(), state_.q_actual.data() + state_.q_actual.size())},
                  {"rtt_median_s", stats.count > 0 ? nlohmann::json(stats.median_s) : nlohmann::json(nullptr)},
                  {"alive", link_->remote_alive()},
                  {"camera_problem", camera_problem_}};
    }
    return s;
  }

  struct PendingCamera {
    std::uint64_t id = 0;
    std::size_t index = 0;
    Clock::time_point deadline;
  };

  const DisplaySettings& a_;
  Inputs in_;
  std::unique_ptr<ground_link::GroundLink> link_;
  std::size_t cam_index_;
  std::unique_ptr<render::GlContext> context_;
  display::DisplayComposer composer_;
  std::unique_ptr<render::SyntheticCamera> synth_;
  std::unique_ptr<display::CaptureSource> capture_;
  cv::VideoWriter writer_;
  const cv::Size record_size_;
  std::optional<PendingCamera> pending_camera_;
  std::string camera_problem_;
  int camera_switches_ = 0;
  display::DisplayState state_;
  // Calibration health: the aligner's per-frame score, a monitor per camera shown.
  std::unique_ptr<align::ModelAligner> aligner_;
  align::HealthMonitor monitor_;
  int health_scored_ = 0;
  bool camera_moved_ = false;
  nlohmann::json health_warnings_ = nlohmann::json::array(), health_last_;
  std::string last_problem_;
  int shown_ = 0, recorded_ = 0, video_frames_ = 0, problems_ = 0;
  double compose_s_ = 0.0;
  cv::Mat picture_;
};

}  // namespace

DisplaySummary run_display(const DisplaySettings& settings) {
  Inputs in = check_and_load(settings);  // bad input before any window or GL work
  std::unique_ptr<ground_link::GroundLink> link;
  if (settings.remote) link = connect_remote(settings.link);
  DisplayLoop loop(settings, std::move(in), std::move(link));
  return loop.run();
}

}  // namespace foresight::session
