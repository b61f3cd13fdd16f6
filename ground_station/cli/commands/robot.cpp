// foresight robot: print the robot model (joints, limits), the pose of every
// chain link at a configuration, and optionally solve IK for a target pose.
//
//   foresight robot [--robot config/robot.urdf] [--joints q1,..,q7 (rad) | --joints-deg ...]
//                   [--target x,y,z,roll,pitch,yaw (m, deg)] [--seed q1,..,q7 (deg)]
//                   [--centre] [--json]
// Exit: 0 ok, 1 IK did not converge (best attempt and residual still printed),
// 2 bad arguments or URDF.

#include <cmath>
#include <cstdio>
#include <iostream>
#include <stdexcept>

#include "command.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct RobotArgs {
  std::string robot_path = default_config("robot.urdf");
  std::string joints, joints_deg;
  std::string target;
  std::string seed, seed_deg;
  bool centre = false;
  bool json = false;
};

/// Roll, pitch, yaw in degrees, rounding-noise zeros shown as 0 (not -0.00).
Eigen::Vector3d rpy_deg(const Pose& T) {
  Eigen::Vector3d rpy = rpy_from_rotation(T.linear()) / kDeg;
  for (int i = 0; i < 3; ++i)
    if (std::abs(rpy[i]) < 1e-9) rpy[i] = 0.0;
  return rpy;
}

nlohmann::json link_json(int k, const std::string& name, const Pose& T) {
  const Eigen::Vector3d rpy = rpy_deg(T);
  return {{"index", k},
          {"name", name},
          {"xyz_m", vec_json(T.translation())},
          {"rpy_deg", vec_json(rpy)},
          {"base_T_link", localization::pose_json(T)}};
}

void print_pose_row(int k, const std::string& name, const Pose& T) {
  Eigen::Vector3d p = T.translation();
  for (int i = 0; i < 3; ++i)
    if (std::abs(p[i]) < 1e-12) p[i] = 0.0;
  const Eigen::Vector3d rpy = rpy_deg(T);
  std::printf("  %2d %-10s %8.4f %8.4f %8.4f   %8.2f %8.2f %8.2f\n", k, name.c_str(), p.x(), p.y(), p.z(), rpy.x(),
              rpy.y(), rpy.z());
}

void print_q(const char* label, const Eigen::VectorXd& q) {
  std::printf("%s", label);
  for (int i = 0; i < q.size(); ++i) std::printf("%s%.3f", i ? ", " : "", q[i] / kDeg);
  std::printf("]\n");
}

int run_robot(const RobotArgs& a) {
  const RobotModel m = RobotModel::from_file(a.robot_path);
  KinematicsWorkspace ws(m);
  // Every argument is checked before anything is printed.
  const Eigen::VectorXd q = !a.joints.empty()       ? parse_joints(a.joints, "--joints", m)
                            : !a.joints_deg.empty() ? parse_joints(a.joints_deg, "--joints-deg", m, true)
                                                    : m.mid_configuration();
  if (!(a.seed.empty() && a.seed_deg.empty()) && a.target.empty())
    throw std::invalid_argument(std::string(a.seed.empty() ? "--seed-deg" : "--seed") + ": only meaningful with --target");
  Eigen::VectorXd t;
  if (!a.target.empty()) {
    t = parse_numbers(a.target, "--target");
    if (t.size() != 6)
      throw std::invalid_argument("--target: expected 6 numbers x,y,z (m), roll,pitch,yaw (deg), got " +
                                  std::to_string(t.size()));
  }
  const Eigen::VectorXd seed = !a.seed.empty()       ? parse_joints(a.seed, "--seed", m)
                               : !a.seed_deg.empty() ? parse_joints(a.seed_deg, "--seed-deg", m, true)
                                                     : q;

  nlohmann::json out;
  out["robot"] = a.robot_path;
  out["dof"] = m.dof();
  nlohmann::json joints = nlohmann::json::array();
  for (int i = 0; i < m.dof(); ++i) {
    const JointLimits& l = m.limits()[i];
    joints.push_back({{"name", m.joint_names()[i]},
                      {"lower_deg", l.lower_rad / kDeg},
                      {"upper_deg", l.upper_rad / kDeg},
                      {"velocity_deg_s", l.velocity_rad_s / kDeg},
                      {"acceleration_deg_s2", l.acceleration_rad_s2 / kDeg},
                      {"effort_nm", l.effort_nm}});
  }
  out["joints"] = joints;
  out["q_deg"] = vec_json(q / kDeg);
  out["q_rad"] = vec_json(q);
  nlohmann::json links = nlohmann::json::array();
  for (int k = 0; k < static_cast<int>(m.links().size()); ++k)
    links.push_back(link_json(k, m.links()[k].name, forward_kinematics(m, ws, q, k)));
  out["links"] = links;

  if (!a.json) {
    std::printf("robot %s: %d joints, %zu links on the chain %s -> %s\n", a.robot_path.c_str(), m.dof(),
                m.links().size(), m.links().front().name.c_str(), m.links().back().name.c_str());
    std::printf("  %-8s %10s %10s %12s %14s %10s\n", "joint", "lower_deg", "upper_deg", "vel_deg/s", "acc_deg/s^2",
                "effort_Nm");
    for (int i = 0; i < m.dof(); ++i) {
      const JointLimits& l = m.limits()[i];
      std::printf("  %-8s %10.1f %10.1f %12.1f %14.1f %10.1f\n", m.joint_names()[i].c_str(), l.lower_rad / kDeg,
                  l.upper_rad / kDeg, l.velocity_rad_s / kDeg, l.acceleration_rad_s2 / kDeg, l.effort_nm);
    }
    print_q(a.joints_deg.empty() ? "configuration (mid, deg): [" : "configuration (deg): [", q);
    std::printf("forward kinematics, base_T_link:\n  %2s %-10s %8s %8s %8s   %8s %8s %8s\n", "k", "link", "x_m", "y_m",
                "z_m", "roll_deg", "pitch_deg", "yaw_deg");
    for (int k = 0; k < static_cast<int>(m.links().size()); ++k)
      print_pose_row(k, m.links()[k].name, forward_kinematics(m, ws, q, k));
  }

  int status = kExitOk;
  if (!a.target.empty()) {
    const Pose target = make_pose(t.head<3>(), t.tail<3>() * kDeg);
    IkOptions options;
    options.centre_joints = a.centre;
    const IkResult r = inverse_kinematics(m, ws, target, seed, options);
    status = r.success ? kExitOk : kExitFailure;
    out["ik"] = {{"target", {{"xyz_m", vec_json(t.head<3>())}, {"rpy_deg", vec_json(t.tail<3>())}}},
                 {"seed_deg", vec_json(seed / kDeg)},
                 {"success", r.success},
                 {"attempts", r.attempts},
                 {"q_deg", vec_json(r.q / kDeg)},
                 {"q_rad", vec_json(r.q)},
                 {"position_error_m", r.position_error_m},
                 {"rotation_error_deg", r.rotation_error_rad / kDeg},
                 {"tip", link_json(m.tip_index(), m.links().back().name, forward_kinematics(m, ws, r.q))}};
    if (!a.json) {
      std::printf("inverse kinematics for %s at (%.4f, %.4f, %.4f) m, rpy (%.2f, %.2f, %.2f) deg:\n",
                  m.links().back().name.c_str(), t[0], t[1], t[2], t[3], t[4], t[5]);
      std::printf("  %s after %d attempt(s); residual %.3g mm, %.3g deg\n", r.success ? "solved" : "FAILED",
                  r.attempts, r.position_error_m * 1e3, r.rotation_error_rad / kDeg);
      print_q(r.success ? "  solution (deg): [" : "  best attempt (deg): [", r.q);
    }
    if (!r.success)
      std::cerr << "foresight robot: IK did not reach the target (residual " << r.position_error_m * 1e3 << " mm, "
                << r.rotation_error_rad / kDeg << " deg)\n";
  }
  if (a.json) std::cout << out.dump(2) << "\n";
  return status;
}

std::function<int()> setup(Command& sub) {
  auto a = std::make_shared<RobotArgs>();
  sub.add_option("--robot", a->robot_path, "URDF of the arm")->capture_default_str();
  auto* joints = sub.add_option("--joints", a->joints, "joint angles q1,...,qN in radians (default: mid configuration)");
  sub.add_option("--joints-deg", a->joints_deg, "joint angles in degrees (instead of --joints)")->excludes(joints);
  sub.add_option("--target", a->target, "IK target for the tool tip: x,y,z,roll,pitch,yaw (m, deg; base frame)");
  auto* seed = sub.add_option("--seed", a->seed, "IK seed q1,...,qN in radians (default: the joints above)");
  sub.add_option("--seed-deg", a->seed_deg, "IK seed in degrees (instead of --seed)")->excludes(seed);
  sub.add_flag("--centre", a->centre, "after IK, move the joints away from their limits (null space)");
  sub.add_flag("--json", a->json, "one JSON object on stdout");
  return [a] { return run_robot(*a); };
}

[[maybe_unused]] const bool registered =
    register_command({"robot", "robot model: joints and limits, FK of every link, IK for a tool-tip target", setup});

}  // namespace
}  // namespace foresight::cli
