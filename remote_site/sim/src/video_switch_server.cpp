#include "foresight/sim/video_switch_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "foresight/common/scene.hpp"
#include "foresight/hw/video_switch.hpp"
#include "modbus_serving.hpp"

namespace foresight::sim {

namespace video = hw::video;

struct VideoSwitchServer::Impl {
  modbus_t* ctx = nullptr;
  modbus_mapping_t* map = nullptr;
  std::uint8_t query[MODBUS_MAX_ADU_LENGTH] = {};
};

VideoSwitchServerOptions video_switch_options_from_scene(const std::string& scene_yaml_path) {
  const Scene scene = Scene::from_file(scene_yaml_path);
  VideoSwitchServerOptions o;
  o.camera_names = scene.camera_order;
  o.initial_focal_px.clear();
  for (const std::string& name : scene.camera_order) o.initial_focal_px.push_back(scene.cameras.at(name).f_px);
  return o;
}

VideoSwitchServer::VideoSwitchServer(VideoSwitchServerOptions options)
    : options_(std::move(options)), impl_(std::make_unique<Impl>()) {
  const auto& o = options_;
  if (o.camera_names.empty()) throw VideoSwitchServerError("VideoSwitchServer: no cameras");
  if (o.camera_names.size() > 1000) throw VideoSwitchServerError("VideoSwitchServer: more than 1000 cameras");
  if (o.initial_focal_px.size() != o.camera_names.size())
    throw VideoSwitchServerError("VideoSwitchServer: " + std::to_string(o.camera_names.size()) + " cameras but " +
                                 std::to_string(o.initial_focal_px.size()) + " initial focal lengths");
  auto in_range = [](int v, int lo, int hi) { return v >= lo && v <= hi; };
  if (!in_range(o.pan_limit_mrad, 0, 32767) || !in_range(o.tilt_limit_mrad, 0, 32767))
    throw VideoSwitchServerError("VideoSwitchServer: pan/tilt limits must lie in 0..32767 mrad");
  if (!in_range(o.focal_min_px, 1, 65535) || !in_range(o.focal_max_px, o.focal_min_px, 65535))
    throw VideoSwitchServerError("VideoSwitchServer: focal range must satisfy 1 <= min <= max <= 65535 px");
  if (!(o.poll_s > 0.0 && o.poll_s < 1.0)) throw VideoSwitchServerError("VideoSwitchServer: poll_s must lie in (0, 1) s");
  for (std::size_t i = 0; i < o.initial_focal_px.size(); ++i) {
    const double f = o.initial_focal_px[i];
    if (!std::isfinite(f) || std::lround(f) < o.focal_min_px || std::lround(f) > o.focal_max_px)
      throw VideoSwitchServerError("VideoSwitchServer: initial focal length of camera '" + o.camera_names[i] +
                                   "' outside " + std::to_string(o.focal_min_px) + ".." +
                                   std::to_string(o.focal_max_px) + " px");
    state_.views.push_back({0, 0, static_cast<int>(std::lround(f))});
  }

  impl_->map = modbus_mapping_new(video::kNumCoils, 0, video::kNumHolding, video::kNumInput);
  if (!impl_->map) throw VideoSwitchServerError("VideoSwitchServer: modbus_mapping_new failed");
  impl_->map->tab_registers[video::kHoldCamera] = 0;
  impl_->map->tab_registers[video::kHoldPan] = 0;
  impl_->map->tab_registers[video::kHoldTilt] = 0;
  impl_->map->tab_registers[video::kHoldFocal] = static_cast<std::uint16_t>(state_.views[0].focal_px);
  apply_outputs();

  port_ = o.port;
  impl_->ctx = modbus_new_tcp(o.host.c_str(), port_);
  if (!impl_->ctx) {
    modbus_mapping_free(impl_->map);
    throw VideoSwitchServerError("VideoSwitchServer: modbus_new_tcp failed for " + o.host);
  }
  listen_fd_ = modbus_tcp_listen(impl_->ctx, 1);
  if (listen_fd_ < 0) {
    const std::string msg = "VideoSwitchServer: cannot listen on " + o.host + ":" + std::to_string(port_) + ": " +
                            modbus_strerror(errno);
    modbus_free(impl_->ctx);
    modbus_mapping_free(impl_->map);
    throw VideoSwitchServerError(msg);
  }
  fcntl(listen_fd_, F_SETFD, FD_CLOEXEC);
  sockaddr_in addr{};
  socklen_t len = sizeof addr;
  if (getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len) == 0) port_ = ntohs(addr.sin_port);
  const auto poll_us = static_cast<std::uint32_t>(std::lround(o.poll_s * 1e6));
  modbus_set_indication_timeout(impl_->ctx, 0, poll_us);
  modbus_set_byte_timeout(impl_->ctx, 0, 50000);
  thread_ = std::thread([this] { loop(); });
}

VideoSwitchServer::~VideoSwitchServer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (client_fd_ >= 0) close(client_fd_);
  if (listen_fd_ >= 0) close(listen_fd_);
  modbus_set_socket(impl_->ctx, -1);
  modbus_free(impl_->ctx);
  modbus_mapping_free(impl_->map);
}

VideoSwitchState VideoSwitchServer::state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

int VideoSwitchServer::camera_index(const std::string& name) const {
  const auto& n = options_.camera_names;
  const auto it = std::find(n.begin(), n.end(), name);
  return it == n.end() ? -1 : static_cast<int>(it - n.begin());
}

void VideoSwitchServer::apply_outputs() {
  modbus_mapping_t* m = impl_->map;
  const VideoSwitchState::View& v = state_.views[static_cast<std::size_t>(state_.active)];
  m->tab_input_registers[video::kInActive] = static_cast<std::uint16_t>(state_.active);
  m->tab_input_registers[video::kInPan] = static_cast<std::uint16_t>(static_cast<std::int16_t>(v.pan_mrad));
  m->tab_input_registers[video::kInTilt] = static_cast<std::uint16_t>(static_cast<std::int16_t>(v.tilt_mrad));
  m->tab_input_registers[video::kInFocal] = static_cast<std::uint16_t>(v.focal_px);
  m->tab_input_registers[video::kInCameraCount] = static_cast<std::uint16_t>(state_.views.size());
  m->tab_input_registers[video::kInGrabHi] = static_cast<std::uint16_t>(state_.grabs >> 16);
  m->tab_input_registers[video::kInGrabLo] = static_cast<std::uint16_t>(state_.grabs & 0xFFFFu);
  m->tab_input_registers[video::kInSwitches] = state_.switches;
}

void VideoSwitchServer::serve_one(int rc) {
  if (silent_) return;
  modbus_t* ctx = impl_->ctx;
  modbus_mapping_t* m = impl_->map;
  const std::uint8_t* q = impl_->query;
  std::lock_guard lock(mutex_);
  // Which holding registers this request writes (FC 6, 16, 22, 23), and
  // whether every value is in range (out of range: exception 03, nothing
  // changes).
  int lo = 1 << 20, hi = -1;
  std::uint16_t values[video::kNumHolding] = {};
  auto check = [&](int address, std::uint16_t v) {
    const auto s = static_cast<std::int16_t>(v);
    switch (address) {
      case video::kHoldCamera: return v < state_.views.size();
      case video::kHoldPan: return std::abs(static_cast<int>(s)) <= options_.pan_limit_mrad;
      case video::kHoldTilt: return std::abs(static_cast<int>(s)) <= options_.tilt_limit_mrad;
      case video::kHoldFocal: return v >= options_.focal_min_px && v <= options_.focal_max_px;
      default: return true;  // outside the map: libmodbus answers exception 02
    }
  };
  const bool refuse = !modbus_serving::register_writes_ok(ctx, q, rc, m, [&](int address, std::uint16_t v) {
    if (!check(address, v)) return false;
    if (address >= 0 && address < video::kNumHolding) values[address] = v;
    lo = std::min(lo, address);  // a write running past the map is exception 02: nothing changes
    hi = std::max(hi, address);
    return true;
  });
  const int first = hi >= lo ? lo : -1;
  const int count = hi >= lo ? hi - lo + 1 : 0;
  if (refuse) {
    modbus_reply_exception(ctx, q, MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE);
    ++answered_;
    return;
  }
  if (modbus_reply(ctx, q, rc, m) != -1) ++answered_;
  const bool wrote_holding = first >= 0 && count >= 1 && first + count <= video::kNumHolding;
  if (wrote_holding) {
    auto written = [&](int a) { return a >= first && a < first + count; };
    if (written(video::kHoldCamera)) {
      const int cam = values[video::kHoldCamera];
      if (cam != state_.active) ++state_.switches;
      state_.active = cam;
      const VideoSwitchState::View& v = state_.views[static_cast<std::size_t>(cam)];
      if (!written(video::kHoldPan)) m->tab_registers[video::kHoldPan] = static_cast<std::uint16_t>(static_cast<std::int16_t>(v.pan_mrad));
      if (!written(video::kHoldTilt)) m->tab_registers[video::kHoldTilt] = static_cast<std::uint16_t>(static_cast<std::int16_t>(v.tilt_mrad));
      if (!written(video::kHoldFocal)) m->tab_registers[video::kHoldFocal] = static_cast<std::uint16_t>(v.focal_px);
    }
    VideoSwitchState::View& v = state_.views[static_cast<std::size_t>(state_.active)];
    v.pan_mrad = static_cast<std::int16_t>(m->tab_registers[video::kHoldPan]);
    v.tilt_mrad = static_cast<std::int16_t>(m->tab_registers[video::kHoldTilt]);
    v.focal_px = m->tab_registers[video::kHoldFocal];
  }
  if (m->tab_bits[video::kCoilGrab]) {
    ++state_.grabs;
    m->tab_bits[video::kCoilGrab] = 0;
  }
  apply_outputs();
}

void VideoSwitchServer::loop() {
  const int poll_ms = std::max(1, static_cast<int>(std::lround(options_.poll_s * 1e3)));
  while (!stop_)
    modbus_serving::serve_tcp_once(impl_->ctx, listen_fd_, client_fd_, impl_->query, poll_ms,
                                   [this](int rc) { serve_one(rc); });
}

}  // namespace foresight::sim
