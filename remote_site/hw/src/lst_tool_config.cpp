// The `tool:` section of config/remote.yaml (LST over Modbus).
#include <cmath>
#include <sstream>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"
#include "foresight/hw/lst_tool.hpp"

namespace foresight::hw {

std::string LstToolConfig::describe() const {
  if (transport == Transport::Tcp)
    return "tcp " + host + ":" + std::to_string(port) + " unit " + std::to_string(unit_id);
  return "rtu " + device + " " + std::to_string(baud) + " " + std::to_string(data_bits) + parity +
         std::to_string(stop_bits) + " unit " + std::to_string(unit_id);
}

namespace {

using yaml::line_of;

class ToolParser {
 public:
  ToolParser(std::string source, const YAML::Node& section, std::string prefix)
      : source_(std::move(source)), section_(section), prefix_(std::move(prefix)) {}

  [[noreturn]] void fail(const YAML::Node& at, const std::string& msg) const {
    throw InputError(source_, line_of(at), prefix_ + msg);
  }

  YAML::Node node(const char* key) const { return section_[key]; }

  void check_keys(std::initializer_list<const char*> allowed) const {
    if (const auto key = yaml::unknown_key(section_, allowed))
      fail(*key, key->as<std::string>() + ": unknown key (expected one of: " + yaml::key_list(allowed) + ")");
  }

  double number(const char* key, double fallback) const {
    const double v = yaml::number_or(section_, key, fallback, source_, prefix_);
    if (!std::isfinite(v)) fail(section_[key], std::string(key) + ": not a finite number");
    return v;
  }

  int integer(const char* key, int fallback) const {
    return yaml::integer_or(section_, key, fallback, source_, prefix_);
  }

  std::string text(const char* key, const std::string& fallback) const {
    const YAML::Node n = section_[key];
    if (!n) return fallback;
    if (!n.IsScalar()) fail(n, std::string(key) + ": expected a string");
    return n.Scalar();
  }

 private:
  std::string source_;
  YAML::Node section_;
  std::string prefix_;
};

LstToolConfig parse_root(const YAML::Node& root, const std::string& source) {
  if (!root.IsMap()) throw InputError(source, "expected a map at the top level");
  const YAML::Node section = yaml::section(root, "tool", source, "the LST power tool");
  ToolParser t(source, section, "tool.");
  t.check_keys({"modbus", "max_speed_rad_s", "max_torque_nm", "speed_rad_s", "tighten_torque_nm",
                "loosen_torque_limit_nm"});
  const YAML::Node link = section["modbus"];
  if (!link) throw InputError(source, line_of(section), "tool: missing 'modbus' (the link to the tool)");
  if (!link.IsMap()) throw InputError(source, line_of(link), "tool.modbus: expected a map");
  ToolParser m(source, link, "tool.modbus.");
  m.check_keys({"transport", "host", "port", "device", "baud", "parity", "data_bits", "stop_bits", "unit_id",
                "response_timeout_ms", "retries", "reconnect_interval_ms"});
  LstToolConfig c;
  c.source = source;
  c.line = line_of(section);
  const std::string transport = m.text("transport", "tcp");
  if (transport == "tcp")
    c.transport = LstToolConfig::Transport::Tcp;
  else if (transport == "rtu")
    c.transport = LstToolConfig::Transport::Rtu;
  else
    m.fail(m.node("transport"), "transport: '" + transport + "' is not tcp or rtu");
  c.host = m.text("host", c.host);
  c.port = m.integer("port", c.port);
  c.device = m.text("device", c.device);
  c.baud = m.integer("baud", c.baud);
  const std::string parity = m.text("parity", std::string(1, c.parity));
  if (parity.size() != 1) m.fail(m.node("parity"), "parity: '" + parity + "' is not N, E or O");
  c.parity = parity[0];
  c.data_bits = m.integer("data_bits", c.data_bits);
  c.stop_bits = m.integer("stop_bits", c.stop_bits);
  c.unit_id = m.integer("unit_id", c.unit_id);
  c.response_timeout_s = 1e-3 * m.number("response_timeout_ms", 1e3 * c.response_timeout_s);
  c.retries = m.integer("retries", c.retries);
  c.reconnect_delay_s = 1e-3 * m.number("reconnect_interval_ms", 1e3 * c.reconnect_delay_s);
  c.max_speed_rad_s = t.number("max_speed_rad_s", c.max_speed_rad_s);
  c.max_torque_nm = t.number("max_torque_nm", c.max_torque_nm);
  c.speed_rad_s = t.number("speed_rad_s", c.speed_rad_s);
  c.tighten_torque_nm = t.number("tighten_torque_nm", c.tighten_torque_nm);
  c.loosen_torque_limit_nm = t.number("loosen_torque_limit_nm", c.loosen_torque_limit_nm);
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
