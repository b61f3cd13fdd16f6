#include "foresight/sim_insertion/sim_insertion.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdint>
#include <vector>

#include "foresight/common/scene.hpp"

namespace foresight::sim_insertion {

WorldFiles default_files(const std::string& config_dir) {
  return {config_dir + "/robot.urdf", config_dir + "/oru.yaml", config_dir + "/scene.yaml"};
}

World::World(const WorldFiles& files)
    : robot(RobotModel::from_file(files.robot_urdf)),
      oru(ObjectModel::from_file(files.object_yaml)),
      base_T_oru(Scene::from_file(files.scene_yaml).base_T_object),
      params(sim::load_plant_params(files.scene_yaml)),
      plant(std::make_unique<sim::Plant>(robot, oru, base_T_oru, params)),
      ws(robot) {
  IkOptions opt;
  opt.centre_joints = true;
  const IkResult ik = inverse_kinematics(robot, ws, base_T_oru * Pose(Eigen::Translation3d(0.0, 0.0, -0.01)),
                                         robot.mid_configuration(), opt);
  q_nominal = ik.success ? ik.q : robot.mid_configuration();
}

control::ControllerConfig World::controller_config() const {
  control::ControllerConfig c;
  c.cycle_rate_hz = 500.0;
  c.tool.mass_kg = plant->tool_mass_kg();
  const Eigen::Vector3d& com = plant->tool_com_sensor_m();
  c.tool.com_sensor_m = {com.x(), com.y(), com.z()};
  c.tool.sensor_T_tip = plant->sensor_T_tip();
  return c;
}

std::optional<Eigen::VectorXd> World::start_joints(const Pose& base_T_tip) {
  IkOptions opt;
  opt.position_tolerance_m = 1e-6;
  opt.rotation_tolerance_rad = 1e-6;
  const IkResult ik = inverse_kinematics(robot, ws, base_T_tip, q_nominal, opt);
  if (!ik.success) return std::nullopt;
  return ik.q;
}

Outcome run_insertion(World& w, const Eigen::VectorXd& q0, const InsertSpec& spec) {
  Outcome o;
  sim::Plant& plant = *w.plant;
  plant.reset();
  const auto dof = static_cast<std::size_t>(w.robot.dof());
  control::Controller ctl(w.robot, w.controller_config());
  control::CycleInputs in;
  control::CycleOutputs out;
  in.joints = dof;
  std::vector<double> q(dof), qd(dof, 0.0);
  sim::LstToolState tool;  // latch open: the plant is only contact
  if (spec.carry_oru) {
    // Grip the fastened ORU, loosen the screw: it follows the tool from here.
    for (std::size_t j = 0; j < dof; ++j) q[j] = spec.q_grip[static_cast<Eigen::Index>(j)];
    tool.engaged_turns = 8.0;
    plant.step(q, qd, tool);
    tool.latched = true;
    plant.step(q, qd, tool);
    tool.engaged_turns = 0.0;
    plant.step(q, qd, tool);
  }
  for (std::size_t j = 0; j < dof; ++j) in.q[j] = q0[static_cast<Eigen::Index>(j)];
  const double dt = 1.0 / 500.0;

  // The F/T reading: the plant's, tared at the start pose (no contact there).
  control::Wrench6 tare{};
  auto read = [&](bool first) {
    for (std::size_t j = 0; j < dof; ++j) q[j] = in.q[j];
    const sim::PlantStep r = plant.step(q, qd, tool);
    if (first) tare = r.wrench_ft;
    for (std::size_t i = 0; i < 6; ++i) in.wrench_ft[i] = r.wrench_ft[i] - tare[i];
    in.ft_fresh = true;
    return r;
  };
  read(true);

  std::uint64_t cycle = 0;
  auto step = [&] {
    in.cycle = ++cycle;
    in.stamp_ns = static_cast<std::int64_t>(cycle) * 2'000'000;
    ctl.step(in, out);
    if (out.drive_request == control::DriveRequest::Enable) {
      in.drives_enabled = true;
      ctl.drive_request_done(control::DriveRequest::Enable, true, "", out.q_cmd);
    }
  };

  control::MotionCommand enable;
  enable.command_id = 1;
  enable.kind = control::MotionCommandKind::Enable;
  ctl.command(enable);
  for (int i = 0; i < 50 && ctl.mode() != control::ControllerMode::Idle; ++i) {
    read(false);
    step();
  }

  control::MotionCommand ins;
  ins.command_id = 2;
  ins.kind = control::MotionCommandKind::RunAlgorithm;
  ins.algorithm.kind = control::AlgorithmKind::Insert;
  ins.algorithm.insert = spec.params;
  ctl.command(ins);
  const int max_cycles = static_cast<int>((ins.algorithm.insert.timeout_s + 5.0) * 500.0);
  const std::uint64_t start_cycle = cycle;
  bool done = false;
  sim::PlantStep last;
  for (int k = 0; k < max_cycles && !done; ++k) {
    for (std::size_t j = 0; j < dof; ++j) {
      const double qn = out.q_cmd[j];
      qd[j] = k == 0 ? 0.0 : (qn - in.q[j]) / dt;
      in.q[j] = qn;  // kinematic plant: measured = commanded
    }
    last = read(false);
    const sim::ContactResult& c = spec.carry_oru ? last.slot_contact : last.tool_contact;
    o.peak_force_n = std::max(o.peak_force_n, c.sensor.force_n.norm());
    o.touched_face = o.touched_face || c.face_contacts > 0;
    step();
    o.searched = o.searched || ctl.algorithm().phase() == 1;
    for (std::size_t e = 0; e < out.event_count; ++e) {
      const control::MotionEvent& ev = out.events[e];
      if (ev.command_id != ins.command_id || !control::is_final(ev.kind)) continue;
      done = true;
      o.completed = ev.kind == control::MotionEventKind::Completed;
      o.code = ev.code;
      o.text = ev.text;
    }
    if (out.stop != nullptr && !done) {
      done = true;
      o.code = control::Reason::Faulted;
      control::set_text(o.text, out.stop->text.data());
    }
  }
  if (!done) {  // the controller's own timeout did not end it: say so
    o.code = control::Reason::Timeout;
    control::set_text(o.text, "insert: no final event within timeout_s + 5 s of simulated time");
  }
  o.sim_s = static_cast<double>(cycle - start_cycle) * dt;
  if (spec.carry_oru) {
    o.in_hole = last.state == sim::OruState::Seated;
  } else {
    o.in_hole = last.tool_contact.tip_in_hole() && last.tool_contact.insertion_depth_m >= w.params.grasp_depth_m;
  }
  return o;
}

}  // namespace foresight::sim_insertion
