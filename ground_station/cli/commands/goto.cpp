// foresight goto --joints q | --joints-deg q | --tag NAME [--object-pose localize.json]:
// move the arm by the remote's own planner (GOTO_JOINT: a minimum-jerk joint
// move; GOTO_CART: a straight tool-tip line to the tag frame). The ground plans
// the same path first (common plan_motion) for its expected duration; a goal
// it cannot plan is refused before anything is sent.
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/pose_json.hpp"
#include "link_options.hpp"
#include "foresight/session/link_session.hpp"

namespace foresight::cli {

using namespace foresight::session;  // the link session helpers
namespace {

struct Options {
  LinkOptions link;
  std::string joints, joints_deg, tag, object_pose;
  double speed = 0.5;
  std::string robot = default_config("robot.urdf");
  std::string object = default_config("oru.yaml");
  std::string scene = default_config("scene.yaml");
};

int run(const Options& o) {
  const int given = !o.joints.empty() + !o.joints_deg.empty() + !o.tag.empty();
  if (given != 1) throw std::invalid_argument("give exactly one of --joints, --joints-deg or --tag");
  const RobotModel model = RobotModel::from_file(o.robot);
  protocol::Payload payload;
  protocol::CommandKind kind;
  std::string target, pose_source;
  if (!o.tag.empty()) {
    const ObjectModel object = ObjectModel::from_file(o.object);
    const auto tag = object.tags.find(o.tag);
    if (tag == object.tags.end()) {
      std::string names;
      for (const auto& [n, T] : object.tags) names += (names.empty() ? "" : ", ") + n;
      throw std::invalid_argument("--tag: unknown tag '" + o.tag + "' (tags of " + object.name + ": " + names + ")");
    }
    Pose base_T_object;
    if (!o.object_pose.empty()) {
      base_T_object = localization::read_object_pose_json(o.object_pose);
      pose_source = o.object_pose;
    } else {
      base_T_object = Scene::from_file(o.scene).base_T_object;
      pose_source = o.scene + " (the work site's true pose; give --object-pose for the localized one)";
    }
    protocol::GotoCart c;
    c.frame = "lst_tip";
    c.base_T_frame = base_T_object * tag->second;
    c.speed_fraction = o.speed;
    payload = c;
    kind = protocol::CommandKind::GotoCart;
    target = "tag " + o.tag;
  } else {
    const Eigen::VectorXd q = !o.joints.empty() ? parse_joints(o.joints, "--joints", model)
                                                : parse_joints(o.joints_deg, "--joints-deg", model, true);
    protocol::GotoJoint g;
    g.q_rad.assign(q.data(), q.data() + q.size());
    g.speed_fraction = o.speed;
    payload = g;
    kind = protocol::CommandKind::GotoJoint;
    target = "joints";
  }
  auto link = connect_remote(o.link);
  const auto joints = wait_joints(*link, o.link.connect_timeout_s);
  if (!joints) throw LinkFailure("no joint report from the remote; cannot plan the move");
  double expected_s = 0.0;
  try {
    expected_s = planned_goto_duration_s(model, joints->value.q_rad, payload);
  } catch (const PlanError& e) {
    throw LinkFailure(std::string("not sent: the move to ") + target + " cannot be planned: " + e.what());
  }
  const ControlGuard control_guard(*link);
  const auto r = send_and_wait(*link, kind, payload, final_ack_timeout(*link, expected_s, o.link.timeout_s));
  if (o.link.json) {
    auto j = result_json(kind, r);
    j["target"] = target;
    j["expected_duration_s"] = expected_s;
    if (!pose_source.empty()) j["object_pose"] = pose_source;
    std::cout << j.dump(2) << "\n";
  } else {
    if (!pose_source.empty()) std::cout << "object pose from " << pose_source << "\n";
    std::printf("goto %s: planned %.2f s\n", target.c_str(), expected_s);
    std::cout << result_line(kind, r) << "\n";
    if (!r.final_q_rad.empty()) {
      std::printf("final joints (deg):");
      for (double q : r.final_q_rad) std::printf(" %.3f", q * 180.0 / M_PI);
      std::printf("\n");
    }
  }
  return exit_status(r);
}

const bool registered = register_command(
    {"goto", "move the arm to joint angles (GOTO_JOINT) or the tool tip to an object tag (GOTO_CART)",
     [](Command& sub) -> std::function<int()> {
       auto o = std::make_shared<Options>();
       sub.add_option("--joints", o->joints, "target joint angles q1,...,qN (rad)");
       sub.add_option("--joints-deg", o->joints_deg, "target joint angles in degrees");
       sub.add_option("--tag", o->tag, "tag frame of the object for the tool tip (straight line)");
       sub.add_option("--object-pose", o->object_pose, "JSON from `foresight localize --json` (default: scene.yaml)");
       sub.add_option("--speed", o->speed, "fraction of the joint limits, (0, 1]")
           ->check(check::Range(1e-3, 1.0))
           ->capture_default_str();
       sub.add_option("--robot", o->robot, "robot URDF")->capture_default_str();
       sub.add_option("--object", o->object, "task object model (tags)")->capture_default_str();
       sub.add_option("--scene", o->scene, "work site (the object's pose without --object-pose)")
           ->capture_default_str();
       add_link_options(sub, o->link);
       return [o] { return run(*o); };
     }});

}  // namespace
}  // namespace foresight::cli
