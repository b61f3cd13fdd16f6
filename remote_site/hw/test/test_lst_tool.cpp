// The LST Modbus client on its own: configuration, named errors, register
// decoding, range checks, and a timeout against a TCP peer that never
// answers (the simulator-backed tests are in ../sim/test/test_lst_server.cpp).
#include <gtest/gtest.h>

#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>
#include <cmath>
#include <fstream>
#include <limits>

#include "foresight/common/error.hpp"
#include "foresight/hw/lst_tool.hpp"

using namespace foresight;
using namespace foresight::hw;

namespace {

std::string write_temp(const std::string& text) {
  char name[] = "/tmp/foresight_lst_XXXXXX";
  const int fd = mkstemp(name);
  close(fd);
  std::ofstream(name) << text;
  return name;
}

std::string load_error(const std::string& yaml) {
  const std::string path = write_temp(yaml);
  std::string what;
  try {
    load_lst_tool_config(path);
  } catch (const InputError& e) {
    what = e.what();
    what.replace(0, path.size(), "F");
  }
  unlink(path.c_str());
  return what;
}

/// A TCP listener that accepts (in the kernel backlog) and never answers.
struct MuteListener {
  int fd = -1;
  int port = 0;
  MuteListener() {
    fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    listen(fd, 4);
    socklen_t len = sizeof a;
    getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
  }
  ~MuteListener() { close(fd); }
};

/// A TCP peer that answers every request with a response carrying the wrong
/// transaction id (a garbled / misrouted answer).
struct JunkServer {
  MuteListener listener;
  std::atomic<bool> stop{false};
  std::vector<int> clients;
  std::thread thread;
  JunkServer() {
    thread = std::thread([this] {
      while (!stop) {
        pollfd lp{listener.fd, POLLIN, 0};
        if (poll(&lp, 1, 10) > 0) clients.push_back(accept(listener.fd, nullptr, nullptr));
        for (int c : clients) {
          pollfd cp{c, POLLIN, 0};
          std::uint8_t req[260];
          if (c < 0 || poll(&cp, 1, 0) <= 0) continue;
          if (read(c, req, sizeof req) < 8) continue;
          const std::uint8_t rsp[] = {static_cast<std::uint8_t>(req[0] ^ 0x5A), req[1], 0, 0, 0, 5, req[6], 0x04, 2, 0, 0};
          (void)!write(c, rsp, sizeof rsp);
        }
      }
      for (int c : clients)
        if (c >= 0) close(c);
    });
  }
  ~JunkServer() {
    stop = true;
    thread.join();
  }
};

}  // namespace

TEST(LstToolConfig, LoadsTheRemoteYaml) {
  const LstToolConfig c = load_lst_tool_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  EXPECT_EQ(c.transport, LstToolConfig::Transport::Tcp);
  EXPECT_EQ(c.host, "127.0.0.1");
  EXPECT_GT(c.port, 0);
  EXPECT_GT(c.response_timeout_s, 0.0);
  EXPECT_EQ(c.port, 1502);
  EXPECT_DOUBLE_EQ(c.response_timeout_s, 0.05);
  EXPECT_EQ(c.retries, 3);
  EXPECT_DOUBLE_EQ(c.reconnect_delay_s, 0.5);
  EXPECT_DOUBLE_EQ(c.speed_rad_s, 6.0);
  EXPECT_DOUBLE_EQ(c.tighten_torque_nm, 20.0);
  EXPECT_DOUBLE_EQ(c.loosen_torque_limit_nm, 40.0);
  EXPECT_LE(c.tighten_torque_nm, c.max_torque_nm);
  EXPECT_EQ(c.describe(), "tcp 127.0.0.1:" + std::to_string(c.port) + " unit " + std::to_string(c.unit_id));
}

TEST(LstToolConfig, ParsesEveryKey) {
  const LstToolConfig c = parse_lst_tool_config(
      "tool:\n"
      "  modbus: {transport: rtu, device: /dev/ttyS3, baud: 19200, parity: E, data_bits: 8, stop_bits: 1,\n"
      "           unit_id: 7, response_timeout_ms: 40, retries: 4, reconnect_interval_ms: 250}\n"
      "  max_speed_rad_s: 12\n  max_torque_nm: 50\n  speed_rad_s: 6\n  tighten_torque_nm: 22\n"
      "  loosen_torque_limit_nm: 45\n",
      "t.yaml");
  EXPECT_EQ(c.transport, LstToolConfig::Transport::Rtu);
  EXPECT_EQ(c.describe(), "rtu /dev/ttyS3 19200 8E1 unit 7");
  EXPECT_DOUBLE_EQ(c.response_timeout_s, 0.04);
  EXPECT_EQ(c.retries, 4);
  EXPECT_DOUBLE_EQ(c.reconnect_delay_s, 0.25);
  EXPECT_DOUBLE_EQ(c.max_speed_rad_s, 12.0);
  EXPECT_DOUBLE_EQ(c.loosen_torque_limit_nm, 45.0);
}

TEST(LstToolConfig, BadInputsNameFileLineAndKey) {
  EXPECT_EQ(load_error("cycle_rate_hz: 500\n"), "F: missing section 'tool' (the LST power tool)");
  EXPECT_EQ(load_error("tool:\n  modbus: {transport: udp}\n"), "F:2: tool.modbus.transport: 'udp' is not tcp or rtu");
  EXPECT_EQ(load_error("tool:\n  modbus:\n    transport: tcp\n    port: 70000\n"),
            "F:4: tool.modbus.port: 70000 is outside 1..65535");
  EXPECT_EQ(load_error("tool:\n  modbus:\n    response_timeout_ms: -5\n"),
            "F:3: tool.modbus.response_timeout_ms: -5 must lie in (0, 60000]");
  EXPECT_EQ(load_error("tool:\n  modbus:\n    retries: many\n"), "F:3: tool.modbus.retries: not an integer: 'many'");
  EXPECT_EQ(load_error("tool:\n  modbus: {}\n  max_torque_nm: 30\n  tighten_torque_nm: 35\n"),
            "F:4: tool.tighten_torque_nm: 35 must lie in (0, 30]");
  EXPECT_EQ(load_error("tool:\n  modbus: {}\n  torque: 3\n"),
            "F:3: tool.torque: unknown key (expected one of: modbus, max_speed_rad_s, max_torque_nm, speed_rad_s, "
            "tighten_torque_nm, loosen_torque_limit_nm)");
  EXPECT_EQ(load_error("tool:\n  speed_rad_s: 3\n"), "F:2: tool: missing 'modbus' (the link to the tool)");
  EXPECT_EQ(load_error("tool:\n  modbus: {transport: rtu, parity: X}\n"), "F:2: tool.modbus.parity: 'X' is not N, E or O");
  const std::string malformed = load_error("tool: [1, 2\n");
  EXPECT_EQ(malformed.substr(0, 2), "F:");
  EXPECT_NE(malformed.find("malformed YAML"), std::string::npos) << malformed;
  try {
    load_lst_tool_config("/nonexistent/remote.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/remote.yaml: cannot open the remote configuration");
  }
  LstToolConfig bad;
  bad.retries = 11;
  EXPECT_THROW(LstTool{bad}, InputError);
}

TEST(LstError, CategoryNamesEveryError) {
  EXPECT_STREQ(lst_error_category().name(), "lst_tool");
  EXPECT_EQ(std::error_code(LstError::IllegalDataAddress).message(), "illegal data address (Modbus exception 02)");
  EXPECT_EQ(std::error_code(LstError::DeviceFailure).message(), "device failure (Modbus exception 04)");
  EXPECT_EQ(std::error_code(LstError::GatewayTargetFailed).message(),
            "gateway target failed to respond (Modbus exception 0B)");
  EXPECT_EQ(std::error_code(LstError::Timeout).message(), "timeout: no response from the tool");
  EXPECT_EQ(std::error_code(LstError::IllegalDataAddress).value(), 2);  // = the Modbus exception code
  EXPECT_NE(std::error_code(LstError::Timeout), std::make_error_code(std::errc::timed_out));
}

TEST(LstStatus, DecodesRegistersWithSignAndScale) {
  const std::int32_t turns = -12345;  // -12.345 turns
  const auto u = static_cast<std::uint32_t>(turns);
  const std::uint16_t in[lst::kNumInput] = {
      static_cast<std::uint16_t>(lst::kStatusReady | lst::kStatusRunning | lst::kStatusLatched),
      0,
      static_cast<std::uint16_t>(u >> 16),
      static_cast<std::uint16_t>(u & 0xFFFF),
      static_cast<std::uint16_t>(static_cast<std::int16_t>(-1500)),
      static_cast<std::uint16_t>(static_cast<std::int16_t>(628)),
      41,
      static_cast<std::uint16_t>(static_cast<std::int16_t>(-2012))};
  const LstStatus s = decode_status(in);
  EXPECT_NEAR(s.turns, -12.345, 1e-12);
  EXPECT_NEAR(s.torque_nm, -15.0, 1e-12);
  EXPECT_NEAR(s.speed_rad_s, 6.28, 1e-12);
  EXPECT_EQ(s.alive, 41);
  EXPECT_NEAR(s.peak_torque_nm, -20.12, 1e-12);
  EXPECT_TRUE(s.ready() && s.running() && s.latched());
  EXPECT_FALSE(s.unlatched() || s.fault() || s.torque_reached());
  EXPECT_EQ(s.describe(), "ready running latched");
}

TEST(LstTool, RefusesOutOfRangeValuesWithoutSending) {
  LstToolConfig c;
  c.port = 1;  // never contacted
  c.max_speed_rad_s = 10.0;
  c.speed_rad_s = 5.0;
  LstTool tool(c);
  EXPECT_EQ(tool.set_speed(-1.0), LstError::InvalidArgument);
  EXPECT_EQ(tool.set_speed(10.5), LstError::InvalidArgument);
  EXPECT_EQ(tool.last_error_message(),
            "set speed 10.500000 rad/s (allowed 0..10.000000) (tcp 127.0.0.1:1 unit 1): invalid argument");
  EXPECT_EQ(tool.set_torque_limit(std::numeric_limits<double>::quiet_NaN()), LstError::InvalidArgument);
  EXPECT_EQ(tool.run(LstDirection::Loosen, 5.0, 1e9), LstError::InvalidArgument);
  std::uint16_t r[200];
  EXPECT_EQ(tool.read_input_registers(0, 200, r), LstError::InvalidArgument);  // > 125 registers
  EXPECT_EQ(tool.stats().requests, 0u);
  EXPECT_FALSE(tool.connected());
}

TEST(LstTool, TimesOutAgainstAPeerThatNeverAnswers) {
  MuteListener mute;
  LstToolConfig c;
  c.port = mute.port;
  c.response_timeout_s = 0.05;
  c.retries = 2;
  c.reconnect_delay_s = 0.0;
  LstTool tool(c);
  LstStatus s;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(tool.read_status(s), LstError::Timeout);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_GE(took, 0.15 - 0.005);
  EXPECT_LT(took, 1.0);
  EXPECT_EQ(tool.stats().attempts, 3u);
  EXPECT_EQ(tool.stats().timeouts, 3u);
  EXPECT_EQ(tool.stats().retries, 2u);
  EXPECT_EQ(tool.stats().reconnects, 2u);  // a fresh connection before each retry
}

TEST(LstTool, MissingSerialDeviceIsAConnectionFailure) {
  LstToolConfig c;
  c.transport = LstToolConfig::Transport::Rtu;
  c.device = "/nonexistent/ttyLST";
  c.retries = 0;
  LstTool tool(c);
  LstStatus s;
  EXPECT_EQ(tool.read_status(s), LstError::ConnectionFailed);
  EXPECT_EQ(tool.last_error_message(),
            "read input registers 0..7 (rtu /nonexistent/ttyLST 115200 8N1 unit 1): connection failed "
            "(connect: No such file or directory)");
}

TEST(LstTool, GarbledResponsesAreBadResponseAfterRetries) {
  JunkServer junk;
  LstToolConfig c;
  c.port = junk.listener.port;
  c.response_timeout_s = 0.2;
  c.retries = 1;
  c.reconnect_delay_s = 0.0;
  LstTool tool(c);
  LstStatus s;
  EXPECT_EQ(tool.read_status(s), LstError::BadResponse);
  EXPECT_EQ(tool.stats().attempts, 2u);
  EXPECT_EQ(tool.stats().timeouts, 0u);
  EXPECT_EQ(tool.last_error_message(),
            "read input registers 0..7 (tcp 127.0.0.1:" + std::to_string(c.port) +
                " unit 1): bad response (CRC, length, unit or exception code) after 2 attempts");
}
