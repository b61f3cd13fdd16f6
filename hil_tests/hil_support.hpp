#pragma once
// What the end-to-end tests against the real daemon share: bounded polling of
// a condition, and the daemon's journal as JSON.

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <string>
#include <thread>

#include <Eigen/Core>

#include "foresight/ground_link/ground_link.hpp"
#include "foresight/test/cli.hpp"

namespace foresight::test {

/// Polls `condition` every 10 ms until it holds or `timeout` passes; the last
/// answer (never a fixed sleep: CI machines are loaded).
template <class F>
bool eventually(F condition, std::chrono::nanoseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return condition();
}

/// `foresight-remote journal --json --db DB`, parsed. A failed run or output
/// that is not a JSON object is a test failure (and an empty object).
inline nlohmann::json journal_json(const std::string& db) {
  const CliRun r = run_program("foresight-remote", "journal --json --db " + db);
  EXPECT_EQ(r.status, 0) << r.err;
  auto j = nlohmann::json::parse(r.out, nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    ADD_FAILURE() << "journal of " << db << " is not a JSON object: " << r.out.substr(0, 400);
    return nlohmann::json::object();
  }
  return j;
}

/// The arm's joint angles as the ground last received them (within 10 s);
/// a test failure and zeros when none arrive.
inline Eigen::VectorXd current_q(const ground_link::GroundLink& ground) {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(7);
  const bool ok = eventually(
      [&] {
        const auto js = ground.joint_state();
        if (!js || js->value.q_rad.size() != 7) return false;
        q = Eigen::Map<const Eigen::VectorXd>(js->value.q_rad.data(), 7);
        return true;
      },
      std::chrono::seconds(10));
  EXPECT_TRUE(ok) << "no joint state";
  return q;
}

/// Sends a slow GOTO_JOINT (10% speed) of joint 1 by `delta` from `q0`;
/// returns its command id once the remote reports it EXECUTING (within 5 s).
inline std::uint64_t start_slow_motion(ground_link::GroundLink& ground, const Eigen::VectorXd& q0, double delta) {
  control::GotoJoint g;
  g.q_rad.assign(q0.data(), q0.data() + 7);
  g.q_rad[0] += delta;
  g.speed_fraction = 0.1;
  const std::uint64_t id = ground.send(control::CommandKind::GotoJoint, g);
  const bool executing = eventually(
      [&] {
        const auto partial = ground.wait_final(id, std::chrono::milliseconds(0));
        for (const auto& a : partial.acks)
          if (a.state == control::AckState::Executing) return true;
        return false;
      },
      std::chrono::seconds(5));
  EXPECT_TRUE(executing) << "command " << id << " never EXECUTING";
  return id;
}

}  // namespace foresight::test
