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
#include "foresight/session/operations.hpp"

namespace foresight::cli {
namespace {

struct PreviewArgs {
  session::PreviewRequest request;
  bool json = false;
};

int run_preview(const PreviewArgs& args) {
  using namespace foresight::render;
  const session::PreviewRequest& a = args.request;
  const session::Previewed p = session::preview_trajectory(a);
  const preview::PreviewOptions& o = p.options;
  const preview::PreviewResult& r = p.result;
  const camera::Camera& camera = p.camera;
  for (const auto& v : p.violations) std::cerr << "foresight preview: warning: " << a.trajectory << ": " << v.message << "\n";
  if (p.violations_total > p.violations.size())
    std::cerr << "foresight preview: warning: " << a.trajectory << ": ... and " << p.violations_total - p.violations.size()
              << " more\n";
  if (args.json) {
    nlohmann::json j = {{"out", a.out},
                        {"contact_sheet", a.sheet},
                        {"camera", camera.name},
                        {"mode", to_string(o.mode)},
                        {"gl", to_string(p.backend)},
                        {"speed", o.speed},
                        {"fps", o.fps},
                        {"frames", r.frames},
                        {"trajectory_duration_s", r.duration_s},
                        {"video_duration_s", r.video_duration_s},
                        {"sheet_times_s", r.sheet_times_s},
                        {"triangles_per_frame", r.triangles_per_frame},
                        {"violations", p.violations_total},
                        {"wall_time_s", p.wall_time_s}};
    std::cout << j.dump() << "\n";
  } else {
    std::printf("preview: %s (%d samples, %.2f s, %d joints) through camera %s, mode %s, %s back end\n",
                a.trajectory.c_str(), p.samples, r.duration_s, p.joints, camera.name.c_str(), to_string(o.mode),
                to_string(p.backend));
    std::printf("  %d frames at %.1f frames/s (speed x%.2f): %.2f s of video; wrote %s\n", r.frames, o.fps, o.speed,
                r.video_duration_s, a.out.c_str());
    if (!a.sheet.empty()) std::printf("  contact sheet of %zu key frames: %s\n", r.sheet_times_s.size(), a.sheet.c_str());
    if (!p.violations.empty())
      std::printf("  WARNING: %zu limit violations (listed on stderr); the remote would reject this trajectory\n",
                  p.violations_total);
    std::printf("  rendered in %.1f s\n", p.wall_time_s);
  }
  return kExitOk;
}

const bool registered = register_command(
    {"preview", "preview a trajectory: the simulated arm moving over the video frame, as a video and a contact sheet",
     [](Command& sub) -> std::function<int()> {
       auto args = std::make_shared<PreviewArgs>();
       session::PreviewRequest* a = &args->request;
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
       add_render_options(sub, a->gl, a->robot, a->object, args->json);
       return [args] { return run_preview(*args); };
     }});

}  // namespace
}  // namespace foresight::cli
