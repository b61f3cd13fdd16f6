#include "foresight/remote/daemon_config.hpp"

#include <cmath>

#include "foresight/common/text_file.hpp"
#include "foresight/common/trajectory.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight::remote {

const char* to_string(LinkLossPolicy policy) noexcept {
  switch (policy) {
    case LinkLossPolicy::FinishAndHold: return "finish_and_hold";
    case LinkLossPolicy::Stop: return "stop";
  }
  return "?";
}

namespace {

/// A positive, finite number at map[key], `fallback` when absent.
double positive(const yaml::MapReader& m, const char* key, double fallback) {
  const double v = m.get_or<double>(key, fallback);
  if (!(v > 0.0) || !std::isfinite(v)) m.fail_key(key, "must be a positive number");
  return v;
}

}  // namespace

DaemonConfig parse_daemon_config(const std::string& yaml_text, const std::string& source_name) {
  const YAML::Node root = yaml::parse(yaml_text, source_name);
  DaemonConfig c;
  c.source = source_name;
  if (!root["controller"]) return c;
  const yaml::MapReader s(root["controller"], source_name, "controller");
  c.line = s.line();
  s.check_keys({"start_tolerance_rad", "link", "reports", "journal", "estop_file", "tool_poll_hz",
                "default_algorithm_timeout_s", "control_lease_s"});
  c.start_tolerance_rad = positive(s, "start_tolerance_rad", c.start_tolerance_rad);
  if (c.start_tolerance_rad > kMaxStartToleranceRad)
    s.fail_key("start_tolerance_rad", "must be at most 0.02 rad (a larger start offset would jump the arm: plan an approach "
                                          "segment)");
  c.estop_file = s.get_or<std::string>("estop_file", c.estop_file);
  c.tool_poll_hz = positive(s, "tool_poll_hz", c.tool_poll_hz);
  c.default_algorithm_timeout_s = positive(s, "default_algorithm_timeout_s", c.default_algorithm_timeout_s);
  c.control_lease_s = positive(s, "control_lease_s", c.control_lease_s);

  if (s["link"]) {
    const yaml::MapReader link = s.map("link");
    link.check_keys({"loss_timeout_s", "loss_policy"});
    c.link_loss_timeout_s = positive(link, "loss_timeout_s", c.link_loss_timeout_s);
    const std::string policy = link.get_or<std::string>("loss_policy", "finish_and_hold");
    if (policy == "finish_and_hold") {
      c.link_loss_policy = LinkLossPolicy::FinishAndHold;
    } else if (policy == "stop") {
      c.link_loss_policy = LinkLossPolicy::Stop;
    } else {
      link.fail_key("loss_policy", "'" + policy + "' is not a policy (expected finish_and_hold or stop)");
    }
  }
  if (s["reports"]) {
    const yaml::MapReader rep = s.map("reports");
    rep.check_keys({"joint_state_hz", "wrench_hz", "tool_hz", "status_hz"});
    c.reports.joint_state_hz = positive(rep, "joint_state_hz", c.reports.joint_state_hz);
    c.reports.wrench_hz = positive(rep, "wrench_hz", c.reports.wrench_hz);
    c.reports.tool_hz = positive(rep, "tool_hz", c.reports.tool_hz);
    c.reports.status_hz = positive(rep, "status_hz", c.reports.status_hz);
  }
  if (s["journal"]) {
    const yaml::MapReader j = s.map("journal");
    j.check_keys({"path", "max_mb", "keep_files", "telemetry_hz"});
    c.journal.path = j.get_or<std::string>("path", c.journal.path);
    if (c.journal.path.empty()) j.fail_key("path", "must not be empty");
    c.journal.max_mb = positive(j, "max_mb", c.journal.max_mb);
    c.journal.keep_files = j.get_or<int>("keep_files", c.journal.keep_files);
    if (c.journal.keep_files < 1 || c.journal.keep_files > 100) j.fail_key("keep_files", "must be in 1..100");
    c.journal.telemetry_hz = positive(j, "telemetry_hz", c.journal.telemetry_hz);
  }
  return c;
}

DaemonConfig load_daemon_config(const std::string& remote_yaml_path) {
  return parse_daemon_config(read_text_file(remote_yaml_path, "cannot open the remote configuration"),
                             remote_yaml_path);
}

}  // namespace foresight::remote
