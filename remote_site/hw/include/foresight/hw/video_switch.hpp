#pragma once
// The video switch over Modbus TCP (libmodbus): selects which camera feeds the
// downlink and drives the selected camera's pan/tilt unit and zoom. The CAMERA
// command of the remote (select a camera and its set point) is one register
// write here. The simulated switch: remote_site/sim video_switch_server.hpp.
// docs/hardware.md "Video switch" has the same table for people.
//
// NOT REAL-TIME. Every call does blocking I/O (up to response_timeout_s x
// (1 + retries), plus reconnect pauses) and may allocate; call it from a
// non-real-time thread, never from the control cycle. Not thread-safe: one
// owner thread. Errors are values (std::error_code in
// video_switch_error_category); only the constructor throws (InputError on a
// bad configuration). The link is the shared ModbusClient (modbus_client.hpp):
// a request that times out, loses its connection or is garbled is retried
// `retries` more times, reconnecting first; Modbus exceptions are the
// switch's definite answer and are not retried, except DeviceBusy.
//
// Register map (0-based protocol addresses):
//
// Coils (FC 01 read, FC 05 write)
//   0 GRAB          write 1: grab one frame from the active camera (GRAB_COUNT
//                   + 1); self-clearing, reads 0
//
// Holding registers (FC 03 read, FC 06 write one, FC 16 write many)
//   0 CAMERA        uint16, camera index 0 .. CAMERA_COUNT-1 (else exception 03)
//   1 PAN_MRAD      int16, pan of the selected camera, mrad, |pan| <= pan limit
//   2 TILT_MRAD     int16, tilt of the selected camera, mrad, |tilt| <= tilt limit
//   3 FOCAL_PX      uint16, focal length of the selected camera in pixels,
//                   focal_min .. focal_max
//   Registers 1..3 are the set point of the camera in CAMERA. Writing CAMERA
//   alone selects that camera and loads its stored set point into 1..3;
//   writing 0..3 in one FC 16 selects the camera and sets its set point at
//   once (what set_view does). A value out of range refuses the whole
//   request with exception 03 and changes nothing.
//
// Input registers (FC 04), 0..7 read in one request
//   0 ACTIVE        camera feeding the video output
//   1 PAN_MRAD      int16, actual pan of the active camera
//   2 TILT_MRAD     int16, actual tilt
//   3 FOCAL_PX      uint16, actual focal length
//   4 CAMERA_COUNT  number of cameras on the switch
//   5 GRAB_HI       uint32 grab counter (frames grabbed since power-on), high word
//   6 GRAB_LO       ... low word
//   7 SWITCHES      uint16, camera selections made (wraps)
//
// Any other address: exception 02.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>
#include <system_error>


#include "foresight/hw/modbus_client.hpp"

namespace foresight::hw {

namespace video {
inline constexpr int kCoilGrab = 0;
inline constexpr int kNumCoils = 1;

inline constexpr int kHoldCamera = 0;
inline constexpr int kHoldPan = 1;
inline constexpr int kHoldTilt = 2;
inline constexpr int kHoldFocal = 3;
inline constexpr int kNumHolding = 4;

inline constexpr int kInActive = 0;
inline constexpr int kInPan = 1;
inline constexpr int kInTilt = 2;
inline constexpr int kInFocal = 3;
inline constexpr int kInCameraCount = 4;
inline constexpr int kInGrabHi = 5;
inline constexpr int kInGrabLo = 6;
inline constexpr int kInSwitches = 7;
inline constexpr int kNumInput = 8;

inline constexpr double kRadPerCount = 0.001;  ///< pan/tilt: 1 mrad per count
}  // namespace video

/// Named errors of the video switch link. Values 1..11 equal the Modbus
/// exception codes they stand for.
enum class VideoSwitchError {
  IllegalFunction = 1,     ///< exception 01
  IllegalDataAddress = 2,  ///< exception 02: address outside the map
  IllegalDataValue = 3,    ///< exception 03: value refused (camera index, pan/tilt/focal out of range)
  DeviceFailure = 4,       ///< exception 04
  DeviceBusy = 6,          ///< exception 06
  Timeout = 100,           ///< no (complete) response in time, after all retries
  ConnectionFailed,        ///< cannot connect, or the connection was lost, after all retries
  BadResponse,             ///< garbled response, or an exception code not listed above
  InvalidArgument,         ///< a value not representable on the wire: nothing was sent
};

const std::error_category& video_switch_error_category() noexcept;
std::error_code make_error_code(VideoSwitchError e) noexcept;

}  // namespace foresight::hw

template <>
struct std::is_error_code_enum<foresight::hw::VideoSwitchError> : std::true_type {};

namespace foresight::hw {

struct VideoSwitchConfig {
  std::string host = "127.0.0.1";
  int port = 1503;
  int unit_id = 1;
  double response_timeout_s = 0.1;  ///< per attempt; also the connect timeout
  int retries = 2;                  ///< extra attempts after the first (0..10)
  double reconnect_delay_s = 0.05;
  /// The Modbus link of these settings (TCP).
  ModbusLink link() const;
  /// "tcp 127.0.0.1:1503 unit 1"
  std::string describe() const { return link().describe(); }
};

/// The optional `video_switch:` section of remote.yaml (a real cabinet's
/// switch; --sim replaces the link with its simulated switch):
///   video_switch:
///     host: 192.168.10.21
///     port: 502                    # default 1503
///     unit_id: 1
///     response_timeout_ms: 100
///     retries: 2
///     cameras: [side, oblique, overhead_wide, overhead_zoom]   # index = switch input
struct VideoSwitchSection {
  VideoSwitchConfig link;
  std::vector<std::string> camera_names;  ///< the names CAMERA commands use, by switch input
  int line = 0;
};

/// Reads the section from remote.yaml text; nullopt when there is none.
/// InputError naming the file, line and key: unknown keys, a port outside
/// 1..65535, a unit outside 0..255, a non-positive timeout, retries outside
/// 0..10, no cameras, an empty or repeated camera name.
std::optional<VideoSwitchSection> parse_video_switch_section(const std::string& yaml_text, const std::string& source);
std::optional<VideoSwitchSection> load_video_switch_section(const std::string& remote_yaml_path);

/// A camera and its set point. SI inside: radians and pixels.
struct CameraView {
  int camera = 0;
  double pan_rad = 0.0;
  double tilt_rad = 0.0;
  double focal_px = 0.0;
};

struct VideoSwitchStatus {
  int active_camera = 0;
  double pan_rad = 0.0;
  double tilt_rad = 0.0;
  double focal_px = 0.0;
  int camera_count = 0;
  std::uint32_t grab_count = 0;
  std::uint16_t switches = 0;
};

/// Decode input registers 0..7 (exposed for tests).
VideoSwitchStatus decode_video_status(const std::uint16_t (&in)[video::kNumInput]) noexcept;

class VideoSwitch {
 public:
  /// Checks the configuration (InputError "video switch: ...": port outside
  /// 1..65535, unit outside 0..255, non-positive timeout, retries outside
  /// 0..10) and creates the context; does not connect.
  explicit VideoSwitch(VideoSwitchConfig config);
  ~VideoSwitch();
  VideoSwitch(const VideoSwitch&) = delete;
  VideoSwitch& operator=(const VideoSwitch&) = delete;

  std::error_code connect();
  void disconnect() noexcept;
  bool connected() const noexcept { return modbus_.connected(); }

  /// Select a camera (its stored set point stays).
  std::error_code select(int camera);
  /// Select a camera and set its pan, tilt and focal length in one request.
  /// InvalidArgument (nothing sent) when a value is not finite or not
  /// representable (pan/tilt beyond +-32.767 rad, focal outside 0..65535 px).
  std::error_code set_view(const CameraView& view);
  /// Grab one frame from the active camera.
  std::error_code grab();
  std::error_code read_status(VideoSwitchStatus& out);
  /// The set point registers 0..3 as a view.
  std::error_code read_view(CameraView& out);

  // raw access (diagnostics, tests)
  std::error_code write_register(int address, std::uint16_t value);
  std::error_code write_registers(int address, int count, const std::uint16_t* values);
  std::error_code read_holding_registers(int address, int count, std::uint16_t* dest);
  std::error_code read_input_registers(int address, int count, std::uint16_t* dest);

  /// "<request> (<link>): <error>[ after N attempts]" for the last failure.
  const std::string& last_error_message() const { return modbus_.last_error_message(); }

 private:
  VideoSwitchConfig config_;
  ModbusClient modbus_;
};

}  // namespace foresight::hw
