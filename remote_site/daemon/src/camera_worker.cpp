#include "foresight/daemon/camera_worker.hpp"

namespace foresight::daemon {

CameraWorker::CameraWorker(hw::VideoSwitchConfig config) : video_(std::move(config)) {
  thread_ = std::thread([this] { run(); });
}

CameraWorker::~CameraWorker() {
  {
    std::lock_guard lock(mu_);
    quit_ = true;
  }
  cv_.notify_one();
  if (thread_.joinable()) thread_.join();
}

bool CameraWorker::start(const CameraJob& job) {
  {
    std::lock_guard lock(mu_);
    if (busy_.load(std::memory_order_acquire)) return false;
    pending_ = job;
    running_id_ = job.command_id;
    busy_.store(true, std::memory_order_release);
  }
  cv_.notify_one();
  return true;
}

std::optional<CameraResult> CameraWorker::poll_result() {
  std::lock_guard lock(mu_);
  std::optional<CameraResult> r;
  r.swap(result_);
  return r;
}

std::uint64_t CameraWorker::running_command() const {
  std::lock_guard lock(mu_);
  return busy_.load(std::memory_order_acquire) ? running_id_ : 0;
}

void CameraWorker::run() {
  for (;;) {
    CameraJob job;
    {
      std::unique_lock lock(mu_);
      cv_.wait(lock, [this] { return quit_ || pending_.has_value(); });
      if (quit_) return;
      job = *pending_;
      pending_.reset();
    }
    CameraResult r = execute(job);
    std::lock_guard lock(mu_);
    result_ = std::move(r);
    busy_.store(false, std::memory_order_release);
  }
}

CameraResult CameraWorker::execute(const CameraJob& job) {
  std::error_code ec;
  switch (job.action) {
    case protocol::CameraAction::Select: ec = video_.select(job.camera); break;
    case protocol::CameraAction::Point: {
      hw::CameraView v;
      v.camera = job.camera;
      v.pan_rad = job.pan_rad;
      v.tilt_rad = job.tilt_rad;
      v.focal_px = job.focal_px;
      if (job.focal_px <= 0.0) {
        hw::CameraView now;
        if (!video_.read_view(now)) v.focal_px = now.focal_px;
      }
      ec = video_.set_view(v);
      break;
    }
    case protocol::CameraAction::Grab:
      if (!(ec = video_.select(job.camera))) ec = video_.grab();
      break;
  }
  CameraResult r;
  r.command_id = job.command_id;
  r.ok = !ec;
  r.refused = ec.value() == 3;
  if (ec) r.error = video_.last_error_message();
  return r;
}

}  // namespace foresight::daemon
