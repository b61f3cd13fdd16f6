#include "foresight/hw/lst_tool.hpp"

#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>

#include "foresight/common/error.hpp"

namespace foresight::hw {

// ---- error category ------------------------------------------------------------

namespace {

class LstCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "lst_tool"; }
  std::string message(int ev) const override {
    switch (static_cast<LstError>(ev)) {
      case LstError::IllegalFunction: return "illegal function (Modbus exception 01)";
      case LstError::IllegalDataAddress: return "illegal data address (Modbus exception 02)";
      case LstError::IllegalDataValue: return "illegal data value (Modbus exception 03)";
      case LstError::DeviceFailure: return "device failure (Modbus exception 04)";
      case LstError::Acknowledge: return "acknowledge (Modbus exception 05)";
      case LstError::DeviceBusy: return "device busy (Modbus exception 06)";
      case LstError::NegativeAcknowledge: return "negative acknowledge (Modbus exception 07)";
      case LstError::MemoryParity: return "memory parity error (Modbus exception 08)";
      case LstError::GatewayPathUnavailable: return "gateway path unavailable (Modbus exception 0A)";
      case LstError::GatewayTargetFailed: return "gateway target failed to respond (Modbus exception 0B)";
      case LstError::Timeout: return "timeout: no response from the tool";
      case LstError::ConnectionFailed: return "connection failed";
      case LstError::BadResponse: return "bad response (CRC, length, unit or exception code)";
      case LstError::InvalidArgument: return "invalid argument";
      case LstError::WaitTimeout: return "the tool did not reach the expected state in time";
      case LstError::ToolFault: return "the tool reports a fault";
      case LstError::TorqueLimitReached: return "the tool stopped at its torque limit before the turns were done";
      case LstError::RunInterrupted: return "the run ended before reaching its goal";
    }
    return "unknown lst_tool error " + std::to_string(ev);
  }
};

}  // namespace

const std::error_category& lst_error_category() noexcept {
  static const LstCategory category;
  return category;
}

std::error_code make_error_code(LstError e) noexcept { return {static_cast<int>(e), lst_error_category()}; }

// ---- status ----------------------------------------------------------------------

LstStatus decode_status(const std::uint16_t (&in)[lst::kNumInput]) noexcept {
  LstStatus s;
  s.status_bits = in[lst::kInStatus];
  s.fault_bits = in[lst::kInFault];
  const auto turns_counts = static_cast<std::int32_t>((static_cast<std::uint32_t>(in[lst::kInTurnsHi]) << 16) |
                                                      static_cast<std::uint32_t>(in[lst::kInTurnsLo]));
  s.turns = turns_counts * lst::kTurnsPerCount;
  s.torque_nm = static_cast<std::int16_t>(in[lst::kInTorque]) * lst::kTorqueNmPerCount;
  s.speed_rad_s = static_cast<std::int16_t>(in[lst::kInSpeed]) * lst::kSpeedRadSPerCount;
  s.alive = in[lst::kInAlive];
  s.peak_torque_nm = static_cast<std::int16_t>(in[lst::kInPeakTorque]) * lst::kTorqueNmPerCount;
  return s;
}

std::string LstStatus::describe() const {
  std::string out;
  auto add = [&out](bool on, const std::string& name) {
    if (!on) return;
    if (!out.empty()) out.push_back(' ');
    out.append(name);
  };
  add(ready(), "ready");
  add(running(), "running");
  add(latched(), "latched");
  add(unlatched(), "unlatched");
  add(torque_reached(), "torque-reached");
  if (fault()) {
    std::string f;
    if (jammed()) f += "jam";
    if (latch_fault()) {
      if (!f.empty()) f.push_back(',');
      f.append("latch");
    }
    add(true, "fault[" + f + "]");
  }
  return out.empty() ? "(no status bits)" : out;
}

// ---- client -------------------------------------------------------------------------

namespace {

void sleep_s(double s) {
  if (s > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(s));
}

ModbusErrors lst_errors() {
  ModbusErrors e;
  e.category = &lst_error_category();
  for (int code : {1, 2, 3, 4, 5, 6, 7, 8, 10, 11}) e.exception[code] = code;  // LstError values = exception codes
  e.timeout = static_cast<int>(LstError::Timeout);
  e.connection_failed = static_cast<int>(LstError::ConnectionFailed);
  e.bad_response = static_cast<int>(LstError::BadResponse);
  e.invalid_argument = static_cast<int>(LstError::InvalidArgument);
  return e;
}

const LstToolConfig& validated(const LstToolConfig& c) {
  validate(c);
  return c;
}

}  // namespace

ModbusLink LstToolConfig::link() const {
  ModbusLink l;
  l.transport = transport == Transport::Tcp ? ModbusLink::Transport::Tcp : ModbusLink::Transport::Rtu;
  l.host = host;
  l.port = port;
  l.device = device;
  l.baud = baud;
  l.parity = parity;
  l.data_bits = data_bits;
  l.stop_bits = stop_bits;
  l.unit_id = unit_id;
  l.response_timeout_s = response_timeout_s;
  l.retries = retries;
  l.reconnect_delay_s = reconnect_delay_s;
  return l;
}

LstTool::LstTool(LstToolConfig config)
    : config_(std::move(config)),
      modbus_(validated(config_).link(), lst_errors(), config_.source, config_.line, "tool") {}

LstTool::~LstTool() = default;

std::error_code LstTool::connect() { return modbus_.connect(); }
void LstTool::disconnect() noexcept { modbus_.disconnect(); }

std::error_code LstTool::read_input_registers(int address, int count, std::uint16_t* dest) {
  return modbus_.read_input_registers(address, count, dest);
}
std::error_code LstTool::read_holding_registers(int address, int count, std::uint16_t* dest) {
  return modbus_.read_holding_registers(address, count, dest);
}
std::error_code LstTool::write_register(int address, std::uint16_t value) { return modbus_.write_register(address, value); }
std::error_code LstTool::read_coils(int address, int count, std::uint8_t* dest) {
  return modbus_.read_coils(address, count, dest);
}
std::error_code LstTool::write_coil(int address, bool value) { return modbus_.write_coil(address, value); }
std::error_code LstTool::read_discrete_inputs(int address, int count, std::uint8_t* dest) {
  return modbus_.read_discrete_inputs(address, count, dest);
}

std::error_code LstTool::read_status(LstStatus& out) {
  std::uint16_t regs[lst::kNumInput] = {};
  if (auto ec = read_input_registers(0, lst::kNumInput, regs)) return ec;
  out = decode_status(regs);
  return {};
}

std::error_code LstTool::read_setpoints(double& speed_rad_s, double& torque_limit_nm) {
  std::uint16_t regs[lst::kNumHolding] = {};
  if (auto ec = read_holding_registers(0, lst::kNumHolding, regs)) return ec;
  speed_rad_s = regs[lst::kHoldSpeedCmd] * lst::kSpeedRadSPerCount;
  torque_limit_nm = regs[lst::kHoldTorqueLimit] * lst::kTorqueNmPerCount;
  return {};
}

namespace {

bool to_counts(double value, double max, double per_count, std::uint16_t& counts) {
  if (!std::isfinite(value) || value < 0.0 || value > max) return false;
  const double c = std::round(value / per_count);
  if (c > 65535.0) return false;
  counts = static_cast<std::uint16_t>(c);
  return true;
}

}  // namespace

std::error_code LstTool::set_speed(double speed_rad_s) {
  std::uint16_t counts = 0;
  if (!to_counts(speed_rad_s, config_.max_speed_rad_s, lst::kSpeedRadSPerCount, counts))
    return fail("set speed " + std::to_string(speed_rad_s) + " rad/s (allowed 0.." +
                    std::to_string(config_.max_speed_rad_s) + ")", LstError::InvalidArgument);
  return write_register(lst::kHoldSpeedCmd, counts);
}

std::error_code LstTool::set_torque_limit(double torque_nm) {
  std::uint16_t counts = 0;
  if (!to_counts(torque_nm, config_.max_torque_nm, lst::kTorqueNmPerCount, counts))
    return fail("set torque limit " + std::to_string(torque_nm) + " N*m (allowed 0.." +
                    std::to_string(config_.max_torque_nm) + ")", LstError::InvalidArgument);
  return write_register(lst::kHoldTorqueLimit, counts);
}

std::error_code LstTool::set_direction(LstDirection direction) {
  return write_coil(lst::kCoilDirection, direction == LstDirection::Loosen);
}

std::error_code LstTool::run(LstDirection direction, double speed_rad_s, double torque_limit_nm) {
  std::uint16_t regs[lst::kNumHolding] = {};
  if (!to_counts(speed_rad_s, config_.max_speed_rad_s, lst::kSpeedRadSPerCount, regs[lst::kHoldSpeedCmd]))
    return fail("run: speed " + std::to_string(speed_rad_s) + " rad/s (allowed 0.." +
                    std::to_string(config_.max_speed_rad_s) + ")", LstError::InvalidArgument);
  if (!to_counts(torque_limit_nm, config_.max_torque_nm, lst::kTorqueNmPerCount, regs[lst::kHoldTorqueLimit]))
    return fail("run: torque limit " + std::to_string(torque_limit_nm) + " N*m (allowed 0.." +
                    std::to_string(config_.max_torque_nm) + ")", LstError::InvalidArgument);
  if (auto ec = modbus_.write_registers(0, lst::kNumHolding, regs)) return ec;
  std::uint8_t coils[2] = {};
  coils[lst::kCoilRun] = 1;
  coils[lst::kCoilDirection] = direction == LstDirection::Loosen ? 1 : 0;
  return modbus_.write_coils(0, 2, coils);
}

std::error_code LstTool::start() { return write_coil(lst::kCoilRun, true); }
std::error_code LstTool::stop() { return write_coil(lst::kCoilRun, false); }
std::error_code LstTool::latch() { return write_coil(lst::kCoilLatch, true); }
std::error_code LstTool::unlatch() { return write_coil(lst::kCoilLatch, false); }
std::error_code LstTool::reset_fault() { return write_coil(lst::kCoilFaultReset, true); }
std::error_code LstTool::reset_turns() { return write_coil(lst::kCoilTurnsReset, true); }

std::error_code LstTool::wait_for(const std::function<bool(const LstStatus&)>& done, double timeout_s,
                                  LstStatus& last, double poll_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    if (auto ec = read_status(last)) return ec;
    if (done(last)) return {};
    if (last.fault()) return fail("wait: " + last.describe(), LstError::ToolFault);
    if (std::chrono::steady_clock::now() >= deadline)
      return fail("wait " + std::to_string(timeout_s) + " s, last status: " + last.describe(), LstError::WaitTimeout);
    sleep_s(poll_s);
  }
}

std::error_code LstTool::loosen(double turns, double torque_limit_nm, double speed_rad_s, double timeout_s,
                                RunResult& result) {
  result = RunResult{};
  if (!std::isfinite(turns) || !(turns > 0.0) || !(timeout_s > 0.0))
    return fail("loosen " + std::to_string(turns) + " turns", LstError::InvalidArgument);
  if (auto ec = reset_turns()) return ec;
  if (auto ec = run(LstDirection::Loosen, speed_rad_s, torque_limit_nm)) return ec;
  const double goal = -turns;
  std::error_code ec = wait_for(
      [goal](const LstStatus& st) { return st.turns <= goal || st.torque_reached() || !st.running(); }, timeout_s,
      result.last, 0.005);
  // Always try to clear RUN, whatever happened; the first error wins.
  const std::error_code stop_ec = stop();
  result.turns = result.last.turns;
  result.peak_torque_nm = result.last.peak_torque_nm;
  result.torque_reached = result.last.torque_reached();
  if (ec) return ec;
  if (stop_ec) return stop_ec;
  if (result.last.fault()) return fail("loosen: " + result.last.describe(), LstError::ToolFault);
  if (result.turns <= goal) return {};
  if (result.torque_reached) {
    std::ostringstream os;
    os << "loosen " << turns << " turns at " << torque_limit_nm << " N*m: stopped after " << (0.0 - result.turns) + 0.0
       << " turns, peak torque " << result.peak_torque_nm << " N*m";
    return fail(os.str(), LstError::TorqueLimitReached);
  }
  return fail("loosen: " + result.last.describe(), LstError::RunInterrupted);
}

std::error_code LstTool::tighten(double torque_nm, double speed_rad_s, double timeout_s, RunResult& result) {
  result = RunResult{};
  if (!(timeout_s > 0.0)) return fail("tighten", LstError::InvalidArgument);
  if (auto ec = reset_turns()) return ec;
  if (auto ec = run(LstDirection::Tighten, speed_rad_s, torque_nm)) return ec;
  std::error_code ec = wait_for([](const LstStatus& st) { return st.torque_reached() || !st.running(); },
                                timeout_s, result.last, 0.005);
  const std::error_code stop_ec = stop();
  result.turns = result.last.turns;
  result.peak_torque_nm = result.last.peak_torque_nm;
  result.torque_reached = result.last.torque_reached();
  if (ec) return ec;
  if (stop_ec) return stop_ec;
  if (result.last.fault()) return fail("tighten: " + result.last.describe(), LstError::ToolFault);
  if (result.torque_reached) return {};
  return fail("tighten: " + result.last.describe(), LstError::RunInterrupted);
}

}  // namespace foresight::hw
