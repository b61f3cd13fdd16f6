// foresight preview: the paper's preview display. The simulated arm moves
// along a trajectory over the quasi-static video frame, at the trajectory's
// own time (or scaled), written as a video, with a contact sheet of key frames.
//
//   foresight preview TRAJ.csv --cameras cameras.yaml --camera NAME --image IN
//                     --out preview.mp4 [--contact-sheet sheet.png] [--speed 1.0]
//                     [--fps 30] [--mode ghost] [--alpha 0.6] [--no-path]
//                     [--object-pose localize.json] [--tags] [--frame K] [--scale-image]
//                     [--gl osmesa|egl] [--robot robot.urdf] [--object oru.yaml] [--json]
// TRAJ.csv is `t,q1,...,qN` (s, rad). A trajectory that breaks the arm's
// limits is still previewed (that is what a preview is for) and each
// violation is reported on stderr; one that is malformed (a non-finite value,
// time not increasing, too few samples) is refused: nothing that could never
// be sent is previewed as if it could. Exit: 0 ok, 2 bad input, 1 GL failure.

#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <iostream>

#include "command.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/preview/preview.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/video_frame.hpp"
#include "json_util.hpp"

namespace foresight::cli {
namespace {

struct PreviewArgs {
  std::string trajectory, cameras, camera, image, out, sheet, object_pose, mode = "ghost", gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double speed = 1.0, fps = 30.0, alpha = 0.6;
  int frame = 0;
  bool no_path = false, tags = false, scale_image = false, json = false;
};

int run_preview(const PreviewArgs& a) {
  using namespace foresight::render;
  const auto t_start = std::chrono::steady_clock::now();
  preview::PreviewOptions o;
  o.mode = parse_render_mode(a.mode);
  o.speed = a.speed;
  o.fps = a.fps;
  o.ghost_alpha = a.alpha;
  o.tool_path = !a.no_path;
  if (!(a.speed > 0.0) || !std::isfinite(a.speed)) throw std::invalid_argument("--speed must be a positive number");
  if (!(a.fps <= 1000.0)) throw std::invalid_argument("--fps must be at most 1000");
  if (!(a.alpha >= 0.0 && a.alpha <= 1.0)) throw std::invalid_argument("--alpha must be in [0, 1]");
  const GlBackend backend = parse_gl_backend(a.gl);
  const Trajectory tr = read_trajectory_csv(a.trajectory);
  const Camera camera = load_camera(a.cameras, a.camera);
  const RobotModel model = RobotModel::from_file(a.robot);
  if (tr.joints() != model.dof())
    throw InputError(a.trajectory, "trajectory has " + std::to_string(tr.joints()) + " joints but the arm has " +
                                       std::to_string(model.dof()));
  if (a.tags && a.object_pose.empty())
    throw std::invalid_argument("--tags needs --object-pose (the tags are frames of the object)");
  std::size_t total = 0;
  const std::vector<Violation> violations = validate(tr, TrajectoryLimits::from_model(model), &total);
  for (const auto& v : violations)
    if (v.rule == Violation::Rule::NonFinite || v.rule == Violation::Rule::TimeNotIncreasing ||
        v.rule == Violation::Rule::TooFewSamples)
      throw InputError(a.trajectory, v.message + ": cannot be previewed");
  for (const auto& v : violations) std::cerr << "foresight preview: warning: " << a.trajectory << ": " << v.message << "\n";
  if (total > violations.size())
    std::cerr << "foresight preview: warning: " << a.trajectory << ": ... and " << total - violations.size() << " more\n";
  // The frame count must fit before anything renders (--speed 1e-9 overflowed it).
  const std::optional<int> frames = limits::sample_count(tr.duration_s() / a.speed, a.fps);
  if (!frames || *frames > limits::kMaxVideoFrames)
    throw std::invalid_argument("--speed " + std::to_string(a.speed) + " and --fps " + std::to_string(a.fps) +
                                " give more than " + std::to_string(limits::kMaxVideoFrames) + " video frames for " +
                                std::to_string(tr.duration_s()) + " s of trajectory");

  auto context = GlContext::create(backend);
  Renderer renderer(*context, camera.viewport);
  const cv::Mat video = fit_to_viewport(read_video_frame(a.image, a.frame), a.image, camera, a.scale_image);
  ArmGeometry arm(renderer, model);
  preview::OverlayExtras extras;
  if (!a.object_pose.empty()) {
    const ObjectModel object = ObjectModel::from_file(a.object);
    extras.base_T_object = read_object_pose_json(a.object_pose);
    extras.object_body = add_object_body(renderer, object);
    if (a.tags)
      for (const auto& [name, oru_T_tag] : object.tags) extras.base_T_tags.push_back(extras.base_T_object * oru_T_tag);
  }
  const preview::PreviewResult r = preview::render_preview(renderer, arm, camera, video, tr, extras, o, a.out, a.sheet);
  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();

  if (a.json) {
    nlohmann::json j = {{"out", a.out},
                        {"contact_sheet", a.sheet},
                        {"camera", camera.name},
                        {"mode", to_string(o.mode)},
                        {"gl", to_string(backend)},
                        {"speed", o.speed},
                        {"fps", o.fps},
                        {"frames", r.frames},
                        {"trajectory_duration_s", r.duration_s},
                        {"video_duration_s", r.video_duration_s},
                        {"sheet_times_s", r.sheet_times_s},
                        {"triangles_per_frame", r.triangles_per_frame},
                        {"violations", total},
                        {"wall_time_s", total_s}};
    std::cout << j.dump() << "\n";
  } else {
    std::printf("preview: %s (%d samples, %.2f s, %d joints) through camera %s, mode %s, %s back end\n",
                a.trajectory.c_str(), tr.samples(), r.duration_s, tr.joints(), camera.name.c_str(), to_string(o.mode),
                to_string(backend));
    std::printf("  %d frames at %.1f frames/s (speed x%.2f): %.2f s of video; wrote %s\n", r.frames, o.fps, o.speed,
                r.video_duration_s, a.out.c_str());
    if (!a.sheet.empty()) std::printf("  contact sheet of %zu key frames: %s\n", r.sheet_times_s.size(), a.sheet.c_str());
    if (!violations.empty())
      std::printf("  WARNING: %zu limit violations (listed on stderr); the remote would reject this trajectory\n",
                  total);
    std::printf("  rendered in %.1f s\n", total_s);
  }
  return kExitOk;
}

const bool registered = register_command(
    {"preview", "preview a trajectory: the simulated arm moving over the video frame, as a video and a contact sheet",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<PreviewArgs>();
       sub.add_option("trajectory", a->trajectory, "trajectory CSV t,q1,...,qN (s, rad)")->required();
       add_video_frame_options(sub, a->cameras, a->camera, a->image, a->frame,
                               "the quasi-static video frame: an image, or a video file (see --frame)");
       sub.add_option("--out", a->out, "output video (.mp4, .avi or .webm)")->required();
       sub.add_option("--contact-sheet", a->sheet, "also write a PNG contact sheet of key frames");
       sub.add_option("--speed", a->speed, "playback speed relative to the trajectory's time")->capture_default_str();
       sub.add_option("--fps", a->fps, "video frame rate")->capture_default_str()->check(check::PositiveNumber);
       sub.add_option("--mode", a->mode, "wire | solid | hidden | ghost")->capture_default_str();
       sub.add_option("--alpha", a->alpha, "ghost opacity in [0, 1]")->capture_default_str();
       sub.add_flag("--no-path", a->no_path, "do not draw the tool tip's path");
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json` (key base_T_object)");
       sub.add_flag("--tags", a->tags, "draw the object's tag frames (needs --object-pose)");
       sub.add_flag("--scale-image", a->scale_image, "resize an image whose size differs from the camera viewport");
       add_render_options(sub, a->gl, a->robot, a->object, a->json);
       return [a] { return run_preview(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
