#include "foresight/hw/video_switch.hpp"

#include <modbus/modbus.h>

#include <cerrno>
#include <cmath>
#include <thread>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight::hw {

namespace {

class VideoSwitchCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "video_switch"; }
  std::string message(int ev) const override {
    switch (static_cast<VideoSwitchError>(ev)) {
      case VideoSwitchError::IllegalFunction: return "illegal function (Modbus exception 01)";
      case VideoSwitchError::IllegalDataAddress: return "illegal data address (Modbus exception 02)";
      case VideoSwitchError::IllegalDataValue: return "illegal data value (Modbus exception 03)";
      case VideoSwitchError::DeviceFailure: return "device failure (Modbus exception 04)";
      case VideoSwitchError::DeviceBusy: return "device busy (Modbus exception 06)";
      case VideoSwitchError::Timeout: return "timeout: no response from the video switch";
      case VideoSwitchError::ConnectionFailed: return "connection failed";
      case VideoSwitchError::BadResponse: return "bad response";
      case VideoSwitchError::InvalidArgument: return "invalid argument";
    }
    return "unknown video_switch error " + std::to_string(ev);
  }
};

std::error_code map_errno(int err) {
  switch (err) {
    case EMBXILFUN: return VideoSwitchError::IllegalFunction;
    case EMBXILADD: return VideoSwitchError::IllegalDataAddress;
    case EMBXILVAL: return VideoSwitchError::IllegalDataValue;
    case EMBXSFAIL: return VideoSwitchError::DeviceFailure;
    case EMBXSBUSY: return VideoSwitchError::DeviceBusy;
    case ETIMEDOUT: return VideoSwitchError::Timeout;
    case EMBMDATA: return VideoSwitchError::InvalidArgument;
    case EMBXACK:
    case EMBXNACK:
    case EMBXMEMPAR:
    case EMBXGPATH:
    case EMBXGTAR:
    case EMBBADCRC:
    case EMBBADDATA:
    case EMBBADEXC:
    case EMBUNKEXC:
    case EMBBADSLAVE: return VideoSwitchError::BadResponse;
    default: return VideoSwitchError::ConnectionFailed;
  }
}

bool definite_answer(std::error_code ec) {
  return ec == VideoSwitchError::IllegalFunction || ec == VideoSwitchError::IllegalDataAddress ||
         ec == VideoSwitchError::IllegalDataValue || ec == VideoSwitchError::DeviceFailure ||
         ec == VideoSwitchError::InvalidArgument || ec == VideoSwitchError::BadResponse;
}

/// Radians -> int16 mrad counts on the wire.
bool angle_counts(double rad, std::uint16_t& out) {
  if (!std::isfinite(rad)) return false;
  const double c = std::round(rad / video::kRadPerCount);
  if (c < -32768.0 || c > 32767.0) return false;
  out = static_cast<std::uint16_t>(static_cast<std::int16_t>(c));
  return true;
}

}  // namespace

const std::error_category& video_switch_error_category() noexcept {
  static const VideoSwitchCategory category;
  return category;
}

std::error_code make_error_code(VideoSwitchError e) noexcept {
  return {static_cast<int>(e), video_switch_error_category()};
}

std::optional<VideoSwitchSection> parse_video_switch_section(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = yaml::parse(yaml_text, source);
  if (!root.IsMap() || !root["video_switch"]) return std::nullopt;
  const yaml::MapReader n = yaml::MapReader(root, source, "").map("video_switch");
  n.check_keys({"host", "port", "unit_id", "response_timeout_ms", "retries", "cameras"});
  VideoSwitchSection s;
  s.line = n.line();
  s.link.host = n.get<std::string>("host", "the switch's address");
  if (s.link.host.empty()) n.fail_key("host", "empty (the switch's address)");
  s.link.port = n.get_or<int>("port", s.link.port);
  if (s.link.port < 1 || s.link.port > 65535) n.fail_key("port", std::to_string(s.link.port) + " is outside 1..65535");
  s.link.unit_id = n.get_or<int>("unit_id", s.link.unit_id);
  if (s.link.unit_id < 0 || s.link.unit_id > 255)
    n.fail_key("unit_id", std::to_string(s.link.unit_id) + " is outside 0..255");
  const double timeout_ms = n.get_or<double>("response_timeout_ms", s.link.response_timeout_s * 1e3);
  if (!(timeout_ms > 0.0 && timeout_ms <= 10000.0)) n.fail_key("response_timeout_ms", "must be in (0, 10000]");
  s.link.response_timeout_s = timeout_ms * 1e-3;
  s.link.retries = n.get_or<int>("retries", s.link.retries);
  if (s.link.retries < 0 || s.link.retries > 10) n.fail_key("retries", std::to_string(s.link.retries) + " is outside 0..10");
  const YAML::Node cams = n["cameras"];
  if (!cams || !cams.IsSequence() || cams.size() == 0)
    n.fail_key("cameras", "must be a non-empty list of camera names (index = switch input)");
  for (const auto& c : cams) {
    if (!c.IsScalar() || c.Scalar().empty())
      n.fail(c, n.name("cameras") + ": a name must be a non-empty string");
    for (const auto& earlier : s.camera_names)
      if (earlier == c.Scalar())
        n.fail(c, n.name("cameras") + ": '" + earlier + "' is listed twice");
    s.camera_names.push_back(c.Scalar());
  }
  return s;
}

std::optional<VideoSwitchSection> load_video_switch_section(const std::string& remote_yaml_path) {
  return parse_video_switch_section(read_text_file(remote_yaml_path, "cannot open the remote configuration file"),
                                    remote_yaml_path);
}

std::string VideoSwitchConfig::describe() const {
  return "tcp " + host + ":" + std::to_string(port) + " unit " + std::to_string(unit_id);
}

VideoSwitchStatus decode_video_status(const std::uint16_t (&in)[video::kNumInput]) noexcept {
  VideoSwitchStatus s;
  s.active_camera = in[video::kInActive];
  s.pan_rad = static_cast<std::int16_t>(in[video::kInPan]) * video::kRadPerCount;
  s.tilt_rad = static_cast<std::int16_t>(in[video::kInTilt]) * video::kRadPerCount;
  s.focal_px = in[video::kInFocal];
  s.camera_count = in[video::kInCameraCount];
  s.grab_count = (static_cast<std::uint32_t>(in[video::kInGrabHi]) << 16) | in[video::kInGrabLo];
  s.switches = in[video::kInSwitches];
  return s;
}

VideoSwitch::VideoSwitch(VideoSwitchConfig config) : config_(std::move(config)) {
  const std::string src = "video switch";
  if (config_.port < 1 || config_.port > 65535)
    throw InputError(src, "port " + std::to_string(config_.port) + " outside 1..65535");
  if (config_.unit_id < 0 || config_.unit_id > 255)
    throw InputError(src, "unit_id " + std::to_string(config_.unit_id) + " outside 0..255");
  if (!(config_.response_timeout_s > 0.0) || !std::isfinite(config_.response_timeout_s))
    throw InputError(src, "response_timeout_s must be a positive number");
  if (config_.retries < 0 || config_.retries > 10)
    throw InputError(src, "retries " + std::to_string(config_.retries) + " outside 0..10");
  if (!(config_.reconnect_delay_s >= 0.0)) throw InputError(src, "reconnect_delay_s must not be negative");
  ctx_ = modbus_new_tcp(config_.host.c_str(), config_.port);
  if (!ctx_) throw InputError(src, "cannot create the Modbus context for " + config_.describe());
  modbus_set_slave(ctx_, config_.unit_id);
  const double t = config_.response_timeout_s;
  const auto sec = static_cast<std::uint32_t>(t);
  const auto usec = static_cast<std::uint32_t>(std::lround((t - sec) * 1e6));
  modbus_set_response_timeout(ctx_, sec, usec);
  modbus_set_byte_timeout(ctx_, sec, usec);
}

VideoSwitch::~VideoSwitch() {
  close_link();
  if (ctx_) modbus_free(ctx_);
}

std::error_code VideoSwitch::open_link() {
  if (connected_) return {};
  if (modbus_connect(ctx_) == -1) {
    const int err = errno;
    modbus_close(ctx_);
    detail_ = std::string("connect: ") + modbus_strerror(err);
    return VideoSwitchError::ConnectionFailed;
  }
  connected_ = true;
  return {};
}

void VideoSwitch::close_link() noexcept {
  if (ctx_ && connected_) modbus_close(ctx_);
  connected_ = false;
}

std::error_code VideoSwitch::connect() {
  return transact("connect", [](modbus_t*) { return 0; });
}

void VideoSwitch::disconnect() noexcept { close_link(); }

std::error_code VideoSwitch::transact(const std::string& what, const std::function<int(modbus_t*)>& request) {
  std::error_code ec;
  int attempt = 0;
  for (; attempt < 1 + config_.retries; ++attempt) {
    if (attempt > 0 && config_.reconnect_delay_s > 0.0)
      std::this_thread::sleep_for(std::chrono::duration<double>(config_.reconnect_delay_s));
    if (!connected_) {
      ec = open_link();
      if (ec) continue;
    }
    errno = 0;
    if (request(ctx_) != -1) return {};
    const int err = errno;
    ec = map_errno(err);
    detail_ = modbus_strerror(err);
    if (definite_answer(ec)) {
      ++attempt;
      break;
    }
    close_link();  // timeout or lost link: a late answer must not pair with the next request
  }
  last_error_ = what + " (" + config_.describe() + "): " + ec.message();
  if (ec == VideoSwitchError::ConnectionFailed && !detail_.empty()) last_error_ += " (" + detail_ + ")";
  if (attempt > 1) last_error_ += " after " + std::to_string(attempt) + " attempts";
  return ec;
}

std::error_code VideoSwitch::write_register(int address, std::uint16_t value) {
  return transact("write holding register " + std::to_string(address) + " = " + std::to_string(value),
                  [&](modbus_t* ctx) { return modbus_write_register(ctx, address, value) == 1 ? 0 : -1; });
}

std::error_code VideoSwitch::write_registers(int address, int count, const std::uint16_t* values) {
  return transact("write holding registers " + std::to_string(address) + ".." + std::to_string(address + count - 1),
                  [&](modbus_t* ctx) { return modbus_write_registers(ctx, address, count, values) == count ? 0 : -1; });
}

std::error_code VideoSwitch::read_holding_registers(int address, int count, std::uint16_t* dest) {
  return transact("read holding registers " + std::to_string(address), [&](modbus_t* ctx) {
    return modbus_read_registers(ctx, address, count, dest) == count ? 0 : -1;
  });
}

std::error_code VideoSwitch::read_input_registers(int address, int count, std::uint16_t* dest) {
  return transact("read input registers " + std::to_string(address), [&](modbus_t* ctx) {
    return modbus_read_input_registers(ctx, address, count, dest) == count ? 0 : -1;
  });
}

std::error_code VideoSwitch::select(int camera) {
  if (camera < 0 || camera > 65535) {
    last_error_ = "select camera " + std::to_string(camera) + ": " +
                  make_error_code(VideoSwitchError::InvalidArgument).message();
    return VideoSwitchError::InvalidArgument;
  }
  return write_register(video::kHoldCamera, static_cast<std::uint16_t>(camera));
}

std::error_code VideoSwitch::set_view(const CameraView& v) {
  std::uint16_t regs[video::kNumHolding] = {};
  const bool ok = v.camera >= 0 && v.camera <= 65535 && angle_counts(v.pan_rad, regs[video::kHoldPan]) &&
                  angle_counts(v.tilt_rad, regs[video::kHoldTilt]) && std::isfinite(v.focal_px) &&
                  v.focal_px >= 0.0 && std::round(v.focal_px) <= 65535.0;
  if (!ok) {
    last_error_ = "set view of camera " + std::to_string(v.camera) + ": " +
                  make_error_code(VideoSwitchError::InvalidArgument).message() + " (a value not representable)";
    return VideoSwitchError::InvalidArgument;
  }
  regs[video::kHoldCamera] = static_cast<std::uint16_t>(v.camera);
  regs[video::kHoldFocal] = static_cast<std::uint16_t>(std::lround(v.focal_px));
  return write_registers(0, video::kNumHolding, regs);
}

std::error_code VideoSwitch::grab() {
  return transact("grab", [](modbus_t* ctx) { return modbus_write_bit(ctx, video::kCoilGrab, 1) == 1 ? 0 : -1; });
}

std::error_code VideoSwitch::read_status(VideoSwitchStatus& out) {
  std::uint16_t regs[video::kNumInput] = {};
  if (auto ec = read_input_registers(0, video::kNumInput, regs)) return ec;
  out = decode_video_status(regs);
  return {};
}

std::error_code VideoSwitch::read_view(CameraView& out) {
  std::uint16_t regs[video::kNumHolding] = {};
  if (auto ec = read_holding_registers(0, video::kNumHolding, regs)) return ec;
  out.camera = regs[video::kHoldCamera];
  out.pan_rad = static_cast<std::int16_t>(regs[video::kHoldPan]) * video::kRadPerCount;
  out.tilt_rad = static_cast<std::int16_t>(regs[video::kHoldTilt]) * video::kRadPerCount;
  out.focal_px = regs[video::kHoldFocal];
  return {};
}

}  // namespace foresight::hw
