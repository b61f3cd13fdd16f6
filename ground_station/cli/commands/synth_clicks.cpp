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
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>

#include "command.hpp"
#include "foresight/common/atomic_file.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "json_util.hpp"

namespace foresight::cli {
namespace {

struct Args {
  std::string scene = default_config("scene.yaml");
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  double noise_px = 1.0;
  unsigned seed = 1;
  int per_pose = 8;
  std::string calibration_out;
  std::string object_out;
  std::string joints_out;
  bool json = false;
};

/// The text of an output file, written atomically at the end (write_file_atomic).
std::ostringstream open_out(const std::string& path) {
  check_output_path(path);  // before any work
  std::ostringstream f;
  f.precision(15);
  return f;
}

int run(const Args& a) {
  if (!(a.noise_px >= 0.0 && a.noise_px <= limits::kMaxPixelNoise_px))
    throw std::invalid_argument("--noise-px must be a number in [0, " +
                                std::to_string(static_cast<int>(limits::kMaxPixelNoise_px)) + "] px");
  if (a.per_pose < 1) throw std::invalid_argument("--per-pose must be at least 1");
  const Scene scene = Scene::from_file(a.scene);
  const RobotModel robot = RobotModel::from_file(a.robot);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const StudySetup setup = make_study_setup(scene, object, {});
  const std::vector<ArmCalibrationPose> poses = arm_calibration_poses(robot);

  std::mt19937 rng(a.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  auto click = [&](const Camera& c, const Eigen::Vector3d& p_base) {
    return Eigen::Vector2d(c.project(p_base) + a.noise_px * Eigen::Vector2d(noise(rng), noise(rng)));
  };

  nlohmann::json views = nlohmann::json::array();
  std::ostringstream cal, obj;
  if (!a.calibration_out.empty()) {
    cal = open_out(a.calibration_out);
    cal << "n,cam,link,lx,ly,lz";
    for (int j = 1; j <= robot.dof(); ++j) cal << ",q" << j;
    cal << ",u,v\n";
  }
  if (!a.object_out.empty()) {
    obj = open_out(a.object_out);
    obj << "n,cam,x,y,z,u,v\n";
  }
  int n_cal = 0, n_obj = 0;
  for (const StudyView& v : setup.views) {
    int cal_here = 0, obj_here = 0;
    for (const ArmCalibrationPose& pose : poses)
      for (const ArmFeature& f : visible_features(v.truth, pose, a.per_pose)) {
        const Eigen::Vector2d uv = click(v.truth, f.p_base);
        ++cal_here;
        if (a.calibration_out.empty()) continue;
        cal << ++n_cal << ',' << v.truth.name << ',' << robot.links()[f.link].name << ',' << f.p_link.x() << ','
            << f.p_link.y() << ',' << f.p_link.z();
        for (int j = 0; j < robot.dof(); ++j) cal << ',' << pose.q[j];
        cal << ',' << uv.x() << ',' << uv.y() << '\n';
      }
    for (const Eigen::Vector3d& p : v.object_points) {
      const Eigen::Vector2d uv = click(v.truth, setup.base_T_object * p);
      ++obj_here;
      if (!a.object_out.empty())
        obj << ++n_obj << ',' << v.truth.name << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << uv.x() << ','
            << uv.y() << '\n';
    }
    views.push_back({{"camera", v.truth.name}, {"calibration_clicks", cal_here}, {"object_clicks", obj_here}});
  }
  if (!a.calibration_out.empty()) write_file_atomic(a.calibration_out, cal.str());
  if (!a.object_out.empty()) write_file_atomic(a.object_out, obj.str());
  if (!a.joints_out.empty()) {
    std::ostringstream j = open_out(a.joints_out);
    for (int i = 0; i < robot.dof(); ++i) j << (i ? "," : "") << poses.front().q[i];
    j << '\n';
    write_file_atomic(a.joints_out, j.str());
  }

  nlohmann::json arm = nlohmann::json::array();
  for (const auto& p : poses) arm.push_back(vec_json(p.q));
  if (a.json) {
    std::cout << nlohmann::json{{"noise_px", a.noise_px},
                                {"seed", a.seed},
                                {"views", views},
                                {"arm_poses_rad", arm},
                                {"true_base_T_object", pose_json(setup.base_T_object)}}
                     .dump(2)
              << "\n";
    return kExitOk;
  }
  std::cout << "simulated operator: " << a.noise_px << " px noise (seed " << a.seed << "), " << poses.size()
            << " arm poses\n";
  for (const auto& v : views)
    std::cout << "  " << v["camera"].get<std::string>() << ": " << v["calibration_clicks"].get<int>()
              << " arm clicks, " << v["object_clicks"].get<int>() << " ORU clicks\n";
  const Eigen::Vector3d t = setup.base_T_object.translation();
  const Eigen::Vector3d rpy = rpy_from_rotation(setup.base_T_object.linear()) * 180.0 / M_PI;
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
       auto a = std::make_shared<Args>();
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
       sub.add_flag("--json", a->json, "print one JSON object");
       return [a] { return run(*a); };
     }});

}  // namespace
}  // namespace foresight::cli
