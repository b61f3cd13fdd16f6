#pragma once
// Where the display's video comes from, and whether a window can be shown.
// Not real-time code.

#include <chrono>
#include <memory>
#include <opencv2/core.hpp>
#include <string>

namespace foresight::display {

/// A live or recorded source through OpenCV: a V4L2 device ("0", "/dev/video0"),
/// a network stream (rtsp://, http://, udp://) or a video file. When it cannot
/// be opened or stops delivering, read() says why and the source is
/// reopened, at most once per retry period (the display keeps running, shows
/// the problem and tries again). A file that ends is reopened (it loops).
class CaptureSource {
 public:
  explicit CaptureSource(std::string spec, std::chrono::milliseconds retry_period = std::chrono::milliseconds(1000));
  ~CaptureSource();
  CaptureSource(const CaptureSource&) = delete;
  CaptureSource& operator=(const CaptureSource&) = delete;

  /// The next frame (8-bit BGR) into `frame`; false with `problem` set when
  /// there is none now ("video source 'X' cannot be opened (attempt N);
  /// retrying" or "video source 'X' stopped; reopening").
  bool read(cv::Mat& frame, std::string& problem);
  int open_attempts() const { return attempts_; }
  int frames_read() const { return frames_; }
  const std::string& spec() const { return spec_; }

 private:
  bool try_open();
  std::string spec_;
  std::chrono::milliseconds retry_period_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int attempts_ = 0;
  int frames_ = 0;
  std::chrono::steady_clock::time_point next_attempt_{};
  std::string last_problem_;
};

/// Empty when an X display can be opened (DISPLAY set and the server
/// answers), else the reason ("DISPLAY is not set", "cannot open display
/// ':7'"). Looks up libX11 at run time so nothing is linked for headless use.
std::string x_display_problem();

}  // namespace foresight::display
