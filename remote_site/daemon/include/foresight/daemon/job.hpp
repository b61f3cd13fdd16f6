#pragma once
// A command the supervisor accepted, as it will run: the job factory makes
// it from the command (checked, planned, its trajectory prepared for the
// loop), the queue holds it, the supervisor starts it.

#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "foresight/common/robot_model.hpp"
#include "foresight/control/trajectory_executor.hpp"
#include "foresight/daemon/daemon_config.hpp"
#include "foresight/daemon/tool_worker.hpp"
#include "foresight/daemon/upload_store.hpp"
#include "foresight/protocol/command.hpp"

namespace foresight::daemon {

enum class JobKind { Trajectory, Goto, Algorithm, ToolStep, Recover, Tare, Report };

struct Job {
  using Clock = std::chrono::steady_clock;
  protocol::Command command;
  JobKind kind = JobKind::Trajectory;
  std::shared_ptr<const Trajectory> trajectory;           ///< Trajectory, or the planned Goto
  std::unique_ptr<control::PreparedTrajectory> prepared;  ///< alive until the final event
  control::AlgorithmParams algorithm{};
  int tare_samples = 50;
  ToolStep tool_step;
  bool compliant = false;
  double start_tolerance_rad = 0.0;
  bool executing = false;
  /// A RUN that overtook its upload (RunTrajectory.upload_wait_s > 0): the
  /// upload's id (0: not waiting); it starts only once that upload committed
  /// with the RUN's hash, and FAILS at upload_deadline.
  std::uint64_t awaiting_upload = 0;
  Clock::time_point upload_deadline{};
  /// The id the control loop knows this job's MotionCommand by: unique
  /// whatever the sessions' own command ids (a loop event is matched by it,
  /// so another session's command with the same id cannot finish it).
  std::uint64_t loop_id = 0;
};

/// The job factory: a command's own checks (its arguments against the arm,
/// the tool, the uploads) and its job. Every refusal names its code and why.
class JobFactory {
 public:
  /// `tool` may be null: the tool steps are then refused.
  JobFactory(const RobotModel& model, const DaemonConfig& config, const ToolWorker* tool, const UploadStore& uploads)
      : model_(model), config_(config), tool_(tool), uploads_(uploads) {}

  /// The job of a motion, algorithm, RECOVER or chained REQUEST; null, with
  /// the code and the reason, when refused. A GOTO is planned later (plan_goto).
  std::unique_ptr<Job> make(const protocol::Command& command, protocol::Reason* code, std::string* reason) const;
  /// Plan a GOTO from the commanded joints `q_cmd` (the loop's), with the
  /// planner the ground previews with (plan_motion).
  bool plan_goto(Job& job, std::span<const double> q_cmd, protocol::Reason* code, std::string* reason) const;
  /// A RUN's trajectory: the committed upload `committed` when its hash is
  /// the RUN's, prepared for the loop (HashMismatch, ValidationFailed).
  bool attach_upload(Job& job, const UploadStore::Committed& committed, protocol::Reason* code,
                     std::string* reason) const;

 private:
  bool make_trajectory_job(const protocol::RunTrajectory& run, Job& job, protocol::Reason* code,
                           std::string* reason) const;
  bool check_goto(const protocol::Command& command, protocol::Reason* code, std::string* reason) const;
  bool make_invoke_job(const protocol::InvokeAlgorithm& invoke, Job& job, protocol::Reason* code,
                       std::string* reason) const;

  const RobotModel& model_;
  const DaemonConfig& config_;
  const ToolWorker* tool_;
  const UploadStore& uploads_;
};

}  // namespace foresight::daemon
