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
  std::vector<Violation> samples;  // the sample rules' ("row R, ..."; the executed motion's say "between rows")
  for (const auto& x : v)
    if (x.message.rfind("row ", 0) == 0) samples.push_back(x);
  ASSERT_EQ(samples.size(), 1u);
  EXPECT_EQ(samples[0].rule, Rule::AccelerationLimit);
  EXPECT_EQ(samples[0].row, 101);
  EXPECT_EQ(samples[0].joint, 1);
  EXPECT_NEAR(samples[0].value, -100.0, 1e-9);
  EXPECT_EQ(samples[0].message, "row 101, joint q1: acceleration -100 rad/s^2 exceeds limit 4 rad/s^2");
  // The ramp also starts and ends moving: what the remote would execute
  // breaks the acceleration limit there too (TheExecutedAccelerationIsBoundedFromRestToRest).
  for (const auto& x : v) EXPECT_EQ(x.rule, Rule::AccelerationLimit) << x.message;
}

// Issue 25: samples that pass every sample rule (velocity 1 rad/s at the
// limit, acceleration 1 rad/s^2) whose interpolant, the motion the remote
// executes, reaches 1.35x the velocity limit between them and stops from
// 1.125x the acceleration limit: refused with the
// rows, the joint and the limit.
TEST(Trajectory, TheExecutedInterpolantIsBoundedNotOnlyTheSamples) {
  Trajectory t;
  t.time_s = {0.0, 1.0, 2.0};
  t.positions_rad = Eigen::MatrixXd::Zero(3, 2);
  t.positions_rad(2, 0) = 1.0;
  // The clamped spline: m = (0, 3/4, 0) rad/s (m0 + 4 m1 + m2 = 3 (q2 - q0) / h);
  // on the second segment P(s) = -1.25 s^3 + 1.5 s^2 + 0.75 s, its velocity
  // peaks at s = 0.4 at 1.35 rad/s, its acceleration ends at -4.5 rad/s^2 (to rest).
  const auto v = validate(t, two_joint_limits());
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].rule, Rule::VelocityLimit);
  EXPECT_EQ(v[0].row, 3);
  EXPECT_EQ(v[0].joint, 1);
  EXPECT_NEAR(v[0].value, 1.35, 1e-12);
  EXPECT_EQ(v[0].message,
            "between rows 2 and 3, joint q1: the executed velocity reaches 1.35 rad/s, over the limit 1 rad/s");
  EXPECT_EQ(v[1].rule, Rule::AccelerationLimit);
  EXPECT_EQ(v[1].row, 3);
  EXPECT_EQ(v[1].joint, 1);
  EXPECT_NEAR(v[1].value, 4.5, 1e-12);
  EXPECT_DOUBLE_EQ(v[1].limit, 4.0);
  EXPECT_EQ(v[1].message,
            "between rows 2 and 3, joint q1: the executed acceleration reaches 4.5 rad/s^2, over the limit 4 rad/s^2");
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

// The interpolant is the clamped cubic spline: at every sample of uneven
// spacing, position, velocity and acceleration from the left equal those
// from the right; the first and last velocities are exactly zero.
TEST(Trajectory, TheInterpolantIsC2AndAtRestAtBothEnds) {
  std::vector<double> t{0.0}, q{0.3};
  for (int i = 1; i < 60; ++i) {
    t.push_back(t.back() + 0.005 + 0.01 * ((i * 7) % 5));  // 5 to 45 ms
    q.push_back(0.3 + 0.2 * std::sin(0.9 * t.back()) + 0.001 * ((i * 3) % 4));
  }
  const std::size_t n = t.size();
  const std::vector<double> m = hermite::spline_velocities(t.data(), q.data(), n);
  ASSERT_EQ(m.size(), n);
  EXPECT_EQ(m.front(), 0.0);
  EXPECT_EQ(m.back(), 0.0);
  for (std::size_t i = 1; i + 1 < n; ++i) {
    const double h0 = t[i] - t[i - 1], h1 = t[i + 1] - t[i];
    double q_left = 0, v_left = 0, q_right = 0, v_right = 0;
    hermite::evaluate(q[i - 1], q[i], m[i - 1], m[i], h0, 1.0, q_left, v_left);
    hermite::evaluate(q[i], q[i + 1], m[i], m[i + 1], h1, 0.0, q_right, v_right);
    EXPECT_NEAR(q_left, q[i], 1e-12);
    EXPECT_NEAR(q_right, q[i], 1e-12);
    EXPECT_NEAR(v_left, v_right, 1e-12);
    const double a_left = hermite::acceleration(q[i - 1], q[i], m[i - 1], m[i], h0, 1.0);
    const double a_right = hermite::acceleration(q[i], q[i + 1], m[i], m[i + 1], h1, 0.0);
    EXPECT_NEAR(a_left, a_right, 1e-9 * std::max(1.0, std::abs(a_left))) << "sample " << i;
  }
}

// Known answers. A cubic at rest at both ends, the smoothstep
// p(t) = D (3 x^2 - 2 x^3), x = t / T, meets every condition of the clamped
// spline, so the spline through its samples (any spacing) is p itself:
// velocity p'(t_i) and acceleration 6 D (1 - 2 x) / T^2 at every sample.
// A steady ramp at v from rest: the velocities are v (1 - r^i),
// r = sqrt(3) - 2 (r^2 + 4 r + 1 = 0), so the arm leaves rest at
// (6 v - 2 m_1) / h = 2 sqrt(3) v / h.
TEST(Trajectory, TheInterpolantReproducesKnownAnswers) {
  const double D = 0.4, T = 1.7;
  std::vector<double> t{0.0}, q{0.0};
  for (int i = 1; t.back() < T; ++i) t.push_back(std::min(T, t.back() + 0.01 + 0.02 * (i % 3)));
  for (std::size_t i = 1; i < t.size(); ++i) {
    const double x = t[i] / T;
    q.push_back(D * x * x * (3 - 2 * x));
  }
  const std::vector<double> m = hermite::spline_velocities(t.data(), q.data(), t.size());
  for (std::size_t i = 0; i + 1 < t.size(); ++i) {
    const double x = t[i] / T;
    EXPECT_NEAR(m[i], 6 * D * x * (1 - x) / T, 1e-12) << "sample " << i;
    EXPECT_NEAR(hermite::acceleration(q[i], q[i + 1], m[i], m[i + 1], t[i + 1] - t[i], 0.0), 6 * D * (1 - 2 * x) / (T * T),
                1e-9)
        << "sample " << i;
  }

  const double v = 0.5, h = 0.01, r = std::sqrt(3.0) - 2.0;
  std::vector<double> tr, qr;
  for (int i = 0; i <= 100; ++i) {
    tr.push_back(h * i);
    qr.push_back(v * h * i);
  }
  const std::vector<double> mr = hermite::spline_velocities(tr.data(), qr.data(), tr.size());
  for (int i = 0; i <= 10; ++i) EXPECT_NEAR(mr[static_cast<std::size_t>(i)], v * (1 - std::pow(r, i)), 1e-12) << i;
  EXPECT_NEAR(hermite::acceleration(qr[0], qr[1], mr[0], mr[1], h, 0.0), 2 * std::sqrt(3.0) * v / h, 1e-9);
}

// Issue 25: a ramp whose samples pass every sample rule (0.5 rad/s, no
// acceleration between samples) but which starts and ends moving: the arm
// would leave rest at 2 sqrt(3) v / h = 173 rad/s^2 and stop as hard. The
// executed acceleration at sample i is 173 r^i (r = sqrt(3) - 2): over the
// 4 rad/s^2 limit on the first three segments and the last three.
TEST(Trajectory, TheExecutedAccelerationIsBoundedFromRestToRest) {
  Trajectory t;
  t.positions_rad = Eigen::MatrixXd::Zero(101, 2);
  for (int i = 0; i <= 100; ++i) {
    t.time_s.push_back(0.01 * i);
    t.positions_rad(i, 0) = 0.005 * i;
  }
  const auto v = validate(t, two_joint_limits());
  ASSERT_EQ(v.size(), 6u);
  const double a0 = 2 * std::sqrt(3.0) * 0.5 / 0.01;
  const std::vector<int> rows{2, 3, 4, 99, 100, 101};
  for (std::size_t k = 0; k < v.size(); ++k) {
    EXPECT_EQ(v[k].rule, Rule::AccelerationLimit);
    EXPECT_EQ(v[k].row, rows[k]);
    EXPECT_EQ(v[k].joint, 1);
    EXPECT_DOUBLE_EQ(v[k].limit, 4.0);
  }
  EXPECT_NEAR(v[0].value, a0, 1e-9);
  EXPECT_NEAR(v[1].value, a0 * (2 - std::sqrt(3.0)), 1e-9);
  EXPECT_NEAR(v[5].value, a0, 1e-9);
  EXPECT_EQ(v[0].message,
            "between rows 1 and 2, joint q1: the executed acceleration reaches 173.205 rad/s^2, over the limit 4 rad/s^2");
  EXPECT_EQ(v[5].message, "between rows 100 and 101, joint q1: the executed acceleration reaches 173.205 rad/s^2, "
                          "over the limit 4 rad/s^2");
  // The same 0.5 rad distance as a smoothstep over 1 s (6 D / T^2 = 3 rad/s^2 at the ends): it passes.
  for (int i = 0; i <= 100; ++i) {
    const double x = 0.01 * i;
    t.positions_rad(i, 0) = 0.5 * x * x * (3 - 2 * x);
  }
  EXPECT_TRUE(validate(t, two_joint_limits()).empty());
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
