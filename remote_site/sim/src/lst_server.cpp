#include "foresight/sim/lst_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <poll.h>
#include <pty.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>

#include "foresight/hw/lst_tool_registers.hpp"
#include "modbus_serving.hpp"

namespace foresight::sim {

namespace lst = hw::lst;

struct LstServer::Impl {
  modbus_t* ctx = nullptr;
  modbus_mapping_t* map = nullptr;
  std::uint8_t query[MODBUS_MAX_ADU_LENGTH] = {};
  std::chrono::steady_clock::time_point last_step{};
};

namespace {

std::string errno_text(const char* what) { return std::string(what) + ": " + std::strerror(errno); }

std::int16_t clamp16(double v) {
  return static_cast<std::int16_t>(std::clamp(std::lround(v), -32768L, 32767L));
}

}  // namespace

LstServerOptions lst_server_options(const hw::LstToolConfig& tool, const std::string& scene_yaml_path) {
  LstServerOptions o;
  o.transport = tool.transport == hw::LstToolConfig::Transport::Tcp ? LstServerOptions::Transport::Tcp
                                                                   : LstServerOptions::Transport::Rtu;
  o.host = tool.host;
  o.port = tool.port;
  o.unit_id = tool.unit_id;
  o.baud = tool.baud;
  o.mechanism = load_lst_mechanism_params(scene_yaml_path);
  return o;
}

LstServer::LstServer(LstServerOptions options)
    : options_(std::move(options)), impl_(std::make_unique<Impl>()), mech_(options_.mechanism) {
  if (!(options_.poll_s > 0.0 && options_.poll_s < 1.0)) throw LstServerError("LstServer: poll_s must lie in (0, 1) s");
  impl_->map = modbus_mapping_new(lst::kNumCoils, lst::kNumDiscreteInputs, lst::kNumHolding, lst::kNumInput);
  if (!impl_->map) throw LstServerError(errno_text("LstServer: modbus_mapping_new"));
  port_ = options_.port;
  if (options_.transport == LstServerOptions::Transport::Rtu) {
    char name[256] = {};
    if (openpty(&pty_master_, &pty_slave_, name, nullptr, nullptr) != 0) {
      modbus_mapping_free(impl_->map);
      throw LstServerError(errno_text("LstServer: openpty"));
    }
    // Raw line discipline on the slave until a client opens and configures it.
    termios tio{};
    tcgetattr(pty_slave_, &tio);
    cfmakeraw(&tio);
    tcsetattr(pty_slave_, TCSANOW, &tio);
    fcntl(pty_master_, F_SETFD, FD_CLOEXEC);
    fcntl(pty_slave_, F_SETFD, FD_CLOEXEC);
    device_path_ = name;
  }
  {
    std::lock_guard lock(mutex_);
    apply_outputs(false);
  }
  try {
    start();
  } catch (...) {
    if (pty_master_ >= 0) close(pty_master_);
    if (pty_slave_ >= 0) close(pty_slave_);
    modbus_mapping_free(impl_->map);
    throw;
  }
}

LstServer::~LstServer() {
  stop();
  if (pty_master_ >= 0) close(pty_master_);
  if (pty_slave_ >= 0) close(pty_slave_);
  modbus_mapping_free(impl_->map);
}

void LstServer::open_link() {
  const auto poll_us = static_cast<std::uint32_t>(std::lround(options_.poll_s * 1e6));
  if (options_.transport == LstServerOptions::Transport::Tcp) {
    impl_->ctx = modbus_new_tcp(options_.host.c_str(), port_);
    if (!impl_->ctx) throw LstServerError(errno_text("LstServer: modbus_new_tcp"));
    listen_fd_ = modbus_tcp_listen(impl_->ctx, 1);
    if (listen_fd_ < 0) {
      const std::string msg = "LstServer: cannot listen on " + options_.host + ":" + std::to_string(port_) + ": " +
                              modbus_strerror(errno);
      modbus_free(impl_->ctx);
      impl_->ctx = nullptr;
      throw LstServerError(msg);
    }
    fcntl(listen_fd_, F_SETFD, FD_CLOEXEC);
    sockaddr_in addr{};
    socklen_t len = sizeof addr;
    if (getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len) == 0) port_ = ntohs(addr.sin_port);
  } else {
    impl_->ctx = modbus_new_rtu(device_path_.c_str(), options_.baud, 'N', 8, 1);
    if (!impl_->ctx) throw LstServerError(errno_text("LstServer: modbus_new_rtu"));
    modbus_set_slave(impl_->ctx, options_.unit_id);
    modbus_set_socket(impl_->ctx, pty_master_);
  }
  modbus_set_indication_timeout(impl_->ctx, 0, poll_us);
  // RTU: after a request for another unit libmodbus waits this long for that
  // unit's answer; keep it short so the loop (and stop()) stays prompt.
  modbus_set_response_timeout(impl_->ctx, 0, poll_us);
  // A request's bytes arrive together; a stalled half-request is dropped.
  modbus_set_byte_timeout(impl_->ctx, 0, 50000);
}

void LstServer::close_link() {
  if (client_fd_ >= 0) close(client_fd_);
  if (listen_fd_ >= 0) close(listen_fd_);
  client_fd_ = listen_fd_ = -1;
  if (impl_->ctx) {
    modbus_set_socket(impl_->ctx, -1);  // the pty master stays ours (closed in the destructor)
    modbus_free(impl_->ctx);
    impl_->ctx = nullptr;
  }
}

void LstServer::start() {
  if (thread_.joinable()) return;
  open_link();
  stop_ = false;
  impl_->last_step = std::chrono::steady_clock::now();
  thread_ = std::thread([this] { loop(); });
}

void LstServer::stop() {
  if (!thread_.joinable()) return;
  stop_ = true;
  thread_.join();
  close_link();
}

void LstServer::inject_exception(int code, int count) {
  std::lock_guard lock(mutex_);
  exception_code_ = code;
  exception_count_ = code == 0 ? 0 : count;
}

void LstServer::set_jam(bool jammed) {
  std::lock_guard lock(mutex_);
  mech_.set_jam(jammed);
}

void LstServer::set_latch_stuck(bool stuck) {
  std::lock_guard lock(mutex_);
  mech_.set_latch_stuck(stuck);
}

void LstServer::set_socket_engaged(bool engaged) {
  std::lock_guard lock(mutex_);
  mech_.set_socket_engaged(engaged);
}

LstToolState LstServer::state() const {
  std::lock_guard lock(mutex_);
  return mech_.state();
}

// Registers <- mechanism (mutex_ held).
void LstServer::apply_outputs(bool stopped) {
  modbus_mapping_t* m = impl_->map;
  const LstToolState& s = mech_.state();
  if (stopped) m->tab_bits[lst::kCoilRun] = 0;
  std::uint16_t status = 0;
  if (s.fault_bits == 0) status |= lst::kStatusReady;
  if (s.running) status |= lst::kStatusRunning;
  if (s.latched) status |= lst::kStatusLatched;
  if (s.unlatched) status |= lst::kStatusUnlatched;
  if (s.torque_reached) status |= lst::kStatusTorqueReached;
  if (s.fault_bits != 0) status |= lst::kStatusFault;
  for (int i = 0; i < lst::kNumDiscreteInputs; ++i) m->tab_input_bits[i] = (status >> i) & 1u;
  const std::int32_t turns = lst::turns_to_counts(s.turns);
  const auto uturns = static_cast<std::uint32_t>(turns);
  m->tab_input_registers[lst::kInStatus] = status;
  m->tab_input_registers[lst::kInFault] = s.fault_bits;
  m->tab_input_registers[lst::kInTurnsHi] = static_cast<std::uint16_t>(uturns >> 16);
  m->tab_input_registers[lst::kInTurnsLo] = static_cast<std::uint16_t>(uturns & 0xFFFFu);
  m->tab_input_registers[lst::kInTorque] = static_cast<std::uint16_t>(clamp16(s.torque_nm / lst::kTorqueNmPerCount));
  m->tab_input_registers[lst::kInSpeed] = static_cast<std::uint16_t>(clamp16(s.speed_rad_s / lst::kSpeedRadSPerCount));
  m->tab_input_registers[lst::kInPeakTorque] =
      static_cast<std::uint16_t>(clamp16(s.peak_torque_nm / lst::kTorqueNmPerCount));
  m->tab_input_registers[lst::kInAlive] =
      static_cast<std::uint16_t>(static_cast<std::uint64_t>(s.time_s / lst::kAlivePeriodS) & 0xFFFFu);
}

namespace {

void advance(LstMechanism& mech, modbus_mapping_t* m, std::chrono::steady_clock::time_point& last, bool& stopped) {
  const auto now = std::chrono::steady_clock::now();
  double dt = std::chrono::duration<double>(now - last).count();
  last = now;
  LstCommand cmd;
  cmd.run = m->tab_bits[lst::kCoilRun] != 0;
  cmd.loosen = m->tab_bits[lst::kCoilDirection] == lst::kDirectionLoosen;
  cmd.latch = m->tab_bits[lst::kCoilLatch] != 0;
  cmd.speed_rad_s = m->tab_registers[lst::kHoldSpeedCmd] * lst::kSpeedRadSPerCount;
  cmd.torque_limit_nm = m->tab_registers[lst::kHoldTorqueLimit] * lst::kTorqueNmPerCount;
  // Integrate in steps of at most 1 ms so torque limits and stalls resolve finely.
  do {
    const double h = std::min(dt, 1e-3);
    if (mech.step(cmd, h)) {
      stopped = true;
      cmd.run = false;
    }
    dt -= h;
  } while (dt > 0.0);
}

}  // namespace

void LstServer::serve_one(int rc) {
  ++received_;
  if (silent_) return;
  modbus_t* ctx = impl_->ctx;
  const std::uint8_t* q = impl_->query;
  std::lock_guard lock(mutex_);
  // Bring the physics up to now so a read sees the present state.
  bool stopped = false;
  advance(mech_, impl_->map, impl_->last_step, stopped);
  apply_outputs(stopped);
  if (exception_code_ != 0 && exception_count_ != 0) {
    const int code = exception_code_;
    if (exception_count_ > 0 && --exception_count_ == 0) exception_code_ = 0;
    modbus_reply_exception(ctx, q, static_cast<unsigned>(code));
    ++answered_;
    return;
  }
  // The tool refuses setpoints beyond its limits (exception 03), whichever
  // function writes them.
  auto out_of_range = [&](int address, std::uint16_t value) {
    if (address == lst::kHoldSpeedCmd) return value * lst::kSpeedRadSPerCount > options_.mechanism.max_speed_rad_s + 1e-9;
    if (address == lst::kHoldTorqueLimit) return value * lst::kTorqueNmPerCount > options_.mechanism.max_torque_nm + 1e-9;
    return false;
  };
  const bool refuse = !modbus_serving::register_writes_ok(
      ctx, q, rc, impl_->map, [&](int address, std::uint16_t value) { return !out_of_range(address, value); });
  if (refuse) {
    modbus_reply_exception(ctx, q, MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE);
    ++answered_;
    return;
  }
  if (modbus_reply(ctx, q, rc, impl_->map) != -1) ++answered_;
  // Self-clearing command coils.
  modbus_mapping_t* m = impl_->map;
  if (m->tab_bits[lst::kCoilFaultReset]) {
    mech_.reset_fault();
    m->tab_bits[lst::kCoilFaultReset] = 0;
  }
  if (m->tab_bits[lst::kCoilTurnsReset]) {
    mech_.reset_turns();
    m->tab_bits[lst::kCoilTurnsReset] = 0;
  }
  stopped = false;
  advance(mech_, m, impl_->last_step, stopped);  // dt ~ 0: applies a new RUN edge at once
  apply_outputs(stopped);
}

void LstServer::loop() {
  const int poll_ms = std::max(1, static_cast<int>(std::lround(options_.poll_s * 1e3)));
  while (!stop_) {
    {
      std::lock_guard lock(mutex_);
      bool stopped = false;
      advance(mech_, impl_->map, impl_->last_step, stopped);
      apply_outputs(stopped);
    }
    if (options_.transport == LstServerOptions::Transport::Tcp) {
      modbus_serving::serve_tcp_once(impl_->ctx, listen_fd_, client_fd_, impl_->query, poll_ms,
                                     [this](int rc) { serve_one(rc); });
    } else {
      const int rc = modbus_receive(impl_->ctx, impl_->query);  // bounded by the indication timeout
      if (rc > 0)
        serve_one(rc);
      else if (rc == -1 && errno != ETIMEDOUT) {
        modbus_flush(impl_->ctx);  // bad CRC or a half frame: resynchronise
        if (errno == EIO || errno == EBADF) poll(nullptr, 0, poll_ms);  // never spin on a dead line
      }
    }
  }
}

}  // namespace foresight::sim
