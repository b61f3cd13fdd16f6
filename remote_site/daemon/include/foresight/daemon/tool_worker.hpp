#pragma once
// The LST tool's own thread. Every Modbus call blocks (response timeouts,
// retries, reconnects), so the tool never runs on the supervisor thread and
// never near the control cycle: the supervisor hands one step at a time to
// this thread and polls for its result; between steps the thread reads the
// tool's status at `poll_hz` for the ToolState reports.
//
// The steps (parameters, defaults and criteria; docs/control.md "Tool steps"):
//   latch    LATCH = 1, wait for the latched end switch.      timeout_s (5)
//   unlatch  LATCH = 0, wait for the unlatched end switch.    timeout_s (5)
//   loosen   zero the turns counter, run loosening at speed_rad_s with
//            torque_limit_nm until `turns` turns are made (success). The tool
//            stopping at its torque limit first means the screw did not break
//            loose (ToolFault). turns (8.5), torque_limit_nm, speed_rad_s
//            (tool config), timeout_s (30)
//   tighten  run tightening at speed_rad_s with torque_nm as the limit until
//            the tool reports TORQUE_REACHED (success). torque_nm, speed_rad_s
//            (tool config), timeout_s (30)
// Any tool fault bit (jam, latch) while a step runs fails it (ToolFault, with
// the fault named); a step still running at its timeout fails (Timeout);
// cancel() stops the motor (RUN = 0) and ends the step (Aborted). RUN is
// always cleared when a run step ends.
//
// Thread-safety: start_step, cancel, poll_result, latest are called from the
// supervisor thread (any one thread) and only lock a short mutex.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "foresight/control/command.hpp"
#include "foresight/hw/lst_tool.hpp"

namespace foresight::daemon {

enum class ToolStepKind : std::uint8_t { Latch, Unlatch, Loosen, Tighten };
const char* to_string(ToolStepKind kind) noexcept;
/// "latch" ... -> kind; nullopt when the name is not a tool step.
std::optional<ToolStepKind> tool_step_from_name(const std::string& name) noexcept;

struct ToolStep {
  std::uint64_t command_id = 0;
  ToolStepKind kind = ToolStepKind::Latch;
  double turns = 8.5;
  double torque_nm = 0.0;     ///< tighten: target torque; loosen: torque limit (0 = config)
  double speed_rad_s = 0.0;   ///< 0 = config
  double timeout_s = 0.0;     ///< 0 = the step's default
};

/// Parses the InvokeAlgorithm parameters of a tool step into `step`. Returns
/// "" when they are valid, else the reason (unknown parameter, not finite,
/// out of range against the tool config).
std::string parse_tool_step(const protocol::InvokeAlgorithm& invoke, ToolStepKind kind,
                            const hw::LstToolConfig& tool, ToolStep& step);

struct ToolStepResult {
  std::uint64_t command_id = 0;
  bool ok = false;
  protocol::Reason code = protocol::Reason::None;
  std::string text;         ///< what happened, with numbers ("loosened 8.5 turns, peak 15.2 N m")
  double turns = 0.0;
  double peak_torque_nm = 0.0;
};

class ToolWorker {
 public:
  /// Starts the thread. The tool is connected lazily (the first request).
  ToolWorker(hw::LstToolConfig config, double poll_hz);
  ~ToolWorker();
  ToolWorker(const ToolWorker&) = delete;
  ToolWorker& operator=(const ToolWorker&) = delete;

  /// False (nothing started) when a step is already running.
  bool start_step(const ToolStep& step);
  /// Ends the running step (if `command_id` is 0 or the running one's).
  void cancel(std::uint64_t command_id = 0) noexcept;
  /// The result of a finished step, once.
  std::optional<ToolStepResult> poll_result();
  bool busy() const noexcept { return busy_.load(std::memory_order_acquire); }
  /// Latest status read (stamp in ns, CLOCK_REALTIME; 0 = never read) and
  /// whether the last read failed (with why).
  struct Latest {
    std::int64_t stamp_ns = 0;
    hw::LstStatus status;
    bool link_ok = false;
    std::string error;
  };
  Latest latest() const;
  const hw::LstToolConfig& config() const noexcept { return config_; }

 private:
  void run();
  ToolStepResult execute(const ToolStep& step);
  void read_status();
  bool canceled() const noexcept { return cancel_.load(std::memory_order_acquire); }

  hw::LstToolConfig config_;
  double poll_period_s_;
  hw::LstTool tool_;  // used by the worker thread only
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::optional<ToolStep> pending_;
  std::optional<ToolStepResult> result_;
  Latest latest_;
  std::atomic<bool> busy_{false};
  std::atomic<bool> cancel_{false};
  std::atomic<std::uint64_t> running_id_{0};
  bool quit_ = false;
  std::thread thread_;
};

}  // namespace foresight::daemon
