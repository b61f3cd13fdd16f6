// foresight synth-clicks: the simulated operator. Writes the clicks an
// operator would make on the synthetic work site (config/scene.yaml), with
// Gaussian pixel noise, in the points-CSV formats of calibrate and localize:
//
//   - calibration clicks on the arm (the robot arm as the fixture): at four
//     arm poses, the link features each camera sees, as link-form rows
//     n,cam,link,lx,ly,lz,q1..qN,u,v;
//   - localization clicks on the ORU: the model points each camera sees, as
//     n,cam,x,y,z,u,v in the object frame.
//
// Used by the demo and by tests to run calibrate -> localize -> overlay with
// a known ground truth (printed, and in --json).
#include <iostream>

#include "command.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/session/operations.hpp"

namespace foresight::cli {
namespace {

struct Args {
  session::SynthClicksRequest request;
  bool json = false;
};

int run(const Args& args) {
  const session::SynthClicksRequest& a = args.request;
  const session::SynthClicks r = session::synth_clicks(a);
  nlohmann::json views = nlohmann::json::array();
  for (const auto& v : r.views)
    views.push_back({{"camera", v.camera}, {"calibration_clicks", v.calibration_clicks}, {"object_clicks", v.object_clicks}});
  const Pose& true_pose = r.true_base_T_object;
  nlohmann::json arm = nlohmann::json::array();
  for (const auto& q : r.arm_poses) arm.push_back(vec_json(q));
  if (args.json) {
    std::cout << nlohmann::json{{"noise_px", a.noise_px},
                                {"seed", a.seed},
                                {"views", views},
                                {"arm_poses_rad", arm},
                                {"true_base_T_object", localization::pose_json(true_pose)}}
                     .dump(2)
              << "\n";
    return kExitOk;
  }
  std::cout << "simulated operator: " << a.noise_px << " px noise (seed " << a.seed << "), " << r.arm_poses.size()
            << " arm poses\n";
  for (const auto& v : views)
    std::cout << "  " << v["camera"].get<std::string>() << ": " << v["calibration_clicks"].get<int>()
              << " arm clicks, " << v["object_clicks"].get<int>() << " ORU clicks\n";
  const Eigen::Vector3d t = true_pose.translation();
  const Eigen::Vector3d rpy = rpy_from_rotation(true_pose.linear()) * 180.0 / M_PI;
  std::printf("  true ORU pose: position %.4f %.4f %.4f m, roll/pitch/yaw %.3f %.3f %.3f deg\n", t.x(), t.y(),
              t.z(), rpy.x(), rpy.y(), rpy.z());
  if (!a.calibration_out.empty()) std::cout << "  wrote " << a.calibration_out << "\n";
  if (!a.object_out.empty()) std::cout << "  wrote " << a.object_out << "\n";
  if (!a.joints_out.empty()) std::cout << "  wrote " << a.joints_out << " (arm pose 1, rad)\n";
  return kExitOk;
}

const bool registered = register_command(
    {"synth-clicks", "simulated operator: noisy calibration clicks on the arm and localization clicks on the ORU",
     [](Command& sub) -> std::function<int()> {
       auto args = std::make_shared<Args>();
       session::SynthClicksRequest* a = &args->request;
       sub.add_option("--calibration-out", a->calibration_out, "arm clicks CSV for calibrate (link-form rows)");
       sub.add_option("--object-out", a->object_out, "ORU clicks CSV for localize (object-frame rows)");
       sub.add_option("--joints-out", a->joints_out, "write arm pose 1 as q1,...,qN (rad) for synth/overlay");
       sub.add_option("--noise-px", a->noise_px, "click noise sigma, pixels")->capture_default_str();
       sub.add_option("--seed", a->seed, "noise seed")->capture_default_str();
       sub.add_option("--per-pose", a->per_pose, "at most this many arm clicks per camera and arm pose")
           ->capture_default_str();
       sub.add_option("--scene", a->scene, "the work site (true cameras, ORU pose)")->capture_default_str();
       sub.add_option("--robot", a->robot, "robot URDF")->capture_default_str();
       sub.add_option("--object", a->object, "task object model")->capture_default_str();
       sub.add_flag("--json", args->json, "print one JSON object");
       return [args] { return run(*args); };
     }});

}  // namespace
}  // namespace foresight::cli
