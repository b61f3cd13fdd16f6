// The joint velocity end to end: the real daemon `foresight-remote --sim`
// runs a trajectory whose joint 1 cruises at a known constant velocity; the
// ground's JointReport carries the simulated drive's own velocity actual
// (0x606C, TPDO2): its median over the cruise within 2 % of the cruise
// velocity, and (all but a stalled host's few) values a whole number of
// encoder counts per second (so the drive's value, not a differentiated one). At rest
// `foresight status --json` and `foresight request joints --json` report
// the velocities under their keys.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <thread>

#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/ground_link/ground_link.hpp"
#include "foresight/test/cli.hpp"
#include "hil_support.hpp"

using namespace foresight;
using namespace std::chrono_literals;
using protocol::AckState;
using protocol::CommandKind;

namespace {

bool eventually_joint_state(const ground_link::GroundLink& ground) {
  for (int i = 0; i < 500; ++i) {
    if (auto js = ground.joint_state(); js && js->value.q_rad.size() == 7) return true;
    std::this_thread::sleep_for(20ms);
  }
  return false;
}

// Joint 1's drive in config/remote.yaml: 131072 counts per motor turn, gear 160, direction +1.
constexpr double kCountsPerRad = 131072.0 * 160.0 / (2.0 * std::numbers::pi);

constexpr double kCruise_rad_s = 0.2;  // joint 1's known velocity
constexpr double kRamp_s = 0.5;        // smooth ramps up and down (smoothstep velocity)
constexpr double kCruiseTime_s = 2.5;

/// Joint 1 from q0 with velocity sign * kCruise x smoothstep ramps, the other joints still; 100 Hz samples.
Trajectory cruise_trajectory(const std::vector<double>& q0, double sign) {
  const double total = 2 * kRamp_s + kCruiseTime_s;
  const double ramp_dist = kCruise_rad_s * kRamp_s / 2;  // integral of the smoothstep ramp
  const auto position = [&](double t) {
    const auto up = [&](double tau) {  // distance covered tau into the up ramp
      const double u = tau / kRamp_s;
      return kCruise_rad_s * kRamp_s * (u * u * u - u * u * u * u / 2);
    };
    if (t <= kRamp_s) return up(t);
    if (t <= kRamp_s + kCruiseTime_s) return ramp_dist + kCruise_rad_s * (t - kRamp_s);
    return 2 * ramp_dist + kCruise_rad_s * kCruiseTime_s - up(total - t);
  };
  Trajectory tr;
  const int n = static_cast<int>(std::lround(total * 100.0)) + 1;
  tr.positions_rad.resize(n, static_cast<Eigen::Index>(q0.size()));
  for (int i = 0; i < n; ++i) {
    const double t = i / 100.0;
    tr.time_s.push_back(t);
    for (std::size_t j = 0; j < q0.size(); ++j) tr.positions_rad(i, static_cast<Eigen::Index>(j)) = q0[j];
    tr.positions_rad(i, 0) = q0[0] + sign * position(t);
  }
  return tr;
}

}  // namespace

class JointVelocity : public test::DaemonTest {
 protected:
  void SetUp() override {
    ground_config_.joints = 7;
    DaemonTest::SetUp();
  }
};

TEST_F(JointVelocity, TheGroundReceivesTheDrivesVelocityOfAKnownCruise) {
  auto& ground = *ground_;
  auto& remote = *remote_;
  take_and_recover();

  std::vector<double> q0;
  for (int i = 0; i < 500 && q0.empty(); ++i) {
    if (auto js = ground.joint_state(); js && js->value.q_rad.size() == 7) {
      q0 = js->value.q_rad;
    } else {
      std::this_thread::sleep_for(20ms);
    }
  }
  ASSERT_EQ(q0.size(), 7u) << "no joint state";
  const auto& lim = model_.limits()[0];
  const double sign = q0[0] < 0.5 * (lim.lower_rad + lim.upper_rad) ? 1.0 : -1.0;  // towards the far limit
  const Trajectory tr = cruise_trajectory(q0, sign);
  const auto up = ground.upload(tr, 30s);
  ASSERT_TRUE(up.committed()) << up.reason;

  protocol::RunTrajectory run;
  run.trajectory_id = up.trajectory_id;
  run.content_hash = up.local_hash;
  const std::uint64_t id = ground.send(CommandKind::Trajectory, run);

  // Every report during the run (one per cycle number); the cruise by position:
  // its middle 80 %, away from the ramps and the drive's tracking lag.
  const double cruise_from = kCruise_rad_s * kRamp_s / 2, cruise_to = cruise_from + kCruise_rad_s * kCruiseTime_s;
  const double lo = cruise_from + 0.1 * (cruise_to - cruise_from), hi = cruise_to - 0.1 * (cruise_to - cruise_from);
  std::vector<double> cruise_dq;
  std::size_t fallback_reports = 0;
  std::vector<double> other_dq_max(7, 0.0);
  std::uint64_t last_cycle = 0;
  bool finished = false;
  ground_link::CommandResult result;
  const auto deadline = std::chrono::steady_clock::now() + ground.timeout_for(tr.duration_s());
  while (!finished && std::chrono::steady_clock::now() < deadline) {
    result = ground.wait_final(id, 5ms);
    finished = result.finished;
    const auto js = ground.joint_state();
    if (!js || js->value.cycle == last_cycle) continue;
    last_cycle = js->value.cycle;
    const auto& v = js->value;
    ASSERT_EQ(v.dq_rad_s.size(), 7u);
    const double moved = sign * (v.q_rad[0] - q0[0]);
    if (moved > lo && moved < hi) {
      cruise_dq.push_back(sign * v.dq_rad_s[0]);
      for (std::size_t j = 1; j < 7; ++j) other_dq_max[j] = std::max(other_dq_max[j], std::abs(v.dq_rad_s[j]));
      // The drive's 0x606C is a whole number of counts per second on the joint
      // side; the remote's differentiated fallback (a velocity TPDO more than
      // 2 x velocity_tpdo_every cycles old: a stalled host) is not.
      const double counts = v.dq_rad_s[0] * kCountsPerRad;
      if (std::abs(counts - std::round(counts)) > 1e-6 * std::max(1.0, std::abs(counts))) ++fallback_reports;
    }
  }
  ASSERT_TRUE(finished) << remote.log();
  ASSERT_TRUE(result.succeeded()) << result.reason << "\n" << remote.log();
  // 2 s of cruise at 50 Hz reports: about 100; a loaded machine still gets a good share.
  ASSERT_GE(cruise_dq.size(), 20u);
  // The simulated drives advance by wall time between SYNCs (docs/hardware.md):
  // a late SYNC on a loaded machine makes the drive catch up with the demand,
  // and its velocity actual spikes for that sample (seen: 0.85 rad/s once in 91
  // at load 10). The cruise is the bulk: the median (measured 0.4-0.5 % high at
  // load 10, before SYNC first) and the middle half of the reports (25th to
  // 75th percentile). The share within 2 % varies too much from run to run to
  // be a criterion (measured 5-85 %): it is printed only.
  std::vector<double> sorted = cruise_dq;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::size_t near = 0;
  double sum = 0.0;
  for (const double d : cruise_dq) {
    near += std::abs(d - kCruise_rad_s) <= 0.02 * kCruise_rad_s ? 1 : 0;
    sum += d;
  }
  const double share = static_cast<double>(near) / static_cast<double>(cruise_dq.size());
  const double q25 = sorted[sorted.size() / 4], q75 = sorted[(3 * sorted.size()) / 4];
  std::printf("cruise %.3f rad/s: %zu reports, median %.6f, quartiles %.6f / %.6f, mean %.6f, min %.6f, max %.6f rad/s, "
              "%.0f %% within 2 %%, %zu fallback\n",
              kCruise_rad_s, cruise_dq.size(), median, q25, q75, sum / static_cast<double>(cruise_dq.size()),
              sorted.front(), sorted.back(), 100.0 * share, fallback_reports);
  // The values are the drive's: whole counts/s. A loaded host (CPU steal
  // stalls even the SCHED_FIFO loop by 5-20 ms) makes a few late velocity
  // TPDOs; 1 of 103 cruise reports was the fallback in the worst of 12 runs
  // beside 3 busy loops and two compilers.
  EXPECT_LE(fallback_reports * 10, cruise_dq.size()) << fallback_reports << " of " << cruise_dq.size()
                                                     << " cruise reports were not the drive's velocity";
  // Noisy runs were the simulator's doing: its thread (a normal one then)
  // lagged and read two SYNCs at once, so the drive moved over a 0.2 ms
  // "period" at ten times the speed (median 0.227, quartiles to 0.27 rad/s
  // beside 3 busy loops). The simulated drives now time the bus by the
  // frames' kernel stamps and run SCHED_FIFO: 8 loaded runs had medians
  // within 0.5 %. Still noisy: runs where the loop itself overran (172
  // overruns, wakeup p99 10 ms under 13 % CPU steal), when the arm really
  // does stall. The bounds hold those with margin.
  EXPECT_NEAR(median, kCruise_rad_s, 0.075 * kCruise_rad_s);
  EXPECT_GT(q25, 0.5 * kCruise_rad_s);
  EXPECT_LT(q75, 1.5 * kCruise_rad_s);
  for (std::size_t j = 1; j < 7; ++j) EXPECT_LT(other_dq_max[j], 2e-3) << "joint " << j + 1 << " should stand still";

  EXPECT_EQ(ground.dropped().joint_state(), 0u);
}

// At rest (drives disabled: the simulated arm holds still): the operator's
// JSON carries the velocities, about zero, beside the angles.
TEST_F(JointVelocity, TheOperatorsJsonCarriesTheVelocities) {
  ASSERT_TRUE(eventually_joint_state(*ground_));
  const auto status = test::run_foresight("status --json --samples 2 --domain " + std::to_string(domain_));
  ASSERT_EQ(status.status, 0) << status.err;
  const auto sj = nlohmann::json::parse(status.out);
  ASSERT_EQ(sj["joint_velocities_rad_s"].size(), 7u) << status.out;
  for (const auto& v : sj["joint_velocities_rad_s"]) EXPECT_LT(std::abs(v.get<double>()), 2e-3) << status.out;
  ASSERT_EQ(sj["joints_rad"].size(), 7u);
  EXPECT_EQ(sj["joint_states_dropped"], nlohmann::json({{"joint_count", 0}, {"length", 0}, {"not_finite", 0}}));
  // The control loop's grant and timing (--sim: real time not required, no overrun stop).
  ASSERT_TRUE(sj.contains("loop")) << status.out;
  EXPECT_FALSE(sj["loop"]["realtime_required"].get<bool>());
  EXPECT_EQ(sj["loop"]["max_missed_cycles"], 0);
  EXPECT_GT(sj["loop"]["cycles"].get<std::uint64_t>(), 0u);
  EXPECT_GT(sj["loop"]["wakeup_latency_us"]["max"].get<double>(), 0.0);
  const auto text = test::run_foresight("status --samples 2 --domain " + std::to_string(domain_));
  ASSERT_EQ(text.status, 0) << text.err;
  EXPECT_NE(text.out.find("control loop: "), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("no overrun stop"), std::string::npos) << text.out;
  ASSERT_TRUE(sj.contains("rate_limit")) << status.out;
  EXPECT_EQ(sj["rate_limit"]["cycles"], 0) << "nothing moved: the rate limiter never acted";
  EXPECT_NE(text.out.find("rate limiter: never acted"), std::string::npos) << text.out;
  const auto req = test::run_foresight("request joints --json --domain " + std::to_string(domain_));
  ASSERT_EQ(req.status, 0) << req.err;
  const auto rj = nlohmann::json::parse(req.out);
  ASSERT_EQ(rj["report"]["joint_velocities_rad_s"].size(), 7u) << req.out;
  ASSERT_EQ(rj["report"]["joints_rad"].size(), 7u) << req.out;
  // `watch`'s line shows them too, after the angles: "| dq deg/s" and 7 values.
  const auto watch = test::run_foresight("watch --count 1 --period 0.1 --domain " + std::to_string(domain_));
  ASSERT_EQ(watch.status, 0) << watch.err;
  const std::size_t at = watch.out.find("| dq deg/s");
  ASSERT_NE(at, std::string::npos) << watch.out;
  ASSERT_LT(watch.out.find("| q deg"), at) << watch.out;
  std::istringstream dq(watch.out.substr(at + std::string("| dq deg/s").size()));
  for (int j = 0; j < 7; ++j) {
    double v = 1e9;
    ASSERT_TRUE(dq >> v) << "velocity " << j + 1 << " of: " << watch.out;
    EXPECT_LT(std::abs(v), 0.2) << watch.out;
  }
  std::string next;
  dq >> next;
  EXPECT_TRUE(next.empty() || next == "|") << "more than 7 velocities: " << watch.out;
}
