#include "foresight/hw/modbus_client.hpp"

#include <modbus/modbus.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <thread>
#include <utility>

#include "foresight/common/error.hpp"

namespace foresight::hw {

namespace {

void sleep_s(double s) {
  if (s > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(s));
}

std::string range(int address, int count) {
  return count == 1 ? std::to_string(address) : std::to_string(address) + ".." + std::to_string(address + count - 1);
}

bool bad_span(int address, int count, int max_count) {
  return count < 1 || count > max_count || address < 0 || address > 0xFFFF || address + count - 1 > 0xFFFF;
}

}  // namespace

std::string ModbusLink::describe() const {
  if (transport == Transport::Tcp)
    return "tcp " + host + ":" + std::to_string(port) + " unit " + std::to_string(unit_id);
  return "rtu " + device + " " + std::to_string(baud) + " " + std::to_string(data_bits) + parity +
         std::to_string(stop_bits) + " unit " + std::to_string(unit_id);
}

ModbusClient::ModbusClient(ModbusLink link, ModbusErrors errors, const std::string& file, int line,
                           const std::string& what)
    : link_(std::move(link)), errors_(errors) {
  if (link_.transport == ModbusLink::Transport::Tcp)
    ctx_ = modbus_new_tcp(link_.host.c_str(), link_.port);
  else
    ctx_ = modbus_new_rtu(link_.device.c_str(), link_.baud, link_.parity, link_.data_bits, link_.stop_bits);
  if (!ctx_)
    throw InputError(file, line,
                     what + ": cannot create the Modbus context for " + link_.describe() + ": " + modbus_strerror(errno));
  modbus_set_slave(ctx_, link_.unit_id);
  const double t = link_.response_timeout_s;
  const auto sec = static_cast<std::uint32_t>(t);
  const auto usec = static_cast<std::uint32_t>(std::lround((t - sec) * 1e6));
  modbus_set_response_timeout(ctx_, sec, usec);
  // Bytes inside one response must follow each other closely; a stalled
  // half-response ends in a timeout too.
  modbus_set_byte_timeout(ctx_, sec, usec);
}

ModbusClient::~ModbusClient() {
  close_link();
  if (ctx_) modbus_free(ctx_);
}

std::error_code ModbusClient::map_errno(int err) const {
  int code = 0;
  switch (err) {
    case EMBXILFUN: code = 1; break;
    case EMBXILADD: code = 2; break;
    case EMBXILVAL: code = 3; break;
    case EMBXSFAIL: code = 4; break;
    case EMBXACK: code = 5; break;
    case EMBXSBUSY: code = 6; break;
    case EMBXNACK: code = 7; break;
    case EMBXMEMPAR: code = 8; break;
    case EMBXGPATH: code = 10; break;
    case EMBXGTAR: code = 11; break;
    case ETIMEDOUT: return error(errors_.timeout);
    case EMBBADCRC:
    case EMBBADDATA:
    case EMBBADEXC:
    case EMBUNKEXC:
    case EMBBADSLAVE: return error(errors_.bad_response);
    case EMBMDATA: return error(errors_.invalid_argument);
    default: return error(errors_.connection_failed);  // ECONNRESET, EPIPE, EBADF, ECONNREFUSED, EIO ...
  }
  return error(errors_.exception[code] != 0 ? errors_.exception[code] : errors_.bad_response);
}

bool ModbusClient::is_exception(std::error_code ec) const {
  if (ec.category() != *errors_.category) return false;
  for (int code = 1; code < 12; ++code)
    if (errors_.exception[code] != 0 && ec.value() == errors_.exception[code]) return true;
  return false;
}

std::error_code ModbusClient::open_link() {
  if (connected_) return {};
  if (modbus_connect(ctx_) == -1) {
    const int err = errno;
    modbus_close(ctx_);
    detail_ = std::string("connect: ") + modbus_strerror(err);
    return error(errors_.connection_failed);
  }
  connected_ = true;
  if (ever_connected_) ++stats_.reconnects;
  ever_connected_ = true;
  return {};
}

void ModbusClient::close_link() noexcept {
  if (ctx_ && connected_) modbus_close(ctx_);
  connected_ = false;
}

std::error_code ModbusClient::connect() {
  return transact("connect", [](modbus_t*) { return 0; });
}

void ModbusClient::disconnect() noexcept { close_link(); }

std::error_code ModbusClient::fail(const std::string& what, std::error_code ec, int attempts) {
  last_error_ = what + " (" + link_.describe() + "): " + ec.message();
  if (ec == error(errors_.connection_failed) && !detail_.empty()) last_error_ += " (" + detail_ + ")";
  if (attempts > 1) last_error_ += " after " + std::to_string(attempts) + " attempts";
  return ec;
}

std::error_code ModbusClient::refuse(const std::string& what, int value) { return fail(what, error(value), 1); }

std::error_code ModbusClient::transact(const std::string& what, const std::function<int(modbus_t*)>& request) {
  ++stats_.requests;
  std::error_code ec;
  const std::error_code timeout = error(errors_.timeout), lost = error(errors_.connection_failed),
                        garbled = error(errors_.bad_response), busy = error(errors_.exception[6]);
  const int max_attempts = 1 + link_.retries;
  int attempt = 0;
  for (; attempt < max_attempts; ++attempt) {
    if (attempt > 0) {
      ++stats_.retries;
      // Pause before a reconnect, and give a busy device time.
      if (!connected_ || ec == timeout || ec == lost || (errors_.exception[6] != 0 && ec == busy))
        sleep_s(link_.reconnect_delay_s);
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
      if (errors_.exception[6] == 0 || ec != busy) return fail(what, ec, attempt + 1);
      continue;
    }
    if (ec == error(errors_.invalid_argument)) return fail(what, ec, attempt + 1);
    if (ec == timeout) ++stats_.timeouts;
    if (ec == garbled && link_.transport == ModbusLink::Transport::Rtu) {
      modbus_flush(ctx_);  // resynchronise on the next frame
      continue;
    }
    // Timeout, lost connection or a garbled TCP stream: a late answer could
    // pair with the next request, so start over on a fresh link.
    close_link();
  }
  return fail(what, ec, attempt);
}

std::error_code ModbusClient::read_input_registers(int address, int count, std::uint16_t* dest) {
  const std::string what = "read input registers " + range(address, count);
  if (bad_span(address, count, MODBUS_MAX_READ_REGISTERS)) return refuse(what, errors_.invalid_argument);
  return transact(what, [&](modbus_t* ctx) {
    return modbus_read_input_registers(ctx, address, count, dest) == count ? 0 : -1;
  });
}

std::error_code ModbusClient::read_holding_registers(int address, int count, std::uint16_t* dest) {
  const std::string what = "read holding registers " + range(address, count);
  if (bad_span(address, count, MODBUS_MAX_READ_REGISTERS)) return refuse(what, errors_.invalid_argument);
  return transact(what, [&](modbus_t* ctx) { return modbus_read_registers(ctx, address, count, dest) == count ? 0 : -1; });
}

std::error_code ModbusClient::write_register(int address, std::uint16_t value) {
  if (bad_span(address, 1, 1)) return refuse("write holding register", errors_.invalid_argument);
  return transact("write holding register " + std::to_string(address) + " = " + std::to_string(value),
                  [&](modbus_t* ctx) { return modbus_write_register(ctx, address, value) == 1 ? 0 : -1; });
}

std::error_code ModbusClient::write_registers(int address, int count, const std::uint16_t* values) {
  const std::string what = "write holding registers " + range(address, count);
  if (bad_span(address, count, MODBUS_MAX_WRITE_REGISTERS)) return refuse(what, errors_.invalid_argument);
  return transact(what,
                  [&](modbus_t* ctx) { return modbus_write_registers(ctx, address, count, values) == count ? 0 : -1; });
}

std::error_code ModbusClient::read_coils(int address, int count, std::uint8_t* dest) {
  const std::string what = "read coils " + range(address, count);
  if (bad_span(address, count, MODBUS_MAX_READ_BITS)) return refuse(what, errors_.invalid_argument);
  return transact(what, [&](modbus_t* ctx) { return modbus_read_bits(ctx, address, count, dest) == count ? 0 : -1; });
}

std::error_code ModbusClient::write_coil(int address, bool value) {
  if (bad_span(address, 1, 1)) return refuse("write coil", errors_.invalid_argument);
  return transact("write coil " + std::to_string(address) + " = " + (value ? "1" : "0"),
                  [&](modbus_t* ctx) { return modbus_write_bit(ctx, address, value ? 1 : 0) == 1 ? 0 : -1; });
}

std::error_code ModbusClient::write_coils(int address, int count, const std::uint8_t* values) {
  const std::string what = "write coils " + range(address, count);
  if (bad_span(address, count, MODBUS_MAX_WRITE_BITS)) return refuse(what, errors_.invalid_argument);
  return transact(what, [&](modbus_t* ctx) { return modbus_write_bits(ctx, address, count, values) == count ? 0 : -1; });
}

std::error_code ModbusClient::read_discrete_inputs(int address, int count, std::uint8_t* dest) {
  const std::string what = "read discrete inputs " + range(address, count);
  if (bad_span(address, count, MODBUS_MAX_READ_BITS)) return refuse(what, errors_.invalid_argument);
  return transact(what,
                  [&](modbus_t* ctx) { return modbus_read_input_bits(ctx, address, count, dest) == count ? 0 : -1; });
}

}  // namespace foresight::hw
