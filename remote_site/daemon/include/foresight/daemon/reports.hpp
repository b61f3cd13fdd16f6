#pragma once
// What the remote tells the ground besides acks: joint, wrench and tool
// reports at their configured rates, and the status report (on change, on
// request and at its rate), all built from what the supervisor holds.

#include <chrono>
#include <cstdint>
#include <functional>
#include <vector>

#include "foresight/daemon/daemon_config.hpp"
#include "foresight/daemon/job_queue.hpp"
#include "foresight/daemon/loop_bridge.hpp"
#include "foresight/daemon/tool_worker.hpp"
#include "foresight/protocol/command.hpp"

namespace foresight::daemon {

/// Where acks and reports go (the DDS link in the daemon; a recorder in tests).
struct Outbox {
  std::function<void(const protocol::Ack&)> ack;
  std::function<void(const protocol::JointReport&)> joints;
  std::function<void(const protocol::WrenchReport&)> wrench;
  std::function<void(const protocol::ToolReport&)> tool;
  std::function<void(const protocol::StatusReport&)> status;
  std::function<void()> republish_uploads;
  /// The participant in control changed (unknown: nobody): the link keeps
  /// only its heartbeats and chunks (RemoteLink::set_commander).
  std::function<void(const protocol::ParticipantGuid&)> commander;
};

/// The site's inputs as the supervisor last saw them.
struct SiteInputs {
  bool estop = false;      ///< the E-stop file exists
  bool link_lost = false;  ///< no ground heartbeat within the link timeout
  std::uint64_t last_sequence = 0;  ///< the highest command sequence number received
};

class Reports {
 public:
  struct Sources {
    const control::ControlLoop& loop;
    const LoopBridge& bridge;
    const JobQueue& jobs;
    const SiteInputs& site;
    const ToolWorker* tool;  ///< null: no tool reports
  };
  /// `drive_nodes`: the CANopen node id per joint (the status's drives).
  Reports(const ReportRates& rates, const Outbox& outbox, std::vector<int> drive_nodes, Sources sources);

  /// The reports that are due; the status too when `force_status`.
  void publish(bool force_status);
  /// The joint and wrench reports (or the tool's) go out at the next publish.
  void joints_and_wrench_now() noexcept { next_joints_ = next_wrench_ = Clock::time_point{}; }
  void tool_now() noexcept { next_tool_ = Clock::time_point{}; }
  /// The controller's mode differs from the last status sent.
  bool mode_changed() const noexcept { return s_.bridge.latest().mode != reported_mode_; }

  protocol::StatusReport status() const;

 private:
  using Clock = std::chrono::steady_clock;
  const ReportRates& rates_;
  const Outbox& outbox_;
  std::vector<int> drive_nodes_;
  Sources s_;
  protocol::ControllerMode reported_mode_ = protocol::ControllerMode::Disabled;
  Clock::time_point next_joints_{}, next_wrench_{}, next_tool_{}, next_status_{};
};

}  // namespace foresight::daemon
