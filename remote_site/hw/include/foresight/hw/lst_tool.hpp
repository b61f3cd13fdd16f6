#pragma once
// The LST power tool (latch + nut-driver) over Modbus, TCP or RTU (libmodbus).
// Register map: lst_tool_registers.hpp and docs/hardware.md.
//
// NOT REAL-TIME. Every call here does blocking I/O (up to
// response_timeout_s x (1 + retries), plus reconnect pauses) and may allocate.
// The controller calls it from its own non-real-time tool thread, never from
// the control cycle. An LstTool is not thread-safe: one owner thread.
//
// Errors are values: every operation returns std::error_code in the
// lst_error_category (LstError below): Modbus exceptions from the tool map to
// their named errors (IllegalDataAddress, DeviceFailure, ...), a tool that
// does not answer in time is Timeout, a tool that cannot be reached is
// ConnectionFailed. last_error_message() says which request failed and where.
// Only the constructor throws (InputError on a bad configuration).
//
// The link (retries, reconnects, the Modbus functions) is the shared
// ModbusClient (modbus_client.hpp): a request that times out, or whose
// connection is lost or refused, or whose response is garbled, is retried up
// to `retries` more times on a fresh link; Modbus exceptions are the tool's
// definite answer and are not retried, except DeviceBusy.

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <system_error>

#include "foresight/hw/lst_tool_registers.hpp"
#include "foresight/hw/modbus_client.hpp"

namespace foresight::hw {

/// Named errors of the tool link. Values 1..11 (except 9) equal the Modbus
/// exception codes they stand for.
enum class LstError {
  IllegalFunction = 1,         ///< exception 01: the tool does not support the function
  IllegalDataAddress = 2,      ///< exception 02: register/coil address outside the map
  IllegalDataValue = 3,        ///< exception 03: value refused (e.g. speed above the tool's maximum)
  DeviceFailure = 4,           ///< exception 04: the tool failed while executing the request
  Acknowledge = 5,             ///< exception 05: accepted, long operation in progress
  DeviceBusy = 6,              ///< exception 06: busy, retry later
  NegativeAcknowledge = 7,     ///< exception 07
  MemoryParity = 8,            ///< exception 08
  GatewayPathUnavailable = 10, ///< exception 0A
  GatewayTargetFailed = 11,    ///< exception 0B: no response from the target behind a gateway
  Timeout = 100,               ///< no (complete) response within the response timeout, after all retries
  ConnectionFailed,            ///< cannot connect, or the connection was lost, after all retries
  BadResponse,                 ///< garbled response (CRC, length, wrong unit, unknown exception code)
  InvalidArgument,             ///< a value out of range or not finite: nothing was sent
  WaitTimeout,                 ///< wait_for: the condition did not become true in time
  ToolFault,                   ///< wait_for: the tool raised a fault bit while waiting
  TorqueLimitReached,          ///< loosen: the tool stopped at its torque limit before the turns were done
  RunInterrupted,              ///< loosen/tighten: the run ended without reaching its goal (RUN cleared elsewhere)
};

const std::error_category& lst_error_category() noexcept;
std::error_code make_error_code(LstError e) noexcept;

}  // namespace foresight::hw

template <>
struct std::is_error_code_enum<foresight::hw::LstError> : std::true_type {};

namespace foresight::hw {

/// The `tool:` section of config/remote.yaml (docs/hardware.md): the link in
/// `tool.modbus` (transport, host, port, device, baud, parity, data_bits,
/// stop_bits, unit_id, response_timeout_ms, retries, reconnect_interval_ms),
/// limits and task defaults directly under `tool` (max_speed_rad_s,
/// max_torque_nm, speed_rad_s, tighten_torque_nm, loosen_torque_limit_nm).
/// SI inside: the _ms keys are converted to seconds.
struct LstToolConfig {
  enum class Transport { Tcp, Rtu };
  Transport transport = Transport::Tcp;
  // TCP
  std::string host = "127.0.0.1";
  int port = 502;
  // RTU (serial line)
  std::string device = "/dev/ttyUSB0";
  int baud = 115200;
  char parity = 'N';  ///< 'N', 'E' or 'O'
  int data_bits = 8;
  int stop_bits = 1;

  int unit_id = 1;                  ///< Modbus slave/unit address (RTU 1..247, TCP 0..255)
  double response_timeout_s = 0.1;  ///< per attempt; also the TCP connect timeout
  int retries = 2;                  ///< extra attempts after the first (0..10)
  double reconnect_delay_s = 0.05;  ///< pause before a reconnect
  double max_speed_rad_s = 20.0;    ///< client-side range check of SPEED_CMD
  double max_torque_nm = 60.0;      ///< client-side range check of TORQUE_LIMIT
  // Task defaults (used by the controller's tool sequence).
  double speed_rad_s = 6.0;              ///< socket speed for runs
  double tighten_torque_nm = 20.0;       ///< target torque when tightening
  double loosen_torque_limit_nm = 40.0;  ///< most torque applied to break a screw loose

  std::string source = "LstToolConfig";  ///< file it came from, for messages
  int line = 0;                          ///< line of the `tool:` key

  /// The Modbus link of these settings.
  ModbusLink link() const;
  /// "tcp 127.0.0.1:502 unit 1" / "rtu /dev/ttyUSB0 115200 8N1 unit 1"
  std::string describe() const { return link().describe(); }
};

/// Read and validate the `tool:` section of a remote.yaml. Throws InputError
/// "<file>:<line>: tool.<key> ..." naming the key (e.g. tool.modbus.port):
/// missing section, unknown keys, unknown transport, out-of-range
/// port/unit/baud/parity/bits, non-positive timeouts, negative or > 10
/// retries, torque/speed defaults above the maxima.
LstToolConfig load_lst_tool_config(const std::string& path);
/// As load_lst_tool_config, from YAML text; `source_name` is used in messages.
LstToolConfig parse_lst_tool_config(const std::string& yaml_text, const std::string& source_name);
/// Validate a configuration built in code (the loaders call it). Throws InputError.
void validate(const LstToolConfig& config);

enum class LstDirection : std::uint8_t { Tighten = lst::kDirectionTighten, Loosen = lst::kDirectionLoosen };

/// One read of input registers 0..7, decoded to SI units.
struct LstStatus {
  std::uint16_t status_bits = 0;  ///< lst::kStatus*
  std::uint16_t fault_bits = 0;   ///< lst::kFault*
  double turns = 0.0;             ///< turns counter, + = tightening (clockwise)
  double torque_nm = 0.0;         ///< output torque, + = clockwise
  double speed_rad_s = 0.0;       ///< socket speed, + = clockwise
  std::uint16_t alive = 0;        ///< tool clock, +1 per 10 ms
  double peak_torque_nm = 0.0;    ///< largest |torque| of the present/last run, signed

  bool ready() const { return status_bits & lst::kStatusReady; }
  bool running() const { return status_bits & lst::kStatusRunning; }
  bool latched() const { return status_bits & lst::kStatusLatched; }
  bool unlatched() const { return status_bits & lst::kStatusUnlatched; }
  bool torque_reached() const { return status_bits & lst::kStatusTorqueReached; }
  bool fault() const { return status_bits & lst::kStatusFault; }
  bool jammed() const { return fault_bits & lst::kFaultJam; }
  bool latch_fault() const { return fault_bits & lst::kFaultLatch; }
  /// "ready running latched torque-reached fault[jam]" (bits that are set)
  std::string describe() const;
};

/// Decode / encode the raw registers (exposed for the simulator and tests).
LstStatus decode_status(const std::uint16_t (&in)[lst::kNumInput]) noexcept;

class LstTool {
 public:
  /// Validates the configuration (throws InputError) and creates the libmodbus
  /// context; does not connect (the first request, or connect(), does).
  explicit LstTool(LstToolConfig config);
  ~LstTool();
  LstTool(const LstTool&) = delete;
  LstTool& operator=(const LstTool&) = delete;

  const LstToolConfig& config() const { return config_; }

  /// Connect now (with retries). Requests connect by themselves when needed.
  std::error_code connect();
  void disconnect() noexcept;
  bool connected() const noexcept { return modbus_.connected(); }

  // ---- tool operations ----------------------------------------------------------
  std::error_code read_status(LstStatus& out);
  std::error_code read_setpoints(double& speed_rad_s, double& torque_limit_nm);
  std::error_code set_speed(double speed_rad_s);          ///< 0 .. max_speed_rad_s
  std::error_code set_torque_limit(double torque_nm);     ///< 0 .. max_torque_nm
  std::error_code set_direction(LstDirection direction);
  /// Set speed and torque limit (one FC 16), then DIRECTION and RUN = 1 (one FC 15).
  std::error_code run(LstDirection direction, double speed_rad_s, double torque_limit_nm);
  std::error_code start();   ///< RUN = 1 with the present setpoints
  std::error_code stop();    ///< RUN = 0
  std::error_code latch();   ///< LATCH = 1 (see status().latched())
  std::error_code unlatch(); ///< LATCH = 0 (see status().unlatched())
  std::error_code reset_fault();
  std::error_code reset_turns();

  /// Poll read_status every poll_s until `done(status)` is true (returns {}),
  /// the tool reports a fault and `done` is still false (ToolFault), the time
  /// runs out (WaitTimeout), or a request fails (its error). `last` holds the
  /// last status read.
  std::error_code wait_for(const std::function<bool(const LstStatus&)>& done, double timeout_s,
                           LstStatus& last, double poll_s = 0.01);

  // ---- task steps (poll until done; RUN is always cleared at the end) ----------
  struct RunResult {
    double turns = 0.0;           ///< turns made in this run (+ = tightening)
    double peak_torque_nm = 0.0;  ///< PEAK_TORQUE at the end
    bool torque_reached = false;
    LstStatus last;               ///< last status read
  };
  /// Zero the turns counter, loosen at speed_rad_s with the torque limit and
  /// stop after `turns` turns. TorqueLimitReached when the screw would not
  /// turn (breakaway above the limit), ToolFault on a fault (jam), WaitTimeout
  /// after timeout_s.
  std::error_code loosen(double turns, double torque_limit_nm, double speed_rad_s, double timeout_s,
                         RunResult& result);
  /// Tighten at speed_rad_s until the tool stops at torque_nm (TORQUE_REACHED).
  std::error_code tighten(double torque_nm, double speed_rad_s, double timeout_s, RunResult& result);

  // ---- raw access (diagnostics, tests) --------------------------------------------
  std::error_code read_input_registers(int address, int count, std::uint16_t* dest);
  std::error_code read_holding_registers(int address, int count, std::uint16_t* dest);
  std::error_code write_register(int address, std::uint16_t value);
  std::error_code read_coils(int address, int count, std::uint8_t* dest);
  std::error_code write_coil(int address, bool value);
  std::error_code read_discrete_inputs(int address, int count, std::uint8_t* dest);

  /// "<request> (<link>): <error>[ after N attempts]" for the last failure.
  const std::string& last_error_message() const { return modbus_.last_error_message(); }

  using Stats = ModbusClient::Stats;
  const Stats& stats() const { return modbus_.stats(); }

 private:
  std::error_code fail(const std::string& what, LstError e) { return modbus_.refuse(what, static_cast<int>(e)); }

  LstToolConfig config_;
  ModbusClient modbus_;
};

}  // namespace foresight::hw
