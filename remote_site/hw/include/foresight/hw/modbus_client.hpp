#pragma once
// The one Modbus client core (libmodbus, TCP or RTU) under the devices that
// speak Modbus: the LST power tool (lst_tool.hpp) and the video switch
// (video_switch.hpp). It owns the libmodbus context and the link, and does
// every request through one transaction with retries and reconnects; the
// devices add their register maps and their task logic on top.
//
// NOT REAL-TIME: blocking I/O (up to response_timeout_s x (1 + retries), plus
// reconnect pauses), allocation. One owner thread.
//
// Errors are values in the device's own error category (ModbusErrors): a
// Modbus exception from the device maps to its named error, a device that
// does not answer in time is `timeout`, one that cannot be reached is
// `connection_failed`. last_error_message() says which request failed and
// where. Only the constructor throws (InputError when the context cannot be
// created).
//
// Retries and reconnect: a request that times out, whose connection is lost
// or refused, or whose response is garbled, is retried up to `retries` more
// times; before a retry after a timeout, a lost connection or DeviceBusy the
// client pauses reconnect_delay_s, and after a timeout or a lost link it
// reconnects first (TCP: a new connection; RTU: reopens the port), so a late
// answer never pairs with the next request. A garbled RTU frame flushes the
// line. Modbus exceptions are the device's definite answer and are not
// retried, except DeviceBusy.

#include <cstdint>
#include <functional>
#include <string>
#include <system_error>

typedef struct _modbus modbus_t;  // libmodbus context (opaque)

namespace foresight::hw {

/// The link: where the device is and how patiently to talk to it.
struct ModbusLink {
  enum class Transport { Tcp, Rtu };
  Transport transport = Transport::Tcp;
  std::string host = "127.0.0.1";  ///< TCP
  int port = 502;
  std::string device = "/dev/ttyUSB0";  ///< RTU (serial line)
  int baud = 115200;
  char parity = 'N';  ///< 'N', 'E' or 'O'
  int data_bits = 8;
  int stop_bits = 1;
  int unit_id = 1;                  ///< Modbus slave/unit address
  double response_timeout_s = 0.1;  ///< per attempt; also the TCP connect timeout
  int retries = 2;                  ///< extra attempts after the first
  double reconnect_delay_s = 0.05;  ///< pause before a reconnect

  /// "tcp 127.0.0.1:502 unit 1" / "rtu /dev/ttyUSB0 115200 8N1 unit 1"
  std::string describe() const;
};

/// How a device names the link's errors: its error category, and its values
/// for the Modbus exceptions (1..11, by exception code; 0 = not named: the
/// answer counts as `bad_response`) and the link's own failures.
struct ModbusErrors {
  const std::error_category* category = nullptr;
  int exception[12] = {};
  int timeout = 0;
  int connection_failed = 0;
  int bad_response = 0;
  int invalid_argument = 0;
};

class ModbusClient {
 public:
  /// Creates the libmodbus context (no connection yet: the first request, or
  /// connect(), makes it). Throws InputError "<file>:<line>: <what>: cannot
  /// create the Modbus context for <link>: <reason>" when it cannot.
  ModbusClient(ModbusLink link, ModbusErrors errors, const std::string& file, int line, const std::string& what);
  ~ModbusClient();
  ModbusClient(const ModbusClient&) = delete;
  ModbusClient& operator=(const ModbusClient&) = delete;

  const ModbusLink& link() const noexcept { return link_; }
  /// Connect now (with retries). Requests connect by themselves when needed.
  std::error_code connect();
  void disconnect() noexcept;
  bool connected() const noexcept { return connected_; }

  // ---- the Modbus functions (address and count checked: InvalidArgument, nothing sent)
  std::error_code read_input_registers(int address, int count, std::uint16_t* dest);    ///< FC 4
  std::error_code read_holding_registers(int address, int count, std::uint16_t* dest);  ///< FC 3
  std::error_code write_register(int address, std::uint16_t value);                     ///< FC 6
  std::error_code write_registers(int address, int count, const std::uint16_t* values); ///< FC 16
  std::error_code read_coils(int address, int count, std::uint8_t* dest);               ///< FC 1
  std::error_code write_coil(int address, bool value);                                  ///< FC 5
  std::error_code write_coils(int address, int count, const std::uint8_t* values);      ///< FC 15
  std::error_code read_discrete_inputs(int address, int count, std::uint8_t* dest);     ///< FC 2

  /// One request of the caller's own (several functions as one step, a
  /// device-specific function): `request` returns -1 with errno set on failure.
  std::error_code transact(const std::string& what, const std::function<int(modbus_t*)>& request);
  /// The device's error `value` with `what` as the failed request (a check
  /// of the device's own, before anything is sent).
  std::error_code refuse(const std::string& what, int value);

  /// "<request> (<link>): <error>[ (<detail>)][ after N attempts]" for the last failure.
  const std::string& last_error_message() const noexcept { return last_error_; }

  struct Stats {
    std::uint64_t requests = 0;    ///< operations that reached the wire
    std::uint64_t attempts = 0;    ///< wire attempts including retries
    std::uint64_t retries = 0;
    std::uint64_t reconnects = 0;  ///< successful (re)connections after the first
    std::uint64_t timeouts = 0;    ///< attempts that timed out
    std::uint64_t exceptions = 0;  ///< Modbus exception responses
  };
  const Stats& stats() const noexcept { return stats_; }

 private:
  std::error_code map_errno(int err) const;
  bool is_exception(std::error_code ec) const;
  std::error_code open_link();
  void close_link() noexcept;
  std::error_code fail(const std::string& what, std::error_code ec, int attempts);
  std::error_code error(int value) const { return {value, *errors_.category}; }

  ModbusLink link_;
  ModbusErrors errors_;
  modbus_t* ctx_ = nullptr;
  bool connected_ = false;
  bool ever_connected_ = false;
  std::string detail_;  ///< libmodbus' words for the last failure
  std::string last_error_;
  Stats stats_;
};

}  // namespace foresight::hw
