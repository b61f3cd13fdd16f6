// The payload on the wrist F/T sensor: the tool and the carried ORU removed
// at every orientation (against the simulated plant's own weight model),
// identify_payload (known mass and centre of mass recovered from noisy
// readings; refusals with their reasons), the tare's conditions.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "control_fixture.hpp"
#include "foresight/control/payload.hpp"
#include "foresight/control/trajectory_executor.hpp"

namespace foresight::control::test {
namespace {

constexpr double kDeg = M_PI / 180.0;

/// The simulated plant with the ORU gripped 6 cm deep, freed and pulled 9 cm
/// out of its slot: carried, in free space. The truth of what hangs on the
/// sensor, from the plant.
struct CarriedOru {
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_home = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  sim::PlantParams params = sim::load_plant_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  sim::Plant plant{robot(), oru, base_T_home, params};
  sim::LstToolState tool{};
  JointArray q{};
  PayloadMass tool_truth{}, oru_truth{};

  CarriedOru() {
    OruHandling h;
    const auto along = OruHandling::along;
    auto q_at = [&](const Pose& base_T_tip) { return h.q_at(base_T_tip); };
    auto plant_at = [&](const Eigen::VectorXd& qv, double engaged_turns) { return h.plant_at(plant, qv, engaged_turns); };
    const Eigen::VectorXd q_in = q_at(base_T_home * along(0.06));
    plant_at(q_in, 8.0);
    EXPECT_EQ(plant_at(q_in, 0.0), sim::OruState::Seated);
    const Eigen::VectorXd q_out = q_at(base_T_home * along(-0.09));
    EXPECT_EQ(plant_at(q_out, 0.0), sim::OruState::Carried);
    tool = h.tool;
    for (int j = 0; j < robot().dof(); ++j) q[static_cast<std::size_t>(j)] = q_out(j);
    tool_truth.mass_kg = plant.tool_mass_kg();
    for (std::size_t i = 0; i < 3; ++i) tool_truth.com_sensor_m[i] = plant.tool_com_sensor_m()[static_cast<Eigen::Index>(i)];
    const Pose base_T_sensor = forward_kinematics(robot(), h.ws, q_out, robot().link_index("ft_sensor"));
    const Eigen::Vector3d c = base_T_sensor.inverse(Eigen::Isometry) * (plant.truth().base_T_oru * params.oru_com_m);
    oru_truth.mass_kg = params.oru_mass_kg;
    for (std::size_t i = 0; i < 3; ++i) oru_truth.com_sensor_m[i] = c(static_cast<Eigen::Index>(i));
  }

  /// A bench on this plant (its weights on the sensor, tared at the first cycle).
  std::unique_ptr<Bench> bench(ControllerConfig config) {
    auto b = std::make_unique<Bench>(q, config);
    b->plant = &plant;
    b->plant_tool = tool;
    b->plant_weights = true;
    b->add_tool_weight = false;
    return b;
  }
};

double force_of(const Wrench6& w) { return std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]); }

/// The carried ORU's wrist turned by 10 degrees (joint 6) and back, stiffly;
/// the largest compensated force seen (the filtered contact wrench: what
/// limits and compliant motions use). The sensor was tared with the ORU on.
double apparent_force_over_10_degrees(CarriedOru& c, bool controller_knows_oru) {
  ControllerConfig config;
  config.tool.mass_kg = c.tool_truth.mass_kg;
  config.tool.com_sensor_m = c.tool_truth.com_sensor_m;
  config.oru = controller_knows_oru ? c.oru_truth : PayloadMass{};
  auto b = c.bench(config);
  MotionCommand latch;
  latch.kind = MotionCommandKind::SetPayload;
  latch.oru_latched = true;
  b->send(latch);
  b->enable();
  JointArray to = c.q;
  to[5] += 10.0 * kDeg;
  const PreparedTrajectory there(line_trajectory(c.q, to, 2.0));
  const PreparedTrajectory back(line_trajectory(to, c.q, 2.0));
  double peak = 0.0;
  for (const PreparedTrajectory* t : {&there, &back}) {
    MotionCommand m;
    m.kind = MotionCommandKind::RunTrajectory;
    m.trajectory = t;
    const auto id = b->send(m);
    for (int k = 0; k < 1500; ++k) {
      b->step();
      peak = std::max(peak, force_of(b->out.telemetry.wrench_tool));
    }
    const MotionEvent e = b->run_until_final(id, 10);
    EXPECT_EQ(e.kind, MotionEventKind::Completed) << e.text.data();
  }
  EXPECT_TRUE(b->stops.empty());
  return peak;
}

TEST(Payload, CarryingTheOruThroughATenDegreeReorientationAddsLessThanOneNewton) {
  CarriedOru c;
  const double before = apparent_force_over_10_degrees(c, false);  // the tare's weight only: the old behaviour
  const double after = apparent_force_over_10_degrees(c, true);
  std::printf("carried ORU (%.2f kg), 10 deg wrist reorientation: apparent force %.2f N tared only, %.3f N with the "
              "ORU in the payload\n",
              c.oru_truth.mass_kg, before, after);
  EXPECT_GT(before, 5.0);  // 5 kg x 9.81 x 2 sin(5 deg) = 8.6 N at most
  EXPECT_LT(after, 1.0);
}

TEST(Payload, SetPayloadAddsTheOruAndReportsTheTotal) {
  ControllerConfig config;
  config.tool.mass_kg = 2.0;
  config.tool.com_sensor_m = {0.0, 0.0, 0.1};
  config.oru = PayloadMass{6.0, {0.0, 0.0, 0.3}};
  Bench b(home_q(), config);
  b.enable();
  MotionCommand m;
  m.kind = MotionCommandKind::SetPayload;
  m.oru_latched = true;
  const MotionEvent on = b.run_until_final(b.send(m), 2);
  EXPECT_EQ(on.kind, MotionEventKind::Completed);
  EXPECT_STREQ(on.text.data(), "payload 8.000 kg (tool + ORU)");
  EXPECT_DOUBLE_EQ(on.payload_mass_kg, 8.0);
  EXPECT_DOUBLE_EQ(on.payload_com_m[2], 0.25);  // (2 x 0.1 + 6 x 0.3) / 8
  m.oru_latched = false;
  const MotionEvent off = b.run_until_final(b.send(m), 2);
  EXPECT_STREQ(off.text.data(), "payload 2.000 kg (tool)");
  EXPECT_DOUBLE_EQ(b.ctl->compensator().payload().mass_kg, 2.0);
}

TEST(Payload, FitRecoversAKnownPayloadExactly) {
  const Eigen::Vector3d g(0.0, 0.0, -9.81);
  const PayloadMass truth{3.2, {0.01, -0.02, 0.15}};
  const Wrench6 offset{1.0, -2.0, 0.5, 0.05, 0.02, -0.03};
  PayloadPose poses[4];
  const Eigen::Vector3d axes[4] = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitX(),
                                   Eigen::Vector3d::UnitZ()};
  const double angles[4] = {0.0, 0.3, -0.3, 0.5};
  for (int k = 0; k < 4; ++k) {
    poses[k].base_R_sensor = Eigen::AngleAxisd(angles[k], axes[k]).toRotationMatrix() *
                             Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix();
    const Eigen::Vector3d f = poses[k].base_R_sensor.transpose() * (truth.mass_kg * g);
    const Eigen::Vector3d c(truth.com_sensor_m[0], truth.com_sensor_m[1], truth.com_sensor_m[2]);
    const Eigen::Vector3d t = c.cross(f);
    for (int i = 0; i < 3; ++i) {
      poses[k].ft[static_cast<std::size_t>(i)] = f(i) + offset[static_cast<std::size_t>(i)];
      poses[k].ft[static_cast<std::size_t>(i + 3)] = t(i) + offset[static_cast<std::size_t>(i + 3)];
    }
  }
  const PayloadFit fit = fit_payload(poses, 4, g);
  EXPECT_NEAR(fit.payload.mass_kg, 3.2, 1e-9);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(fit.payload.com_sensor_m[i], truth.com_sensor_m[i], 1e-9);
  for (std::size_t i = 0; i < 6; ++i) EXPECT_NEAR(fit.offset_ft[i], offset[i], 1e-9);
  EXPECT_LT(fit.residual_n, 1e-9);
  EXPECT_LT(fit.condition, 20.0);
  // One orientation only: nothing separates the weight from the offset.
  PayloadPose same[2] = {poses[0], poses[0]};
  EXPECT_FALSE(std::isfinite(fit_payload(same, 2, g).condition) && fit_payload(same, 2, g).condition < 1e6);
}

MotionCommand identify(double angle_rad = 0.2) {
  MotionCommand m;
  m.kind = MotionCommandKind::RunAlgorithm;
  m.algorithm.kind = AlgorithmKind::IdentifyPayload;
  m.algorithm.identify_payload.angle_rad = angle_rad;
  return m;
}

// The controller configured with the tool alone, the ORU carried and latched:
// identify_payload finds the total (tool + ORU) from readings with the
// sensor's noise (0.2 N, 0.01 N m per sample), the ORU's part is the total
// less the tool, and reorienting afterwards shows no weight.
TEST(Payload, IdentifyRecoversTheCarriedOruFromNoisyReadings) {
  CarriedOru c;
  ControllerConfig config;
  config.tool.mass_kg = c.tool_truth.mass_kg;
  config.tool.com_sensor_m = c.tool_truth.com_sensor_m;
  config.oru = PayloadMass{};  // unknown
  auto b = c.bench(config);
  b->noise_n = 0.2;
  b->noise_nm = 0.01;
  MotionCommand latch;
  latch.kind = MotionCommandKind::SetPayload;
  latch.oru_latched = true;
  b->send(latch);
  b->enable();
  const auto id = b->send(identify());
  const MotionEvent e = b->run_until_final(id, 20000);
  ASSERT_EQ(e.kind, MotionEventKind::Completed) << e.text.data();
  const PayloadMass total = combined(c.tool_truth, c.oru_truth);
  std::printf("identify_payload: %s (truth %.3f kg, com [%.4f %.4f %.4f] m), %.1f s\n", e.text.data(), total.mass_kg,
              total.com_sensor_m[0], total.com_sensor_m[1], total.com_sensor_m[2],
              static_cast<double>(e.cycle) * 0.002);
  EXPECT_NEAR(e.payload_mass_kg, total.mass_kg, 0.05);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(e.payload_com_m[i], total.com_sensor_m[i], 0.005) << i;
  EXPECT_NEAR(b->ctl->oru_payload().mass_kg, c.oru_truth.mass_kg, 0.05);
  EXPECT_NEAR(b->ctl->tool_payload().mass_kg, c.tool_truth.mass_kg, 1e-12);  // unchanged
  for (std::size_t j = 0; j < kMaxJoints; ++j) EXPECT_NEAR(e.final_q[j], c.q[j], 2e-3);  // back where it began
  EXPECT_EQ(b->ctl->mode(), ControllerMode::Idle);
  EXPECT_TRUE(b->stops.empty());
  // Now reorient by 10 degrees: the identified payload leaves < 1 N.
  JointArray to = c.q;
  to[5] += 10.0 * kDeg;
  const PreparedTrajectory there(line_trajectory(c.q, to, 2.0));
  MotionCommand m;
  m.kind = MotionCommandKind::RunTrajectory;
  m.trajectory = &there;
  const auto tid = b->send(m);
  b->noise_n = 0.0;
  b->noise_nm = 0.0;
  double peak = 0.0;
  for (int k = 0; k < 1500; ++k) {
    b->step();
    peak = std::max(peak, force_of(b->out.telemetry.wrench_tool));
  }
  EXPECT_EQ(b->run_until_final(tid, 10).kind, MotionEventKind::Completed);
  std::printf("after identify_payload, 10 deg reorientation: apparent force %.3f N\n", peak);
  EXPECT_LT(peak, 1.0);
}

TEST(Payload, IdentifyRefusesPosesThatDoNotExciteTheModel) {
  Bench b(home_q());
  b.enable();
  const JointArray before = b.out.q_cmd;
  const MotionEvent e = b.run_until_final(b.send(identify(0.001)), 2);  // refused before anything moves
  ASSERT_EQ(e.kind, MotionEventKind::Rejected) << e.text.data();
  EXPECT_EQ(e.code, Reason::ValidationFailed);
  EXPECT_STREQ(e.text.data(), "identify_payload: the poses do not excite the payload (condition 5812 > 100)");
  EXPECT_EQ(b.ctl->mode(), ControllerMode::Idle);
  EXPECT_EQ(b.out.q_cmd, before);
  // The default 0.2 rad poses are well conditioned.
  const MotionEvent ok = b.run_until_final(b.send(identify(0.2)), 20000);
  EXPECT_EQ(ok.kind, MotionEventKind::Completed) << ok.text.data();
  EXPECT_LT(ok.payload_condition, 100.0);
}

// A stop while identify_payload moves between its poses: a joint-wise
// controlled stop from where the arm is (its moves are joint moves; the
// Cartesian reference stop of the contact algorithms does not apply), nothing
// steps back towards the start.
TEST(Payload, AStopDuringIdentificationDeceleratesWhereTheArmIs) {
  Bench b(home_q());
  b.enable();
  const JointArray start = b.out.q_cmd;
  const auto id = b.send(identify(0.2));
  double moved = 0.0;
  JointArray prev = b.out.q_cmd, v_prev{};
  for (int k = 0; k < 5000 && moved < 0.05; ++k) {
    b.step();
    for (std::size_t j = 0; j < 7; ++j) {
      moved = std::max(moved, std::abs(b.out.q_cmd[j] - start[j]));
      v_prev[j] = (b.out.q_cmd[j] - prev[j]) / 0.002;
    }
    prev = b.out.q_cmd;
  }
  ASSERT_GE(moved, 0.05);
  MotionCommand stop;
  stop.kind = MotionCommandKind::Stop;
  stop.category = StopCategory::Cat2;
  b.send(stop);
  double worst_accel_ratio = 0.0;
  for (int k = 0; k < 2000 && b.ctl->mode() != ControllerMode::Stopped; ++k) {
    b.step();
    for (std::size_t j = 0; j < 7; ++j) {
      const double v = (b.out.q_cmd[j] - prev[j]) / 0.002;
      worst_accel_ratio =
          std::max(worst_accel_ratio, std::abs(v - v_prev[j]) / 0.002 / robot().limits()[j].acceleration_rad_s2);
      v_prev[j] = v;
    }
    prev = b.out.q_cmd;
  }
  ASSERT_EQ(b.ctl->mode(), ControllerMode::Stopped);
  EXPECT_LE(worst_accel_ratio, 1.0 + 1e-6) << "a controlled stop, no step";
  bool canceled = false;
  for (const auto& e : b.events) canceled = canceled || (e.command_id == id && e.kind == MotionEventKind::Canceled);
  EXPECT_TRUE(canceled);
}

TEST(Payload, IdentifyRefusesContactMotionAndBadParameters) {
  Bench b(home_q());
  b.enable();
  b.extra_ft = {0.0, 12.0, 0.0, 0.0, 0.0, 0.0};
  for (int k = 0; k < 300; ++k) b.step();
  MotionEvent e = b.run_until_final(b.send(identify()), 2);
  EXPECT_EQ(e.kind, MotionEventKind::Rejected);
  EXPECT_EQ(e.code, Reason::ForceLimit);
  EXPECT_STREQ(e.text.data(), "identify_payload: in contact (12.0 N > 5.0 N): move clear first");
  b.extra_ft = {};
  for (int k = 0; k < 300; ++k) b.step();
  e = b.run_until_final(b.send(identify(0.9)), 2);
  EXPECT_EQ(e.kind, MotionEventKind::Rejected);
  EXPECT_STREQ(e.text.data(), "identify_payload: angle_rad must be in [0.0001, 0.5] rad");
  MotionCommand hold;
  hold.kind = MotionCommandKind::Hold;
  hold.compliant = true;
  b.run_until_final(b.send(hold), 2);
  e = b.run_until_final(b.send(identify()), 2);
  EXPECT_STREQ(e.text.data(), "identify_payload: needs a stiff hold (send Hold first)");
}

// Tare: only in a stiff hold, only out of contact; it resets the admittance.
TEST(Tare, OnlyInAStiffHoldOutOfContactAndResetsTheAdmittance) {
  Bench b(home_q());
  b.enable();
  MotionCommand tare;
  tare.kind = MotionCommandKind::Tare;
  tare.tare_samples = 10;
  ASSERT_EQ(b.run_until_final(b.send(tare), 20).kind, MotionEventKind::Completed);  // the first zero
  // A compliant hold pushed aside, then a category 2 stop: the arm holds
  // stiffly with the admittance's state from the push.
  MotionCommand hold;
  hold.kind = MotionCommandKind::Hold;
  hold.compliant = true;
  b.run_until_final(b.send(hold), 2);
  b.extra_ft = {0.0, 15.0, 0.0, 0.0, 0.0, 0.0};
  MotionEvent e = b.run_until_final(b.send(tare), 2);
  EXPECT_EQ(e.kind, MotionEventKind::Rejected);
  EXPECT_EQ(e.code, Reason::Busy);
  EXPECT_STREQ(e.text.data(), "tare needs a stiff hold (send Hold first)");
  for (int k = 0; k < 300; ++k) b.step();
  MotionCommand stop;
  stop.kind = MotionCommandKind::Stop;
  stop.category = StopCategory::Cat2;
  b.send(stop);
  for (int k = 0; k < 300; ++k) b.step();
  ASSERT_EQ(b.ctl->mode(), ControllerMode::Stopped);
  EXPECT_GT(b.ctl->admittance().offset().norm(), 1e-3);
  e = b.run_until_final(b.send(tare), 2);
  EXPECT_EQ(e.kind, MotionEventKind::Rejected);
  EXPECT_EQ(e.code, Reason::ForceLimit);
  EXPECT_STREQ(e.text.data(), "tare refused: contact force 15.0 N > 10.0 N (tare only out of contact)");
  b.extra_ft = {};
  for (int k = 0; k < 300; ++k) b.step();
  e = b.run_until_final(b.send(tare), 20);
  EXPECT_EQ(e.kind, MotionEventKind::Completed) << e.text.data();
  EXPECT_EQ(b.ctl->admittance().offset().norm(), 0.0);
  EXPECT_EQ(b.ctl->admittance().velocity().norm(), 0.0);
}

}  // namespace
}  // namespace foresight::control::test
