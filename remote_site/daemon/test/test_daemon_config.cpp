// The `controller:` section of remote.yaml: defaults, every key, and bad
// values refused with the file, line and key.
#include <gtest/gtest.h>

#include "foresight/common/error.hpp"
#include "foresight/daemon/daemon_config.hpp"

using namespace foresight;
using namespace foresight::daemon;

namespace {

std::string error_of(const std::string& yaml) {
  try {
    parse_daemon_config(yaml, "r.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

TEST(DaemonConfig, ProjectFileLoads) {
  const DaemonConfig c = load_daemon_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_GT(c.line, 0);
  EXPECT_GT(c.link_loss_timeout_s, 0.0);
  EXPECT_GT(c.reports.joint_state_hz, 0.0);
}

TEST(DaemonConfig, ThePayloadIsTheSimulatedTruth) {
  // The shipped values are the simulated plant's (config/scene.yaml, the URDF):
  // the demo's compensation is right; identify_payload finds the same.
  const DaemonConfig c = load_daemon_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  ASSERT_TRUE(c.payload.configured);
  EXPECT_DOUBLE_EQ(c.payload.tool_mass_kg, 2.6);
  EXPECT_DOUBLE_EQ(c.payload.tool_com_m[2], 0.125);
  EXPECT_DOUBLE_EQ(c.payload.oru_mass_kg, 5.0);
  EXPECT_DOUBLE_EQ(c.payload.oru_com_m[2], 0.405);
  EXPECT_DOUBLE_EQ(c.payload.tare_max_force_n, 10.0);
}

TEST(DaemonConfig, BadPayloadValuesNameTheFileAndKey) {
  const std::string head = "controller:\n  payload:\n";
  EXPECT_EQ(error_of(head + "    tool: {mass_kg: -1, com_m: [0, 0, 0.1]}\n"),
            "r.yaml:3: controller.payload.tool.mass_kg: -1 is outside [0, 30] kg");
  EXPECT_EQ(error_of(head + "    tool: {mass_kg: 2, com_m: [0, 1.5, 0.1]}\n"),
            "r.yaml:3: controller.payload.tool.com_m: element 2 (1.5) is outside [-1, 1] m (sensor frame)");
  EXPECT_EQ(error_of(head + "    tool: {mass_kg: 2, com_m: [0, 0]}\n"),
            "r.yaml:3: 'controller.payload.tool.com_m' must be a list of 3 numbers");
  EXPECT_EQ(error_of(head + "    oru: {mass_kg: 5, com_m: [0, 0, 0.4]}\n"),
            "r.yaml:3: controller.payload: missing 'tool' (the tool's mass and centre of mass)");
  EXPECT_EQ(error_of(head + "    tool: {mass_kg: 20, com_m: [0, 0, 0.1]}\n    oru: {mass_kg: 15, com_m: [0, 0, 0.4]}\n"),
            "r.yaml:4: controller.payload.oru: tool and ORU together exceed 30 kg (the F/T sensor's full scale)");
  EXPECT_EQ(error_of(head + "    tool: {mass_kg: 2, com_m: [0, 0, 0.1]}\n    tare_max_force_n: 0\n"),
            "r.yaml:4: controller.payload.tare_max_force_n: 0 is outside [0.5, 100] N");
  EXPECT_EQ(error_of(head + "    tool: {mass_kg: 2, com_m: [0, 0, 0.1], inertia: 1}\n"),
            "r.yaml:3: controller.payload.tool.inertia: unknown key (expected one of: mass_kg, com_m)");
}

TEST(DaemonConfig, DefaultsWhenTheSectionIsAbsent) {
  const DaemonConfig c = parse_daemon_config("cycle_rate_hz: 500\n", "r.yaml");
  EXPECT_EQ(c.line, 0);
  EXPECT_DOUBLE_EQ(c.start_tolerance_rad, 0.01);
  EXPECT_EQ(c.link_loss_policy, LinkLossPolicy::FinishAndHold);
  EXPECT_EQ(c.journal.keep_files, 4);
  EXPECT_TRUE(c.estop_file.empty());
}

TEST(DaemonConfig, EveryKeyIsRead) {
  const DaemonConfig c = parse_daemon_config(
      "controller:\n"
      "  start_tolerance_rad: 0.02\n"
      "  link: {loss_timeout_s: 7.5, loss_policy: stop}\n"
      "  reports: {joint_state_hz: 20, wrench_hz: 25, tool_hz: 2, status_hz: 1}\n"
      "  journal: {path: j.db, max_mb: 8, keep_files: 2, telemetry_hz: 4}\n"
      "  estop_file: /tmp/estop\n"
      "  tool_poll_hz: 3\n"
      "  default_algorithm_timeout_s: 30\n"
      "  control_lease_s: 4\n"
      "  rate_limit: {acceleration_fraction: 2, jerk_per_s: 500}\n"
      "  max_queued_commands: 10\n"
      "  max_chain_length: 5\n"
      "  max_upload_wait_s: 12\n",
      "r.yaml");
  EXPECT_DOUBLE_EQ(c.max_upload_wait_s, 12);
  EXPECT_EQ(c.max_queued_commands, 10u);
  EXPECT_EQ(c.max_chain_length, 5u);
  EXPECT_DOUBLE_EQ(c.start_tolerance_rad, 0.02);
  EXPECT_DOUBLE_EQ(c.link_loss_timeout_s, 7.5);
  EXPECT_EQ(c.link_loss_policy, LinkLossPolicy::Stop);
  EXPECT_DOUBLE_EQ(c.reports.joint_state_hz, 20);
  EXPECT_DOUBLE_EQ(c.reports.wrench_hz, 25);
  EXPECT_DOUBLE_EQ(c.reports.tool_hz, 2);
  EXPECT_DOUBLE_EQ(c.reports.status_hz, 1);
  EXPECT_EQ(c.journal.path, "j.db");
  EXPECT_DOUBLE_EQ(c.journal.max_mb, 8);
  EXPECT_EQ(c.journal.keep_files, 2);
  EXPECT_DOUBLE_EQ(c.journal.telemetry_hz, 4);
  EXPECT_EQ(c.estop_file, "/tmp/estop");
  EXPECT_DOUBLE_EQ(c.tool_poll_hz, 3);
  EXPECT_DOUBLE_EQ(c.default_algorithm_timeout_s, 30);
  EXPECT_DOUBLE_EQ(c.control_lease_s, 4);
  EXPECT_DOUBLE_EQ(c.rate_limit_acceleration_fraction, 2);
  EXPECT_DOUBLE_EQ(c.rate_limit_jerk_per_s, 500);
}

TEST(DaemonConfig, BadValuesNameFileLineAndKey) {
  EXPECT_EQ(error_of("controller:\n  speed: 1\n"),
            "r.yaml:2: controller.speed: unknown key (expected one of: start_tolerance_rad, link, reports, journal, "
            "estop_file, tool_poll_hz, default_algorithm_timeout_s, control_lease_s, rate_limit, max_queued_commands, "
            "max_chain_length, max_upload_wait_s, payload)");
  EXPECT_EQ(error_of("controller:\n  max_upload_wait_s: 0.5\n"),
            "r.yaml:2: controller.max_upload_wait_s: 0.5 is outside [1, 600] s");
  // The status lists every held command: at most the IDL's MAX_QUEUE.
  EXPECT_EQ(error_of("controller:\n  max_queued_commands: 65\n"),
            "r.yaml:2: controller.max_queued_commands: 65 is outside [1, 64] commands");
  EXPECT_EQ(error_of("controller:\n  max_chain_length: 0\n"),
            "r.yaml:2: controller.max_chain_length: 0 is outside [1, 64] commands");
  // The rate limiter: below its planning limit it would act on every motion.
  EXPECT_EQ(error_of("controller:\n  rate_limit: {acceleration_fraction: 0.5}\n"),
            "r.yaml:2: controller.rate_limit.acceleration_fraction: 0.5 is outside [1, 10] x the URDF acceleration "
            "limit");
  EXPECT_EQ(error_of("controller:\n  rate_limit: {compliant_acceleration_fraction: 1.2}\n"),
            "r.yaml:2: controller.rate_limit.compliant_acceleration_fraction: below acceleration_fraction (1.50): the "
            "force loop would be limited harder than stiff motion");
  EXPECT_EQ(error_of("controller:\n  rate_limit: {jerk_per_s: .nan}\n"),
            "r.yaml:2: controller.rate_limit.jerk_per_s: nan is outside [10, 100000] 1/s (x the URDF acceleration "
            "limit)");
  // Issue 25: a start tolerance above 0.02 rad let a trajectory jump the arm.
  EXPECT_EQ(error_of("controller:\n  start_tolerance_rad: 2.5\n"),
            "r.yaml:2: controller.start_tolerance_rad: must be at most 0.02 rad (a larger start offset would jump "
            "the arm: plan an approach segment)");
  EXPECT_EQ(error_of("controller:\n  start_tolerance_rad: 0.0201\n"),
            "r.yaml:2: controller.start_tolerance_rad: must be at most 0.02 rad (a larger start offset would jump "
            "the arm: plan an approach segment)");
  EXPECT_EQ(error_of("controller:\n  link:\n    loss_policy: panic\n"),
            "r.yaml:3: controller.link.loss_policy: 'panic' is not a policy (expected finish_and_hold or stop)");
  EXPECT_EQ(error_of("controller:\n  reports:\n    wrench_hz: -5\n"),
            "r.yaml:3: controller.reports.wrench_hz: -5 is outside [0.1, 1000] Hz");
  // Issue 26: every time and rate has a range (1e300 s overflowed the time
  // arithmetic; NaN passed the old "positive" check's first half).
  EXPECT_EQ(error_of("controller:\n  default_algorithm_timeout_s: 1e300\n"),
            "r.yaml:2: controller.default_algorithm_timeout_s: 1e+300 is outside [0.1, 600] s");
  EXPECT_EQ(error_of("controller:\n  link: {loss_timeout_s: .nan}\n"),
            "r.yaml:2: controller.link.loss_timeout_s: nan is outside [0.05, 3600] s");
  EXPECT_EQ(error_of("controller:\n  journal: {max_mb: 1e300}\n"),
            "r.yaml:2: controller.journal.max_mb: 1e+300 is outside [1, 1000000] MB");
  EXPECT_EQ(error_of("controller:\n  tool_poll_hz: 1e9\n"),
            "r.yaml:2: controller.tool_poll_hz: 1000000000 is outside [0.1, 1000] Hz");
  EXPECT_EQ(error_of("controller:\n  reports:\n    wrench_hz: fast\n"),
            "r.yaml:3: controller.reports.wrench_hz: not a number: 'fast'");
  EXPECT_EQ(error_of("controller:\n  journal: {keep_files: 0}\n"),
            "r.yaml:2: controller.journal.keep_files: 0 is outside [1, 100] files");
  EXPECT_EQ(error_of("controller: 5\n"), "r.yaml:1: controller: expected a map");
  EXPECT_EQ(error_of("controller:\n  journal: {keep_files: many}\n"),
            "r.yaml:2: controller.journal.keep_files: not an integer: 'many'");
  EXPECT_EQ(error_of("controller:\n  estop_file: [a, b]\n"), "r.yaml:2: controller.estop_file: not a string (a list)");
  EXPECT_EQ(error_of("controller:\n  link: 3\n"), "r.yaml:2: controller.link: expected a map");
  // Issue 28: the link's security, network and session settings.
  EXPECT_EQ(error_of("controller:\n  link: {session_idle_s: 1}\n"),
            "r.yaml:2: controller.link.session_idle_s: 1 is outside [10, 604800] s");
  EXPECT_EQ(error_of("controller:\n  link: {insecure: yes please}\n"),
            "r.yaml:2: controller.link.insecure: not true or false: 'yes please'");
  EXPECT_EQ(error_of("controller:\n  link: {identity: ../remote}\n"),
            "r.yaml:2: controller.link.identity: '../remote' is not an identity name (a folder under identities/)");
  EXPECT_EQ(error_of("controller:\n  link:\n    network: {interface: lo, multicast: false, peers: []}\n"),
            "r.yaml:3: controller.link.network.peers: is empty and multicast is off: nothing could be discovered");
  const DaemonConfig c = parse_daemon_config(
      "controller:\n  link:\n    security: sec\n    network: {interface: eth1, peers: [10.42.0.1, 10.42.0.2]}\n",
      "/etc/foresight/remote.yaml");
  EXPECT_EQ(c.security_dir, "/etc/foresight/sec");  // relative to the file
  EXPECT_EQ(c.security_identity, "remote");
  EXPECT_EQ(c.network.interface, "eth1");
  EXPECT_EQ(c.network.peers, (std::vector<std::string>{"10.42.0.1", "10.42.0.2"}));
  EXPECT_EQ(c.network.source, "/etc/foresight/remote.yaml: controller.link.network");
}
