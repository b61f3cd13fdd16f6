#pragma once
// The `controller:` section of config/remote.yaml: what the daemon
// foresight-remote does above the hardware (which config/remote.yaml's other
// sections describe): the link-loss policy, report rates, the journal, the
// E-stop input of the simulated cabinet, trajectory start tolerance.
// Set-up code only: throws InputError "<file>:<line>: controller.<key> ...".

#include <array>
#include <cstddef>
#include <string>

#include "foresight/protocol/network.hpp"

namespace foresight::daemon {

enum class LinkLossPolicy {
  FinishAndHold,  ///< a committed motion runs to its end, then the arm holds
  Stop,           ///< controlled stop (category 2) at once, the arm holds powered
};
const char* to_string(LinkLossPolicy policy) noexcept;

struct ReportRates {
  double joint_state_hz = 50.0;
  double wrench_hz = 50.0;
  double tool_hz = 5.0;
  double status_hz = 2.0;
};

struct JournalSettings {
  std::string path = "foresight-journal.db";  ///< relative to the working directory; --journal overrides
  double max_mb = 64.0;                       ///< rotate past this size
  int keep_files = 4;                         ///< rotated files kept
  double telemetry_hz = 10.0;                 ///< telemetry rows per second
};

/// `controller.payload`: what hangs on the wrist F/T sensor (docs/control.md
/// "Payload"). The tool's mass and centre of mass (sensor frame), the
/// carried ORU's as the tool holds it (sensor frame), and the largest
/// compensated force a tare accepts (out of contact).
struct PayloadSettings {
  bool configured = false;                     ///< the section is present (then `tool` is required)
  double tool_mass_kg = 0.0;
  std::array<double, 3> tool_com_m{};
  double oru_mass_kg = 0.0;                    ///< 0: no ORU configured (its weight is not compensated)
  std::array<double, 3> oru_com_m{};
  double tare_max_force_n = 10.0;
};

struct DaemonConfig {
  std::string source;                     ///< the file, for messages
  int line = 0;                           ///< line of `controller:`
  double start_tolerance_rad = 0.01;      ///< a trajectory must start this close to the arm, every joint
  double link_loss_timeout_s = 3.0;       ///< no ground heartbeat this long: the link is lost
  LinkLossPolicy link_loss_policy = LinkLossPolicy::FinishAndHold;
  /// DDS Security on the link (`link.security`: the folder made by
  /// make_dds_security.sh, relative to this file; --security overrides) and
  /// this side's identity in it. Empty: plain DDS, which the daemon accepts
  /// only with --sim or `link.insecure: true` (said in so many words).
  std::string security_dir;
  std::string security_identity = "remote";
  bool insecure = false;
  /// `link.network`: the DDS interface, unicast peers and multicast (the
  /// default: one machine, loopback). A user's CYCLONEDDS_URI wins.
  protocol::NetworkSettings network;
  /// `link.session_idle_s`: a ground session without a command this long is
  /// forgotten and its commands refused from then on (remote_link::Config).
  double session_idle_s = 3600.0;
  ReportRates reports;
  JournalSettings journal;
  std::string estop_file;                 ///< E-stop (category 0) while this file exists; "" = no such input
  double tool_poll_hz = 5.0;              ///< LST status reads when the tool is idle
  double default_algorithm_timeout_s = 60.0;
  /// A ground session holding control that has sent nothing for this long,
  /// with nothing of its own running, may be superseded by another's
  /// TAKE_CONTROL (a commander that crashed does not lock the robot).
  double control_lease_s = 10.0;
  /// The real-time rate limiter on stiff motion (control::ControllerConfig,
  /// docs/control.md "The rate limiter"): acceleration as a multiple of the
  /// URDF limit, jerk as a multiple of it per second.
  double rate_limit_acceleration_fraction = 1.5;
  double rate_limit_jerk_per_s = 1000.0;
  /// Inside the force loop of compliant modes (with anti-windup), at least
  /// the stiff fraction.
  double rate_limit_compliant_acceleration_fraction = 10.0;
  /// Commands the remote holds at once (running + queued; the status lists
  /// them all: at most the IDL's MAX_QUEUE), and the longest chain of
  /// commands following each other (after_command_id).
  std::size_t max_queued_commands = 32;
  std::size_t max_chain_length = 32;
  /// The longest a RUN that overtook its upload waits for it to commit
  /// (RunTrajectory.upload_wait_s is capped here): past it the RUN FAILS.
  double max_upload_wait_s = 60.0;
  PayloadSettings payload;
};

/// Reads the optional `controller:` section (defaults when absent). Unknown
/// keys, wrong types, non-positive rates and unknown policies are refused.
DaemonConfig load_daemon_config(const std::string& remote_yaml_path);
DaemonConfig parse_daemon_config(const std::string& yaml_text, const std::string& source_name);

}  // namespace foresight::daemon
