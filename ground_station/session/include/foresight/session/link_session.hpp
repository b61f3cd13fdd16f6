#pragma once
// What the link commands (status, send, abort, request, goto, invoke,
// take-control, release-control, recover, watch) and `run` share: the DDS
// domain, connecting to the remote, waiting for a command's final
// acknowledgement (interruptible), and printing outcomes. Each command file
// adds its own options (link_options.hpp). Not real-time.

#include <chrono>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>

#include "foresight/common/error.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/command.hpp"
#include "foresight/protocol/network.hpp"
#include "foresight/ground_link/ground_link.hpp"

namespace foresight::session {

/// The remote did not answer, an upload was not committed, or a command was
/// rejected/failed/timed out (exit 1).
class LinkFailure : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

/// The options every command that talks to the remote shares
/// (link_options.hpp registers them).
struct LinkOptions {
  int domain = -1;               ///< < 0: $FORESIGHT_DDS_DOMAIN, else 0
  double connect_timeout_s = 10.0;
  double timeout_s = 0.0;        ///< final-ack timeout; 0 = derived from the measured delay
  bool json = false;
  std::string security_dir;      ///< "": $FORESIGHT_DDS_SECURITY, else plain DDS
  std::string identity;          ///< "": $FORESIGHT_DDS_IDENTITY, else "ground"
};

/// ground.yaml's `link:` section: the station's DDS Security folder and
/// identity and its DDS network. Defaults (no security, "ground", loopback)
/// when the file does not exist; InputError "<file>:<line>: link.<key>: ..."
/// for a bad one.
struct GroundLinkFile {
  std::string path;
  std::string security_dir;  ///< absolute, or relative to the working directory
  std::string identity = "ground";
  protocol::NetworkSettings network;
};
GroundLinkFile load_ground_link_file(const std::string& path);

/// The DDS domain: `option` when >= 0, else $FORESIGHT_DDS_DOMAIN, else 0.
/// std::invalid_argument "FORESIGHT_DDS_DOMAIN: 'x' is not a DDS domain id (0-232)".
int resolve_domain(int option);

/// Joins the domain and waits for the remote (its command reader matched and a
/// first pong), at most `timeout_s`. LinkFailure "no remote answered on DDS
/// domain D within T s".
std::unique_ptr<ground_link::GroundLink> connect_remote(int domain, double timeout_s);
/// The same with the options' domain, DDS Security folder and identity (each
/// from the environment when not given, else from ground.yaml) and
/// ground.yaml's DDS network (unless CYCLONEDDS_URI is set). A damaged
/// security file is named (protocol::verify_security_files): InputError
/// "--security: ..." (or the variable or file it came from); a missing
/// interface or a peer that does not resolve: InputError "<ground.yaml>:
/// link.network: ...".
std::unique_ptr<ground_link::GroundLink> connect_remote(const LinkOptions& options);

/// How long a command may take before its final ack: the link's
/// timeout_for(expected_s), or `override_s` when > 0.
std::chrono::nanoseconds final_ack_timeout(const ground_link::GroundLink& link, double expected_s,
                                           double override_s);

/// Sends and waits for the final ack, polling `interrupted` every 0.1 s (may be
/// empty). When it returns true the command is aborted (ABORT of its id,
/// category 2) and the wait goes on for its final ack (CANCELED). A timeout
/// leaves result.finished false.
ground_link::CommandResult send_and_wait(ground_link::GroundLink& link, protocol::CommandKind kind,
                                         const protocol::Payload& payload, std::chrono::nanoseconds timeout,
                                         const std::function<bool()>& interrupted = {});

/// The waiting half of send_and_wait, for a command already sent at `sent`.
ground_link::CommandResult wait_or_abort(ground_link::GroundLink& link, std::uint64_t command_id,
                                         std::chrono::steady_clock::time_point sent, std::chrono::nanoseconds timeout,
                                         const std::function<bool()>& interrupted = {});

/// A command that moves the arm takes control first (LinkFailure when
/// refused, e.g. another station holds it). Without DDS Security each CLI
/// process is its own ground station and gives control back when the guard
/// goes out of scope. With it, the station is its identity: control stays
/// with it across its commands (the remote binds it to the identity) until
/// `release-control` or the lease (controller.control_lease_s of silence).
class ControlGuard {
 public:
  explicit ControlGuard(ground_link::GroundLink& link);
  ~ControlGuard();
  ControlGuard(const ControlGuard&) = delete;
  ControlGuard& operator=(const ControlGuard&) = delete;

 private:
  ground_link::GroundLink& link_;
};

/// {"command", "command_id", "state", "code", "reason", "finished", "elapsed_s", "final_q_rad", "acks"}.
nlohmann::json result_json(protocol::CommandKind kind, const ground_link::CommandResult& r);
/// One line: "goto_joint 12: completed in 3.2 s" or "... rejected (busy): reason"
/// or "... timed out after 5.0 s waiting for the final ack (last: queued)".
std::string result_line(protocol::CommandKind kind, const ground_link::CommandResult& r);

/// Every trajectory/goto/algorithm command's exit status: 0 on COMPLETED, else 1.
int exit_status(const ground_link::CommandResult& r);

/// The arm's joint vector from a joint report: std::nullopt when the report
/// has another number of joints than the model.
std::optional<Eigen::VectorXd> joints_of(const protocol::JointReport& report, const RobotModel& model);
/// The same, or LinkFailure "the remote reports N joint angles, the robot
/// model has M joints".
Eigen::VectorXd require_joints(const protocol::JointReport& report, const RobotModel& model);

/// The latest joint angles, waiting for the first report at most `timeout_s`.
std::optional<ground_link::Timed<protocol::JointReport>> wait_joints(const ground_link::GroundLink& link,
                                                                    double timeout_s);

/// Uploads and waits for COMMITTED with the remote's hash equal to the local
/// one (LinkFailure otherwise, naming both hashes or the rejection reason).
ground_link::UploadResult upload_committed(ground_link::GroundLink& link, const Trajectory& trajectory,
                                           double timeout_s);
/// upload_committed's check of a finished wait (LinkFailure with the same messages).
void require_committed(const ground_link::UploadResult& r, double timeout_s);

/// The ground's cap on RunTrajectory::upload_wait_s (the shipped remote's
/// controller.max_upload_wait_s).
inline constexpr double kMaxUploadWaitS = 60.0;
/// How long a RUN sent together with its upload lets the remote wait for the
/// commit: the link's derived timeout for the transfer (3 x the measured p99
/// round trip + margin: a lost chunk's repair), at most kMaxUploadWaitS.
double upload_wait_for(const ground_link::GroundLink& link, const Trajectory& trajectory);

/// Upload and RUN in one go: every chunk written, then the RUN at once with
/// the local hash and upload_wait_for(); the remote runs the trajectory only
/// once the whole upload committed with that hash (else FAILS the RUN with
/// why). `run`'s id, hash and wait are filled in; `after_command_id` chains it.
struct UploadAndRun {
  ground_link::UploadResult upload;
  std::uint64_t command_id = 0;
  std::chrono::steady_clock::time_point sent{};
  double upload_wait_s = 0.0;
};
UploadAndRun upload_and_run(ground_link::GroundLink& link, const Trajectory& trajectory, protocol::RunTrajectory run,
                            std::uint64_t after_command_id = 0);

/// The duration of the path the remote will plan for a GOTO_JOINT or GOTO_CART
/// from joints `q_now` (the same common plan_motion, the same options as the
/// remote's supervisor). Throws PlanError when the goal cannot be planned (the
/// remote would answer Unreachable).
double planned_goto_duration_s(const RobotModel& model, const std::vector<double>& q_now,
                               const protocol::Payload& payload);

/// The status object of `foresight status --json` (keys: rtt_s{median, p95,
/// p99, max, count, share_over_0_5s, share_over_4s}, clock_offset_s,
/// joints_rad[], joints_age_s, state, active_command_id, stop_category,
/// stop_reason, faults[], tool{...}, wrench{...}, remote_alive, drives[]: per
/// joint {joint, node_id, state, powered} as the drive reported itself, state
/// in CiA 402 snake case or "unknown" while the drive is silent).
nlohmann::json status_json(const ground_link::GroundLink& link);
/// The remote's queue (a chain) in one line: "running 5 trajectory | queued
/// 6 7 8", "" when it holds nothing (watch, display).
std::string queue_text(const protocol::StatusReport& status);

}  // namespace foresight::session
