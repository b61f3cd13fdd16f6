// foresight predictive: the predictive display in one picture. The commanded
// arm (where the operator's command puts it now) as a ghost over the actual
// arm as last reported, which is `--delay-s` old, solid; labelled with the delay.
//
//   foresight predictive --cameras cameras.yaml --camera NAME --image IN
//                        --commanded q1,...,qN --actual q1,...,qN (rad; or --deg)
//                        --delay-s D --out OUT.png [--alpha 0.45]
//                        [--object-pose localize.json] [--frame K] [--scale-image]
//                        [--gl osmesa|egl] [--robot robot.urdf] [--object oru.yaml] [--json]
// Exit: 0 ok, 2 bad input, 1 GL failure.

#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/preview/preview.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/render/video_frame.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

struct PredictiveArgs {
  std::string cameras, camera, image, commanded, actual, out, object_pose, gl = "osmesa";
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double delay_s = -1.0, alpha = 0.45;
  int frame = 0;
  bool deg = false, scale_image = false, json = false;
};

int run_predictive(const PredictiveArgs& a) {
  using namespace foresight::render;
  const GlBackend backend = parse_gl_backend(a.gl);
  if (!(a.alpha >= 0.0 && a.alpha <= 1.0)) throw std::invalid_argument("--alpha must be in [0, 1]");
  if (!(a.delay_s >= 0.0)) throw std::invalid_argument("--delay-s must be a non-negative number of seconds");
  const camera::Camera camera = load_camera(a.cameras, a.camera);
  const RobotModel model = RobotModel::from_file(a.robot);
  const Eigen::VectorXd q_cmd = parse_joints(a.commanded, "--commanded", model, a.deg);
  const Eigen::VectorXd q_act = parse_joints(a.actual, "--actual", model, a.deg);
  auto context = GlContext::create(backend);
  Renderer renderer(*context, camera.viewport);
  const cv::Mat video = fit_to_viewport(read_video_frame(a.image, a.frame), a.image, camera, a.scale_image);
  ArmGeometry arm(renderer, model);
  preview::OverlayExtras extras;
  if (!a.object_pose.empty()) {
    extras.base_T_object = localization::read_object_pose_json(a.object_pose);
    extras.object_body = add_object_body(renderer, ObjectModel::from_file(a.object));
  }
  preview::PredictiveOptions o;
  o.ghost_alpha = a.alpha;
  const cv::Mat out = preview::predictive_frame(renderer, arm, camera, video, q_cmd, q_act, a.delay_s, extras, o);
  write_image(a.out, out);
  const double tip_gap_m = (arm.tip_pose(q_cmd).translation() - arm.tip_pose(q_act).translation()).norm();
  if (a.json) {
    std::cout << nlohmann::json{{"out", a.out},           {"camera", camera.name},   {"gl", to_string(backend)},
                                {"delay_s", a.delay_s},   {"alpha", a.alpha},       {"commanded_rad", vec_json(q_cmd)},
                                {"actual_rad", vec_json(q_act)}, {"tip_gap_m", tip_gap_m}}
                     .dump()
              << "\n";
  } else {
    std::printf("predictive: camera %s, commanded arm as ghost (alpha %.2f) over the actual arm delayed %.2f s\n",
                camera.name.c_str(), a.alpha, a.delay_s);
    std::printf("  tool tips %.1f cm apart; wrote %s\n", tip_gap_m * 100.0, a.out.c_str());
  }
  return kExitOk;
}

const bool registered = register_command(
    {"predictive", "predictive display: the commanded arm (ghost) over the delayed actual arm (solid), labelled",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<PredictiveArgs>();
       add_video_frame_options(sub, a->cameras, a->camera, a->image, a->frame,
                               "video frame: an image, or a video file (see --frame)");
       sub.add_option("--commanded", a->commanded, "commanded joint angles q1,...,qN (rad)")->required();
       sub.add_option("--actual", a->actual, "actual (delayed) joint angles q1,...,qN (rad)")->required();
       sub.add_flag("--deg", a->deg, "joint angles are in degrees");
       sub.add_option("--delay-s", a->delay_s, "age of the actual joint angles, seconds")->required();
       sub.add_option("--out", a->out, "output image (PNG)")->required();
       sub.add_option("--alpha", a->alpha, "ghost opacity of the commanded arm")->capture_default_str();
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json` (key base_T_object)");
       sub.add_flag("--scale-image", a->scale_image, "resize an image whose size differs from the camera viewport");
       add_render_options(sub, a->gl, a->robot, a->object, a->json);
       return [a] { return run_predictive(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
