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
#include "foresight/align/arm_links_file.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/synthetic_camera.hpp"
#include "foresight/render/video_frame.hpp"
#include "json_util.hpp"

namespace foresight::cli {
namespace {

struct SynthArgs {
  std::string camera, joints, joints_deg, out, arm_mask, write_cameras, arm_links, gl = "osmesa";
  std::string scene = default_config("scene.yaml");
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double noise_dn = 2.0, blur_px = 0.6;
  unsigned seed = 1;
  bool json = false;
};

int run_synth(const SynthArgs& a) {
  using namespace foresight::render;
  const GlBackend backend = parse_gl_backend(a.gl);
  if (!(a.noise_dn >= 0.0) || !(a.blur_px >= 0.0)) throw std::invalid_argument("--noise-dn and --blur-px must be >= 0");
  if (!a.joints.empty() && !a.joints_deg.empty()) throw std::invalid_argument("give only one of --joints, --joints-deg");
  const Scene scene = Scene::from_file(a.scene);
  const Camera camera = scene_camera(scene, a.camera, a.scene);
  const RobotModel nominal = RobotModel::from_file(a.robot);
  const RobotModel model =
      a.arm_links.empty() ? nominal : nominal.with_link_lengths_changed(align::load_arm_links(a.arm_links, nominal).delta_m);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const Eigen::VectorXd q = !a.joints.empty()       ? parse_joints(a.joints, "--joints", model)
                            : !a.joints_deg.empty() ? parse_joints(a.joints_deg, "--joints-deg", model, true)
                                                    : model.mid_configuration();
  if (!a.write_cameras.empty()) {
    std::map<std::string, CameraRecord> cams;
    for (const auto& name : scene.camera_order) cams[name].camera = scene_camera(scene, name, a.scene);
    save_cameras(a.write_cameras, cams);
  }
  auto context = GlContext::create(backend);
  SyntheticOptions o;
  o.noise_sigma_dn = a.noise_dn;
  o.blur_sigma_px = a.blur_px;
  o.seed = a.seed;
  SyntheticCamera synth(*context, model, object, scene, camera.viewport, o);
  const SyntheticFrame f = synth.render(camera, q);
  write_image(a.out, f.image_bgr);
  if (!a.arm_mask.empty()) write_image(a.arm_mask, f.arm_mask);
  if (a.json) {
    std::cout << nlohmann::json{{"out", a.out},
                                {"camera", camera.name},
                                {"gl", to_string(backend)},
                                {"joints_rad", vec_json(q)},
                                {"base_T_camera", pose_json(camera.base_T_camera)},
                                {"f_px", camera.f_px},
                                {"arm_pixels", cv::countNonZero(f.arm_mask)},
                                {"object_pixels", cv::countNonZero(f.object_mask)}}
                     .dump()
              << "\n";
  } else {
    std::printf("synth: camera %s (%dx%d, f %.1f px), noise %.1f DN, blur %.2f px; wrote %s\n", camera.name.c_str(),
                camera.viewport.width_px, camera.viewport.height_px, camera.f_px, a.noise_dn, a.blur_px, a.out.c_str());
    std::printf("  arm covers %d pixels, task object %d pixels\n", cv::countNonZero(f.arm_mask),
                cv::countNonZero(f.object_mask));
    if (!a.write_cameras.empty()) std::printf("  true cameras written to %s\n", a.write_cameras.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"synth", "render a synthetic camera frame of the true work site (stand-in for live video)",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<SynthArgs>();
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
       add_render_options(sub, a->gl, a->robot, a->object, a->json);
       return [a] { return run_synth(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
