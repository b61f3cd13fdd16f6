#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <algorithm>
#include <set>
#include <tuple>

#include "foresight/common/error.hpp"
#include "foresight/common/trajectory.hpp"

using namespace foresight;
using Rule = Violation::Rule;

namespace {

// Two joints: q in [-1, 1] rad, 1 rad/s, 4 rad/s^2.
TrajectoryLimits two_joint_limits() {
  TrajectoryLimits l;
  l.joints = 2;
  JointLimits j;
  j.lower_rad = -1.0;
  j.upper_rad = 1.0;
  j.velocity_rad_s = 1.0;
  j.acceleration_rad_s2 = 4.0;
  j.effort_nm = 100.0;
  l.joint_limits = {j, j};
  return l;
}

// A smooth, legal move, from rest to rest on both joints (cosine blends over
// 2 s at 100 Hz, well inside the limits).
Trajectory smooth() {
  Trajectory t;
  const int n = 201;
  t.positions_rad.resize(n, 2);
  for (int i = 0; i < n; ++i) {
    const double s = i * 0.01;
    t.time_s.push_back(s);
    t.positions_rad(i, 0) = 0.25 * (1 - std::cos(M_PI * s / 2.0));
    t.positions_rad(i, 1) = -0.1 * (1 - std::cos(M_PI * s / 2.0));
  }
  return t;
}

std::vector<Rule> rules(const std::vector<Violation>& v) {
  std::vector<Rule> r;
  for (const auto& x : v) r.push_back(x.rule);
  return r;
}

}  // namespace

TEST(Trajectory, SmoothMovePasses) {
  const auto v = validate(smooth(), two_joint_limits());
  EXPECT_TRUE(v.empty()) << v.front().message;
}

TEST(Trajectory, CsvRoundTripIsExact) {
  const Trajectory t = smooth();
  const Trajectory back = parse_trajectory_csv(to_csv(t), "mem");
  ASSERT_EQ(back.samples(), t.samples());
  ASSERT_EQ(back.joints(), 2);
  EXPECT_EQ(back.time_s, t.time_s);
  EXPECT_EQ((back.positions_rad - t.positions_rad).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(trajectory_hash(back), trajectory_hash(t));
}

TEST(Trajectory, HashIsSensitiveToEveryValue) {
  Trajectory t = smooth();
  const TrajectoryHash h = trajectory_hash(t);
  EXPECT_EQ(to_hex(h).size(), 64u);
  t.positions_rad(100, 1) = std::nextafter(t.positions_rad(100, 1), 1.0);
  EXPECT_NE(trajectory_hash(t), h);
  t = smooth();
  t.time_s[5] += 1e-12;
  EXPECT_NE(trajectory_hash(t), h);
}

TEST(Trajectory, HashOfKnownContent) {
  // SHA-256 of "FSTRAJ1" + u32 1 + u32 1 + double 0 + double 0 (little endian),
  // computed independently with `printf ... | sha256sum`.
  Trajectory t;
  t.time_s = {0.0};
  t.positions_rad = Eigen::MatrixXd::Zero(1, 1);
  EXPECT_EQ(to_hex(trajectory_hash(t)), "238722286f1e770d728a7c03d11565db60c5e04f76eddc5e28c1427b9f972a5b");
}

TEST(Trajectory, NonFiniteReportedWithRowAndJoint) {
  Trajectory t = smooth();
  t.positions_rad(10, 1) = std::numeric_limits<double>::quiet_NaN();
  t.time_s[20] = std::numeric_limits<double>::infinity();
  const auto v = validate(t, two_joint_limits());
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].rule, Rule::NonFinite);
  EXPECT_EQ(v[0].row, 11);
  EXPECT_EQ(v[0].joint, 2);
  EXPECT_EQ(v[0].message, "row 11, joint q2: position is not finite");
  EXPECT_EQ(v[1].rule, Rule::NonFinite);
  EXPECT_EQ(v[1].row, 21);
  EXPECT_EQ(v[1].joint, 0);
  EXPECT_EQ(v[1].message, "row 21: t is not finite");
}

TEST(Trajectory, PositionLimit) {
  Trajectory t = smooth();
  t.positions_rad.col(1).array() -= 0.9;  // ends at -1.1 rad
  const auto v = validate(t, two_joint_limits());
  ASSERT_FALSE(v.empty());
  for (const auto& x : v) {
    EXPECT_EQ(x.rule, Rule::PositionLimit);
    EXPECT_EQ(x.joint, 2);
    EXPECT_LT(x.value, -1.0);
  }
  // -0.9 - 0.1 (1 - cos(pi s / 2)) < -1 from s > 1 s: rows 102..201 (1-based).
  EXPECT_EQ(v.front().row, 102);
  EXPECT_EQ(v.size(), 100u);
  EXPECT_EQ(v.front().message, "row 102, joint q2: position -1.00157 rad outside [-1, 1] rad");
}

TEST(Trajectory, VelocityLimitAtLaterRow) {
  Trajectory t = smooth();
  t.positions_rad(50, 0) += 0.05;  // a 5 rad/s spike in and out
  const auto v = validate(t, two_joint_limits());
  std::vector<Violation> vel;
  for (const auto& x : v)
    if (x.rule == Rule::VelocityLimit) vel.push_back(x);
  ASSERT_EQ(vel.size(), 2u);
  EXPECT_EQ(vel[0].row, 51);
  EXPECT_EQ(vel[1].row, 52);
  EXPECT_EQ(vel[0].joint, 1);
  EXPECT_GT(vel[0].value, 1.0);
  EXPECT_LT(vel[1].value, -1.0);
  EXPECT_DOUBLE_EQ(vel[0].limit, 1.0);
}

TEST(Trajectory, AccelerationLimitAtMiddleRow) {
  // Constant velocity 0.5 rad/s then suddenly -0.5 rad/s at row 101: a = -1 / 0.01 = -100 rad/s^2.
  Trajectory t;
  t.positions_rad.resize(201, 2);
  for (int i = 0; i < 201; ++i) {
    t.time_s.push_back(i * 0.01);
    t.positions_rad(i, 0) = i <= 100 ? 0.005 * i : 0.5 - 0.005 * (i - 100);
    t.positions_rad(i, 1) = 0.0;
  }
  const auto v = validate(t, two_joint_limits());
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].rule, Rule::AccelerationLimit);
  EXPECT_EQ(v[0].row, 101);
  EXPECT_EQ(v[0].joint, 1);
  EXPECT_NEAR(v[0].value, -100.0, 1e-9);
  // What the remote would execute from rest into the first 10 ms segment: the
  // interpolant's acceleration there (not yet a rule: docs/control.md).
  const hermite::Extremes first = hermite::extremes(0.0, 0.005, 0.0, 0.5, 0.01);
  EXPECT_NEAR(first.a_abs, 200.0, 1e-6);
}

// Issue 25: samples that pass every sample rule (velocity 1 rad/s at the
// limit, acceleration 1 rad/s^2) whose interpolant, the motion the remote
// executes, reaches 1.39x the velocity limit between them: refused with the
// rows, the joint and the limit.
TEST(Trajectory, TheExecutedInterpolantIsBoundedNotOnlyTheSamples) {
  Trajectory t;
  t.time_s = {0.0, 1.0, 2.0};
  t.positions_rad = Eigen::MatrixXd::Zero(3, 2);
  t.positions_rad(2, 0) = 1.0;
  const auto v = validate(t, two_joint_limits());
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].rule, Rule::VelocityLimit);
  EXPECT_EQ(v[0].row, 3);
  EXPECT_EQ(v[0].joint, 1);
  EXPECT_NEAR(v[0].value, 0.5 + 4.0 / 4.5, 1e-12);  // the tangent 0.5 plus the cubic's bulge
  EXPECT_EQ(v[0].message,
            "between rows 2 and 3, joint q1: the executed velocity reaches 1.38889 rad/s, over the limit 1 rad/s");
  // Limits with room for the executed motion: it passes.
  TrajectoryLimits roomy = two_joint_limits();
  for (auto& j : roomy.joint_limits) {
    j.velocity_rad_s = 1.4;
    j.acceleration_rad_s2 = 5.0;
  }
  EXPECT_TRUE(validate(t, roomy).empty());
}

// The extremes are of the whole cubic: sampled densely, nothing exceeds them.
TEST(Trajectory, HermiteExtremesBoundTheDenselySampledSegment) {
  for (const auto& [p0, p1, m0, m1, h] : {std::tuple{0.0, 1.0, 0.5, 0.0, 1.0}, std::tuple{0.3, -0.2, -1.0, 2.0, 0.01},
                                          std::tuple{1.0, 1.0, 3.0, -3.0, 0.5}}) {
    const hermite::Extremes e = hermite::extremes(p0, p1, m0, m1, h);
    double qmin = 1e9, qmax = -1e9, vmax = 0.0, amax = 0.0, v_prev = 0.0;
    const int k = 20000;
    for (int i = 0; i <= k; ++i) {
      double q = 0.0, dq = 0.0;
      hermite::evaluate(p0, p1, m0, m1, h, static_cast<double>(i) / k, q, dq);
      qmin = std::min(qmin, q);
      qmax = std::max(qmax, q);
      vmax = std::max(vmax, std::abs(dq));
      if (i > 0) amax = std::max(amax, std::abs(dq - v_prev) / (h / k));
      v_prev = dq;
    }
    EXPECT_NEAR(e.q_min, qmin, 1e-6);
    EXPECT_NEAR(e.q_max, qmax, 1e-6);
    EXPECT_NEAR(e.v_abs, vmax, 1e-6 * std::max(1.0, vmax));
    EXPECT_NEAR(e.a_abs, amax, 1e-3 * std::max(1.0, amax));
  }
}

TEST(Trajectory, TimeMustIncrease) {
  Trajectory t = smooth();
  t.positions_rad.setZero();  // at rest: a time fault alone, no rate effects
  t.time_s[30] = t.time_s[29];
  const auto v = validate(t, two_joint_limits());
  ASSERT_EQ(rules(v), std::vector<Rule>{Rule::TimeNotIncreasing});
  EXPECT_EQ(v[0].row, 31);
  EXPECT_EQ(v[0].message, "row 31: t = 0.29 s does not increase (previous 0.29 s)");
}

TEST(Trajectory, SampleGapAndSizeBounds) {
  TrajectoryLimits l = two_joint_limits();
  Trajectory t = smooth();
  for (std::size_t i = 150; i < t.time_s.size(); ++i) t.time_s[i] += 2.0;
  auto v = validate(t, l);
  ASSERT_EQ(rules(v), std::vector<Rule>{Rule::SampleGap});
  EXPECT_EQ(v[0].row, 151);

  l.max_samples = 100;
  l.max_duration_s = 1.0;
  v = validate(smooth(), l);
  EXPECT_EQ(rules(v), (std::vector<Rule>{Rule::TooManySamples, Rule::Duration}));

  Trajectory one;
  one.time_s = {0.0};
  one.positions_rad = Eigen::MatrixXd::Zero(1, 2);
  v = validate(one, two_joint_limits());
  EXPECT_EQ(rules(v), std::vector<Rule>{Rule::TooFewSamples});
}

TEST(Trajectory, JointCountMismatch) {
  TrajectoryLimits l = two_joint_limits();
  l.joints = 7;
  const auto v = validate(smooth(), l);
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].rule, Rule::JointCount);
  EXPECT_EQ(v[0].message, "trajectory has 2 joints, the robot has 7");
}

TEST(Trajectory, EveryViolationIsReported) {
  Trajectory t = smooth();
  t.positions_rad(10, 0) = std::numeric_limits<double>::quiet_NaN();
  t.time_s[60] = t.time_s[59];
  t.positions_rad(150, 1) = 5.0;
  const auto v = validate(t, two_joint_limits());
  std::set<Rule> seen;
  for (const auto& x : v) seen.insert(x.rule);
  EXPECT_TRUE(seen.count(Rule::NonFinite));
  EXPECT_TRUE(seen.count(Rule::TimeNotIncreasing));
  EXPECT_TRUE(seen.count(Rule::PositionLimit));
  EXPECT_TRUE(seen.count(Rule::VelocityLimit));
  EXPECT_TRUE(seen.count(Rule::AccelerationLimit));
  for (std::size_t i = 1; i < v.size(); ++i) EXPECT_LE(v[i - 1].row, v[i].row);
}

TEST(TrajectoryCsv, MalformedRowsNameTheLine) {
  auto message = [](const std::string& text) {
    try {
      parse_trajectory_csv(text, "traj.csv");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message("t,q1,q2\n0,0,0\n0.1,0,abc\n"), "traj.csv:3: column 3 ('abc') is not a number");
  EXPECT_EQ(message("t,q1,q2\n0,0,0\n0.1,0\n"), "traj.csv:3: expected 3 columns (t,q1..q2), found 2");
  EXPECT_EQ(message("time,q1\n0,0\n"), "traj.csv:1: expected the header t,q1,...,qN");
  EXPECT_EQ(message("t,q1,q3\n"), "traj.csv:1: header column 3 is 'q3', expected 'q2'");
  EXPECT_EQ(message("t,q1\n"), "traj.csv: trajectory has no samples");
  EXPECT_EQ(message(""), "traj.csv: empty trajectory file: expected the header t,q1,...,qN");
  EXPECT_EQ(message("# comment\nt,q1\n\n0, 0.5\n"), "no error");
}

TEST(TrajectoryCsv, MissingFile) {
  try {
    read_trajectory_csv("/nonexistent/traj.csv");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/traj.csv: cannot open trajectory file");
  }
}
