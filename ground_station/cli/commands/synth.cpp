// foresight synth: one frame of the synthetic camera, the stand-in for live
// video. Renders the true work site of scene.yaml (shaded arm, the ORU in the
// satellite panel, floor) through a true camera, with blur and sensor noise.
//
//   foresight synth --camera NAME [--joints q1,...,qN (rad) | --joints-deg ...]
//                   --out frame.png [--arm-mask mask.png] [--noise-dn 2] [--blur-px 0.6]
//                   [--seed 1] [--write-cameras cameras_true.yaml] [--scene scene.yaml]
//                   [--arm-links arm_links.yaml]
//                   [--gl osmesa|egl] [--robot robot.urdf] [--object oru.yaml] [--json]
// Without joints the arm is in the middle of its joint ranges. --write-cameras
// writes every scene camera (the ground truth) in cameras.yaml form.
// --arm-links renders a true arm whose link lengths differ from the model by
// those corrections (foresight/align/arm_links_file.hpp): the arm-model error
// that `align --arm-prior-mm` estimates.
// Exit: 0 ok, 2 bad input, 1 GL failure.

#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/session/operations.hpp"

namespace foresight::cli {
namespace {

struct SynthArgs {
  session::SynthRequest request;
  bool json = false;
};

int run_synth(const SynthArgs& args) {
  using namespace foresight::render;
  const session::SynthRequest& a = args.request;
  const session::Synthesized f = session::synth_frame(a);
  const camera::Camera& camera = f.camera;
  if (args.json) {
    std::cout << nlohmann::json{{"out", a.out},
                                {"camera", camera.name},
                                {"gl", to_string(f.backend)},
                                {"joints_rad", vec_json(f.q)},
                                {"base_T_camera", localization::pose_json(camera.base_T_camera)},
                                {"f_px", camera.f_px},
                                {"arm_pixels", f.arm_pixels},
                                {"object_pixels", f.object_pixels}}
                     .dump()
              << "\n";
  } else {
    std::printf("synth: camera %s (%dx%d, f %.1f px), noise %.1f DN, blur %.2f px; wrote %s\n", camera.name.c_str(),
                camera.viewport.width_px, camera.viewport.height_px, camera.f_px, a.noise_dn, a.blur_px, a.out.c_str());
    std::printf("  arm covers %d pixels, task object %d pixels\n", f.arm_pixels,
                f.object_pixels);
    if (!a.write_cameras.empty()) std::printf("  true cameras written to %s\n", a.write_cameras.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"synth", "render a synthetic camera frame of the true work site (stand-in for live video)",
     [](Command& sub) -> std::function<int()> {
       auto args = std::make_shared<SynthArgs>();
       session::SynthRequest* a = &args->request;
       sub.add_option("--camera", a->camera, "camera name in scene.yaml")->required();
       sub.add_option("--joints", a->joints, "arm joint angles q1,...,qN in radians");
       sub.add_option("--joints-deg", a->joints_deg, "arm joint angles in degrees");
       sub.add_option("--out", a->out, "output image (PNG)")->required();
       sub.add_option("--arm-mask", a->arm_mask, "also write the arm's true silhouette (PNG, 255 = arm)");
       sub.add_option("--noise-dn", a->noise_dn, "sensor noise sigma, digital numbers")->capture_default_str();
       sub.add_option("--blur-px", a->blur_px, "optical blur sigma, pixels")->capture_default_str();
       sub.add_option("--seed", a->seed, "noise seed")->capture_default_str();
       sub.add_option("--arm-links", a->arm_links, "render the arm with these link-length corrections (arm_links.yaml)");
       sub.add_option("--write-cameras", a->write_cameras, "write the true cameras as cameras.yaml");
       sub.add_option("--scene", a->scene, "the work site")->capture_default_str();
       add_render_options(sub, a->gl, a->robot, a->object, args->json);
       return [args] { return run_synth(*args); };
     }});

}  // namespace
}  // namespace foresight::cli
