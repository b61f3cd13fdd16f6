#pragma once
// Test helpers: the robot model, an in-process plant (by default perfectly
// tracking: measured q = last command, one cycle late; optionally the real
// loop's delay and the drives' servo lag) with the ORU contact model, or the
// whole simulated plant (tool, carried ORU, slot), as the F/T sensor, and a
// Controller stepped by hand.

#include <gtest/gtest.h>

#include <cmath>
#include <array>
#include <deque>
#include <functional>
#include <memory>
#include <random>
#include <span>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/control/controller.hpp"
#include "foresight/hw/remote_config.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/sim/contact_model.hpp"
#include "foresight/sim/plant.hpp"

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
  /// The whole simulated plant as the sensor's contact (its tool/ORU and
  /// ORU/slot contacts; no weights, no bias: as if tared), with this tool state.
  sim::Plant* plant = nullptr;
  sim::LstToolState plant_tool{};
  double peak_contact_nm = 0.0;  ///< with `plant`: largest contact torque at the sensor
  /// With `plant`: its weights too (the tool, the carried ORU) as the sensor
  /// reads them: less the weight at its last tare (the first cycle, and the
  /// cycle after each tare request), plus white noise of these deviations.
  bool plant_weights = false;
  double noise_n = 0.0, noise_nm = 0.0;
  std::mt19937 rng{7};
  Wrench6 plant_tare{};
  bool plant_tare_next = true;
  /// Cycles from a command to the measurement that sees it: 1 = the next
  /// cycle's; the real bus is 3 (docs/hardware.md "Frame order and loop delay").
  int delay_cycles = 1;
  /// The drives' position servo as a first-order lag at this bandwidth (Hz); 0: none.
  double servo_hz = 0.0;
  std::deque<JointArray> in_flight;  ///< commands sent, not yet latched by the drives
  JointArray q_prev{};               ///< the joints a cycle ago (the plant's joint rates)

  explicit Bench(const JointArray& q0, ControllerConfig c = {}) : config(c) {
    ctl = std::make_unique<Controller>(robot(), config);
    q_arm = q0;
    q_prev = q0;
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
    if (plant != nullptr) {
      std::array<double, kMaxJoints> qd{};
      for (std::size_t j = 0; j < kMaxJoints; ++j) qd[j] = (q_arm[j] - q_prev[j]) / 0.002;
      const sim::PlantStep r = plant->step(std::span<const double>(q_arm.data(), static_cast<std::size_t>(robot().dof())),
                                           std::span<const double>(qd.data(), static_cast<std::size_t>(robot().dof())),
                                           plant_tool);
      const Eigen::Vector3d f = r.contact_ft.force_n + r.slot_ft.force_n;
      const Eigen::Vector3d m = r.contact_ft.torque_nm + r.slot_ft.torque_nm;
      for (int i = 0; i < 3; ++i) {
        w[static_cast<std::size_t>(i)] += f(i);
        w[static_cast<std::size_t>(i + 3)] += m(i);
      }
      if (plant_weights) {
        const Wrench6 g{r.weight_ft.force_n(0),  r.weight_ft.force_n(1),  r.weight_ft.force_n(2),
                        r.weight_ft.torque_nm(0), r.weight_ft.torque_nm(1), r.weight_ft.torque_nm(2)};
        if (plant_tare_next) plant_tare = g;
        plant_tare_next = false;
        std::normal_distribution<double> nf(0.0, noise_n > 0.0 ? noise_n : 1.0), nt(0.0, noise_nm > 0.0 ? noise_nm : 1.0);
        for (std::size_t i = 0; i < 6; ++i) {
          w[i] += g[i] - plant_tare[i];
          if (i < 3 && noise_n > 0.0) w[i] += nf(rng);
          if (i >= 3 && noise_nm > 0.0) w[i] += nt(rng);
        }
      }
      peak_contact_n = std::max(peak_contact_n, f.norm());
      peak_contact_nm = std::max(peak_contact_nm, m.norm());
    }
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
    if (out.tare_samples > 0) {  // the decoder zeroes the reading where the arm is
      plant_tare_next = true;
      tare_R = sensor_R(q_arm);
    }
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
    if (follow && (in.drives_enabled || out.drive_request != DriveRequest::None)) move_arm(out.q_cmd);
  }

  /// The drives: the command reaches the joints delay_cycles - 1 cycles
  /// later, through the servo lag.
  void move_arm(const JointArray& cmd) {
    in_flight.push_back(cmd);
    if (static_cast<int>(in_flight.size()) < delay_cycles) return;
    const JointArray target = in_flight.front();
    in_flight.pop_front();
    q_prev = q_arm;
    const double a = servo_hz > 0.0 ? 1.0 - std::exp(-2.0 * M_PI * servo_hz * 0.002) : 1.0;
    for (std::size_t j = 0; j < kMaxJoints; ++j) q_arm[j] += a * (target[j] - q_arm[j]);
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

/// Joints from `from` to `to` along a smoothstep, sampled at rate_hz.
inline Trajectory line_trajectory(const JointArray& from, const JointArray& to, double duration_s, double rate_hz = 100.0) {
  Trajectory t;
  const int n = static_cast<int>(duration_s * rate_hz) + 1;
  t.positions_rad.resize(n, 7);
  for (int i = 0; i < n; ++i) {
    const double s = static_cast<double>(i) / (n - 1);
    const double b = s * s * (3.0 - 2.0 * s);
    t.time_s.push_back(i / rate_hz);
    for (int j = 0; j < 7; ++j) {
      const auto u = static_cast<std::size_t>(j);
      t.positions_rad(i, j) = from[u] + b * (to[u] - from[u]);
    }
  }
  return t;
}

/// A comfortable arm configuration (elbow bent, tool pointing forward-down).
inline JointArray home_q() {
  JointArray q{};
  const double v[7] = {0.0, 0.6, 0.0, -1.2, 0.0, 0.9, 0.0};
  for (int i = 0; i < 7; ++i) q[static_cast<std::size_t>(i)] = v[i];
  return q;
}

/// The simulated plant's ORU handled by the latched tool at tip poses found
/// by IK, each seeded from the last (first: the elbow-bent home, away from
/// the joint limits).
struct OruHandling {
  KinematicsWorkspace ws{robot()};
  Eigen::VectorXd seed;
  sim::LstToolState tool{};

  OruHandling() : seed(robot().dof()) {
    for (int j = 0; j < robot().dof(); ++j) seed(j) = home_q()[static_cast<std::size_t>(j)];
    tool.latched = true;
    tool.unlatched = false;
    tool.latch_position = 1.0;
  }
  static Pose along(double z) { return Pose(Eigen::Translation3d(0.0, 0.0, z)); }
  Eigen::VectorXd q_at(const Pose& base_T_tip) {
    IkOptions opt;
    opt.position_tolerance_m = 1e-7;
    opt.rotation_tolerance_rad = 1e-7;
    const IkResult ik = inverse_kinematics(robot(), ws, base_T_tip, seed, opt);
    EXPECT_TRUE(ik.success);
    seed = ik.q;
    return ik.q;
  }
  /// One plant step at rest at q with the bolt's engaged turns: the ORU's state.
  sim::OruState plant_at(sim::Plant& plant, const Eigen::VectorXd& q, double engaged_turns) {
    tool.engaged_turns = engaged_turns;
    const std::vector<double> qv(q.data(), q.data() + q.size()), qd(qv.size(), 0.0);
    return plant.step(qv, qd, tool).state;
  }
};

/// For a SimRig's before_start: every simulated drive at the joints `q`
/// (rad), and with `contact` the simulated F/T sensor reading the ORU contact
/// model at the arm's pose (contact only, no weights: as if tared).
inline void place_arm(sim::CanSimulator& s, const hw::RemoteConfig& config, const Eigen::VectorXd& q,
                      std::shared_ptr<const sim::ContactModel> contact = nullptr, const Pose& base_T_oru = Pose::Identity()) {
  for (std::size_t j = 0; j < config.drives.size(); ++j) {
    std::int32_t counts = 0;
    ASSERT_TRUE(config.drives[j].to_counts(q(static_cast<Eigen::Index>(j)), counts));
    s.drive(j).set_position_counts(counts);
  }
  if (!contact) return;
  auto ws = std::make_shared<KinematicsWorkspace>(robot());
  auto q_sim = std::make_shared<std::vector<double>>(config.drives.size());
  sim::CanSimulator* simulator = &s;
  s.ft_sensor()->set_wrench_source([contact, ws, q_sim, simulator, base_T_oru]() {
    simulator->joint_positions_rad(*q_sim);
    const Eigen::Map<const Eigen::VectorXd> qm(q_sim->data(), static_cast<Eigen::Index>(q_sim->size()));
    const sim::ContactResult r = contact->compute(forward_kinematics(robot(), *ws, qm), base_T_oru);
    const Eigen::Vector3d& f = r.sensor.force_n;
    const Eigen::Vector3d& m = r.sensor.torque_nm;
    return sim::SimFtSensor::Wrench{f.x(), f.y(), f.z(), m.x(), m.y(), m.z()};
  });
}

}  // namespace foresight::control::test
