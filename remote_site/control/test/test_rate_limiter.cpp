// The rate limiter (issue 25 item 3): what it leaves alone, what it limits,
// and the controller's commands under a trajectory whose interpolant asks for
// 100x the acceleration limit (validate() refuses it; run without it).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "control_fixture.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/control/rate_limiter.hpp"
#include "foresight/control/trajectory_executor.hpp"

namespace foresight::control::test {
namespace {

constexpr double kDt = 0.002;

RateLimits one_joint(double v, double a, double j) {
  RateLimits l;
  l.velocity[0] = v;
  l.acceleration[0] = a;
  l.jerk[0] = j;
  return l;
}

/// Feeds targets one cycle each; records what was sent and checks every
/// commanded velocity, acceleration and jerk against the limits.
struct Feed {
  JointRateLimiter lim;
  std::vector<double> sent;
  std::vector<std::uint32_t> masks;
  double v_prev = 0.0, a_prev = 0.0, worst_v = 0.0, worst_a = 0.0, worst_j = 0.0;
  explicit Feed(const RateLimits& l, double q0) {
    lim.configure(1, l, kDt);
    JointArray q{};
    q[0] = q0;
    lim.reset(q);
    sent.push_back(q0);
  }
  double feed(double target) {
    JointArray t{}, c{};
    t[0] = target;
    masks.push_back(lim.apply(t, c));
    const double v = (c[0] - sent.back()) / kDt;
    const double a = (v - v_prev) / kDt;
    worst_v = std::max(worst_v, std::abs(v));
    worst_a = std::max(worst_a, std::abs(a));
    worst_j = std::max(worst_j, std::abs((a - a_prev) / kDt));
    v_prev = v;
    a_prev = a;
    sent.push_back(c[0]);
    return c[0];
  }
};

TEST(RateLimiter, ACommandInsideItsLimitsPassesUnchanged) {
  // 0.2 (1 - cos) rad at 1 Hz from rest: peak 1.26 rad/s (limit 2), 7.9 rad/s^2
  // (limit 10), 49.6 rad/s^3 (limit 5000; the start's acceleration step 3950).
  Feed r(one_joint(2.0, 10.0, 5000.0), 0.0);
  for (int k = 1; k <= 1500; ++k) {
    const double target = 0.2 * (1.0 - std::cos(2.0 * M_PI * k * kDt));
    ASSERT_EQ(r.feed(target), target) << "cycle " << k;
    ASSERT_EQ(r.masks.back(), 0u) << "cycle " << k;
  }
}

TEST(RateLimiter, AStepIsReachedInsideTheLimitsWithoutOvershoot) {
  const double V = 0.9, A = 3.0, J = 2000.0, step = 0.0015;  // 0.75 rad/s in one cycle: 375 rad/s^2 asked
  Feed r(one_joint(V, A, J), 0.0);
  int reached = -1;
  double peak = 0.0;
  for (int k = 1; k <= 1000; ++k) {
    const double q = r.feed(step);
    peak = std::max(peak, q);
    if (reached < 0 && std::abs(q - step) <= 1e-6) reached = k;
  }
  EXPECT_LE(r.worst_v, V * (1 + 1e-9));
  EXPECT_LE(r.worst_a, A * (1 + 1e-6));
  EXPECT_LE(r.worst_j, J * (1 + 1e-6));
  EXPECT_LE(peak, step + 1e-9) << "overshoot";
  // Bang-bang at A covers 1.5 mm in 2 sqrt(d / A) = 45 ms; the limiter is
  // within a micro-radian of it within 30% more.
  ASSERT_GT(reached, 0);
  EXPECT_LT(reached * kDt, 1.3 * 2.0 * std::sqrt(step / A)) << reached;
  EXPECT_GT(reached * kDt, 2.0 * std::sqrt(step / A) * 0.95) << reached;
  EXPECT_EQ(r.masks.front(), 1u);
  EXPECT_EQ(r.masks.back(), 0u) << "released once on the target";
  EXPECT_EQ(r.sent.back(), step);
}

TEST(RateLimiter, AnInstantReversalIsFollowedAndCaughtUpWith) {
  // The target runs at 0.6 rad/s and reverses in one cycle (600 rad/s^2 asked).
  const double V = 0.9, A = 4.0, J = 4000.0;
  Feed r(one_joint(V, A, J), 0.0);
  double target = 0.0;
  for (int k = 1; k <= 200; ++k) r.feed(target += 0.6 * kDt);  // ramps up inside the limits after 75 ms
  const double turn = target;
  double peak = 0.0;
  int released = -1;
  for (int k = 1; k <= 1500; ++k) {
    target -= 0.6 * kDt;
    peak = std::max(peak, r.feed(target));
    if (released < 0 && k > 1 && r.masks.back() == 0u) released = k;
  }
  EXPECT_LE(r.worst_v, V * (1 + 1e-9));
  EXPECT_LE(r.worst_a, A * (1 + 1e-6));
  EXPECT_LE(r.worst_j, J * (1 + 1e-6));
  // It cannot turn at once: it runs on by about v^2 / 2A = 45 mm, not more.
  EXPECT_GT(peak - turn, 0.6 * 0.6 / (2 * A) * 0.8);
  EXPECT_LT(peak - turn, 0.6 * 0.6 / (2 * A) * 1.3);
  ASSERT_GT(released, 0) << "still limiting 3 s after the reversal";
  EXPECT_NEAR(r.sent.back(), target, 1e-9) << "back on the target";
}

TEST(RateLimiter, ATargetFasterThanTheVelocityLimitIsLeftToTheSafetyCheck) {
  Feed r(one_joint(0.9, 3.0, 2000.0), 0.0);
  EXPECT_EQ(r.feed(0.1), 0.1) << "50 rad/s in one cycle: passed on for the controller to refuse";
  JointRateLimiter lim;
  EXPECT_THROW(lim.configure(1, one_joint(0.9, 0.0, 1.0), kDt), std::invalid_argument);
  EXPECT_THROW(lim.configure(1, one_joint(0.9, 1.0, NAN), kDt), std::invalid_argument);
}

TEST(RateLimiter, TheControllerSmoothsATrajectoryThatValidateRefusesAndSaysSo) {
  // A ramp that starts moving at its first sample: every sample rule passes,
  // but the interpolant leaves rest at 2 sqrt(3) v / h = 208 rad/s^2 on
  // joint 1 (100x its 2 rad/s^2 limit) and stops as hard at the end: validate
  // refuses it (the first four segments and the last four). Run as it is,
  // bypassing validate, the limiter is the last word.
  const JointArray q0 = home_q();
  Trajectory traj;
  const int n = 101;
  traj.positions_rad.resize(n, 7);
  for (int i = 0; i < n; ++i) {
    traj.time_s.push_back(0.01 * i);
    for (int j = 0; j < 7; ++j) traj.positions_rad(i, j) = q0[static_cast<std::size_t>(j)] + (j == 0 ? 0.006 * i : 0.0);
  }
  const auto refused = validate(traj, TrajectoryLimits::from_model(robot()));
  ASSERT_EQ(refused.size(), 8u);
  EXPECT_EQ(refused[0].rule, Violation::Rule::AccelerationLimit);
  EXPECT_EQ(refused[0].message,
            "between rows 1 and 2, joint q1: the executed acceleration reaches 207.846 rad/s^2, over the limit 2 rad/s^2");
  EXPECT_EQ(refused[7].message, "between rows 100 and 101, joint q1: the executed acceleration reaches 207.846 "
                                "rad/s^2, over the limit 2 rad/s^2");
  const PreparedTrajectory prepared(traj);

  Bench b(q0);
  b.enable();
  MotionCommand c;
  c.kind = MotionCommandKind::RunTrajectory;
  c.trajectory = &prepared;
  const auto id = b.send(c);
  const double A = robot().limits()[0].acceleration_rad_s2 * b.config.rate_limit_acceleration_fraction;
  double q_prev = b.out.q_cmd[0], v_prev = 0.0, worst_a = 0.0, worst_lag = 0.0;
  std::uint64_t limited_cycles = 0;
  bool final_seen = false;
  for (int k = 0; k < 1500; ++k) {
    b.step();
    const double v = (b.out.q_cmd[0] - q_prev) / kDt;
    worst_a = std::max(worst_a, std::abs(v - v_prev) / kDt);
    worst_lag = std::max(worst_lag, std::abs(b.out.telemetry.rate_limit_lag[0]));
    q_prev = b.out.q_cmd[0];
    v_prev = v;
    limited_cycles = b.out.telemetry.rate_limited_cycles;
    for (const MotionEvent& e : b.events) final_seen = final_seen || (e.command_id == id && is_final(e.kind));
  }
  ASSERT_TRUE(final_seen);
  EXPECT_TRUE(b.stops.empty()) << (b.stops.empty() ? "" : b.stops[0].text.data());
  EXPECT_LE(worst_a, A * (1 + 1e-6)) << "the command's acceleration";
  EXPECT_GT(limited_cycles, 10u) << "the limiter acted and the telemetry says so";
  EXPECT_GT(b.out.telemetry.rate_limited_joint_cycles[0], 10u);
  EXPECT_EQ(b.out.telemetry.rate_limited_joint_cycles[1], 0u) << "joint 2 stood still";
  EXPECT_GT(worst_lag, 1e-4);
  EXPECT_EQ(b.out.telemetry.rate_limited_mask, 0u) << "released at rest";
  EXPECT_NEAR(b.out.q_cmd[0], q0[0] + 0.6, 1e-9) << "it ends where the trajectory ends";
}

/// Runs a trajectory that starts at home_q() stiffly to its end; the cycles
/// the rate limiter limited.
std::uint64_t limited_cycles_running(const Trajectory& traj) {
  const PreparedTrajectory prepared(traj);
  Bench b(home_q());
  b.enable();
  MotionCommand c;
  c.kind = MotionCommandKind::RunTrajectory;
  c.trajectory = &prepared;
  const auto id = b.send(c);
  const MotionEvent e = b.run_until_final(id, static_cast<int>(traj.duration_s() / kDt) + 500);
  EXPECT_EQ(e.kind, MotionEventKind::Completed) << e.text.data();
  return b.out.telemetry.rate_limited_cycles;
}

TEST(RateLimiter, APlannedTrajectoryIsNotTouched) {
  // The smoothstep line the other controller tests run: inside every limit.
  JointArray to = home_q();
  to[0] += 0.3;
  to[3] -= 0.2;
  Trajectory traj;
  const int n = 201;
  traj.positions_rad.resize(n, 7);
  for (int i = 0; i < n; ++i) {
    const double s = static_cast<double>(i) / (n - 1), w = s * s * (3.0 - 2.0 * s);
    traj.time_s.push_back(0.01 * i);
    for (int j = 0; j < 7; ++j) {
      const auto u = static_cast<std::size_t>(j);
      traj.positions_rad(i, j) = home_q()[u] + w * (to[u] - home_q()[u]);
    }
  }
  EXPECT_TRUE(validate(traj, TrajectoryLimits::from_model(robot())).empty());
  EXPECT_EQ(limited_cycles_running(traj), 0u);
}

// The planner's moves at the full limits: a joint move timed by the
// acceleration limit and a straight tool line (IK at every sample). Both pass
// validate(), which bounds their executed acceleration at 1x the limit, and
// the limiter (1.5x) never acts on them.
TEST(RateLimiter, ThePlannersMovesAtTheFullLimitsAreNotTouched) {
  Eigen::VectorXd q0(7);
  for (int j = 0; j < 7; ++j) q0[j] = home_q()[static_cast<std::size_t>(j)];
  PlanOptions o;
  o.limit_fraction = 1.0;
  Goal joint;
  joint.name = "joint";
  joint.is_pose = false;
  joint.q = q0;
  joint.q[0] += 0.2;
  joint.q[3] -= 0.2;
  KinematicsWorkspace ws(robot());
  Goal line;
  line.name = "line";
  line.kind = SegmentKind::Linear;
  line.base_T_tip = forward_kinematics(robot(), ws, q0);
  line.base_T_tip.translation() += Eigen::Vector3d(0.05, 0.0, -0.05);
  o.tool_speed_m_s = 0.2;
  o.tool_accel_m_s2 = 1.0;
  for (const Goal& g : {joint, line}) {
    const Plan p = plan_motion(robot(), q0, {g}, o);
    const auto v = validate(p.trajectory, TrajectoryLimits::from_model(robot()));
    EXPECT_TRUE(v.empty()) << g.name << ": " << v.front().message;
    EXPECT_EQ(limited_cycles_running(p.trajectory), 0u) << g.name;
  }
}

TEST(RateLimiter, ACompliantHoldIsLimitedInsideItsForceLoopWithoutWindup) {
  // A compliant hold hit by a torque step about the tool axis: the admittance
  // (20 N m s/rad) asks the wrist for 0.4 rad/s within a few cycles, many
  // times its acceleration limit. The limiter cuts it; the admittance
  // takes back what the command did not carry, so its offset stays the
  // command's (no windup to snap back), and the hold returns when the
  // torque goes. At the stiff motions' 1.5x, so that it limits for a while.
  ControllerConfig config;
  config.rate_limit_compliant_acceleration_fraction = config.rate_limit_acceleration_fraction;
  Bench b(home_q(), config);
  b.enable();
  MotionCommand h;
  h.kind = MotionCommandKind::Hold;
  h.compliant = true;
  b.send(h);
  for (int k = 0; k < 20; ++k) b.step();
  const Pose hold = b.tip(b.out.q_cmd);
  const double frac = b.config.rate_limit_compliant_acceleration_fraction;
  JointArray q_prev = b.out.q_cmd, v_prev{};
  double worst_ratio = 0.0, worst_gap = 0.0, worst_release_gap = 0.0, peak = 0.0;
  for (int k = 0; k < 1600; ++k) {
    b.extra_ft = {};
    if (k < 150) b.extra_ft[5] = 8.0;
    b.step();
    for (std::size_t j = 0; j < 7; ++j) {
      const double v = (b.out.q_cmd[j] - q_prev[j]) / kDt;
      worst_ratio = std::max(worst_ratio, std::abs(v - v_prev[j]) / kDt / (frac * robot().limits()[j].acceleration_rad_s2));
      v_prev[j] = v;
    }
    q_prev = b.out.q_cmd;
    // The commanded rotation about the tool axis against the admittance's offset.
    const Eigen::AngleAxisd turn(hold.linear().transpose() * b.tip(b.out.q_cmd).linear());
    const double about_z = turn.angle() * turn.axis().z();
    const double gap = std::abs(about_z - b.ctl->admittance().offset()(5));
    (k < 150 ? worst_gap : worst_release_gap) = std::max(k < 150 ? worst_gap : worst_release_gap, gap);
    peak = std::max(peak, std::abs(about_z));
  }
  std::printf("compliant hold, 8 N m step: %llu cycles limited, peak acceleration %.2f of the limit, peak turn %.4f rad, "
              "offset vs command %.2e rad at most while pushed, %.2e rad when released\n",
              static_cast<unsigned long long>(b.out.telemetry.rate_limited_cycles), worst_ratio, peak, worst_gap,
              worst_release_gap);
  EXPECT_TRUE(b.stops.empty());
  EXPECT_GT(b.out.telemetry.rate_limited_cycles, 0u) << "the limiter acted inside the force loop";
  EXPECT_LE(worst_ratio, 1.0 + 1e-6);
  EXPECT_GT(peak, 0.05);
  EXPECT_LT(worst_gap, 2e-4) << "the admittance's state is what was commanded";
  // Released, the admittance stops at once; the command brakes at its limit
  // (joint 7: 1.5 x 6 rad/s^2) and runs on by at most v^2 / 2a (0.38 rad/s: 8 mrad).
  EXPECT_LT(worst_release_gap, 0.38 * 0.38 / (2.0 * 1.5 * 6.0));
  EXPECT_LT(peak, b.config.admittance.max_offset[5] + 0.38 * 0.38 / (2.0 * 1.5 * 6.0));
  // Released: back to the hold (20 N m/rad, 1 s time constant: 3 s in, e^-3).
  const Eigen::AngleAxisd back(hold.linear().transpose() * b.tip(b.out.q_cmd).linear());
  EXPECT_LT(back.angle(), 0.06 * peak);
  EXPECT_EQ(b.out.telemetry.rate_limited_mask, 0u);
}

}  // namespace
}  // namespace foresight::control::test
