#pragma once
// Test helpers: the robot model, a perfectly tracking in-process plant
// (measured q = last command, one cycle late) with the ORU contact model as
// the F/T sensor, and a Controller stepped by hand.

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <memory>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/control/controller.hpp"
#include "foresight/sim/contact_model.hpp"

namespace foresight::control::test {

inline const RobotModel& robot() {
  static const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  return model;
}

/// A controller plus a plant: the arm reaches each command one cycle later;
/// the F/T sensor reads `wrench_ft` (sensor frame) plus, optionally, the
/// contact model's wrench for the ORU at base_T_oru, plus the tool's weight
/// change since the tare (the sensor was tared at the start pose).
struct Bench {
  ControllerConfig config;
  std::unique_ptr<Controller> ctl;
  KinematicsWorkspace ws{robot()};
  CycleInputs in;
  CycleOutputs out;
  std::uint64_t cycle = 0;
  std::uint64_t next_id = 1;
  JointArray q_arm{};
  const sim::ContactModel* contact = nullptr;
  Pose base_T_oru = Pose::Identity();
  Wrench6 extra_ft{};       ///< added to the reading
  bool follow = true;       ///< plant follows the command
  bool add_tool_weight = true;
  Eigen::Matrix3d tare_R = Eigen::Matrix3d::Identity();
  std::vector<MotionEvent> events;
  std::vector<StopEvent> stops;
  int power_offs = 0;  ///< cycles whose outputs asked for DriveSystem::request_power_off()
  double peak_contact_n = 0.0;
  Pose last_tip = Pose::Identity();
  void (*arm)(bool) = nullptr;  ///< allocation counting around the controller's calls only

  explicit Bench(const JointArray& q0, ControllerConfig c = {}) : config(c) {
    ctl = std::make_unique<Controller>(robot(), config);
    q_arm = q0;
    in.joints = static_cast<std::size_t>(robot().dof());
    tare_R = sensor_R(q0);
  }

  Eigen::VectorXd qvec(const JointArray& q) const {
    Eigen::VectorXd v(robot().dof());
    for (int j = 0; j < robot().dof(); ++j) v(j) = q[static_cast<std::size_t>(j)];
    return v;
  }
  Eigen::Matrix3d sensor_R(const JointArray& q) {
    return forward_kinematics(robot(), ws, qvec(q), robot().link_index("ft_sensor")).linear();
  }
  Pose tip(const JointArray& q) { return forward_kinematics(robot(), ws, qvec(q)); }

  /// One cycle: build the inputs from the plant, step, apply the outputs.
  void step() {
    in.cycle = ++cycle;
    in.stamp_ns = static_cast<std::int64_t>(cycle) * 2000000;
    in.q = q_arm;
    Wrench6 w = extra_ft;
    if (contact != nullptr) {
      const Pose t = tip(q_arm);
      sim::Twist tw;
      tw.v_m_s = (t.translation() - last_tip.translation()) / 0.002;
      last_tip = t;
      const sim::ContactResult r = contact->compute(t, base_T_oru, tw);
      for (int i = 0; i < 3; ++i) {
        w[static_cast<std::size_t>(i)] += r.sensor.force_n(i);
        w[static_cast<std::size_t>(i + 3)] += r.sensor.torque_nm(i);
      }
      peak_contact_n = std::max(peak_contact_n, r.sensor.force_n.norm());
    }
    if (add_tool_weight) {
      const WrenchCompensator& c = ctl->compensator();
      const Wrench6 g = c.tool_gravity_ft(sensor_R(q_arm));
      const Wrench6 g0 = c.tool_gravity_ft(tare_R);
      for (std::size_t i = 0; i < 6; ++i) w[i] += g[i] - g0[i];
    }
    in.wrench_ft = w;
    in.ft_fresh = true;
    if (arm) arm(true);
    ctl->step(in, out);
    if (arm) arm(false);
    for (std::size_t i = 0; i < out.event_count; ++i) events.push_back(out.events[i]);
    if (out.stop != nullptr) stops.push_back(*out.stop);
    power_offs += out.power_off;
    if (out.drive_request == DriveRequest::Enable) {
      in.drives_enabled = true;
      if (arm) arm(true);
      ctl->drive_request_done(DriveRequest::Enable, true, "", q_arm);
      if (arm) arm(false);
    } else if (out.drive_request == DriveRequest::Disable) {
      in.drives_enabled = false;
      if (arm) arm(true);
      ctl->drive_request_done(DriveRequest::Disable, true, "", q_arm);
      if (arm) arm(false);
    }
    if (follow && (in.drives_enabled || out.drive_request != DriveRequest::None)) q_arm = out.q_cmd;
  }

  std::uint64_t send(MotionCommand c) {
    c.command_id = next_id++;
    if (arm) arm(true);
    ctl->command(c);
    if (arm) arm(false);
    return c.command_id;
  }

  /// Step until the command has a final event (or max_cycles); returns it.
  MotionEvent run_until_final(std::uint64_t id, int max_cycles) {
    for (int i = 0; i < max_cycles; ++i) {
      for (const MotionEvent& e : events)
        if (e.command_id == id && is_final(e.kind)) return e;
      step();
    }
    for (const MotionEvent& e : events)
      if (e.command_id == id && is_final(e.kind)) return e;
    MotionEvent none;
    none.kind = MotionEventKind::Started;
    set_text(none.text, "no final event");
    return none;
  }

  void enable() {
    step();
    MotionCommand c;
    c.kind = MotionCommandKind::Enable;
    const auto id = send(c);
    const MotionEvent e = run_until_final(id, 10);
    ASSERT_EQ(e.kind, MotionEventKind::Completed) << e.text.data();
    ASSERT_EQ(ctl->mode(), ControllerMode::Idle);
  }
};

/// A comfortable arm configuration (elbow bent, tool pointing forward-down).
inline JointArray home_q() {
  JointArray q{};
  const double v[7] = {0.0, 0.6, 0.0, -1.2, 0.0, 0.9, 0.0};
  for (int i = 0; i < 7; ++i) q[static_cast<std::size_t>(i)] = v[i];
  return q;
}

}  // namespace foresight::control::test
