// foresight validate TRAJ.csv: check a trajectory against the robot's limits
// with the same rules the remote applies on arrival (common/trajectory).
#include <iostream>

#include "command.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

struct Options {
  std::string trajectory;
  std::string robot = default_config("robot.urdf");
  bool json = false;
};

int run(const Options& o) {
  const RobotModel model = RobotModel::from_file(o.robot);
  const Trajectory traj = read_trajectory_csv(o.trajectory);
  std::size_t total = 0;  // violations in all; the first limits::kMaxListedViolations are listed
  const auto violations = validate(traj, TrajectoryLimits::from_model(model), &total);
  const std::string hash = to_hex(trajectory_hash(traj));
  if (o.json) {
    nlohmann::json j = {{"file", o.trajectory}, {"samples", traj.samples()}, {"joints", traj.joints()},
                        {"duration_s", traj.duration_s()}, {"sha256", hash}, {"ok", violations.empty()},
                        {"violation_count", total}};
    j["violations"] = nlohmann::json::array();
    for (const auto& v : violations)
      j["violations"].push_back({{"rule", to_string(v.rule)}, {"row", v.row}, {"joint", v.joint},
                                 {"value", v.value}, {"limit", v.limit}, {"message", v.message}});
    std::cout << j.dump(2) << "\n";
  } else {
    std::cout << o.trajectory << ": " << traj.samples() << " samples x " << traj.joints() << " joints, "
              << traj.duration_s() << " s, sha256 " << hash << "\n";
    if (violations.empty()) std::cout << "ok: within every limit of " << o.robot << "\n";
    for (const auto& v : violations) std::cout << "  " << to_string(v.rule) << ": " << v.message << "\n";
    if (total > violations.size()) std::cout << "  ... and " << total - violations.size() << " more\n";
  }
  if (!violations.empty())
    std::cerr << "foresight validate: " << total << " violation(s); the remote would reject this trajectory\n";
  return violations.empty() ? kExitOk : kExitFailure;
}

const bool registered = register_command(
    {"validate", "Check a trajectory CSV (t,q1..qN) against the robot's joint limits, as the remote will",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("trajectory", o->trajectory, "trajectory CSV (t,q1,...,qN; s, rad)")->required();
       sub.add_option("--robot", o->robot, "robot URDF")->capture_default_str();
       sub.add_flag("--json", o->json, "print one JSON object");
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
