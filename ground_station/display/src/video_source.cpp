#include "foresight/display/video_source.hpp"

#include <dlfcn.h>

#include <cstdlib>
#include <opencv2/videoio.hpp>

namespace foresight::display {

struct CaptureSource::Impl {
  cv::VideoCapture capture;
};

CaptureSource::CaptureSource(std::string spec, std::chrono::milliseconds retry_period)
    : spec_(std::move(spec)), retry_period_(retry_period), impl_(std::make_unique<Impl>()) {}

CaptureSource::~CaptureSource() = default;

bool CaptureSource::try_open() {
  ++attempts_;
  next_attempt_ = std::chrono::steady_clock::now() + retry_period_;
  impl_->capture.release();
  // A bare number is a device index (V4L2); everything else a path or URL.
  bool is_index = !spec_.empty() && spec_.size() < 4;
  for (const char c : spec_) is_index = is_index && c >= '0' && c <= '9';
  try {
    if (is_index)
      impl_->capture.open(std::atoi(spec_.c_str()));
    else
      impl_->capture.open(spec_);
  } catch (const cv::Exception&) {
    return false;
  }
  return impl_->capture.isOpened();
}

bool CaptureSource::read(cv::Mat& frame, std::string& problem) {
  if (!impl_->capture.isOpened()) {
    if (std::chrono::steady_clock::now() < next_attempt_) {
      problem = last_problem_;
      return false;
    }
    if (!try_open()) {
      problem = last_problem_ =
          "video source '" + spec_ + "' cannot be opened (attempt " + std::to_string(attempts_) + "); retrying";
      return false;
    }
  }
  cv::Mat raw;
  bool ok = false;
  try {
    ok = impl_->capture.read(raw) && !raw.empty();
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) {
    impl_->capture.release();
    // A file at its end (or a stream that dropped): reopen at once the first time.
    next_attempt_ = frames_ > 0 ? std::chrono::steady_clock::now() : std::chrono::steady_clock::now() + retry_period_;
    problem = last_problem_ = "video source '" + spec_ + "' stopped; reopening";
    return false;
  }
  if (raw.channels() == 1) {
    cv::Mat bgr;
    cv::merge(std::vector<cv::Mat>{raw, raw, raw}, bgr);
    raw = bgr;
  }
  if (raw.depth() != CV_8U) raw.convertTo(raw, CV_8U);
  frame = raw;
  ++frames_;
  problem.clear();
  return true;
}

std::string x_display_problem() {
  const char* name = std::getenv("DISPLAY");
  if (name == nullptr || *name == '\0') return "DISPLAY is not set";
  void* lib = dlopen("libX11.so.6", RTLD_NOW | RTLD_LOCAL);
  if (lib == nullptr) return "libX11 is not available";
  using Open = void* (*)(const char*);
  using Close = int (*)(void*);
  auto open = reinterpret_cast<Open>(dlsym(lib, "XOpenDisplay"));
  auto close = reinterpret_cast<Close>(dlsym(lib, "XCloseDisplay"));
  std::string problem;
  if (open == nullptr || close == nullptr) {
    problem = "libX11 has no XOpenDisplay";
  } else if (void* d = open(name); d == nullptr) {
    problem = std::string("cannot open display '") + name + "'";
  } else {
    close(d);
  }
  dlclose(lib);
  return problem;
}

}  // namespace foresight::display
