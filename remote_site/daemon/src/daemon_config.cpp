#include "foresight/remote/daemon_config.hpp"

#include <array>
#include <cmath>

#include "foresight/common/text_file.hpp"
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

using yaml::line_of;

class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}

  [[noreturn]] void fail(const YAML::Node& at, const std::string& msg) const {
    throw InputError(source_, line_of(at), msg);
  }

  void check_keys(const YAML::Node& map, const std::string& where, std::span<const char* const> allowed) const {
    if (!map.IsMap()) fail(map, where + ": expected a map");
    if (const auto key = yaml::unknown_key(map, allowed))
      fail(*key, where + ": unknown key '" + key->as<std::string>() + "' (expected one of: " +
                     yaml::key_list(allowed) + ")");
  }

  double positive(const YAML::Node& map, const char* key, double fallback, const std::string& where) const {
    const double v = yaml::number_or(map, key, fallback, source_, where + ".");
    if (!(v > 0.0) || !std::isfinite(v)) fail(map[key], where + "." + key + ": must be a positive number");
    return v;
  }

  std::string text(const YAML::Node& map, const char* key, const std::string& fallback,
                   const std::string& where) const {
    const YAML::Node n = map[key];
    if (!n) return fallback;
    if (!n.IsScalar()) fail(n, where + "." + key + ": expected a string");
    return n.as<std::string>();
  }

  const std::string& source() const { return source_; }

 private:
  std::string source_;
};

}  // namespace

DaemonConfig parse_daemon_config(const std::string& yaml_text, const std::string& source_name) {
  const YAML::Node root = yaml::parse(yaml_text, source_name);
  DaemonConfig c;
  c.source = source_name;
  const YAML::Node s = root["controller"];
  if (!s) return c;
  const Reader r(source_name);
  c.line = line_of(s);
  static constexpr std::array kTop{"start_tolerance_rad", "link",          "reports",
                                   "journal",             "estop_file",    "tool_poll_hz",
                                   "default_algorithm_timeout_s", "control_lease_s"};
  r.check_keys(s, "controller", kTop);
  c.start_tolerance_rad = r.positive(s, "start_tolerance_rad", c.start_tolerance_rad, "controller");
  c.estop_file = r.text(s, "estop_file", c.estop_file, "controller");
  c.tool_poll_hz = r.positive(s, "tool_poll_hz", c.tool_poll_hz, "controller");
  c.default_algorithm_timeout_s =
      r.positive(s, "default_algorithm_timeout_s", c.default_algorithm_timeout_s, "controller");
  c.control_lease_s = r.positive(s, "control_lease_s", c.control_lease_s, "controller");

  if (const YAML::Node link = s["link"]) {
    static constexpr std::array kLink{"loss_timeout_s", "loss_policy"};
    r.check_keys(link, "controller.link", kLink);
    c.link_loss_timeout_s = r.positive(link, "loss_timeout_s", c.link_loss_timeout_s, "controller.link");
    const std::string policy = r.text(link, "loss_policy", "finish_and_hold", "controller.link");
    if (policy == "finish_and_hold") {
      c.link_loss_policy = LinkLossPolicy::FinishAndHold;
    } else if (policy == "stop") {
      c.link_loss_policy = LinkLossPolicy::Stop;
    } else {
      r.fail(link["loss_policy"], "controller.link.loss_policy: '" + policy +
                                      "' is not a policy (expected finish_and_hold or stop)");
    }
  }
  if (const YAML::Node rep = s["reports"]) {
    static constexpr std::array kRep{"joint_state_hz", "wrench_hz", "tool_hz", "status_hz"};
    r.check_keys(rep, "controller.reports", kRep);
    c.reports.joint_state_hz = r.positive(rep, "joint_state_hz", c.reports.joint_state_hz, "controller.reports");
    c.reports.wrench_hz = r.positive(rep, "wrench_hz", c.reports.wrench_hz, "controller.reports");
    c.reports.tool_hz = r.positive(rep, "tool_hz", c.reports.tool_hz, "controller.reports");
    c.reports.status_hz = r.positive(rep, "status_hz", c.reports.status_hz, "controller.reports");
  }
  if (const YAML::Node j = s["journal"]) {
    static constexpr std::array kJ{"path", "max_mb", "keep_files", "telemetry_hz"};
    r.check_keys(j, "controller.journal", kJ);
    c.journal.path = r.text(j, "path", c.journal.path, "controller.journal");
    if (c.journal.path.empty()) r.fail(j["path"], "controller.journal.path: must not be empty");
    c.journal.max_mb = r.positive(j, "max_mb", c.journal.max_mb, "controller.journal");
    c.journal.keep_files = yaml::integer_or(j, "keep_files", c.journal.keep_files, source_name, "controller.journal.");
    if (c.journal.keep_files < 1 || c.journal.keep_files > 100)
      r.fail(j["keep_files"], "controller.journal.keep_files: must be in 1..100");
    c.journal.telemetry_hz = r.positive(j, "telemetry_hz", c.journal.telemetry_hz, "controller.journal");
  }
  return c;
}

DaemonConfig load_daemon_config(const std::string& remote_yaml_path) {
  return parse_daemon_config(read_text_file(remote_yaml_path, "cannot open the remote configuration"),
                             remote_yaml_path);
}

}  // namespace foresight::remote
