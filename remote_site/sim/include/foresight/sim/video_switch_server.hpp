#pragma once
// The simulated video switch: a libmodbus TCP server on 127.0.0.1 speaking
// the register map of foresight/hw/video_switch.hpp (docs/hardware.md "Video
// switch"): camera selection, each camera's pan/tilt (mrad) and focal length
// (px), a grab counter. Port 0 = an ephemeral port chosen by the kernel (read
// it with port()), so parallel tests never collide. One client at a time; a
// new connection replaces the old. Values out of range are refused with
// exception 03 and change nothing; unknown addresses get exception 02.
//
// Not real-time: a simulator for tests, the demo and hil_tests. It runs on
// its own thread; the control and ground-truth methods are thread-safe.

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "foresight/common/error.hpp"

namespace foresight::sim {

struct VideoSwitchServerOptions {
  std::string host = "127.0.0.1";
  int port = 0;  ///< 0 = ephemeral
  /// One entry per camera on the switch (index = position); focal length at
  /// power-on for each (pixels).
  std::vector<std::string> camera_names{"camera0"};
  std::vector<double> initial_focal_px{700.0};
  int pan_limit_mrad = 3000;    ///< |pan| above this: exception 03
  int tilt_limit_mrad = 1500;   ///< |tilt| above this: exception 03
  int focal_min_px = 100;
  int focal_max_px = 5000;
  double poll_s = 0.005;        ///< longest wait of the server loop (stop() latency)
};

/// The cameras of config/scene.yaml in file order (the paper's views 1..4),
/// with their f_px. Throws InputError from the scene loader.
VideoSwitchServerOptions video_switch_options_from_scene(const std::string& scene_yaml_path);

class VideoSwitchServerError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

/// Ground truth of the switch.
struct VideoSwitchState {
  struct View {
    int pan_mrad = 0;
    int tilt_mrad = 0;
    int focal_px = 0;
  };
  int active = 0;
  std::vector<View> views;  ///< per camera
  std::uint32_t grabs = 0;
  std::uint16_t switches = 0;
};

class VideoSwitchServer {
 public:
  /// Validates the options (VideoSwitchServerError: no cameras, names and
  /// focal lengths of different counts, an initial focal outside the
  /// range, limits outside 0..32767), listens and starts the thread.
  explicit VideoSwitchServer(VideoSwitchServerOptions options);
  ~VideoSwitchServer();
  VideoSwitchServer(const VideoSwitchServer&) = delete;
  VideoSwitchServer& operator=(const VideoSwitchServer&) = delete;

  int port() const { return port_; }
  VideoSwitchState state() const;
  /// Index of a camera by name, -1 when absent.
  int camera_index(const std::string& name) const;
  const VideoSwitchServerOptions& options() const { return options_; }
  std::uint64_t requests_answered() const { return answered_; }
  /// Fault injection: requests are read and never answered (a hung switch).
  void set_silent(bool silent) { silent_ = silent; }

 private:
  void loop();
  void serve_one(int rc);
  void apply_outputs();  // registers <- state (mutex_ held)

  VideoSwitchServerOptions options_;
  int port_ = 0;
  int listen_fd_ = -1;
  int client_fd_ = -1;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> answered_{0};
  std::atomic<bool> silent_{false};
  mutable std::mutex mutex_;
  VideoSwitchState state_;
};

}  // namespace foresight::sim
