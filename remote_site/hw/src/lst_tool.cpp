#include "foresight/hw/lst_tool.hpp"

#include <modbus/modbus.h>

#include <cerrno>
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

std::error_code map_errno(int err) {
  switch (err) {
    case EMBXILFUN: return LstError::IllegalFunction;
    case EMBXILADD: return LstError::IllegalDataAddress;
    case EMBXILVAL: return LstError::IllegalDataValue;
    case EMBXSFAIL: return LstError::DeviceFailure;
    case EMBXACK: return LstError::Acknowledge;
    case EMBXSBUSY: return LstError::DeviceBusy;
    case EMBXNACK: return LstError::NegativeAcknowledge;
    case EMBXMEMPAR: return LstError::MemoryParity;
    case EMBXGPATH: return LstError::GatewayPathUnavailable;
    case EMBXGTAR: return LstError::GatewayTargetFailed;
    case ETIMEDOUT: return LstError::Timeout;
    case EMBBADCRC:
    case EMBBADDATA:
    case EMBBADEXC:
    case EMBUNKEXC:
    case EMBBADSLAVE: return LstError::BadResponse;
    case EMBMDATA: return LstError::InvalidArgument;
    default: return LstError::ConnectionFailed;  // ECONNRESET, EPIPE, EBADF, ECONNREFUSED, EIO ...
  }
}

bool is_exception(std::error_code ec) {
  return ec.category() == lst_error_category() && ec.value() >= 1 && ec.value() <= 11;
}

void sleep_s(double s) {
  if (s > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(s));
}

std::string range(int address, int count) {
  return count == 1 ? std::to_string(address) : std::to_string(address) + ".." + std::to_string(address + count - 1);
}

}  // namespace

LstTool::LstTool(LstToolConfig config) : config_(std::move(config)) {
  validate(config_);
  if (config_.transport == LstToolConfig::Transport::Tcp)
    ctx_ = modbus_new_tcp(config_.host.c_str(), config_.port);
  else
    ctx_ = modbus_new_rtu(config_.device.c_str(), config_.baud, config_.parity, config_.data_bits, config_.stop_bits);
  if (!ctx_)
    throw InputError(config_.source, config_.line,
                     "tool: cannot create the Modbus context for " + config_.describe() + ": " + modbus_strerror(errno));
  modbus_set_slave(ctx_, config_.unit_id);
  const double t = config_.response_timeout_s;
  const auto sec = static_cast<std::uint32_t>(t);
  const auto usec = static_cast<std::uint32_t>(std::lround((t - sec) * 1e6));
  modbus_set_response_timeout(ctx_, sec, usec);
  // Bytes inside one response must follow each other closely; a stalled
  // half-response ends in a timeout too.
  modbus_set_byte_timeout(ctx_, sec, usec);
}

LstTool::~LstTool() {
  close_link();
  if (ctx_) modbus_free(ctx_);
}

std::error_code LstTool::open_link() {
  if (connected_) return {};
  if (modbus_connect(ctx_) == -1) {
    const int err = errno;
    modbus_close(ctx_);
    detail_ = std::string("connect: ") + modbus_strerror(err);
    return LstError::ConnectionFailed;
  }
  connected_ = true;
  if (ever_connected_) ++stats_.reconnects;
  ever_connected_ = true;
  return {};
}

void LstTool::close_link() noexcept {
  if (ctx_ && connected_) modbus_close(ctx_);
  connected_ = false;
}

std::error_code LstTool::connect() {
  return transact("connect", [](modbus_t*) { return 0; });
}

void LstTool::disconnect() noexcept { close_link(); }

std::error_code LstTool::fail(const std::string& what, std::error_code ec, int attempts) {
  last_error_ = what + " (" + config_.describe() + "): " + ec.message();
  if (ec == LstError::ConnectionFailed && !detail_.empty()) last_error_ += " (" + detail_ + ")";
  if (attempts > 1) last_error_ += " after " + std::to_string(attempts) + " attempts";
  return ec;
}

std::error_code LstTool::transact(const std::string& what, const std::function<int(modbus_t*)>& request) {
  ++stats_.requests;
  std::error_code ec;
  const int max_attempts = 1 + config_.retries;
  int attempt = 0;
  for (; attempt < max_attempts; ++attempt) {
    if (attempt > 0) {
      ++stats_.retries;
      // Pause before a reconnect, and give a busy tool time.
      if (!connected_ || ec == LstError::Timeout || ec == LstError::ConnectionFailed || ec == LstError::DeviceBusy)
        sleep_s(config_.reconnect_delay_s);
    }
    if (!connected_) {
      ec = open_link();
      if (ec) continue;
    }
    ++stats_.attempts;
    errno = 0;
    if (request(ctx_) != -1) return {};
    const int err = errno;
    ec = map_errno(err);
    detail_ = modbus_strerror(err);
    if (is_exception(ec)) {
      ++stats_.exceptions;
      if (ec != LstError::DeviceBusy) return fail(what, ec, attempt + 1);
      continue;
    }
    if (ec == LstError::InvalidArgument) return fail(what, ec, attempt + 1);
    if (ec == LstError::Timeout) ++stats_.timeouts;
    if (ec == LstError::BadResponse && config_.transport == LstToolConfig::Transport::Rtu) {
      modbus_flush(ctx_);  // resynchronise on the next frame
      continue;
    }
    // Timeout, lost connection or a garbled TCP stream: a late answer could
    // pair with the next request, so start over on a fresh link.
    close_link();
  }
  return fail(what, ec, attempt);
}

std::error_code LstTool::read_input_registers(int address, int count, std::uint16_t* dest) {
  if (count < 1 || count > MODBUS_MAX_READ_REGISTERS || address < 0 || address > 0xFFFF)
    return fail("read input registers " + range(address, count), LstError::InvalidArgument, 1);
  return transact("read input registers " + range(address, count), [&](modbus_t* ctx) {
    return modbus_read_input_registers(ctx, address, count, dest) == count ? 0 : -1;
  });
}

std::error_code LstTool::read_holding_registers(int address, int count, std::uint16_t* dest) {
  if (count < 1 || count > MODBUS_MAX_READ_REGISTERS || address < 0 || address > 0xFFFF)
    return fail("read holding registers " + range(address, count), LstError::InvalidArgument, 1);
  return transact("read holding registers " + range(address, count), [&](modbus_t* ctx) {
    return modbus_read_registers(ctx, address, count, dest) == count ? 0 : -1;
  });
}

std::error_code LstTool::write_register(int address, std::uint16_t value) {
  if (address < 0 || address > 0xFFFF) return fail("write holding register", LstError::InvalidArgument, 1);
  return transact("write holding register " + std::to_string(address) + " = " + std::to_string(value),
                  [&](modbus_t* ctx) { return modbus_write_register(ctx, address, value) == 1 ? 0 : -1; });
}

std::error_code LstTool::read_coils(int address, int count, std::uint8_t* dest) {
  if (count < 1 || count > MODBUS_MAX_READ_BITS || address < 0 || address > 0xFFFF)
    return fail("read coils " + range(address, count), LstError::InvalidArgument, 1);
  return transact("read coils " + range(address, count),
                  [&](modbus_t* ctx) { return modbus_read_bits(ctx, address, count, dest) == count ? 0 : -1; });
}

std::error_code LstTool::write_coil(int address, bool value) {
  if (address < 0 || address > 0xFFFF) return fail("write coil", LstError::InvalidArgument, 1);
  return transact("write coil " + std::to_string(address) + " = " + (value ? "1" : "0"),
                  [&](modbus_t* ctx) { return modbus_write_bit(ctx, address, value ? 1 : 0) == 1 ? 0 : -1; });
}

std::error_code LstTool::read_discrete_inputs(int address, int count, std::uint8_t* dest) {
  if (count < 1 || count > MODBUS_MAX_READ_BITS || address < 0 || address > 0xFFFF)
    return fail("read discrete inputs " + range(address, count), LstError::InvalidArgument, 1);
  return transact("read discrete inputs " + range(address, count), [&](modbus_t* ctx) {
    return modbus_read_input_bits(ctx, address, count, dest) == count ? 0 : -1;
  });
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
                    std::to_string(config_.max_speed_rad_s) + ")",
                LstError::InvalidArgument, 1);
  return write_register(lst::kHoldSpeedCmd, counts);
}

std::error_code LstTool::set_torque_limit(double torque_nm) {
  std::uint16_t counts = 0;
  if (!to_counts(torque_nm, config_.max_torque_nm, lst::kTorqueNmPerCount, counts))
    return fail("set torque limit " + std::to_string(torque_nm) + " N*m (allowed 0.." +
                    std::to_string(config_.max_torque_nm) + ")",
                LstError::InvalidArgument, 1);
  return write_register(lst::kHoldTorqueLimit, counts);
}

std::error_code LstTool::set_direction(LstDirection direction) {
  return write_coil(lst::kCoilDirection, direction == LstDirection::Loosen);
}

std::error_code LstTool::run(LstDirection direction, double speed_rad_s, double torque_limit_nm) {
  std::uint16_t regs[lst::kNumHolding] = {};
  if (!to_counts(speed_rad_s, config_.max_speed_rad_s, lst::kSpeedRadSPerCount, regs[lst::kHoldSpeedCmd]))
    return fail("run: speed " + std::to_string(speed_rad_s) + " rad/s (allowed 0.." +
                    std::to_string(config_.max_speed_rad_s) + ")",
                LstError::InvalidArgument, 1);
  if (!to_counts(torque_limit_nm, config_.max_torque_nm, lst::kTorqueNmPerCount, regs[lst::kHoldTorqueLimit]))
    return fail("run: torque limit " + std::to_string(torque_limit_nm) + " N*m (allowed 0.." +
                    std::to_string(config_.max_torque_nm) + ")",
                LstError::InvalidArgument, 1);
  if (auto ec = transact("write holding registers 0..1", [&](modbus_t* ctx) {
        return modbus_write_registers(ctx, 0, lst::kNumHolding, regs) == lst::kNumHolding ? 0 : -1;
      }))
    return ec;
  std::uint8_t coils[2] = {};
  coils[lst::kCoilRun] = 1;
  coils[lst::kCoilDirection] = direction == LstDirection::Loosen ? 1 : 0;
  return transact("write coils 0..1 (RUN, DIRECTION)",
                  [&](modbus_t* ctx) { return modbus_write_bits(ctx, 0, 2, coils) == 2 ? 0 : -1; });
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
    if (last.fault()) return fail("wait: " + last.describe(), LstError::ToolFault, 1);
    if (std::chrono::steady_clock::now() >= deadline)
      return fail("wait " + std::to_string(timeout_s) + " s, last status: " + last.describe(), LstError::WaitTimeout,
                  1);
    sleep_s(poll_s);
  }
}

std::error_code LstTool::loosen(double turns, double torque_limit_nm, double speed_rad_s, double timeout_s,
                                RunResult& result) {
  result = RunResult{};
  if (!std::isfinite(turns) || !(turns > 0.0) || !(timeout_s > 0.0))
    return fail("loosen " + std::to_string(turns) + " turns", LstError::InvalidArgument, 1);
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
  if (result.last.fault()) return fail("loosen: " + result.last.describe(), LstError::ToolFault, 1);
  if (result.turns <= goal) return {};
  if (result.torque_reached) {
    std::ostringstream os;
    os << "loosen " << turns << " turns at " << torque_limit_nm << " N*m: stopped after " << (0.0 - result.turns) + 0.0
       << " turns, peak torque " << result.peak_torque_nm << " N*m";
    return fail(os.str(), LstError::TorqueLimitReached, 1);
  }
  return fail("loosen: " + result.last.describe(), LstError::RunInterrupted, 1);
}

std::error_code LstTool::tighten(double torque_nm, double speed_rad_s, double timeout_s, RunResult& result) {
  result = RunResult{};
  if (!(timeout_s > 0.0)) return fail("tighten", LstError::InvalidArgument, 1);
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
  if (result.last.fault()) return fail("tighten: " + result.last.describe(), LstError::ToolFault, 1);
  if (result.torque_reached) return {};
  return fail("tighten: " + result.last.describe(), LstError::RunInterrupted, 1);
}

}  // namespace foresight::hw
