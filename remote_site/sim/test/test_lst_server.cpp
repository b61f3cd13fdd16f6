// The LST client (foresight_hw) against the simulated tool (a libmodbus
// server on 127.0.0.1 with an ephemeral port, or RTU over a pty): register
// map, screw physics through Modbus, named exceptions, timeout, reconnect.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <numbers>
#include <thread>

#include <modbus.h>

#include "foresight/hw/lst_tool.hpp"
#include "foresight/hw/lst_tool_registers.hpp"
#include "foresight/sim/lst_server.hpp"

using namespace foresight;
using namespace foresight::hw;
using namespace foresight::sim;
using Clock = std::chrono::steady_clock;

namespace {

LstServerOptions server_options(LstServerOptions::Transport t = LstServerOptions::Transport::Tcp) {
  LstServerOptions o;
  o.transport = t;
  o.poll_s = 0.002;
  o.mechanism.max_speed_rad_s = 20.0;
  o.mechanism.max_torque_nm = 60.0;
  o.mechanism.latch_travel_s = 0.1;
  o.mechanism.stall_time_s = 0.1;
  o.mechanism.screw.engaged_turns = 2.0;
  o.mechanism.screw.initial_engaged_turns = 2.0;
  o.mechanism.screw.breakaway_torque_nm = 15.0;
  return o;
}

LstToolConfig client_config(const LstServer& server) {
  LstToolConfig c;
  c.transport = LstToolConfig::Transport::Tcp;
  c.host = "127.0.0.1";
  c.port = server.port();
  // Generous: on a loaded machine (ctest -j2 beside a build) the server thread
  // can be descheduled for 100 ms; a spurious timeout is not what these tests
  // are about. The timeout tests set their own short timeouts.
  c.response_timeout_s = 1.0;
  c.retries = 1;
  c.reconnect_delay_s = 0.01;
  c.max_speed_rad_s = 100.0;  // above the tool's 20 rad/s: the tool itself must refuse
  c.max_torque_nm = 100.0;
  c.speed_rad_s = 10.0;
  c.tighten_torque_nm = 20.0;
  c.loosen_torque_limit_nm = 40.0;
  return c;
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

TEST(LstServer, StatusOverTcp) {
  LstServer server(server_options());
  ASSERT_GT(server.port(), 0);
  LstTool tool(client_config(server));
  LstStatus s;
  ASSERT_FALSE(tool.read_status(s)) << tool.last_error_message();
  EXPECT_TRUE(s.ready());
  EXPECT_TRUE(s.unlatched());
  EXPECT_FALSE(s.latched());
  EXPECT_FALSE(s.running());
  EXPECT_FALSE(s.fault());
  EXPECT_EQ(s.turns, 0.0);
  // The tool's clock ticks every 10 ms.
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  LstStatus later;
  ASSERT_FALSE(tool.read_status(later));
  EXPECT_GE(static_cast<std::uint16_t>(later.alive - s.alive), 4);
  // Discrete inputs mirror the status word; setpoints read back.
  std::uint8_t bits[lst::kNumDiscreteInputs] = {};
  ASSERT_FALSE(tool.read_discrete_inputs(0, lst::kNumDiscreteInputs, bits));
  EXPECT_EQ(bits[0], 1);  // READY
  EXPECT_EQ(bits[3], 1);  // UNLATCHED
  ASSERT_FALSE(tool.set_speed(12.34));
  ASSERT_FALSE(tool.set_torque_limit(7.5));
  double speed = 0, torque = 0;
  ASSERT_FALSE(tool.read_setpoints(speed, torque));
  EXPECT_DOUBLE_EQ(speed, 12.34);
  EXPECT_DOUBLE_EQ(torque, 7.5);
  EXPECT_EQ(tool.stats().retries, 0u);
}

TEST(LstServer, LooseningTakesNTurnsAboveTThroughModbus) {
  LstServer server(server_options());
  LstTool tool(client_config(server));
  ASSERT_FALSE(tool.run(LstDirection::Loosen, 20.0, 20.0)) << tool.last_error_message();
  LstStatus s;
  ASSERT_FALSE(tool.read_status(s));
  EXPECT_TRUE(s.running());
  // While engaged the tool reads the breakaway torque, counter-clockwise.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_FALSE(tool.read_status(s));
  EXPECT_NEAR(s.torque_nm, -15.0, 1e-9);
  EXPECT_NEAR(s.speed_rad_s, -20.0, 1e-9);
  EXPECT_FALSE(server.state().screw_free());
  // Two turns at 20 rad/s take 0.63 s; the screw is free after -2 turns.
  const auto t0 = Clock::now();
  ASSERT_FALSE(tool.wait_for([](const LstStatus& st) { return st.turns <= -2.01; }, 3.0, s, 0.005))
      << tool.last_error_message();
  EXPECT_LT(seconds_since(t0), 1.0);
  ASSERT_FALSE(tool.stop());
  const LstToolState truth = server.state();
  EXPECT_TRUE(truth.screw_free());
  ASSERT_FALSE(tool.read_status(s));
  EXPECT_FALSE(s.running());
  EXPECT_NEAR(s.turns, truth.turns, 1e-3);  // register quantisation
  EXPECT_LE(s.turns, -2.0);
}

// The counter reports whole counts passed: a turns reading at the goal
// means the goal was reached, not half a count before it.
TEST(LstRegisters, TheTurnsCounterTruncatesTowardZero) {
  using foresight::hw::lst::turns_to_counts;
  EXPECT_EQ(turns_to_counts(-1.9996), -1999);
  EXPECT_EQ(turns_to_counts(-1.9999999999999998), -1999);
  EXPECT_EQ(turns_to_counts(-2.0), -2000);
  EXPECT_EQ(turns_to_counts(-2.0004), -2000);
  EXPECT_EQ(turns_to_counts(1.9996), 1999);
  EXPECT_EQ(turns_to_counts(2.0), 2000);
  EXPECT_EQ(turns_to_counts(0.0004), 0);
}

TEST(LstServer, LoosenAndTightenTaskSteps) {
  LstServer server(server_options());
  LstTool tool(client_config(server));
  LstTool::RunResult r;
  // Too little torque: the screw does not break loose.
  EXPECT_EQ(tool.loosen(2.0, 12.0, 20.0, 2.0, r), LstError::TorqueLimitReached);
  EXPECT_EQ(tool.last_error_message(),
            "loosen 2 turns at 12 N*m: stopped after 0 turns, peak torque -12 N*m (tcp 127.0.0.1:" +
                std::to_string(server.port()) +
                " unit 1): the tool stopped at its torque limit before the turns were done");
  EXPECT_TRUE(r.torque_reached);
  EXPECT_DOUBLE_EQ(server.state().engaged_turns, 2.0);
  // Enough torque: 2 turns and the screw is free.
  ASSERT_FALSE(tool.loosen(2.0, 20.0, 20.0, 2.0, r)) << tool.last_error_message();
  EXPECT_LE(r.turns, -2.0);
  EXPECT_NEAR(r.peak_torque_nm, -15.0, 1e-9);  // the breakaway torque
  EXPECT_TRUE(server.state().screw_free());
  EXPECT_FALSE(server.state().running);
  // Tighten back to 25 N*m: 2 turns of run-down, then the torque rises.
  ASSERT_FALSE(tool.tighten(25.0, 20.0, 2.0, r)) << tool.last_error_message();
  EXPECT_TRUE(r.torque_reached);
  EXPECT_NEAR(r.peak_torque_nm, 25.0, 1e-9);
  EXPECT_NEAR(r.turns, 2.0 + (25.0 - 2.0) / 40.0 / (2.0 * std::numbers::pi), 2e-3);
  EXPECT_NEAR(server.state().preload_nm, 25.0, 1e-9);
  // Jammed: a named fault.
  server.set_jam(true);
  EXPECT_EQ(tool.loosen(1.0, 40.0, 20.0, 2.0, r), LstError::ToolFault);
  EXPECT_TRUE(r.last.jammed());
}

TEST(LstServer, BelowBreakawayItStopsAtTheTorqueLimit) {
  LstServer server(server_options());
  LstTool tool(client_config(server));
  ASSERT_FALSE(tool.run(LstDirection::Loosen, 20.0, 10.0));
  LstStatus s;
  ASSERT_FALSE(tool.wait_for([](const LstStatus& st) { return st.torque_reached(); }, 1.0, s))
      << tool.last_error_message();
  EXPECT_FALSE(s.running());
  EXPECT_EQ(s.turns, 0.0);
  EXPECT_NEAR(s.peak_torque_nm, -10.0, 1e-9);  // it pushed at the limit
  EXPECT_EQ(s.torque_nm, 0.0);                 // and then stopped
  EXPECT_DOUBLE_EQ(server.state().engaged_turns, 2.0);
  std::uint8_t coils[lst::kNumCoils] = {};
  ASSERT_FALSE(tool.read_coils(0, lst::kNumCoils, coils));
  EXPECT_EQ(coils[lst::kCoilRun], 0);  // the tool cleared RUN itself
  EXPECT_EQ(coils[lst::kCoilDirection], lst::kDirectionLoosen);
}

TEST(LstServer, JamRaisesTheFaultBit) {
  LstServer server(server_options());
  server.set_jam(true);
  LstTool tool(client_config(server));
  ASSERT_FALSE(tool.run(LstDirection::Loosen, 10.0, 40.0));
  LstStatus s;
  const std::error_code ec = tool.wait_for([](const LstStatus& st) { return !st.running(); }, 2.0, s);
  // wait_for returns as soon as the run ended; the fault shows in the status.
  EXPECT_TRUE(!ec || ec == LstError::ToolFault) << ec.message();
  EXPECT_TRUE(s.fault());
  EXPECT_TRUE(s.jammed());
  EXPECT_FALSE(s.ready());
  EXPECT_EQ(s.turns, 0.0);
  EXPECT_EQ(s.describe(), "unlatched fault[jam]");
  // Waiting for something else while faulted: ToolFault, named.
  EXPECT_EQ(tool.wait_for([](const LstStatus& st) { return st.latched(); }, 1.0, s), LstError::ToolFault);
  EXPECT_NE(tool.last_error_message().find("fault[jam]"), std::string::npos) << tool.last_error_message();
  server.set_jam(false);
  ASSERT_FALSE(tool.reset_fault());
  ASSERT_FALSE(tool.read_status(s));
  EXPECT_FALSE(s.fault());
  EXPECT_TRUE(s.ready());
}

TEST(LstServer, LatchAndUnlatch) {
  LstServer server(server_options());
  LstTool tool(client_config(server));
  LstStatus s;
  ASSERT_FALSE(tool.latch());
  ASSERT_FALSE(tool.wait_for([](const LstStatus& st) { return st.latched(); }, 1.0, s));
  EXPECT_FALSE(s.unlatched());
  ASSERT_FALSE(tool.unlatch());
  ASSERT_FALSE(tool.wait_for([](const LstStatus& st) { return st.unlatched(); }, 1.0, s));
  server.set_latch_stuck(true);
  ASSERT_FALSE(tool.latch());
  EXPECT_EQ(tool.wait_for([](const LstStatus& st) { return st.latched(); }, 1.0, s), LstError::ToolFault);
  EXPECT_TRUE(s.latch_fault());
}

TEST(LstServer, ModbusExceptionsMapToNamedErrors) {
  LstServer server(server_options());
  LstTool tool(client_config(server));
  std::uint16_t reg[4] = {};
  EXPECT_EQ(tool.read_input_registers(50, 1, reg), LstError::IllegalDataAddress);
  EXPECT_EQ(tool.last_error_message(),
            "read input registers 50 (tcp 127.0.0.1:" + std::to_string(server.port()) +
                " unit 1): illegal data address (Modbus exception 02)");
  EXPECT_EQ(tool.read_input_registers(6, 3, reg), LstError::IllegalDataAddress);  // runs past register 7
  EXPECT_EQ(tool.write_register(2, 1), LstError::IllegalDataAddress);
  EXPECT_EQ(tool.write_coil(7, true), LstError::IllegalDataAddress);
  // Above the tool's 20 rad/s (the client allows 100 here): the tool refuses.
  EXPECT_EQ(tool.set_speed(25.0), LstError::IllegalDataValue);
  EXPECT_EQ(tool.run(LstDirection::Tighten, 5.0, 70.0), LstError::IllegalDataValue);
  double speed = -1, torque = -1;
  ASSERT_FALSE(tool.read_setpoints(speed, torque));
  EXPECT_EQ(speed, 0.0);  // nothing was written
  EXPECT_EQ(torque, 0.0);
  // Injected: device failure once, then normal again.
  server.inject_exception(4, 1);
  LstStatus s;
  EXPECT_EQ(tool.read_status(s), LstError::DeviceFailure);
  EXPECT_EQ(tool.last_error_message(),
            "read input registers 0..7 (tcp 127.0.0.1:" + std::to_string(server.port()) +
                " unit 1): device failure (Modbus exception 04)");
  EXPECT_FALSE(tool.read_status(s));
  // Busy is retried: one busy answer, then the retry succeeds.
  server.inject_exception(6, 1);
  const auto retries = tool.stats().retries;
  EXPECT_FALSE(tool.read_status(s));
  EXPECT_EQ(tool.stats().retries, retries + 1);
  // Illegal function, persistently.
  server.inject_exception(1, -1);
  EXPECT_EQ(tool.latch(), LstError::IllegalFunction);
  server.inject_exception(0);
  EXPECT_FALSE(tool.latch());
  EXPECT_GE(tool.stats().exceptions, 8u);
}

TEST(LstServer, TimeoutWhenTheToolStopsAnsweringThenRecovers) {
  LstServer server(server_options());
  LstToolConfig cfg = client_config(server);
  cfg.response_timeout_s = 0.05;
  cfg.retries = 2;
  LstTool tool(cfg);
  LstStatus s;
  ASSERT_FALSE(tool.read_status(s));
  server.set_silent(true);
  const auto t0 = Clock::now();
  EXPECT_EQ(tool.read_status(s), LstError::Timeout);
  const double took = seconds_since(t0);
  EXPECT_GE(took, 3 * 0.05 - 0.005);  // three attempts of 50 ms
  EXPECT_LT(took, 1.0);
  EXPECT_EQ(tool.stats().timeouts, 3u);
  EXPECT_EQ(tool.last_error_message(), "read input registers 0..7 (tcp 127.0.0.1:" + std::to_string(server.port()) +
                                           " unit 1): timeout: no response from the tool after 3 attempts");
  EXPECT_GE(server.requests_received(), 4u);
  server.set_silent(false);
  const auto reconnects = tool.stats().reconnects;
  ASSERT_FALSE(tool.read_status(s)) << tool.last_error_message();
  EXPECT_TRUE(s.ready());
  EXPECT_GT(tool.stats().reconnects, reconnects);  // a fresh connection after the timeout
}

TEST(LstServer, ReconnectsAfterTheServerIsKilledAndRestarted) {
  LstServer server(server_options());
  LstTool tool(client_config(server));
  ASSERT_FALSE(tool.run(LstDirection::Loosen, 20.0, 20.0));
  LstStatus s;
  ASSERT_FALSE(tool.wait_for([](const LstStatus& st) { return st.turns <= -0.5; }, 2.0, s));
  ASSERT_FALSE(tool.stop());
  server.stop();  // killed: the connection drops, new ones are refused
  const auto t0 = Clock::now();
  EXPECT_EQ(tool.read_status(s), LstError::ConnectionFailed);
  EXPECT_LT(seconds_since(t0), 1.0);
  EXPECT_NE(tool.last_error_message().find("connection failed"), std::string::npos) << tool.last_error_message();
  EXPECT_FALSE(tool.connected());
  server.start();  // same port
  ASSERT_FALSE(tool.read_status(s)) << tool.last_error_message();
  EXPECT_TRUE(tool.connected());
  EXPECT_GE(tool.stats().reconnects, 1u);
  EXPECT_LE(s.turns, -0.5);  // the tool kept its state
  EXPECT_FALSE(s.running());
}

TEST(LstServer, ConnectionRefusedIsNamed) {
  int port = 0;
  {
    LstServer server(server_options());
    port = server.port();
  }  // gone: nothing listens on the port any more
  LstToolConfig cfg;
  cfg.port = port;
  cfg.response_timeout_s = 0.05;
  cfg.retries = 1;
  cfg.reconnect_delay_s = 0.0;
  LstTool tool(cfg);
  LstStatus s;
  EXPECT_EQ(tool.read_status(s), LstError::ConnectionFailed);
  EXPECT_EQ(tool.last_error_message(), "read input registers 0..7 (tcp 127.0.0.1:" + std::to_string(port) +
                                           " unit 1): connection failed (connect: Connection refused) after 2 attempts");
}

TEST(LstServer, RtuOverAPty) {
  LstServer server(server_options(LstServerOptions::Transport::Rtu));
  ASSERT_EQ(server.device_path().rfind("/dev/pts/", 0), 0u) << server.device_path();
  LstToolConfig cfg;
  cfg.transport = LstToolConfig::Transport::Rtu;
  cfg.device = server.device_path();
  cfg.baud = 115200;
  cfg.unit_id = 1;
  cfg.response_timeout_s = 0.2;
  cfg.retries = 1;
  cfg.reconnect_delay_s = 0.01;
  LstTool tool(cfg);
  LstStatus s;
  ASSERT_FALSE(tool.read_status(s)) << tool.last_error_message();
  EXPECT_TRUE(s.ready());
  EXPECT_TRUE(s.unlatched());
  ASSERT_FALSE(tool.run(LstDirection::Loosen, 20.0, 10.0)) << tool.last_error_message();
  ASSERT_FALSE(tool.wait_for([](const LstStatus& st) { return st.torque_reached(); }, 1.0, s))
      << tool.last_error_message();
  EXPECT_NEAR(s.peak_torque_nm, -10.0, 1e-9);
  std::uint16_t reg = 0;
  EXPECT_EQ(tool.read_input_registers(9, 1, &reg), LstError::IllegalDataAddress);
  // The tool answers only its own unit address: another one times out.
  cfg.unit_id = 2;
  cfg.retries = 0;
  cfg.response_timeout_s = 0.05;
  tool.disconnect();
  LstTool other(cfg);
  EXPECT_EQ(other.read_status(s), LstError::Timeout);
}

TEST(LstServer, OptionsFromTheProjectConfig) {
  LstToolConfig tool = load_lst_tool_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  LstServerOptions o = lst_server_options(tool, FORESIGHT_CONFIG_DIR "/scene.yaml");
  EXPECT_EQ(o.port, tool.port);
  EXPECT_EQ(o.host, "127.0.0.1");
  EXPECT_DOUBLE_EQ(o.mechanism.screw.engaged_turns, 8.0);
  EXPECT_DOUBLE_EQ(o.mechanism.screw.breakaway_torque_nm, 15.0);
  // The configured task torques fit the simulated screw and tool.
  EXPECT_GT(tool.loosen_torque_limit_nm, o.mechanism.screw.breakaway_torque_nm);
  EXPECT_LE(tool.loosen_torque_limit_nm, o.mechanism.max_torque_nm);
  EXPECT_LE(tool.speed_rad_s, o.mechanism.max_speed_rad_s);
  // Run it on an ephemeral port (the configured one may be taken by a parallel test).
  o.port = 0;
  LstServer server(o);
  tool.port = server.port();
  LstTool client(tool);
  LstStatus s;
  ASSERT_FALSE(client.read_status(s)) << client.last_error_message();
  EXPECT_TRUE(s.ready());
}

TEST(LstServer, GarbageOnTheLinkIsDroppedAndTheNextRequestAnswered) {
  LstServer server(server_options());
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(server.port()));
  ASSERT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  // An MBAP header announcing 16 kB, then junk.
  const std::uint8_t junk[] = {0x12, 0x34, 0x00, 0x00, 0x40, 0x00, 0x01, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
  ASSERT_EQ(write(fd, junk, sizeof junk), static_cast<ssize_t>(sizeof junk));
  // Longer than the server's 50 ms byte timeout: the junk's tail is dropped.
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  // A valid FC 04 request for the 8 status registers on the same connection.
  const std::uint8_t req[] = {0x00, 0x07, 0x00, 0x00, 0x00, 0x06, 0x01, 0x04, 0x00, 0x00, 0x00, 0x08};
  ASSERT_EQ(write(fd, req, sizeof req), static_cast<ssize_t>(sizeof req));
  std::uint8_t rsp[128] = {};
  std::size_t got = 0;
  const auto t0 = Clock::now();
  while (seconds_since(t0) < 0.3) {
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, 20) <= 0) continue;
    const ssize_t n = read(fd, rsp + got, sizeof rsp - got);
    if (n <= 0) break;
    got += static_cast<std::size_t>(n);
  }
  close(fd);
  // The junk's function code 0xFF is answered with exception 01 (illegal
  // function), the rest of the junk is dropped, and our request is answered:
  // MBAP 7 + function + byte count + 16 data bytes.
  ASSERT_EQ(got, 9u + 25u) << "bytes received";
  EXPECT_EQ(rsp[0], 0x12);
  EXPECT_EQ(rsp[1], 0x34);
  EXPECT_EQ(rsp[8], 0x01);
  const std::uint8_t* r = rsp + 9;
  EXPECT_EQ(r[1], 0x07);  // our transaction id
  EXPECT_EQ(r[7], 0x04);
  EXPECT_EQ(r[8], 16);
  EXPECT_EQ(r[10] & lst::kStatusReady, lst::kStatusReady);  // STATUS low byte
  EXPECT_TRUE(server.running());
}

// Every Modbus write function code is range-checked: FC 06, 16, 22 (mask
// write) and 23 (read/write multiple) refuse an out-of-range speed or torque
// limit with exception 03 and leave the register as it was (issue 12).
TEST(LstServer, EveryWriteFunctionCodeIsRangeChecked) {
  LstServer server(server_options());
  modbus_t* ctx = modbus_new_tcp("127.0.0.1", server.port());
  ASSERT_NE(ctx, nullptr);
  modbus_set_response_timeout(ctx, 1, 0);
  ASSERT_EQ(modbus_connect(ctx), 0);
  const auto speed_counts = [](double rad_s) { return static_cast<std::uint16_t>(std::lround(rad_s / lst::kSpeedRadSPerCount)); };
  const auto torque_counts = [](double nm) { return static_cast<std::uint16_t>(std::lround(nm / lst::kTorqueNmPerCount)); };
  const std::uint16_t ok_speed = speed_counts(10.0), bad_speed = speed_counts(25.0);     // tool max 20 rad/s
  const std::uint16_t ok_torque = torque_counts(30.0), bad_torque = torque_counts(70.0);  // tool max 60 N m
  std::uint16_t regs[2] = {};
  auto read_back = [&] {
    EXPECT_EQ(modbus_read_registers(ctx, lst::kHoldSpeedCmd, 2, regs), 2);
  };
  // In range: accepted by each function code.
  ASSERT_EQ(modbus_write_register(ctx, lst::kHoldSpeedCmd, ok_speed), 1);
  const std::uint16_t both[2] = {ok_speed, ok_torque};
  ASSERT_EQ(modbus_write_registers(ctx, lst::kHoldSpeedCmd, 2, both), 2);
  ASSERT_EQ(modbus_mask_write_register(ctx, lst::kHoldTorqueLimit, 0x0000, ok_torque), 1);
  ASSERT_EQ(modbus_write_and_read_registers(ctx, lst::kHoldSpeedCmd, 1, &ok_speed, lst::kHoldSpeedCmd, 2, regs), 2);
  read_back();
  EXPECT_EQ(regs[0], ok_speed);
  EXPECT_EQ(regs[1], ok_torque);
  // Out of range: exception 03 (EMBXILVAL) from every write function code.
  errno = 0;
  EXPECT_EQ(modbus_write_register(ctx, lst::kHoldSpeedCmd, bad_speed), -1);  // FC 06
  EXPECT_EQ(errno, EMBXILVAL);
  const std::uint16_t bad_both[2] = {ok_speed, bad_torque};
  errno = 0;
  EXPECT_EQ(modbus_write_registers(ctx, lst::kHoldSpeedCmd, 2, bad_both), -1);  // FC 16
  EXPECT_EQ(errno, EMBXILVAL);
  errno = 0;
  EXPECT_EQ(modbus_mask_write_register(ctx, lst::kHoldSpeedCmd, 0x0000, bad_speed), -1);  // FC 22
  EXPECT_EQ(errno, EMBXILVAL);
  errno = 0;
  EXPECT_EQ(modbus_mask_write_register(ctx, lst::kHoldTorqueLimit, 0x0000, bad_torque), -1);  // FC 22
  EXPECT_EQ(errno, EMBXILVAL);
  errno = 0;
  EXPECT_EQ(modbus_write_and_read_registers(ctx, lst::kHoldSpeedCmd, 1, &bad_speed, lst::kHoldSpeedCmd, 2, regs), -1);  // FC 23
  EXPECT_EQ(errno, EMBXILVAL);
  errno = 0;
  EXPECT_EQ(modbus_write_and_read_registers(ctx, lst::kHoldSpeedCmd, 2, bad_both, lst::kHoldSpeedCmd, 2, regs), -1);  // FC 23
  EXPECT_EQ(errno, EMBXILVAL);
  read_back();  // nothing changed
  EXPECT_EQ(regs[0], ok_speed);
  EXPECT_EQ(regs[1], ok_torque);
  modbus_close(ctx);
  modbus_free(ctx);
}
