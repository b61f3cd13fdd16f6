// foresight plan: a trajectory for the tool tip through the task object's tag
// frames (from the localized ORU pose) or back to joint angles, written as the
// trajectory CSV that preview shows and the remote runs.
//
//   foresight plan --object-pose localize.json --from q1,..,qN
//                  --to approach_20cm,hole_entrance:linear,tool_inserted:linear
//                  --out traj.csv [--rate-hz 100] [--limit-fraction 0.5]
//                  [--tool-speed 0.05] [--dwell-s 0.5] [--json]
//
// Each --to item is a tag of the object (the tool tip goes to the tag frame),
// or `start` (back to the --from joint angles); `:linear` moves the tip along
// a straight line (insertion, extraction), otherwise the move is in joint space.
#include <iostream>

#include "command.hpp"
#include "foresight/common/atomic_file.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

struct Args {
  std::string object_pose;
  std::string from, from_deg;
  std::string to;
  std::string out;
  PlanOptions plan;
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  bool json = false;
};

std::vector<Goal> parse_goals(const std::string& text, const ObjectModel& object, const Pose& base_T_object,
                                       const Eigen::VectorXd& q_start) {
  std::vector<Goal> goals;
  for (const std::string_view field : split_commas(text)) {
    std::string item(field);
    Goal g;
    const std::size_t colon = item.find(':');
    if (colon != std::string::npos) {
      const std::string kind = item.substr(colon + 1);
      if (kind != "linear" && kind != "joint")
        throw std::invalid_argument("--to: '" + item + "': the move kind after ':' must be linear or joint");
      g.kind = kind == "linear" ? SegmentKind::Linear : SegmentKind::Joint;
      item = item.substr(0, colon);
    }
    g.name = item;
    if (item == "start") {
      if (g.kind == SegmentKind::Linear)
        throw std::invalid_argument("--to: 'start' is a joint-space goal; it cannot be linear");
      g.is_pose = false;
      g.q = q_start;
    } else {
      const auto tag = object.tags.find(item);
      if (tag == object.tags.end()) {
        std::string names;
        for (const auto& [n, T] : object.tags) names += (names.empty() ? "" : ", ") + n;
        throw std::invalid_argument("--to: unknown goal '" + item + "' (tags of " + object.name + ": " + names +
                                    "; or start)");
      }
      g.base_T_tip = base_T_object * tag->second;
    }
    goals.push_back(g);
  }
  return goals;
}

int run(const Args& a) {
  check_output_path(a.out);  // before any work: a folder or a missing folder is bad input
  const RobotModel robot = RobotModel::from_file(a.robot);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const Eigen::VectorXd q0 =
      !a.from.empty() ? parse_joints(a.from, "--from", robot) : parse_joints(a.from_deg, "--from-deg", robot, true);
  const Pose base_T_object = localization::read_object_pose_json(a.object_pose);
  const auto goals = parse_goals(a.to, object, base_T_object, q0);

  Plan plan;
  try {
    plan = plan_motion(robot, q0, goals, a.plan);
  } catch (const PlanError& e) {
    std::cerr << "foresight plan: " << e.what() << "\n";
    return kExitFailure;
  }
  std::size_t total = 0;
  const auto violations = validate(plan.trajectory, TrajectoryLimits::from_model(robot), &total);
  if (!violations.empty()) {
    for (const auto& v : violations) std::cerr << "foresight plan: " << v.message << "\n";
    std::cerr << "foresight plan: the planned trajectory breaks " << total << " rule(s); not written\n";
    return kExitFailure;
  }
  write_trajectory_csv(a.out, plan.trajectory);  // atomic: a failed write leaves the old file whole
  const std::string hash = to_hex(trajectory_hash(plan.trajectory));

  if (a.json) {
    nlohmann::json segs = nlohmann::json::array();
    for (const auto& s : plan.segments)
      segs.push_back({{"goal", s.goal},
                      {"kind", to_string(s.kind)},
                      {"start_s", s.start_s},
                      {"duration_s", s.duration_s},
                      {"q_end_rad", vec_json(s.q_end)},
                      {"position_error_m", s.position_error_m},
                      {"rotation_error_deg", s.rotation_error_rad * 180.0 / M_PI},
                      {"peak_velocity_fraction", s.peak_velocity_fraction}});
    std::cout << nlohmann::json{{"out", a.out},
                                {"samples", plan.trajectory.samples()},
                                {"duration_s", plan.trajectory.duration_s()},
                                {"sha256", hash},
                                {"segments", segs}}
                     .dump(2)
              << "\n";
    return kExitOk;
  }
  std::printf("planned %zu segment(s): %d samples at %.0f Hz, %.2f s\n", plan.segments.size(),
              plan.trajectory.samples(), a.plan.rate_hz, plan.trajectory.duration_s());
  std::printf("  %-16s %-6s %8s %8s %10s %9s %8s\n", "goal", "kind", "start s", "dur s", "err mm", "err deg",
              "peak v");
  for (const auto& s : plan.segments)
    std::printf("  %-16s %-6s %8.2f %8.2f %10.4f %9.4f %7.0f%%\n", s.goal.c_str(), to_string(s.kind),
                s.start_s, s.duration_s, s.position_error_m * 1e3, s.rotation_error_rad * 180.0 / M_PI,
                100.0 * s.peak_velocity_fraction);
  std::printf("  wrote %s (sha256 %s); within every joint limit\n", a.out.c_str(), hash.c_str());
  return kExitOk;
}

const bool registered = register_command(
    {"plan", "plan a trajectory for the tool through the object's tag frames (joint or straight-line moves)",
     [](Command& sub) -> std::function<int()> {
       auto a = std::make_shared<Args>();
       sub.add_option("--object-pose", a->object_pose, "JSON from `foresight localize --json` (key base_T_object)")
           ->required();
       auto* from = sub.add_option("--from", a->from, "start joint angles q1,...,qN (rad)");
       auto* from_deg = sub.add_option("--from-deg", a->from_deg, "start joint angles in degrees");
       from->excludes(from_deg);
       from_deg->excludes(from);
       sub.add_option("--to", a->to, "goals in order: TAG[:linear|:joint] or start, comma-separated")->required();
       sub.add_option("--out", a->out, "trajectory CSV to write (t,q1..qN)")->required();
       sub.add_option("--rate-hz", a->plan.rate_hz, "sample rate")->capture_default_str();
       sub.add_option("--limit-fraction", a->plan.limit_fraction,
                      "fraction of the URDF joint velocity/acceleration limits to plan for, (0, 1]")
           ->capture_default_str();
       sub.add_option("--tool-speed", a->plan.tool_speed_m_s, "peak tool speed of linear moves, m/s")
           ->capture_default_str();
       sub.add_option("--dwell-s", a->plan.dwell_s, "pause at every goal, s")->capture_default_str();
       sub.add_option("--robot", a->robot, "robot URDF")->capture_default_str();
       sub.add_option("--object", a->object, "task object model (tags)")->capture_default_str();
       sub.add_flag("--json", a->json, "print one JSON object");
       return [a] {
         if (a->from.empty() && a->from_deg.empty()) throw std::invalid_argument("--from or --from-deg is required");
         return run(*a);
       };
     }});

}  // namespace
}  // namespace foresight::cli
