// The real-time thread around Controller::step() (control_loop.hpp).
#include "foresight/control/control_loop.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>

#include <cerrno>
#include <cmath>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <thread>

namespace foresight::control {

namespace {

std::int64_t now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

timespec to_timespec(std::int64_t ns) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1000000000LL);
  ts.tv_nsec = static_cast<long>(ns % 1000000000LL);
  return ts;
}

bool is_sensor_fault(hw::HwFault f) noexcept {
  return f == hw::HwFault::FtMissing || f == hw::HwFault::FtSaturated || f == hw::HwFault::FtSensorFault;
}

}  // namespace

double LoopStats::bin_upper_us(std::size_t i) noexcept {
  if (i < 32) return 10.0 * static_cast<double>(i + 1);
  return 320.0 * std::pow(2.0, static_cast<double>(i - 31) / 4.0);
}

std::size_t LoopStats::bin_of(double us) noexcept {
  if (!(us >= 0.0)) return 0;
  if (us < 320.0) return static_cast<std::size_t>(us / 10.0);
  const double k = std::floor(4.0 * std::log2(us / 320.0));  // 0 for [320, 380)
  const double i = 32.0 + k;
  return i >= static_cast<double>(kBins - 1) ? kBins - 1 : static_cast<std::size_t>(i);
}

double LoopStats::percentile_us(const std::array<std::uint64_t, kBins>& hist, double p) noexcept {
  std::uint64_t total = 0;
  for (auto c : hist) total += c;
  if (total == 0) return 0.0;
  const double target = p * static_cast<double>(total);
  std::uint64_t cum = 0;
  for (std::size_t i = 0; i < kBins; ++i) {
    cum += hist[i];
    if (static_cast<double>(cum) >= target) return bin_upper_us(i);
  }
  return bin_upper_us(kBins - 1);
}

void fill_cycle_inputs(const hw::CycleStatus& status, const hw::JointFeedback& fb, const hw::FtReading& ft,
                       CycleInputs& in) noexcept {
  in.cycle = status.cycle;
  in.joints = fb.count;
  bool enabled = fb.count > 0;
  for (std::size_t j = 0; j < fb.count && j < kMaxJoints; ++j) {
    in.q[j] = fb.joints[j].position_rad;
    in.torque[j] = fb.joints[j].torque_nm;
    in.dq_drive[j] = fb.joints[j].velocity_rad_s;
    in.dq_drive_cycle[j] = fb.joints[j].velocity_cycle;
    enabled = enabled && fb.joints[j].state == hw::canopen::PowerState::OperationEnabled;
    in.drive_state[j] =
        fb.joints[j].state_known ? static_cast<std::uint8_t>(fb.joints[j].state) : kDriveStateUnknown;
  }
  in.drives_enabled = enabled;
  in.wrench_ft = ft.wrench_ft;
  in.ft_fresh = ft.fresh;
  in.ft_saturated_mask = ft.saturated_mask;
  in.ft_fault = ft.sensor_fault;
  in.ft_tare_in_progress = ft.tare_in_progress;
  in.hw_stop_required = status.stop_required;
  in.safe_torque_off = status.safe_torque_off;
  in.sto_joint = status.sto_joint;
  in.hw_drive_fault = status.stop_required;
  in.hw_fault = 0;
  in.hw_node = 0;
  in.hw_joint = -1;
  in.hw_code = 0;
  const hw::HwEvent* cause = nullptr;
  for (std::size_t i = 0; i < status.event_count && cause == nullptr; ++i)
    if (hw::requires_stop(status.events[i].fault)) cause = &status.events[i];
  // No new event this cycle: the stop is a fault that persists (a drive
  // still in Fault, a node still silent): name that one.
  if (cause == nullptr && status.stop_required && status.first_active.fault != hw::HwFault::None)
    cause = &status.first_active;
  if (cause != nullptr) {
    in.hw_fault = static_cast<std::uint8_t>(cause->fault);
    in.hw_node = cause->node;
    in.hw_joint = cause->joint;
    in.hw_code = cause->code;
    in.hw_drive_fault = !is_sensor_fault(cause->fault);
  }
}

ControlLoop::ControlLoop(hw::DriveSystem& drives, const RobotModel& model, const ControllerConfig& config,
                         LoopOptions options)
    : drives_(drives), options_(options) {
  if (drives.joint_count() != static_cast<std::size_t>(model.dof()))
    throw std::invalid_argument("control loop: the drive system has " + std::to_string(drives.joint_count()) +
                                " joints, the robot model " + std::to_string(model.dof()));
  if (options_.telemetry_decimation < 1) throw std::invalid_argument("telemetry_decimation must be >= 1");
  if (options_.rt_priority < 1 || options_.rt_priority > 99) throw std::invalid_argument("rt_priority must be 1..99");
  if (options_.max_missed_cycles < 0) throw std::invalid_argument("max_missed_cycles must be >= 0");
  if (!(config.cycle_rate_hz > 0.0)) throw std::invalid_argument("cycle_rate_hz must be > 0");
  controller_ = std::make_unique<Controller>(model, config);
  dof_ = static_cast<std::size_t>(model.dof());
}

ControlLoop::~ControlLoop() { stop(); }

void ControlLoop::start() {
  if (thread_.joinable()) throw std::runtime_error("control loop: already started");
  quit_.store(false);
  shutdown_requested_.store(false);
  setup_done_.store(false);
  thread_ = std::thread([this] { run(); });
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!setup_done_.load(std::memory_order_acquire) && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

void ControlLoop::stop() {
  if (!thread_.joinable()) return;
  shutdown_requested_.store(true, std::memory_order_release);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (running_.load(std::memory_order_acquire) && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  quit_.store(true, std::memory_order_release);
  thread_.join();
}

std::vector<std::string> ControlLoop::warnings() const {
  if (!setup_done_.load(std::memory_order_acquire)) return {};
  return warnings_;
}

LoopStats ControlLoop::stats() const noexcept {
  LoopStats s;
  s.cycles = cycles_.load(std::memory_order_relaxed);
  s.overruns = overruns_.load(std::memory_order_relaxed);
  s.events_dropped = events_dropped_.load(std::memory_order_relaxed);
  s.telemetry_dropped = telemetry_dropped_.load(std::memory_order_relaxed);
  s.drive_events_dropped = drive_events_dropped_.load(std::memory_order_relaxed);
  s.compute_us_max = compute_max_.load(std::memory_order_relaxed);
  s.sync_after_wake_us_max = sync_after_wake_max_.load(std::memory_order_relaxed);
  s.wakeup_latency_us_max = latency_max_.load(std::memory_order_relaxed);
  const double n = s.cycles > 0 ? static_cast<double>(s.cycles) : 1.0;
  s.compute_us_mean = compute_sum_.load(std::memory_order_relaxed) / n;
  s.wakeup_latency_us_mean = latency_sum_.load(std::memory_order_relaxed) / n;
  for (std::size_t i = 0; i < LoopStats::kBins; ++i) {
    s.compute_hist[i] = compute_hist_[i].load(std::memory_order_relaxed);
    s.latency_hist[i] = latency_hist_[i].load(std::memory_order_relaxed);
  }
  s.realtime = realtime_.load(std::memory_order_relaxed);
  s.memory_locked = memory_locked_.load(std::memory_order_relaxed);
  s.missed_streak_max = missed_streak_max_.load(std::memory_order_relaxed);
  s.power_change_gap_us_max = power_gap_max_.load(std::memory_order_relaxed);
  s.power_change_cycles_last = power_cycles_last_.load(std::memory_order_relaxed);
  return s;
}

void ControlLoop::setup_thread() noexcept {
  try {
    sched_param sp{};
    sp.sched_priority = options_.rt_priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (rc == 0)
      realtime_.store(true);
    else
      warnings_.push_back(std::string("SCHED_FIFO not permitted (") + std::strerror(rc) +
                          "): running as a normal thread");
#ifdef FORESIGHT_SANITIZER
    // ASan/TSan map terabytes of shadow memory: mlockall would try to fault it all in.
    if (options_.lock_memory) warnings_.push_back("mlockall skipped in a sanitizer build (cmake/Sanitizers.cmake)");
#else
    if (options_.lock_memory) {
      if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0)
        memory_locked_.store(true);
      else
        warnings_.push_back(std::string("mlockall not permitted (") + std::strerror(errno) + ")");
    }
#endif
    if (options_.cpu >= 0) {
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(options_.cpu, &set);
      const int arc = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
      if (arc != 0)
        warnings_.push_back("CPU affinity " + std::to_string(options_.cpu) + " not permitted (" +
                            std::strerror(arc) + ")");
    }
  } catch (...) {  // a failed push_back: go on without the warning
  }
  setup_done_.store(true, std::memory_order_release);
}

void ControlLoop::begin_power_change(DriveRequest request) noexcept {
  // The drives' state machine, stepped by this and the next cycles
  // (DriveSystem::begin_enable): the controller's step runs every cycle meanwhile.
  char text[96] = "";
  bool ok = true;
  if (request == DriveRequest::Enable) {
    const bool fifo = realtime_.load(std::memory_order_relaxed), locked = memory_locked_.load(std::memory_order_relaxed);
    hw::HwEvent refused;
    if (options_.require_realtime && !(fifo && locked)) {
      ok = false;  // the drives are not touched
      std::snprintf(text, sizeof text, "not real time (%s%s%s): drives stay off; see --allow-non-rt",
                    fifo ? "" : "no SCHED_FIFO", fifo || locked ? "" : ", ", locked ? "" : "no mlockall");
    } else if (!drives_.begin_enable(&refused)) {
      ok = false;
      drives_.describe_power_failure(refused, text, sizeof text);
    }
  } else if (request == DriveRequest::Disable && !drives_.begin_disable()) {
    ok = false;
    std::snprintf(text, sizeof text, "the drives are not configured");
  }
  if (ok) {
    power_request_ = request;
    return;
  }
  drives_.held_targets(targets_);
  JointArray held{};
  for (std::size_t j = 0; j < dof_; ++j) held[j] = targets_.position_rad[j];
  controller_->drive_request_done(request, false, text, held);
}

void ControlLoop::finish_power_change(const hw::CycleStatus& status) noexcept {
  if (power_request_ == DriveRequest::None || !status.power.finished) return;
  const bool ok = status.power.phase != hw::PowerPhase::Failed;
  char text[96] = "";
  if (!ok) drives_.describe_power_failure(status.power.cause, text, sizeof text);
  drives_.held_targets(targets_);
  JointArray held{};
  for (std::size_t j = 0; j < dof_; ++j) held[j] = targets_.position_rad[j];
  power_cycles_last_.store(status.power.cycles, std::memory_order_relaxed);
  controller_->drive_request_done(power_request_, ok, text, held);
  power_request_ = DriveRequest::None;
}

void ControlLoop::cycle(std::int64_t stamp_ns) noexcept {
  const hw::CycleStatus status = drives_.cycle_read(fb_, ft_);
  // SYNC right after the wake-up and the read, before the computation: the
  // drives latch last cycle's targets at a steady time (CiA 301), however
  // long this cycle's computation takes.
  drives_.send_sync();
  const double sync_us = static_cast<double>(now_ns() - stamp_ns) * 1e-3;
  if (sync_us > sync_after_wake_max_.load(std::memory_order_relaxed))
    sync_after_wake_max_.store(sync_us, std::memory_order_relaxed);
  for (std::size_t i = 0; i < status.event_count; ++i)
    if (!drive_events_.try_push({status.events[i], status.cycle, stamp_ns}))
      drive_events_dropped_.fetch_add(1, std::memory_order_relaxed);
  if (status.events_dropped > 0) drive_events_dropped_.fetch_add(status.events_dropped, std::memory_order_relaxed);
  finish_power_change(status);  // before the step: it sees the drives' new state
  fill_cycle_inputs(status, fb_, ft_, in_);
  in_.stamp_ns = stamp_ns;
  in_.estop = estop_.load(std::memory_order_acquire);
  in_.link_lost = link_lost_.load(std::memory_order_acquire);
  in_.missed_cycles = missed_streak_;
  in_.missed_cycles_limit = static_cast<std::uint32_t>(options_.max_missed_cycles);

  MotionCommand cmd;
  for (std::size_t i = 0; i < kCommandCapacity && commands_.try_pop(cmd); ++i) controller_->command(cmd);
  // The shutdown's stop waits for a power change running to end (a stop
  // of an arm still enabling would find it unpowered and do nothing).
  if (shutdown_requested_.load(std::memory_order_acquire) && !shutdown_issued_ && power_request_ == DriveRequest::None) {
    shutdown_issued_ = true;
    MotionCommand stop_cmd;
    stop_cmd.kind = MotionCommandKind::Stop;
    stop_cmd.category = StopCategory::Cat1;
    controller_->command(stop_cmd);
  }

  controller_->step(in_, out_);

  if (out_.power_off) drives_.request_power_off();
  if (out_.tare_samples > 0) drives_.request_tare(out_.tare_samples);
  if (out_.drive_request != DriveRequest::None) begin_power_change(out_.drive_request);
  for (std::size_t j = 0; j < dof_; ++j) targets_.position_rad[j] = out_.q_cmd[j];
  drives_.cycle_write(targets_);

  for (std::size_t i = 0; i < out_.event_count; ++i)
    if (!events_.try_push(out_.events[i])) events_dropped_.fetch_add(1, std::memory_order_relaxed);
  if (out_.stop != nullptr && !stops_.try_push(*out_.stop)) events_dropped_.fetch_add(1, std::memory_order_relaxed);
  if (++telemetry_counter_ >= options_.telemetry_decimation) {
    telemetry_counter_ = 0;
    if (!telemetry_.try_push(out_.telemetry)) telemetry_dropped_.fetch_add(1, std::memory_order_relaxed);
  }
}

void ControlLoop::run() noexcept {
  setup_thread();
  running_.store(true, std::memory_order_release);
  const double rate = controller_->config().cycle_rate_hz;
  const auto period_ns = static_cast<std::int64_t>(1e9 / rate + 0.5);
  std::int64_t next = now_ns();
  shutdown_issued_ = false;
  while (!quit_.load(std::memory_order_acquire)) {
    next += period_ns;
    const timespec ts = to_timespec(next);
    for (int i = 0; i < 100 && clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR; ++i) {
    }
    const std::int64_t wake = now_ns();
    // The longest gap between two wake-ups while the drives' power changes
    // (the enable used to stop the cycle for its whole length).
    if (power_request_ != DriveRequest::None && last_wake_ns_ != 0) {
      const double gap_us = static_cast<double>(wake - last_wake_ns_) * 1e-3;
      if (gap_us > power_gap_max_.load(std::memory_order_relaxed)) power_gap_max_.store(gap_us, std::memory_order_relaxed);
    }
    last_wake_ns_ = wake;
    cycle(wake);
    const std::int64_t end = now_ns();

    const double latency_us = static_cast<double>(wake - next) * 1e-3;
    const double compute_us = static_cast<double>(end - wake) * 1e-3;
    cycles_.fetch_add(1, std::memory_order_relaxed);
    compute_sum_.store(compute_sum_.load(std::memory_order_relaxed) + compute_us, std::memory_order_relaxed);
    latency_sum_.store(latency_sum_.load(std::memory_order_relaxed) + latency_us, std::memory_order_relaxed);
    if (compute_us > compute_max_.load(std::memory_order_relaxed))
      compute_max_.store(compute_us, std::memory_order_relaxed);
    if (latency_us > latency_max_.load(std::memory_order_relaxed))
      latency_max_.store(latency_us, std::memory_order_relaxed);
    compute_hist_[LoopStats::bin_of(compute_us)].fetch_add(1, std::memory_order_relaxed);
    latency_hist_[LoopStats::bin_of(latency_us)].fetch_add(1, std::memory_order_relaxed);
    if (end > next + period_ns) {  // missed at least one deadline: skip to the grid
      overruns_.fetch_add(1, std::memory_order_relaxed);
      const std::int64_t behind = (end - next) / period_ns;
      next += behind * period_ns;
      missed_streak_ += static_cast<std::uint32_t>(std::min<std::int64_t>(behind, 1 << 20));
      if (missed_streak_ > missed_streak_max_.load(std::memory_order_relaxed))
        missed_streak_max_.store(missed_streak_, std::memory_order_relaxed);
    } else {
      missed_streak_ = 0;
    }

    if (shutdown_issued_) {
      const ControllerMode m = controller_->mode();
      if ((m == ControllerMode::Disabled || m == ControllerMode::Fault) && out_.drive_request == DriveRequest::None &&
          power_request_ == DriveRequest::None && !in_.drives_enabled)
        break;
    }
  }
  running_.store(false, std::memory_order_release);
}

}  // namespace foresight::control
