// foresight overlay: the arm (and optionally the localized task object) drawn
// through a calibrated camera over a video frame, in one of the paper's modes.
//
//   foresight overlay --cameras cameras.yaml --camera NAME --image IN
//                     --joints q1,...,qN (rad) | --joints-deg q1,...,qN
//                     [--object-pose localize.json] [--tags] [--check-insert [--ground ground.yaml]]
//                     --mode wire|solid|hidden|ghost [--alpha 0.5]
//                     --out OUT.png [--frame K] [--scale-image]
//                     [--gl osmesa|egl] [--robot robot.urdf] [--object oru.yaml] [--json]
// IN is an image or a video file (frame K, default 0). Exit: 0 ok, 2 bad
// input (missing image, size mismatch, unknown camera, wrong joint count),
// 1 the GL context or framebuffer could not be created.
// --check-insert: the insert's go/no-go on the picture (needs --object-pose
// with its covariance): the hole's 95% ellipse and the tool tip at
// insert_start with its own, green go / red no_go, "insert: go P=0.997"
// (docs/display.md); --json adds insert_check{verdict, p_success, label,
// hole{in_view, ellipse95{centre_px, semi_major_px, semi_minor_px, angle_deg}}, tip{...}}.

#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/session/operations.hpp"

namespace foresight::cli {
namespace {

struct OverlayArgs {
  session::OverlayRequest request;
  bool json = false;
};

int run_overlay(const OverlayArgs& args) {
  using namespace foresight::render;
  const session::OverlayRequest& a = args.request;
  const session::Overlaid o = session::overlay_frame(a);
  const camera::Camera& camera = o.camera;
  const Eigen::VectorXd& q = o.q;
  const Eigen::Vector2d& tip_uv = o.tip_px;
  const int triangles = o.triangles;
  const double render_ms = o.render_ms, total_ms = o.total_ms;
  if (args.json) {
    nlohmann::json j = {{"out", a.out},
                        {"camera", camera.name},
                        {"viewport", {camera.viewport.width_px, camera.viewport.height_px}},
                        {"mode", to_string(o.mode)},
                        {"gl", to_string(o.backend)},
                        {"alpha", o.opacity},
                        {"joints_rad", vec_json(q)},
                        {"object_drawn", o.object_drawn},
                        {"triangles", triangles},
                        {"tip_px", vec_json(tip_uv)},
                        {"render_ms", render_ms},
                        {"total_ms", total_ms}};
    if (o.object_drawn) j["base_T_object"] = localization::pose_json(o.base_T_object);
    if (!o.insert_check.is_null()) j["insert_check"] = o.insert_check;
    std::cout << j.dump() << "\n";
  } else {
    std::printf("overlay: camera %s (%dx%d, f %.1f px), mode %s, %s back end\n", camera.name.c_str(),
                camera.viewport.width_px, camera.viewport.height_px, camera.f_px, to_string(o.mode), to_string(o.backend));
    std::printf("  arm at q (rad):");
    for (int i = 0; i < q.size(); ++i) std::printf(" %.4f", q[i]);
    std::printf("\n  tool tip at pixel (%.1f, %.1f)%s\n", tip_uv.x(), tip_uv.y(),
                o.object_drawn ? ", task object drawn from the localized pose" : "");
    if (!o.insert_check.is_null()) {
      const nlohmann::json& h = o.insert_check["hole"]["ellipse95"];
      std::printf("  %s", o.insert_check["label"].get<std::string>().c_str());
      if (!h.is_null())
        std::printf(": the hole's 95%% ellipse %.1f x %.1f px (semi-axes) at (%.1f, %.1f)",
                    h["semi_major_px"].get<double>(), h["semi_minor_px"].get<double>(), h["centre_px"][0].get<double>(),
                    h["centre_px"][1].get<double>());
      std::printf("\n");
    }
    std::printf("  %d triangles, render+composite %.1f ms; wrote %s\n", triangles, render_ms, a.out.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"overlay", "draw the arm (and the localized object) through a calibrated camera over a video frame",
     [](Command& sub) -> std::function<int()> {
       auto args = std::make_shared<OverlayArgs>();
       session::OverlayRequest* a = &args->request;
       add_video_frame_options(sub, a->cameras, a->camera, a->image, a->frame,
                               "video frame: an image file, or a video file (see --frame)");
       sub.add_option("--joints", a->joints, "arm joint angles q1,...,qN in radians");
       sub.add_option("--joints-deg", a->joints_deg, "arm joint angles in degrees (instead of --joints)");
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json` (key base_T_object)");
       sub.add_flag("--tags", a->tags, "draw the object's tag frames as axis triads (needs --object-pose)");
       sub.add_flag("--check-insert", a->check_insert,
                    "draw the insert's go/no-go: the hole's 95% ellipse and the tool tip at insert_start, green go / red no_go "
                    "(needs --object-pose with its covariance)");
       sub.add_option("--ground", a->ground, "ground.yaml (its contact_check section, for --check-insert)")->capture_default_str();
       sub.add_option("--mode", a->mode, "wire | solid | hidden | ghost")->capture_default_str();
       sub.add_option("--alpha", a->alpha, "ghost opacity in [0, 1]")->capture_default_str();
       sub.add_option("--out", a->out, "output image (PNG)")->required();
       sub.add_flag("--scale-image", a->scale_image, "resize an image whose size differs from the camera viewport");
       add_render_options(sub, a->gl, a->robot, a->object, args->json);
       return [args] { return run_overlay(*args); };
     }});

}  // namespace
}  // namespace foresight::cli
