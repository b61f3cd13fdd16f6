#include "foresight/hw/video_switch.hpp"

#include <cmath>

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
  s.link.port = static_cast<int>(n.get_or_int_in("port", s.link.port, 1, 65535, "(TCP port)"));
  s.link.unit_id = static_cast<int>(n.get_or_int_in("unit_id", s.link.unit_id, 0, 255, "(Modbus unit id)"));
  s.link.response_timeout_s =
      n.get_or_in("response_timeout_ms", s.link.response_timeout_s * 1e3, 1, 10000, "ms") * 1e-3;
  s.link.retries = static_cast<int>(n.get_or_int_in("retries", s.link.retries, 0, 10, "retries"));
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

ModbusLink VideoSwitchConfig::link() const {
  ModbusLink l;
  l.host = host;
  l.port = port;
  l.unit_id = unit_id;
  l.response_timeout_s = response_timeout_s;
  l.retries = retries;
  l.reconnect_delay_s = reconnect_delay_s;
  return l;
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

namespace {

ModbusErrors video_errors() {
  ModbusErrors e;
  e.category = &video_switch_error_category();
  for (int code : {1, 2, 3, 4, 6}) e.exception[code] = code;  // VideoSwitchError values = exception codes
  e.timeout = static_cast<int>(VideoSwitchError::Timeout);
  e.connection_failed = static_cast<int>(VideoSwitchError::ConnectionFailed);
  e.bad_response = static_cast<int>(VideoSwitchError::BadResponse);
  e.invalid_argument = static_cast<int>(VideoSwitchError::InvalidArgument);
  return e;
}

const VideoSwitchConfig& checked(const VideoSwitchConfig& c) {
  const std::string src = "video switch";
  if (c.port < 1 || c.port > 65535) throw InputError(src, "port " + std::to_string(c.port) + " outside 1..65535");
  if (c.unit_id < 0 || c.unit_id > 255)
    throw InputError(src, "unit_id " + std::to_string(c.unit_id) + " outside 0..255");
  if (!(c.response_timeout_s > 0.0) || !std::isfinite(c.response_timeout_s))
    throw InputError(src, "response_timeout_s must be a positive number");
  if (c.retries < 0 || c.retries > 10) throw InputError(src, "retries " + std::to_string(c.retries) + " outside 0..10");
  if (!(c.reconnect_delay_s >= 0.0)) throw InputError(src, "reconnect_delay_s must not be negative");
  return c;
}

}  // namespace

VideoSwitch::VideoSwitch(VideoSwitchConfig config)
    : config_(std::move(config)), modbus_(checked(config_).link(), video_errors(), "video switch", 0, "link") {}

VideoSwitch::~VideoSwitch() = default;

std::error_code VideoSwitch::connect() { return modbus_.connect(); }
void VideoSwitch::disconnect() noexcept { modbus_.disconnect(); }

std::error_code VideoSwitch::write_register(int address, std::uint16_t value) {
  return modbus_.write_register(address, value);
}
std::error_code VideoSwitch::write_registers(int address, int count, const std::uint16_t* values) {
  return modbus_.write_registers(address, count, values);
}
std::error_code VideoSwitch::read_holding_registers(int address, int count, std::uint16_t* dest) {
  return modbus_.read_holding_registers(address, count, dest);
}
std::error_code VideoSwitch::read_input_registers(int address, int count, std::uint16_t* dest) {
  return modbus_.read_input_registers(address, count, dest);
}

std::error_code VideoSwitch::select(int camera) {
  if (camera < 0 || camera > 65535)
    return modbus_.refuse("select camera " + std::to_string(camera), static_cast<int>(VideoSwitchError::InvalidArgument));
  return write_register(video::kHoldCamera, static_cast<std::uint16_t>(camera));
}

std::error_code VideoSwitch::set_view(const CameraView& v) {
  std::uint16_t regs[video::kNumHolding] = {};
  const bool ok = v.camera >= 0 && v.camera <= 65535 && angle_counts(v.pan_rad, regs[video::kHoldPan]) &&
                  angle_counts(v.tilt_rad, regs[video::kHoldTilt]) && std::isfinite(v.focal_px) &&
                  v.focal_px >= 0.0 && std::round(v.focal_px) <= 65535.0;
  if (!ok)
    return modbus_.refuse("set view of camera " + std::to_string(v.camera) + " (a value not representable)",
                          static_cast<int>(VideoSwitchError::InvalidArgument));
  regs[video::kHoldCamera] = static_cast<std::uint16_t>(v.camera);
  regs[video::kHoldFocal] = static_cast<std::uint16_t>(std::lround(v.focal_px));
  return write_registers(0, video::kNumHolding, regs);
}

std::error_code VideoSwitch::grab() {
  return modbus_.write_coil(video::kCoilGrab, true);
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
