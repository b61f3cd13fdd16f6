// The `tool:` section of config/remote.yaml (LST over Modbus).
#include <cmath>
#include <sstream>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/hw/lst_tool.hpp"

namespace foresight::hw {

namespace {

using yaml::line_of;

/// A finite number at map[key], `fallback` when absent (the shared wording
/// of yaml::MapReader, and "<path>.<key>: not a finite number").
double finite_or(const yaml::MapReader& m, const char* key, double fallback) {
  const double v = m.get_or<double>(key, fallback);
  if (!std::isfinite(v)) m.fail_key(key, "not a finite number");
  return v;
}

LstToolConfig parse_root(const YAML::Node& root, const std::string& source) {
  const yaml::MapReader top(root, source, "");
  const yaml::MapReader t(yaml::section(top.node(), "tool", source, "the LST power tool"), source, "tool");
  t.check_keys({"modbus", "max_speed_rad_s", "max_torque_nm", "speed_rad_s", "tighten_torque_nm",
                "loosen_torque_limit_nm"});
  const yaml::MapReader m = t.map("modbus", "the link to the tool");
  m.check_keys({"transport", "host", "port", "device", "baud", "parity", "data_bits", "stop_bits", "unit_id",
                "response_timeout_ms", "retries", "reconnect_interval_ms"});
  const YAML::Node& section = t.node();
  const YAML::Node& link = m.node();
  LstToolConfig c;
  c.source = source;
  c.line = t.line();
  const std::string transport = m.get_or<std::string>("transport", "tcp");
  if (transport == "tcp")
    c.transport = LstToolConfig::Transport::Tcp;
  else if (transport == "rtu")
    c.transport = LstToolConfig::Transport::Rtu;
  else
    m.fail_key("transport", "'" + transport + "' is not tcp or rtu");
  c.host = m.get_or<std::string>("host", c.host);
  c.port = m.get_or<int>("port", c.port);
  c.device = m.get_or<std::string>("device", c.device);
  c.baud = m.get_or<int>("baud", c.baud);
  const std::string parity = m.get_or<std::string>("parity", std::string(1, c.parity));
  if (parity.size() != 1) m.fail_key("parity", "'" + parity + "' is not N, E or O");
  c.parity = parity[0];
  c.data_bits = m.get_or<int>("data_bits", c.data_bits);
  c.stop_bits = m.get_or<int>("stop_bits", c.stop_bits);
  c.unit_id = m.get_or<int>("unit_id", c.unit_id);
  c.response_timeout_s = 1e-3 * finite_or(m, "response_timeout_ms", 1e3 * c.response_timeout_s);
  c.retries = m.get_or<int>("retries", c.retries);
  c.reconnect_delay_s = 1e-3 * finite_or(m, "reconnect_interval_ms", 1e3 * c.reconnect_delay_s);
  c.max_speed_rad_s = finite_or(t, "max_speed_rad_s", c.max_speed_rad_s);
  c.max_torque_nm = finite_or(t, "max_torque_nm", c.max_torque_nm);
  c.speed_rad_s = finite_or(t, "speed_rad_s", c.speed_rad_s);
  c.tighten_torque_nm = finite_or(t, "tighten_torque_nm", c.tighten_torque_nm);
  c.loosen_torque_limit_nm = finite_or(t, "loosen_torque_limit_nm", c.loosen_torque_limit_nm);
  // Point a validation error at the offending key's line.
  try {
    validate(c);
  } catch (const InputError& e) {
    const std::string msg = e.what();
    const auto at = msg.find("tool.");
    if (at != std::string::npos) {
      const std::string tail = msg.substr(at);
      const bool in_link = tail.rfind("tool.modbus.", 0) == 0;
      const std::string key = tail.substr(in_link ? 12 : 5, tail.find(':') - (in_link ? 12 : 5));
      const YAML::Node n = in_link ? link[key] : section[key];
      if (n) throw InputError(source, line_of(n), tail);
    }
    throw;
  }
  return c;
}

}  // namespace

void validate(const LstToolConfig& c) {
  auto bad = [&](const std::string& msg) { throw InputError(c.source, c.line, "tool." + msg); };
  if (c.transport == LstToolConfig::Transport::Tcp) {
    if (c.host.empty()) bad("modbus.host: empty");
    if (c.port < 1 || c.port > 65535) bad("modbus.port: " + std::to_string(c.port) + " is outside 1..65535");
    if (c.unit_id < 0 || c.unit_id > 255) bad("modbus.unit_id: " + std::to_string(c.unit_id) + " is outside 0..255");
  } else {
    if (c.device.empty()) bad("modbus.device: empty");
    if (c.baud <= 0) bad("modbus.baud: " + std::to_string(c.baud) + " must be positive");
    if (c.parity != 'N' && c.parity != 'E' && c.parity != 'O')
      bad(std::string("modbus.parity: '") + c.parity + "' is not N, E or O");
    if (c.data_bits < 5 || c.data_bits > 8)
      bad("modbus.data_bits: " + std::to_string(c.data_bits) + " is outside 5..8");
    if (c.stop_bits != 1 && c.stop_bits != 2) bad("modbus.stop_bits: " + std::to_string(c.stop_bits) + " is not 1 or 2");
    if (c.unit_id < 1 || c.unit_id > 247) bad("modbus.unit_id: " + std::to_string(c.unit_id) + " is outside 1..247");
  }
  auto in_range = [&](const char* key, double v, double scale, double max) {
    if (!(v > 0.0) || !(v <= max)) {
      std::ostringstream os;
      os << key << ": " << v * scale << " must lie in (0, " << max * scale << "]";
      bad(os.str());
    }
  };
  in_range("modbus.response_timeout_ms", c.response_timeout_s, 1e3, 60.0);
  if (c.retries < 0 || c.retries > 10) bad("modbus.retries: " + std::to_string(c.retries) + " is outside 0..10");
  if (!(c.reconnect_delay_s >= 0.0) || c.reconnect_delay_s > 60.0)
    bad("modbus.reconnect_interval_ms: must lie in [0, 60000]");
  in_range("max_speed_rad_s", c.max_speed_rad_s, 1.0, 65535 * lst::kSpeedRadSPerCount);
  in_range("max_torque_nm", c.max_torque_nm, 1.0, 65535 * lst::kTorqueNmPerCount);
  in_range("speed_rad_s", c.speed_rad_s, 1.0, c.max_speed_rad_s);
  in_range("tighten_torque_nm", c.tighten_torque_nm, 1.0, c.max_torque_nm);
  in_range("loosen_torque_limit_nm", c.loosen_torque_limit_nm, 1.0, c.max_torque_nm);
}

LstToolConfig parse_lst_tool_config(const std::string& yaml_text, const std::string& source_name) {
  return parse_root(yaml::parse(yaml_text, source_name), source_name);
}

LstToolConfig load_lst_tool_config(const std::string& path) {
  return parse_lst_tool_config(read_text_file(path, "cannot open the remote configuration"), path);
}

}  // namespace foresight::hw
