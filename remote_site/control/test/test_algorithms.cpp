// guarded_move, insert and pull_out against the ORU contact model in-process
// (sim::ContactModel as the plant's F/T sensor; the ORU where
// config/scene.yaml puts it; the hole's real 1 mm radial clearance).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <random>

#include "control_fixture.hpp"

namespace foresight::control::test {
namespace {

struct ContactScene {
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  sim::ContactParams params = sim::load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  sim::ContactModel contact{oru, params};
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
};

const ContactScene& scene() {
  static const ContactScene s;
  return s;
}

/// Joints putting the tip `standoff` in front of the hole entrance, shifted
/// (dx, dy) across the axis and tilted by tilt_deg about `tilt_axis` (oru frame).
JointArray start_q(double dx, double dy, double standoff, double tilt_deg,
                   const Eigen::Vector3d& tilt_axis = Eigen::Vector3d::UnitX()) {
  const Pose target = scene().base_T_oru * Eigen::Translation3d(dx, dy, -standoff) *
                      Eigen::AngleAxisd(tilt_deg * M_PI / 180.0, tilt_axis.normalized());
  KinematicsWorkspace ws(robot());
  const Eigen::VectorXd seed = robot().mid_configuration();
  const IkResult r = inverse_kinematics(robot(), ws, target, seed);
  EXPECT_TRUE(r.success);
  JointArray q{};
  for (int j = 0; j < robot().dof(); ++j) q[static_cast<std::size_t>(j)] = r.q(j);
  return q;
}

struct AlgoRun {
  MotionEvent final_event;
  sim::ContactResult contact;
  double peak_n = 0.0;
  double seconds = 0.0;
};

AlgoRun run_algorithm(Bench& b, const AlgorithmParams& p, int max_cycles) {
  b.contact = &scene().contact;
  b.base_T_oru = scene().base_T_oru;
  b.last_tip = b.tip(b.q_arm);
  b.enable();
  MotionCommand c;
  c.kind = MotionCommandKind::RunAlgorithm;
  c.algorithm = p;
  const std::uint64_t id = b.send(c);
  const std::uint64_t c0 = b.cycle;
  AlgoRun r;
  r.final_event = b.run_until_final(id, max_cycles);
  r.seconds = static_cast<double>(b.cycle - c0) * 0.002;
  r.contact = scene().contact.compute(b.tip(b.q_arm), scene().base_T_oru);
  r.peak_n = b.peak_contact_n;
  return r;
}

TEST(GuardedMove, StopsOnTheFaceAtTheThreshold) {
  // 6 cm beside the hole, 10 mm in front of the face.
  Bench b(start_q(0.06, 0.0, 0.010, 0.0));
  AlgorithmParams p;
  p.kind = AlgorithmKind::GuardedMove;
  p.guarded_move.force_threshold_n = 10.0;
  const AlgoRun r = run_algorithm(b, p, 10000);
  ASSERT_EQ(r.final_event.kind, MotionEventKind::Completed) << r.final_event.text.data();
  EXPECT_NEAR(r.final_event.distance_m, 0.010, 0.001);
  EXPECT_GE(r.final_event.peak_force_n, 10.0);
  EXPECT_LT(r.peak_n, 25.0);
  EXPECT_TRUE(b.stops.empty());
  // Holding compliantly at the contact: the force settles low, the arm stays.
  for (int k = 0; k < 1000; ++k) b.step();
  const sim::ContactResult now = scene().contact.compute(b.tip(b.q_arm), scene().base_T_oru);
  EXPECT_LT(now.sensor.force_n.norm(), 12.0);
  EXPECT_EQ(b.ctl->mode(), ControllerMode::Idle);
}

TEST(GuardedMove, FailsWithoutContactAtMaxDistance) {
  Bench b(start_q(0.06, 0.0, 0.030, 0.0));
  AlgorithmParams p;
  p.kind = AlgorithmKind::GuardedMove;
  p.guarded_move.max_distance_m = 0.015;
  const AlgoRun r = run_algorithm(b, p, 10000);
  EXPECT_EQ(r.final_event.kind, MotionEventKind::Failed);
  EXPECT_EQ(r.final_event.code, Reason::Unreachable);
  EXPECT_STREQ(r.final_event.text.data(), "guarded_move: no contact within 15.0 mm");
  EXPECT_NEAR(r.final_event.distance_m, 0.015, 0.001);
  EXPECT_EQ(b.ctl->mode(), ControllerMode::Idle);
}

struct InsertCase {
  double dx, dy, tilt_deg;
  Eigen::Vector3d tilt_axis;
};

class Insert : public ::testing::TestWithParam<InsertCase> {};

TEST_P(Insert, EntersFromTheLocalizationErrorAndReachesDepth) {
  const InsertCase ic = GetParam();
  Bench b(start_q(ic.dx, ic.dy, 0.010, ic.tilt_deg, ic.tilt_axis));
  AlgorithmParams p;
  p.kind = AlgorithmKind::Insert;
  p.insert.depth_m = 0.060;  // 10 mm stand-off + 50 mm into the 80 mm hole
  const AlgoRun r = run_algorithm(b, p, 40000);
  ASSERT_EQ(r.final_event.kind, MotionEventKind::Completed) << r.final_event.text.data();
  // In the hole: the tip within the clearance (+ the penalty model's wall penetration).
  EXPECT_LT(r.contact.tip_radial_offset_m, scene().contact.clearance_m() + 5e-4);
  EXPECT_GT(r.contact.insertion_depth_m, 0.048);
  EXPECT_LT(r.peak_n, 60.0);
  for (const StopEvent& s : b.stops) ADD_FAILURE() << "stop: " << to_string(s.cause) << " " << s.text.data() << " cycle " << s.cycle;
  RecordProperty("seconds", std::to_string(r.seconds));
  RecordProperty("peak_force_n", std::to_string(r.peak_n));
  std::printf("depth %.4f radial %.4f tilt %.4f contacts %d %d %d\n", r.contact.insertion_depth_m, r.contact.tip_radial_offset_m, r.contact.tilt_rad, r.contact.face_contacts, r.contact.bottom_contacts, r.contact.wall_contacts);
  std::printf("insert dx %.1f mm dy %.1f mm tilt %.1f deg: %.2f s, peak %.1f N, spiral %.1f mm\n", 1e3 * ic.dx,
              1e3 * ic.dy, ic.tilt_deg, r.seconds, r.peak_n, 1e3 * r.final_event.spiral_radius_m);
}

INSTANTIATE_TEST_SUITE_P(
    LocalizationErrors, Insert,
    ::testing::Values(InsertCase{0.0, 0.0, 0.0, Eigen::Vector3d::UnitX()},
                      InsertCase{0.0025, 0.0, 1.0, Eigen::Vector3d::UnitY()},
                      InsertCase{-0.002, 0.002, 1.0, Eigen::Vector3d::UnitX()},
                      InsertCase{0.0, -0.003, 1.0, Eigen::Vector3d(1, 1, 0)},
                      InsertCase{0.003, 0.0, 0.0, Eigen::Vector3d::UnitX()},
                      // beyond the 3 mm requirement: the tip stalls on the face, the spiral finds the hole
                      InsertCase{0.0045, 0.0, 1.0, Eigen::Vector3d::UnitY()},
                      InsertCase{0.0, 0.006, 0.0, Eigen::Vector3d::UnitX()}));

TEST(Insert, RandomizedStartsWithinTheLocalizationError) {
  // Lateral error uniform over the 3 mm disk, tilt up to 1 deg about a random
  // axis across the hole; FORESIGHT_INSERT_TRIALS overrides the count.
  const char* env = std::getenv("FORESIGHT_INSERT_TRIALS");
  const int trials = env != nullptr ? std::atoi(env) : 24;
  std::mt19937 rng(2026);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int ok = 0;
  double worst_peak = 0.0, total_s = 0.0;
  for (int i = 0; i < trials; ++i) {
    const double r = 0.003 * std::sqrt(u(rng)), a = 2.0 * M_PI * u(rng);
    const double tilt = 1.0 * u(rng), b = 2.0 * M_PI * u(rng);
    Bench bench(start_q(r * std::cos(a), r * std::sin(a), 0.010, tilt, Eigen::Vector3d(std::cos(b), std::sin(b), 0.0)));
    AlgorithmParams p;
    p.kind = AlgorithmKind::Insert;
    p.insert.depth_m = 0.060;
    const AlgoRun run = run_algorithm(bench, p, 40000);
    const bool success = run.final_event.kind == MotionEventKind::Completed && run.contact.insertion_depth_m > 0.048 &&
                         bench.stops.empty();
    if (!success)
      ADD_FAILURE() << "start " << i << ": r " << 1e3 * r << " mm, tilt " << tilt << " deg: "
                    << run.final_event.text.data();
    ok += success ? 1 : 0;
    worst_peak = std::max(worst_peak, run.peak_n);
    total_s += run.seconds;
  }
  std::printf("randomized insert: %d/%d, worst peak %.1f N, mean %.1f s\n", ok, trials, worst_peak, total_s / trials);
}

TEST(InsertFailure, ForceLimitFailsCleanlyAndHolds) {
  Bench b(start_q(0.0025, 0.0, 0.010, 1.0));
  AlgorithmParams p;
  p.kind = AlgorithmKind::Insert;
  p.insert.contact_force_n = 15.0;
  p.insert.max_force_n = 16.0;
  p.insert.speed_m_s = 0.02;
  const AlgoRun r = run_algorithm(b, p, 40000);
  ASSERT_EQ(r.final_event.kind, MotionEventKind::Failed) << r.final_event.text.data();
  EXPECT_EQ(r.final_event.code, Reason::ForceLimit);
  EXPECT_EQ(std::string(r.final_event.text.data()).rfind("insert: force limit", 0), 0u) << r.final_event.text.data();
  EXPECT_TRUE(b.stops.empty());  // the algorithm failed; no safety stop was needed
  // Holding compliantly where the tip is: the push relaxes.
  for (int k = 0; k < 1500; ++k) b.step();
  EXPECT_EQ(b.ctl->mode(), ControllerMode::Idle);
  const sim::ContactResult now = scene().contact.compute(b.tip(b.q_arm), scene().base_T_oru);
  EXPECT_LT(now.sensor.force_n.norm(), 8.0);
}

// Issue 25: a force limit in a compliant motion backs off instead of
// pushing on through a controlled stop. A guarded move that would push to
// 100 N, against a 30 N safety limit: it FAILS with FORCE_LIMIT, the arm holds
// compliantly at the measured pose, and the simulated contact's force falls
// below the limit within 200 ms and stays there; no safety stop.
TEST(ForceLimit, ACompliantMotionBacksOffBelowTheLimitWithin200ms) {
  ControllerConfig cfg;
  cfg.force_limit_n = 30.0;
  Bench b(start_q(0.06, 0.0, 0.010, 0.0), cfg);  // 6 cm beside the hole, 10 mm in front of the face
  AlgorithmParams p;
  p.kind = AlgorithmKind::GuardedMove;
  p.guarded_move.force_threshold_n = 100.0;
  p.guarded_move.speed_m_s = 0.05;
  const AlgoRun r = run_algorithm(b, p, 10000);
  ASSERT_EQ(r.final_event.kind, MotionEventKind::Failed) << r.final_event.text.data();
  EXPECT_EQ(r.final_event.code, Reason::ForceLimit);
  const std::string text = r.final_event.text.data();
  EXPECT_EQ(text.rfind("contact force ", 0), 0u) << text;
  EXPECT_NE(text.find("> 30.0 N: backing off into a compliant hold"), std::string::npos) << text;
  auto contact_n = [&] { return scene().contact.compute(b.tip(b.q_arm), scene().base_T_oru).sensor.force_n.norm(); };
  const double at_limit = contact_n();
  int k = 0;
  while (k < 100 && contact_n() >= 30.0) {
    b.step();
    ++k;
  }
  std::printf("back-off: contact %.1f N at the limit, below 30 N after %d cycles (%.0f ms)\n", at_limit, k, 2.0 * k);
  EXPECT_LT(k, 100);  // within 200 ms
  double worst = 0.0;
  for (int i = 0; i < 1000; ++i) {
    b.step();
    worst = std::max(worst, contact_n());
  }
  EXPECT_LT(worst, 30.0);
  EXPECT_TRUE(b.stops.empty());
  EXPECT_EQ(b.ctl->mode(), ControllerMode::Idle);
}

TEST(InsertFailure, NoHoleWithinTheSearchRadius) {
  Bench b(start_q(0.02, 0.0, 0.010, 0.0));  // 2 cm off: the spiral cannot find it
  AlgorithmParams p;
  p.kind = AlgorithmKind::Insert;
  p.insert.spiral_max_radius_m = 0.004;
  const AlgoRun r = run_algorithm(b, p, 60000);
  ASSERT_EQ(r.final_event.kind, MotionEventKind::Failed) << r.final_event.text.data();
  EXPECT_EQ(r.final_event.code, Reason::Unreachable);
  EXPECT_STREQ(r.final_event.text.data(), "insert: not entered within search radius 4.0 mm");
}

// The ORU back into its slot: the changeout's stiffest contact (its 0.38 m
// guide in a bore with 1 mm play, its back face on the bore bottom), against
// the whole simulated plant (sim::Plant: the carried ORU and its slot), with
// the real loop's delay (3 cycles and the drives' 40 Hz servo, docs/hardware.md
// "Frame order and loop delay") and with a loaded machine's (TPDOs late behind
// their SYNC: 1 to 3 cycles more). The script's parameters (config/scripts/
// oru_changeout.task step 13), the ORU 1.8/-1.7 mm off and tilted against the
// slot as the changeout leaves it. With the controller's tilt damping
// (20 N m s/rad) the tilt loop rings against the guide as the delay grows
// (the contact torque passes the 15 N m limit at 5-6 cycles: what a loaded
// CI machine did to the changeout HIL, up to a saturated F/T sensor); the
// script's 60 N m s/rad keeps it small at every delay.
struct OruCase {
  int delay_cycles;
  double tilt_deg;            ///< about (1, 1, 0) of the slot
  double rotational_damping;  ///< 0: the controller's
  bool completes;             ///< expected
};

class OruReinsert : public ::testing::TestWithParam<OruCase> {};

TEST_P(OruReinsert, IntoItsSlotAgainstTheLoopDelay) {
  const OruCase oc = GetParam();
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const Pose base_T_home = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  sim::Plant plant(robot(), oru, base_T_home, sim::load_plant_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  OruHandling h;
  auto q_at = [&](const Pose& base_T_tip) { return h.q_at(base_T_tip); };
  auto plant_at = [&](const Eigen::VectorXd& q, double engaged_turns) { return h.plant_at(plant, q, engaged_turns); };
  const auto along = OruHandling::along;
  const sim::LstToolState& tool = h.tool;
  // Gripped 6 cm deep, the screw loose: it comes free; 15 cm out: carried.
  const Eigen::VectorXd q_in = q_at(base_T_home * along(0.06));
  plant_at(q_in, 8.0);
  ASSERT_EQ(plant_at(q_in, 0.0), sim::OruState::Seated);
  ASSERT_EQ(plant_at(q_at(base_T_home * along(-0.09)), 0.0), sim::OruState::Carried);
  // In front of the slot, its back 1 cm before the bore, off as above.
  Pose error = Pose::Identity();
  error.translation() = Eigen::Vector3d(0.0018, -0.0017, 0.0);
  error.linear() =
      Eigen::AngleAxisd(oc.tilt_deg * M_PI / 180.0, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  const Eigen::VectorXd q0 = q_at(base_T_home * error * along(-0.05));
  ASSERT_EQ(plant_at(q0, 0.0), sim::OruState::Carried);

  JointArray q_start{};
  for (int j = 0; j < robot().dof(); ++j) q_start[static_cast<std::size_t>(j)] = q0(j);
  Bench b(q_start);
  b.plant = &plant;
  b.plant_tool = tool;
  b.delay_cycles = oc.delay_cycles;
  b.servo_hz = 40.0;
  b.enable();
  MotionCommand c;
  c.kind = MotionCommandKind::RunAlgorithm;
  c.algorithm.kind = AlgorithmKind::Insert;
  InsertParams& p = c.algorithm.insert;
  p.depth_m = 0.11;
  p.speed_m_s = 0.003;
  p.contact_force_n = 10.0;
  p.lateral_stiffness_n_m = 200.0;
  p.rotational_stiffness_nm_rad = 5.0;
  p.max_force_n = 120.0;
  p.rotational_damping_nm_s_rad = oc.rotational_damping;
  p.timeout_s = 60.0;
  const MotionEvent e = b.run_until_final(b.send(c), 32000);
  const sim::PlantTruth truth = plant.truth();
  std::printf("ORU re-insert, delay %d cycles, tilt %.1f deg, tilt damping %.0f: %s, contact peak %.1f N %.2f N m, "
              "slot depth %.1f mm\n",
              oc.delay_cycles, oc.tilt_deg, oc.rotational_damping, e.text.data(), b.peak_contact_n, b.peak_contact_nm,
              1e3 * truth.oru_slot_depth_m);
  if (oc.completes) {
    EXPECT_EQ(e.kind, MotionEventKind::Completed) << e.text.data();
    EXPECT_EQ(truth.state, sim::OruState::Seated);
    EXPECT_LT(b.peak_contact_nm, 15.0);
    EXPECT_TRUE(b.stops.empty());
  } else {
    EXPECT_EQ(e.kind, MotionEventKind::Failed) << e.text.data();
    EXPECT_EQ(e.code, Reason::ForceLimit) << e.text.data();
    EXPECT_GT(b.peak_contact_nm, 15.0);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Delays, OruReinsert,
    ::testing::Values(OruCase{3, -0.8, 60.0, true}, OruCase{4, -0.8, 60.0, true}, OruCase{5, -0.8, 60.0, true},
                      OruCase{6, -0.8, 60.0, true}, OruCase{3, -0.4, 60.0, true}, OruCase{4, -0.4, 60.0, true},
                      OruCase{5, -0.4, 60.0, true},
                      // the controller's tilt damping: the margin the changeout HIL lost on a loaded machine
                      OruCase{6, -0.8, 0.0, false}, OruCase{5, -0.4, 0.0, false}));

TEST(PullOut, ComesOutAlongTheAxis) {
  Bench b(start_q(0.0005, 0.0, -0.040, 0.0));  // 40 mm deep in the hole
  AlgorithmParams p;
  p.kind = AlgorithmKind::PullOut;
  p.pull_out.distance_m = 0.05;
  const AlgoRun r = run_algorithm(b, p, 20000);
  ASSERT_EQ(r.final_event.kind, MotionEventKind::Completed) << r.final_event.text.data();
  EXPECT_NEAR(r.contact.insertion_depth_m, -0.010, 0.0015);
  EXPECT_NEAR(r.final_event.distance_m, 0.05, 0.0015);
}

}  // namespace
}  // namespace foresight::control::test
