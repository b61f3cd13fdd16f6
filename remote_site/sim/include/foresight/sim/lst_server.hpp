#pragma once
// The simulated LST tool: a libmodbus server speaking the register map of
// foresight/hw/lst_tool_registers.hpp, backed by LstMechanism (screw_model.hpp).
// It runs on its own thread; the physics advances by the wall-clock time
// between loop turns (the loop turns at least every poll_s: libmodbus'
// indication timeout bounds every wait, so stop() always returns promptly).
//
//   TCP: listens on host:port (default 127.0.0.1, port 0 = an ephemeral port
//        chosen by the kernel: read it with port(), so parallel tests never
//        collide). One client at a time; a new connection replaces the old.
//   RTU: creates a pseudo-terminal pair (openpty); the server speaks on the
//        master side, a client opens device_path() (the slave, /dev/pts/N)
//        like any serial port.
//
// Fault injection for tests: set_silent (requests are read and never
// answered), inject_exception (answer with a Modbus exception code), jam,
// stuck latch, socket not engaged; stop()/start() kill and restart the server
// (TCP: on the same port).
//
// Not real-time: a simulator for tests, the demo and hil_tests. The control
// methods are thread-safe (called from the test thread while the server runs).

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include "foresight/common/error.hpp"
#include "foresight/hw/lst_tool.hpp"
#include "foresight/sim/screw_model.hpp"

namespace foresight::sim {

struct LstServerOptions {
  enum class Transport { Tcp, Rtu };
  Transport transport = Transport::Tcp;
  std::string host = "127.0.0.1";
  int port = 0;         ///< TCP; 0 = ephemeral
  int unit_id = 1;      ///< RTU: requests to other addresses are ignored
  int baud = 115200;    ///< RTU nominal rate (a pty has no real rate)
  double poll_s = 0.005;  ///< indication timeout = longest physics step
  LstMechanismParams mechanism;
};

/// Options for the simulated tool the daemon's client will reach: the link
/// of `tool` (its `tool:` section; TCP: host and port, RTU: unit id, the
/// device then being the server's own pty) and the mechanism of the scene's
/// `lst_sim:` section. Throws InputError from the scene loader.
LstServerOptions lst_server_options(const hw::LstToolConfig& tool, const std::string& scene_yaml_path);

/// The server could not be set up (bind, listen, openpty); set-up only.
class LstServerError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

class LstServer {
 public:
  /// Sets up the link and starts the server thread. Throws LstServerError.
  explicit LstServer(LstServerOptions options);
  ~LstServer();  ///< stops
  LstServer(const LstServer&) = delete;
  LstServer& operator=(const LstServer&) = delete;

  /// TCP port the server listens on (the ephemeral one when options.port = 0).
  int port() const { return port_; }
  /// RTU: the serial device a client opens (pty slave).
  const std::string& device_path() const { return device_path_; }

  /// Kill: stop the thread and close every socket (clients see the
  /// connection drop; new connections are refused). Idempotent.
  void stop();
  /// Restart after stop() (TCP: same port; RTU: same pty). The mechanism
  /// keeps its state (the tool's power stayed on; only its link restarted).
  void start();
  bool running() const { return thread_.joinable(); }

  // ---- fault injection --------------------------------------------------------
  /// Read requests but never answer them (a tool that stopped answering).
  void set_silent(bool silent) { silent_ = silent; }
  /// Answer the next `count` requests (-1: all until cleared with code 0)
  /// with Modbus exception `code` (1..11).
  void inject_exception(int code, int count = -1);
  void set_jam(bool jammed);
  void set_latch_stuck(bool stuck);
  void set_socket_engaged(bool engaged);

  // ---- ground truth -------------------------------------------------------------
  LstToolState state() const;
  std::uint64_t requests_answered() const { return answered_; }
  std::uint64_t requests_received() const { return received_; }

 private:
  void open_link();
  void close_link();
  void loop();
  void serve_one(int rc);
  void apply_outputs(bool stopped);

  LstServerOptions options_;
  int port_ = 0;
  std::string device_path_;
  int listen_fd_ = -1;
  int client_fd_ = -1;
  int pty_master_ = -1;
  int pty_slave_ = -1;
  struct Impl;
  std::unique_ptr<Impl> impl_;  // libmodbus context + mapping
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> silent_{false};
  std::atomic<std::uint64_t> answered_{0};
  std::atomic<std::uint64_t> received_{0};

  mutable std::mutex mutex_;  // guards mech_ and the injection fields below
  LstMechanism mech_;
  int exception_code_ = 0;
  int exception_count_ = 0;
};

}  // namespace foresight::sim
