// `foresight validate` end to end: the real executable on trajectory files
// with known content: its verdict, the hash the remote will check, every
// violation with row and joint, and bad files named with their line.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <sstream>

#include "foresight/common/trajectory.hpp"
#include "foresight/test/cli.hpp"

using namespace foresight;
using foresight::test::run_foresight;
using foresight::test::write_temp_file;

namespace {

/// 7 joints, 2 s at 100 Hz; joint 1 moves 0.2 rad with a cosine profile
/// (peak velocity 0.157 rad/s, peak acceleration 0.25 rad/s^2: within limits).
Trajectory smooth_move() {
  const int n = 201;
  Trajectory t;
  t.time_s.resize(n);
  t.positions_rad = Eigen::MatrixXd::Zero(n, 7);
  for (int i = 0; i < n; ++i) {
    t.time_s[i] = 0.01 * i;
    t.positions_rad(i, 0) = 0.1 * (1.0 - std::cos(M_PI * t.time_s[i] / 2.0));
    t.positions_rad(i, 3) = -0.5;
  }
  return t;
}

std::string csv_of(const Trajectory& t) {
  const std::string p = foresight::test::temp_path(".csv");
  write_trajectory_csv(p, t);
  return p;
}

}  // namespace

TEST(ValidateCli, AcceptsASmoothMoveAndPrintsTheHashTheRemoteChecks) {
  const Trajectory t = smooth_move();
  const std::string path = csv_of(t);
  const auto r = run_foresight("validate " + path + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["ok"].get<bool>());
  EXPECT_EQ(j["samples"].get<int>(), 201);
  EXPECT_EQ(j["joints"].get<int>(), 7);
  EXPECT_DOUBLE_EQ(j["duration_s"].get<double>(), 2.0);
  EXPECT_TRUE(j["violations"].empty());
  // The hash of what was read back equals the hash of what was written
  // (CSV keeps full precision), so ground and remote agree on it.
  EXPECT_EQ(j["sha256"].get<std::string>(), to_hex(trajectory_hash(read_trajectory_csv(path))));
  EXPECT_EQ(j["sha256"].get<std::string>().size(), 64u);

  const auto text = run_foresight("validate " + path);
  ASSERT_EQ(text.status, 0) << text.err;
  EXPECT_NE(text.out.find("201 samples x 7 joints, 2 s"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("ok: within every limit"), std::string::npos) << text.out;
}

TEST(ValidateCli, ReportsEveryViolationWithRowAndJointAndExitsOne) {
  Trajectory t = smooth_move();
  t.positions_rad(50, 1) = 2.5;             // joint 2 limit is +-2.094 rad (and a velocity spike)
  t.time_s[120] = t.time_s[119];            // time does not increase
  const auto r = run_foresight("validate " + csv_of(t) + " --json");
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("the remote would reject this trajectory"), std::string::npos) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_FALSE(j["ok"].get<bool>());
  bool position = false, time = false, velocity = false;
  for (const auto& v : j["violations"]) {
    const std::string rule = v["rule"];
    if (rule == to_string(Violation::Rule::PositionLimit)) {
      position = true;
      EXPECT_EQ(v["row"].get<int>(), 51);
      EXPECT_EQ(v["joint"].get<int>(), 2);
      EXPECT_DOUBLE_EQ(v["value"].get<double>(), 2.5);
      EXPECT_NEAR(v["limit"].get<double>(), 2.094395, 1e-6);
      EXPECT_EQ(v["message"].get<std::string>(), "row 51, joint q2: position 2.5 rad outside [-2.0944, 2.0944] rad");
    }
    if (rule == to_string(Violation::Rule::TimeNotIncreasing)) {
      time = true;
      EXPECT_EQ(v["row"].get<int>(), 121);
    }
    if (rule == to_string(Violation::Rule::VelocityLimit) && v["row"].get<int>() == 51) velocity = true;
  }
  EXPECT_TRUE(position && time && velocity) << r.out;
}

TEST(ValidateCli, MalformedFileNamesTheLineAndExitsTwo) {
  const std::string p = write_temp_file("t,q1,q2,q3,q4,q5,q6,q7\n0,0,0,0,0,0,0,0\n0.01,0,0,zero,0,0,0,0\n");
  const auto r = run_foresight("validate " + p);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find(p + ":3: column 4 ('zero') is not a number"), std::string::npos) << r.err;

  const std::string six = write_temp_file("t,q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0,0\n0.01,0,0,0,0,0,0\n");
  const auto w = run_foresight("validate " + six + " --json");
  EXPECT_EQ(w.status, 1);
  EXPECT_NE(w.out.find("trajectory has 6 joints, the robot has 7"), std::string::npos) << w.out;

  const auto missing = run_foresight("validate /nonexistent/traj.csv");
  EXPECT_EQ(missing.status, 2);
  EXPECT_NE(missing.err.find("/nonexistent/traj.csv: cannot open trajectory file"), std::string::npos) << missing.err;
}

// Issue 25: a ramp whose samples pass every sample rule (0.5 rad/s on joint 1,
// no acceleration between samples) but which starts and ends moving: the arm
// would leave rest at 2 sqrt(3) v / h = 173 rad/s^2 (joint 1's limit is
// 2 rad/s^2). Refused with the row, joint and limit, the message the remote
// sends back for the same file (ProtocolUpload.TheRemoteRefusesTheExecutedAccelerationWithTheGroundsMessage).
TEST(ValidateCli, RefusesWhatTheRemoteWouldExecuteOverTheAccelerationLimit) {
  Trajectory t = smooth_move();
  for (int i = 0; i < t.samples(); ++i) t.positions_rad(i, 0) = i <= 100 ? 0.005 * i : 0.5;
  const std::string path = csv_of(t);
  const auto r = run_foresight("validate " + path + " --json");
  EXPECT_EQ(r.status, 1) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_FALSE(j["ok"].get<bool>());
  ASSERT_FALSE(j["violations"].empty()) << r.out;
  const auto& first = j["violations"][0];
  EXPECT_EQ(first["rule"].get<std::string>(), to_string(Violation::Rule::AccelerationLimit));
  EXPECT_EQ(first["row"].get<int>(), 2);
  EXPECT_EQ(first["joint"].get<int>(), 1);
  EXPECT_NEAR(first["value"].get<double>(), 2 * std::sqrt(3.0) * 50.0, 1e-9);
  EXPECT_DOUBLE_EQ(first["limit"].get<double>(), 2.0);
  const std::string message =
      "between rows 1 and 2, joint q1: the executed acceleration reaches 173.205 rad/s^2, over the limit 2 rad/s^2";
  EXPECT_EQ(first["message"].get<std::string>(), message);
  for (const auto& v : j["violations"]) EXPECT_EQ(v["rule"].get<std::string>(), "acceleration_limit") << v.dump();
  const auto text = run_foresight("validate " + path);
  EXPECT_EQ(text.status, 1);
  EXPECT_NE(text.out.find(message), std::string::npos) << text.out << text.err;
}
