// link_test_remote: plays the daemon for the link's two-process tests. A
// RemoteLink with a stub handler that acks every command through its
// lifecycle, the way the daemon does (it never lets the link ack):
//   accepted -> RECEIVED, QUEUED, EXECUTING, then COMPLETED with the final
//               joint angles (GOTO_JOINT: the target; TRAJECTORY: the
//               committed trajectory's last sample), or FAILED for the
//               algorithm "fail_me", or REJECTED for a trajectory that is
//               not committed (UNKNOWN_TRAJECTORY) or whose hash differs
//               (HASH_MISMATCH);
//   rejected by the link -> RECEIVED, REJECTED with the link's code and
//               reason; a duplicate -> the command's last ack again.
// Telemetry (joint state, wrench, tool, status) at 50 Hz; on link loss the
// status says mode DISABLED until the first ground heartbeat, IDLE from then;
// on link loss STOPPED with stop_reason "link lost"; on regain IDLE again.
//
// Usage: link_test_remote --domain N [--link-loss-s S] [--max-committed N] [--lifetime-s S]
//                         [--security DIR (scripts/make_dds_security.sh; identity "remote")]
//                         [--ros2 on (also ROS 2 joint_states and wrench)]
//                         [--telemetry-hz R (default 50; 0 = joint states as fast as possible)]
//                         [--upload-idle-s S] [--session-idle-s S]
// Exits on SIGTERM/SIGINT, when its parent dies, or after --lifetime-s.

#include <signal.h>
#include <sys/prctl.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "foresight/common/robot_model.hpp"
#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/loopback.hpp"
#include "foresight/protocol/convert.hpp"
#include "foresight/remote_link/remote_link.hpp"

namespace rl = foresight::remote_link;
namespace protocol = foresight::protocol;

namespace {

struct Stub {
  std::mutex mutex;
  std::vector<double> q = std::vector<double>(7, 0.0);
  protocol::ControllerMode mode = protocol::ControllerMode::Disabled;  // until the first ground heartbeat
  std::string stop_reason;
  std::map<std::uint64_t, protocol::Ack> last_ack;  // by command id
  rl::RemoteLink* link = nullptr;

  void ack(const protocol::Command& c, protocol::AckState state, protocol::Reason code = protocol::Reason::None,
           const std::string& reason = {}, bool with_q = false) {
    protocol::Ack a;
    a.session_id = c.session_id;
    a.command_id = c.command_id;
    a.sequence_number = c.sequence_number;
    a.kind = c.kind;
    a.state = state;
    a.code = code;
    a.reason = reason;
    a.stamp_ns = foresight::protocol::now_ns();
    if (with_q) {
      std::lock_guard lock(mutex);
      a.final_q_rad = q;
    }
    link->ack(a);
    std::lock_guard lock(mutex);
    last_ack[c.command_id] = a;
  }

  void complete(const protocol::Command& c, protocol::AckState final_state = protocol::AckState::Completed,
                protocol::Reason code = protocol::Reason::None, const std::string& reason = {}) {
    ack(c, protocol::AckState::Queued);
    ack(c, protocol::AckState::Executing);
    ack(c, final_state, code, reason, true);
  }

  void on_command(const rl::CommandEvent& e) {
    const protocol::Command& c = e.command;
    if (e.duplicate) {
      protocol::Ack again;
      {
        std::lock_guard lock(mutex);
        const auto it = last_ack.find(c.command_id);
        if (it == last_ack.end()) return;
        again = it->second;
      }
      link->ack(again);
      return;
    }
    ack(c, protocol::AckState::Received);
    if (!e.accepted()) {
      ack(c, protocol::AckState::Rejected, e.code, e.reason);
      return;
    }
    if (const auto* run = std::get_if<protocol::RunTrajectory>(&c.payload)) {
      const auto t = link->committed(run->trajectory_id);
      if (!t) {
        ack(c, protocol::AckState::Rejected, protocol::Reason::UnknownTrajectory,
            "trajectory " + std::to_string(run->trajectory_id) + " is not committed");
        return;
      }
      if (foresight::trajectory_hash(*t) != run->content_hash) {
        ack(c, protocol::AckState::Rejected, protocol::Reason::HashMismatch, "the hash differs from the committed one");
        return;
      }
      {
        std::lock_guard lock(mutex);
        const Eigen::RowVectorXd last = t->positions_rad.row(t->samples() - 1);
        q.assign(last.data(), last.data() + last.size());
      }
      complete(c);
      return;
    }
    if (const auto* go = std::get_if<protocol::GotoJoint>(&c.payload)) {
      {
        std::lock_guard lock(mutex);
        q = go->q_rad;
      }
      complete(c);
      return;
    }
    if (const auto* alg = std::get_if<protocol::InvokeAlgorithm>(&c.payload); alg && alg->name == "fail_me") {
      complete(c, protocol::AckState::Failed, protocol::Reason::ForceLimit, "force limit: 61 N > 60 N");
      return;
    }
    complete(c);
  }

  void on_link(const rl::LinkEvent& e) {
    std::lock_guard lock(mutex);
    if (e.kind == rl::LinkEvent::Kind::CommanderLeft) return;  // this stub has no commander
    if (e.kind == rl::LinkEvent::Kind::Lost) {
      mode = protocol::ControllerMode::Stopped;
      stop_reason = "link lost";
    } else {
      mode = protocol::ControllerMode::Idle;
      stop_reason.clear();
    }
  }

  void publish_all() {
    protocol::JointReport j;
    protocol::StatusReport s;
    {
      std::lock_guard lock(mutex);
      j.q_rad = q;
      s.mode = mode;
      s.stop_reason = stop_reason;
    }
    const std::int64_t now = foresight::protocol::now_ns();
    j.stamp_ns = now;
    j.dq_rad_s.assign(j.q_rad.size(), 0.0);
    j.torque_nm.assign(j.q_rad.size(), 1.5);
    link->publish(j);
    protocol::WrenchReport w;
    w.stamp_ns = now;
    w.force_tool_n = {1.0, 2.0, 3.0};
    w.torque_tool_nm = {0.1, 0.2, 0.3};
    link->publish(w);
    protocol::ToolReport t;
    t.stamp_ns = now;
    t.turns = 2.5;
    link->publish(t);
    s.stamp_ns = now;
    link->publish(s);
  }
};

}  // namespace

int main(int argc, char** argv) {
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  int domain = -1;
  double link_loss_s = 1.0, lifetime_s = 120.0;
  std::size_t max_committed = 8;
  std::string security_dir;
  bool ros2 = false;
  double telemetry_hz = 50.0;
  double upload_idle_s = 60.0;
  double session_idle_s = 3600.0;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    if (key == "--domain") domain = std::atoi(argv[i + 1]);
    else if (key == "--link-loss-s") link_loss_s = std::atof(argv[i + 1]);
    else if (key == "--max-committed") max_committed = static_cast<std::size_t>(std::atoi(argv[i + 1]));
    else if (key == "--lifetime-s") lifetime_s = std::atof(argv[i + 1]);
    else if (key == "--security") security_dir = argv[i + 1];
    else if (key == "--ros2") ros2 = std::string(argv[i + 1]) == "on";
    else if (key == "--telemetry-hz") telemetry_hz = std::atof(argv[i + 1]);
    else if (key == "--upload-idle-s") upload_idle_s = std::atof(argv[i + 1]);
    else if (key == "--session-idle-s") session_idle_s = std::atof(argv[i + 1]);
    else {
      std::fprintf(stderr, "link_test_remote: unknown option %s\n", argv[i]);
      return 2;
    }
  }
  if (domain < 0) {
    std::fprintf(stderr, "usage: link_test_remote --domain N [--link-loss-s S] [--max-committed N]\n");
    return 2;
  }
  // Block the stop signals in every thread; main waits for them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  try {
    foresight::protocol::use_loopback_if_unconfigured();
    const auto model = foresight::RobotModel::from_file(std::string(FORESIGHT_CONFIG_DIR) + "/robot.urdf");
    rl::Config config;
    config.domain = domain;
    config.heartbeat_period_s = std::min(0.1, link_loss_s / 4.0);
    config.link_loss_s = link_loss_s;
    config.trajectory_limits = foresight::TrajectoryLimits::from_model(model);
    config.max_committed = max_committed;
    config.upload_idle_timeout_s = upload_idle_s;
    config.session_idle_s = session_idle_s;
    config.security_dir = security_dir;
    config.ros2 = ros2;
    Stub stub;
    rl::Handlers handlers;
    handlers.on_command = [&](const rl::CommandEvent& e) { stub.on_command(e); };
    handlers.on_link = [&](const rl::LinkEvent& e) { stub.on_link(e); };
    rl::RemoteLink link(config, handlers);
    stub.link = &link;
    link.start();
    const auto start = std::chrono::steady_clock::now();
    const long period_ns = telemetry_hz > 0.0 ? static_cast<long>(1e9 / telemetry_hz) : 0;
    const timespec tick{period_ns / 1'000'000'000, period_ns % 1'000'000'000};
    protocol::JointReport flat_out;
    flat_out.q_rad.assign(7, 0.0);
    flat_out.dq_rad_s.assign(7, 0.0);
    flat_out.torque_nm.assign(7, 0.0);
    for (;;) {
      if (period_ns > 0) {
        stub.publish_all();
      } else {
        for (int k = 0; k < 100; ++k) {  // throughput: joint states only, then check for a signal
          flat_out.stamp_ns = foresight::protocol::now_ns();
          ++flat_out.cycle;
          link.publish(flat_out);
        }
      }
      const int sig = sigtimedwait(&stop_signals, nullptr, &tick);
      if (sig == SIGTERM || sig == SIGINT) break;
      if (std::chrono::steady_clock::now() - start > std::chrono::duration<double>(lifetime_s)) break;
    }
    link.stop();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "link_test_remote: %s\n", e.what());
    return 1;
  }
  return 0;
}
