#pragma once
// `foresight-remote check`: is this cabinet fit to run before the first
// motion? A checklist, each item PASS, WARN, FAIL or SKIP with the reason:
//
//   config          remote.yaml (hardware, tool, controller sections) loads
//   robot model     the URDF parses; drives match its joints in chain order
//   bus budget      worst-case load of every CAN bus (hw::compute_bus_loads)
//   CAN <bus>       real: the SocketCAN interface exists, is a CAN device, is
//                   up, ERROR-ACTIVE, at the configured bit rate, restart-ms
//                   set (from `ip -details -json link show IF`); a kernel
//                   without CAN support says so. --sim: the simulated drives
//                   and F/T sensor answer on the mock buses (DriveSystem::
//                   configure over them: boot-up, SDO, PDO mapping).
//   tool            the LST's Modbus endpoint answers a status read (short
//                   timeout, no retries); --sim: the simulated LstServer.
//   rt priority     SCHED_FIFO at the loop's priority is granted (a test
//                   thread asks for it); RLIMIT_RTPRIO shown
//   memory lock     RLIMIT_MEMLOCK unlimited, or mlockall works
//   kernel          PREEMPT_RT (/sys/kernel/realtime), isolated CPUs (WARN only)
//   clock           adjtimex: STA_UNSYNC clear (WARN when unsynchronised: the
//                   ground measures the offset anyway, but journal times drift)
//   journal         the journal's folder exists and is writable
//   DDS security    when a folder is given: the files are there, the identity's
//                   certificate is signed by the CA, within its validity, and
//                   matches its key (SKIP when security is not configured)
//
// Unfit = any FAIL (exit 1). With --sim the real-time items (rt priority,
// memory lock) are WARN instead of FAIL: the simulated site runs without them.
//
// Set-up code only (blocks for up to a few seconds, allocates); never call it
// from the control cycle. run_check never throws for a bad configuration: the
// error becomes a FAIL item.

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "foresight/hw/lst_tool.hpp"
#include "foresight/protocol/network.hpp"

namespace foresight::daemon {

enum class CheckResult { Pass, Warn, Fail, Skip };
const char* to_string(CheckResult r) noexcept;  ///< "PASS", "WARN", "FAIL", "SKIP"

struct CheckItem {
  std::string name;  ///< "config", "CAN arm_a (can0)", ...
  CheckResult result = CheckResult::Skip;
  std::string why;   ///< what was found, and what to do when it is not PASS
};

struct CheckOptions {
  std::string remote_yaml;            ///< config/remote.yaml (robot.urdf, scene.yaml, oru.yaml beside it)
  std::string urdf;                   ///< default: robot.urdf beside remote_yaml
  bool sim = false;                   ///< check the simulated site (--sim) instead of CAN + Modbus hardware
  std::string security_dir;           ///< DDS security folder (--security); "" = controller.link.security
  std::string security_identity;      ///< "" = controller.link.identity (remote)
  std::string journal_path;           ///< overrides controller.journal.path ("" = the config's)
  double tool_timeout_s = 0.3;        ///< per Modbus attempt, no retries
  int rt_priority = 80;               ///< the control loop's SCHED_FIFO priority (LoopOptions)
};

struct CheckReport {
  std::vector<CheckItem> items;
  bool fit() const noexcept;  ///< no FAIL
  int count(CheckResult r) const noexcept;
  /// One line an item: "FAIL  CAN arm_a (can0)  <why>", then a verdict line.
  std::string text() const;
  /// {"fit":..., "counts":{"pass":n,...}, "items":[{"name","result","why"}]}
  std::string json() const;
  const CheckItem* find(const std::string& name) const noexcept;
};

/// Runs every item. Never throws for configuration or hardware problems.
CheckReport run_check(const CheckOptions& options);

// ---- single items (exposed for tests and for the daemon's own start-up) ------------

/// A SocketCAN interface: `ip_json` is the output of `ip -details -json link
/// show IF` (an array with one object). PASS when it is a CAN device, up,
/// ERROR-ACTIVE (or state absent) and at `bitrate_bps`; WARN when restart-ms
/// is 0 (no automatic bus-off recovery) or the state is ERROR-WARNING; FAIL
/// otherwise (down, BUS-OFF, ERROR-PASSIVE, STOPPED, wrong bit rate, not CAN).
CheckItem assess_can_link(const std::string& name, const std::string& interface, std::uint32_t bitrate_bps,
                          const std::string& ip_json);
/// Looks the interface up on this machine (probes PF_CAN first: a kernel
/// without CAN support is said so) and assesses it.
CheckItem check_can_interface(const std::string& bus_name, const std::string& interface, std::uint32_t bitrate_bps);
/// One status read from the tool at `config`'s endpoint (timeout_s, no retries).
CheckItem check_tool(const hw::LstToolConfig& config, double timeout_s);
CheckItem check_rt_priority(int priority, bool required);
CheckItem check_memlock(bool required);
CheckItem check_kernel();
CheckItem check_clock();
CheckItem check_journal_dir(const std::string& journal_path);
/// The network of controller.link.network on this machine: FAIL naming a
/// missing or down interface, a peer that does not resolve; SKIP when the
/// environment's CYCLONEDDS_URI would win.
CheckItem check_network(const protocol::NetworkSettings& n);
/// `dir` empty: WARN when `insecure` (controller.link.insecure: true), SKIP
/// with `sim`, else FAIL (the daemon would refuse to start).
CheckItem check_security(const std::string& dir, const std::string& identity, bool sim = true, bool insecure = false);

/// The subcommand: prints the report (text, or one JSON object with `json`)
/// on `out`; returns 0 when fit, 1 when not.
int run_check_command(const CheckOptions& options, bool json, std::ostream& out);

}  // namespace foresight::daemon
