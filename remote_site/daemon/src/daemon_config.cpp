#include "foresight/daemon/daemon_config.hpp"

#include <cmath>
#include <filesystem>
#include <string>

#include "foresight/common/format.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/daemon/algorithm_params.hpp"

namespace foresight::daemon {

const char* to_string(LinkLossPolicy policy) noexcept {
  switch (policy) {
    case LinkLossPolicy::FinishAndHold: return "finish_and_hold";
    case LinkLossPolicy::Stop: return "stop";
  }
  return "?";
}

namespace {

/// A centre of mass: three numbers, each within 1 m of the sensor.
std::array<double, 3> read_com(const yaml::MapReader& m, const char* key) {
  const Eigen::Vector3d v = yaml::read_vector<3>(m[key], m.file(), m.name(key));
  for (int i = 0; i < 3; ++i)
    if (!(std::abs(v[i]) <= 1.0))
      m.fail_key(key, printf_text("element %g (%g) is outside [-1, 1] m (sensor frame)", i + 1.0, v[i]));
  return {v[0], v[1], v[2]};
}

PayloadSettings read_payload(const yaml::MapReader& s) {
  PayloadSettings p;
  const yaml::MapReader pl = s.map("payload");
  pl.check_keys({"tool", "oru", "tare_max_force_n"});
  p.configured = true;
  // The sensor's full scale (327 N) carries about 33 kg: 30 kg at most.
  const yaml::MapReader tool = pl.map("tool", "the tool's mass and centre of mass");
  tool.check_keys({"mass_kg", "com_m"});
  p.tool_mass_kg = tool.get_in("mass_kg", 0.0, 30.0, "kg");
  p.tool_com_m = read_com(tool, "com_m");
  if (pl["oru"]) {
    const yaml::MapReader oru = pl.map("oru");
    oru.check_keys({"mass_kg", "com_m"});
    p.oru_mass_kg = oru.get_in("mass_kg", 0.0, 30.0, "kg");
    p.oru_com_m = read_com(oru, "com_m");
  }
  if (!(p.tool_mass_kg + p.oru_mass_kg <= 30.0))
    pl.fail_key("oru", "tool and ORU together exceed 30 kg (the F/T sensor's full scale)");
  p.tare_max_force_n = pl.get_or_in("tare_max_force_n", p.tare_max_force_n, 0.5, 100.0, "N");
  return p;
}

}  // namespace

DaemonConfig parse_daemon_config(const std::string& yaml_text, const std::string& source_name) {
  const YAML::Node root = yaml::parse(yaml_text, source_name);
  DaemonConfig c;
  c.source = source_name;
  c.network.source = source_name + ": controller.link.network (the default)";
  if (!root["controller"]) return c;
  const yaml::MapReader s(root["controller"], source_name, "controller");
  c.line = s.line();
  c.network.source = source_name + ": controller.link.network (the default)";
  s.check_keys({"start_tolerance_rad", "link", "reports", "journal", "estop_file", "tool_poll_hz",
                "default_algorithm_timeout_s", "control_lease_s", "rate_limit", "max_queued_commands",
                "max_chain_length", "max_upload_wait_s", "payload"});
  c.start_tolerance_rad = s.get_or_in("start_tolerance_rad", c.start_tolerance_rad, 1e-6, 1e6, "rad");
  if (c.start_tolerance_rad > kMaxStartToleranceRad)
    s.fail_key("start_tolerance_rad", "must be at most 0.02 rad (a larger start offset would jump the arm: plan an approach "
                                          "segment)");
  c.estop_file = s.get_or<std::string>("estop_file", c.estop_file);
  // Every rate and time with a range (issue 26: 1e300 s once overflowed the
  // time arithmetic; a rate of 1e9 Hz would spin a thread).
  c.tool_poll_hz = s.get_or_in("tool_poll_hz", c.tool_poll_hz, 0.1, 1000, "Hz");
  c.default_algorithm_timeout_s =
      s.get_or_in("default_algorithm_timeout_s", c.default_algorithm_timeout_s, 0.1, kMaxAlgorithmTimeoutS, "s");
  c.control_lease_s = s.get_or_in("control_lease_s", c.control_lease_s, 0.1, 86400, "s");
  // The status lists every held command: at most the IDL's MAX_QUEUE (64).
  c.max_queued_commands = static_cast<std::size_t>(
      s.get_or_int_in("max_queued_commands", static_cast<long long>(c.max_queued_commands), 1, 64, "commands"));
  c.max_chain_length = static_cast<std::size_t>(
      s.get_or_int_in("max_chain_length", static_cast<long long>(c.max_chain_length), 1, 64, "commands"));
  c.max_upload_wait_s = s.get_or_in("max_upload_wait_s", c.max_upload_wait_s, 1.0, 600.0, "s");

  if (s["payload"]) c.payload = read_payload(s);
  if (s["rate_limit"]) {
    // The ranges the controller takes (ControllerConfig); below 1x the limiter
    // would act on every planned motion.
    const yaml::MapReader rl = s.map("rate_limit");
    rl.check_keys({"acceleration_fraction", "jerk_per_s", "compliant_acceleration_fraction"});
    c.rate_limit_acceleration_fraction = rl.get_or_in("acceleration_fraction", c.rate_limit_acceleration_fraction, 1.0,
                                                      10.0, "x the URDF acceleration limit");
    c.rate_limit_jerk_per_s =
        rl.get_or_in("jerk_per_s", c.rate_limit_jerk_per_s, 10.0, 100000.0, "1/s (x the URDF acceleration limit)");
    c.rate_limit_compliant_acceleration_fraction =
        rl.get_or_in("compliant_acceleration_fraction", c.rate_limit_compliant_acceleration_fraction, 1.0, 100.0,
                     "x the URDF acceleration limit");
    if (c.rate_limit_compliant_acceleration_fraction < c.rate_limit_acceleration_fraction)
      rl.fail_key("compliant_acceleration_fraction",
                  "below acceleration_fraction (" + fixed(c.rate_limit_acceleration_fraction, 2) +
                      "): the force loop would be limited harder than stiff motion");
  }
  if (s["link"]) {
    const yaml::MapReader link = s.map("link");
    link.check_keys({"loss_timeout_s", "loss_policy", "security", "identity", "insecure", "network", "session_idle_s"});
    c.session_idle_s = link.get_or_in("session_idle_s", c.session_idle_s, 10, 7 * 86400, "s");
    if (link["network"]) c.network = protocol::read_network(link.map("network"));
    c.link_loss_timeout_s = link.get_or_in("loss_timeout_s", c.link_loss_timeout_s, 0.05, 3600, "s");
    const std::string policy = link.get_or<std::string>("loss_policy", "finish_and_hold");
    if (policy == "finish_and_hold") {
      c.link_loss_policy = LinkLossPolicy::FinishAndHold;
    } else if (policy == "stop") {
      c.link_loss_policy = LinkLossPolicy::Stop;
    } else {
      link.fail_key("loss_policy", "'" + policy + "' is not a policy (expected finish_and_hold or stop)");
    }
    const protocol::LinkSecuritySettings sec = protocol::read_link_security(link, c.security_identity);
    c.security_dir = sec.dir;
    c.security_identity = sec.identity;
    c.insecure = link.get_or<bool>("insecure", false);
    if (c.insecure && !c.security_dir.empty())
      link.fail_key("insecure", "contradicts link.security '" + link.get_or<std::string>("security", "") +
                                    "': say one or the other");
  }
  if (s["reports"]) {
    const yaml::MapReader rep = s.map("reports");
    rep.check_keys({"joint_state_hz", "wrench_hz", "tool_hz", "status_hz"});
    c.reports.joint_state_hz = rep.get_or_in("joint_state_hz", c.reports.joint_state_hz, 0.1, 1000, "Hz");
    c.reports.wrench_hz = rep.get_or_in("wrench_hz", c.reports.wrench_hz, 0.1, 1000, "Hz");
    c.reports.tool_hz = rep.get_or_in("tool_hz", c.reports.tool_hz, 0.1, 1000, "Hz");
    c.reports.status_hz = rep.get_or_in("status_hz", c.reports.status_hz, 0.1, 1000, "Hz");
  }
  if (s["journal"]) {
    const yaml::MapReader j = s.map("journal");
    j.check_keys({"path", "max_mb", "keep_files", "telemetry_hz"});
    c.journal.path = j.get_or<std::string>("path", c.journal.path);
    if (c.journal.path.empty()) j.fail_key("path", "must not be empty");
    c.journal.max_mb = j.get_or_in("max_mb", c.journal.max_mb, 1, 1e6, "MB");
    c.journal.keep_files = static_cast<int>(j.get_or_int_in("keep_files", c.journal.keep_files, 1, 100, "files"));
    c.journal.telemetry_hz = j.get_or_in("telemetry_hz", c.journal.telemetry_hz, 0.1, 1000, "Hz");
  }
  return c;
}

DaemonConfig load_daemon_config(const std::string& remote_yaml_path) {
  return parse_daemon_config(read_text_file(remote_yaml_path, "cannot open the remote configuration"),
                             remote_yaml_path);
}

}  // namespace foresight::daemon
