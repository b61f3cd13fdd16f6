// foresight overlay: the arm (and optionally the localized task object) drawn
// through a calibrated camera over a video frame, in one of the paper's modes.
//
//   foresight overlay --cameras cameras.yaml --camera NAME --image IN
//                     --joints q1,...,qN (rad) | --joints-deg q1,...,qN
//                     [--object-pose localize.json] [--tags]
//                     --mode wire|solid|hidden|ghost [--alpha 0.5]
//                     --out OUT.png [--frame K] [--scale-image]
//                     [--gl osmesa|egl] [--robot robot.urdf] [--object oru.yaml] [--json]
// IN is an image or a video file (frame K, default 0). Exit: 0 ok, 2 bad
// input (missing image, size mismatch, unknown camera, wrong joint count),
// 1 the GL context or framebuffer could not be created.

#include <chrono>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/renderer.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/video_frame.hpp"
#include "json_util.hpp"

namespace foresight::cli {
namespace {

struct OverlayArgs {
  std::string cameras, camera, image, joints, joints_deg, object_pose, mode = "wire", out, gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double alpha = 0.5;
  int frame = 0;
  bool scale_image = false, tags = false, json = false;
};

int run_overlay(const OverlayArgs& a) {
  using namespace foresight::render;
  const auto t_start = std::chrono::steady_clock::now();
  const RenderMode mode = parse_render_mode(a.mode);
  const GlBackend backend = parse_gl_backend(a.gl);
  if (!(a.alpha >= 0.0 && a.alpha <= 1.0)) throw std::invalid_argument("--alpha must be in [0, 1]");
  if (a.joints.empty() == a.joints_deg.empty())
    throw std::invalid_argument("give the arm's joint angles with exactly one of --joints (rad) or --joints-deg");
  const Camera camera = load_camera(a.cameras, a.camera);
  const RobotModel model = RobotModel::from_file(a.robot);
  const Eigen::VectorXd q = a.joints.empty() ? parse_joints(a.joints_deg, "--joints-deg", model, true)
                                             : parse_joints(a.joints, "--joints", model);
  std::optional<ObjectModel> object;
  Pose base_T_object = Pose::Identity();
  if (!a.object_pose.empty()) {
    base_T_object = read_object_pose_json(a.object_pose);
    object = ObjectModel::from_file(a.object);
  } else if (a.tags) {
    throw std::invalid_argument("--tags needs --object-pose (the tags are frames of the object)");
  }
  auto context = GlContext::create(backend);
  Renderer renderer(*context, camera.viewport);
  cv::Mat video = fit_to_viewport(read_video_frame(a.image, a.frame), a.image, camera, a.scale_image);
  ArmGeometry arm(renderer, model);
  DrawList list;
  arm.append(q, list);
  if (object) {
    list.bodies.push_back({add_object_body(renderer, *object), base_T_object, kObjectWireRgba, std::nullopt});
    if (a.tags)
      for (const auto& [name, oru_T_tag] : object->tags) append_triad(list, base_T_object * oru_T_tag, 0.08);
  }
  RenderSettings settings;
  settings.mode = mode;
  cv::Mat layer;
  const auto t_render = std::chrono::steady_clock::now();
  const int triangles = renderer.render(camera, list, settings, layer);
  composite(layer, mode_opacity(mode, a.alpha), video);
  const double render_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_render).count();
  write_image(a.out, video);
  const double total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start).count();

  const Pose tip = arm.tip_pose(q);
  const Eigen::Vector2d tip_uv = camera.project(tip.translation());
  if (a.json) {
    nlohmann::json j = {{"out", a.out},
                        {"camera", camera.name},
                        {"viewport", {camera.viewport.width_px, camera.viewport.height_px}},
                        {"mode", to_string(mode)},
                        {"gl", to_string(backend)},
                        {"alpha", mode_opacity(mode, a.alpha)},
                        {"joints_rad", vec_json(q)},
                        {"object_drawn", object.has_value()},
                        {"triangles", triangles},
                        {"tip_px", vec_json(tip_uv)},
                        {"render_ms", render_ms},
                        {"total_ms", total_ms}};
    if (object) j["base_T_object"] = pose_json(base_T_object);
    std::cout << j.dump() << "\n";
  } else {
    std::printf("overlay: camera %s (%dx%d, f %.1f px), mode %s, %s back end\n", camera.name.c_str(),
                camera.viewport.width_px, camera.viewport.height_px, camera.f_px, to_string(mode), to_string(backend));
    std::printf("  arm at q (rad):");
    for (int i = 0; i < q.size(); ++i) std::printf(" %.4f", q[i]);
    std::printf("\n  tool tip at pixel (%.1f, %.1f)%s\n", tip_uv.x(), tip_uv.y(),
                object ? ", task object drawn from the localized pose" : "");
    std::printf("  %d triangles, render+composite %.1f ms; wrote %s\n", triangles, render_ms, a.out.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"overlay", "draw the arm (and the localized object) through a calibrated camera over a video frame",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<OverlayArgs>();
       add_video_frame_options(sub, a->cameras, a->camera, a->image, a->frame,
                               "video frame: an image file, or a video file (see --frame)");
       sub.add_option("--joints", a->joints, "arm joint angles q1,...,qN in radians");
       sub.add_option("--joints-deg", a->joints_deg, "arm joint angles in degrees (instead of --joints)");
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json` (key base_T_object)");
       sub.add_flag("--tags", a->tags, "draw the object's tag frames as axis triads (needs --object-pose)");
       sub.add_option("--mode", a->mode, "wire | solid | hidden | ghost")->capture_default_str();
       sub.add_option("--alpha", a->alpha, "ghost opacity in [0, 1]")->capture_default_str();
       sub.add_option("--out", a->out, "output image (PNG)")->required();
       sub.add_flag("--scale-image", a->scale_image, "resize an image whose size differs from the camera viewport");
       add_render_options(sub, a->gl, a->robot, a->object, a->json);
       return [a] { return run_overlay(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
