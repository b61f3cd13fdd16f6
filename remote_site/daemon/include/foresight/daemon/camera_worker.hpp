#pragma once
// The video switch's own thread. Every Modbus call blocks (up to the
// response timeout x (1 + retries), plus reconnect pauses), so CAMERA never
// runs on the supervisor thread: a dead switch must not delay an ABORT or the
// reports. The supervisor hands one CAMERA command at a time to this thread
// and polls for its result.
//
// Thread-safety: start, poll_result and busy are called from the supervisor
// thread (any one thread) and only lock a short mutex.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "foresight/control/command.hpp"
#include "foresight/hw/video_switch.hpp"

namespace foresight::daemon {

struct CameraJob {
  std::uint64_t command_id = 0;
  protocol::CameraAction action = protocol::CameraAction::Select;
  int camera = 0;            ///< the switch's index
  double pan_rad = 0.0;
  double tilt_rad = 0.0;
  double focal_px = 0.0;     ///< Point: <= 0 keeps the camera's current focal length
};

struct CameraResult {
  std::uint64_t command_id = 0;
  bool ok = false;
  bool refused = false;      ///< the switch refused the values (Modbus exception 03)
  std::string error;         ///< why it failed (the switch client's message)
};

class CameraWorker {
 public:
  /// Checks the configuration (InputError from hw::VideoSwitch) and starts
  /// the thread; the switch is connected on the first command.
  explicit CameraWorker(hw::VideoSwitchConfig config);
  ~CameraWorker();
  CameraWorker(const CameraWorker&) = delete;
  CameraWorker& operator=(const CameraWorker&) = delete;

  /// False (nothing started) while another command runs.
  bool start(const CameraJob& job);
  /// The result of a finished command, once.
  std::optional<CameraResult> poll_result();
  bool busy() const noexcept { return busy_.load(std::memory_order_acquire); }
  std::uint64_t running_command() const;

 private:
  void run();
  CameraResult execute(const CameraJob& job);

  hw::VideoSwitch video_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::optional<CameraJob> pending_;
  std::optional<CameraResult> result_;
  std::uint64_t running_id_ = 0;
  bool quit_ = false;
  std::atomic<bool> busy_{false};
  std::thread thread_;
};

}  // namespace foresight::daemon
