#pragma once
// The real-time thread around Controller::step():
//
//   every period (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME), 1/cycle_rate_hz):
//     drives.cycle_read -> pop commands -> controller.step -> drives.cycle_write
//     -> push events / stop events / telemetry (every telemetry_decimation cycles)
//
// Start-up (start()): the thread asks for SCHED_FIFO at `rt_priority`, locks
// memory (mlockall) and pins itself to `cpu` (-1: no pinning); where not
// permitted (this machine, CI) it records a warning (warnings()) and runs as a
// normal thread. The daemon starts the loop with the drives configured but
// NOT enabled: the loop cycles from the first period, so the master's CANopen
// heartbeat and SYNC keep going, and the drives stay disabled (mode Disabled)
// until an Enable/Recover command.
//
// Drive power: when the Controller asks (CycleOutputs::drive_request), the
// loop begins the drives' power state machine (DriveSystem::begin_enable /
// begin_disable) after the step; the following cycle_writes step it (one
// controlword per drive per cycle, target = actual position) and each
// cycle_read judges it (CycleStatus::power); when it ends, the loop reports
// to Controller::drive_request_done() before that cycle's step. Nothing
// blocks or allocates: the period grid goes on, and the controller's step
// (E-stop, safe torque off, link, every other check) runs every cycle of the
// change. A failure becomes the command's Failed event naming the drive
// (DriveSystem::describe_power_failure). With require_realtime, Enable fails
// without touching the drives unless SCHED_FIFO and mlockall were granted.
//
// Overruns: a cycle that ends after the next deadline skips to the grid; the
// periods it skipped count as missed. max_missed_cycles missed in a row (a
// 6 ms stall at 500 Hz) are a category 1 stop (CycleInputs::missed_cycles).
//
// Threads: one supervisor thread produces commands (send) and consumes events,
// stop events and telemetry (poll_*); set_estop/set_link_lost/stats may be
// called from any thread. The RT side never blocks on a full ring: a dropped
// event or sample is counted (stats().events_dropped, telemetry_dropped).
//
// Set-up (may allocate, throw): constructor, start(), stop(), warnings().
// Any thread, lock-free: send, poll_*, set_estop, set_link_lost, stats.

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "foresight/control/controller.hpp"
#include "foresight/control/rt_types.hpp"
#include "foresight/common/spsc_ring.hpp"
#include "foresight/hw/drive_system.hpp"

namespace foresight::control {

/// The Controller's inputs from one DriveSystem::cycle_read (joints, F/T,
/// the first stop-requiring hardware event). estop/link_lost, cycle stamp are
/// left to the caller. Real-time: noexcept, no allocation.
void fill_cycle_inputs(const hw::CycleStatus& status, const hw::JointFeedback& joints, const hw::FtReading& ft,
                       CycleInputs& in) noexcept;

/// A drive event (hw::CycleStatus::events: EMCY, state changes during a
/// power change, timeouts, faults, nodes and buses) as the loop read it, for
/// the daemon's journal.
struct DriveEventRecord {
  hw::HwEvent event{};
  std::uint64_t cycle = 0;
  std::int64_t stamp_ns = 0;  ///< CLOCK_MONOTONIC of the cycle that read it
};

struct LoopOptions {
  int rt_priority = 80;            ///< SCHED_FIFO priority (1-99)
  int cpu = -1;                    ///< pin the loop to this CPU; -1: do not pin
  bool lock_memory = true;         ///< mlockall(MCL_CURRENT | MCL_FUTURE)
  int telemetry_decimation = 5;    ///< one TelemetrySample every N cycles (500 Hz / 5 = 100 Hz)
  /// Periods missed in a row (a late cycle that skipped k periods counts k)
  /// that make a category 1 stop, StopCause::Overrun; 0: never. The drives
  /// got no new target and no SYNC for that long. The daemon sets 3 off the
  /// simulator; 0 here because a shared test machine misses 4 in a row now
  /// and then (seen with ctest -j2).
  int max_missed_cycles = 0;
  /// Enable (and Recover) only when SCHED_FIFO and mlockall were granted:
  /// else the power-on fails with the reason and the drives stay off (the
  /// daemon sets it off the simulator unless --allow-non-rt).
  bool require_realtime = false;
};

/// Cycle statistics, updated by the loop with relaxed atomics; read from any
/// thread (a consistent-enough snapshot, no locks).
struct LoopStats {
  /// Histogram bins: 0..31 are 10 us wide (0-320 us), 32..63 grow by 2^(1/4)
  /// each (320 us .. ~82 ms); the last bin also takes everything above.
  static constexpr std::size_t kBins = 64;
  static double bin_upper_us(std::size_t i) noexcept;
  static std::size_t bin_of(double us) noexcept;
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;          ///< cycles whose work ended after the next deadline (periods skipped)
  std::uint64_t events_dropped = 0;    ///< event/stop rings full
  std::uint64_t telemetry_dropped = 0;
  std::uint64_t drive_events_dropped = 0;  ///< drive event ring full (poll_drive_event)
  double compute_us_max = 0.0;         ///< read + step + write
  /// From the wake-up to the cycle's SYNC (the read alone; the computation
  /// comes after it): what the drives see of the loop's timing.
  double sync_after_wake_us_max = 0.0;
  double compute_us_mean = 0.0;
  double wakeup_latency_us_max = 0.0;  ///< wake-up time - deadline (jitter)
  double wakeup_latency_us_mean = 0.0;
  std::array<std::uint64_t, kBins> compute_hist{};
  std::array<std::uint64_t, kBins> latency_hist{};
  bool realtime = false;               ///< SCHED_FIFO was granted
  bool memory_locked = false;          ///< mlockall(MCL_CURRENT | MCL_FUTURE) succeeded
  std::uint64_t missed_streak_max = 0; ///< the most periods missed in a row
  /// The longest gap between two cycle wake-ups while a power change ran (us).
  double power_change_gap_us_max = 0.0;
  /// Cycles the last power change took (CycleStatus::power.cycles when it ended).
  std::uint32_t power_change_cycles_last = 0;
  /// Percentile (0..1) of a histogram in us (the upper edge of its bin: a
  /// bound, resolution 10 us below 320 us, 19% above).
  static double percentile_us(const std::array<std::uint64_t, kBins>& hist, double p) noexcept;
};

class ControlLoop {
 public:
  static constexpr std::size_t kCommandCapacity = 64;
  static constexpr std::size_t kEventCapacity = 256;
  static constexpr std::size_t kStopCapacity = 16;
  static constexpr std::size_t kTelemetryCapacity = 1024;
  static constexpr std::size_t kDriveEventCapacity = 512;

  /// Set-up. `drives` configured (configure() done), not enabled, and not
  /// cycled by anyone else while the loop runs; outlives the loop. Throws
  /// std::invalid_argument when the joint counts differ or config is bad.
  ControlLoop(hw::DriveSystem& drives, const RobotModel& model, const ControllerConfig& config,
              LoopOptions options = {});
  /// Stops the thread (stop()).
  ~ControlLoop();
  ControlLoop(const ControlLoop&) = delete;
  ControlLoop& operator=(const ControlLoop&) = delete;

  /// Start the thread. Throws std::runtime_error if already started.
  void start();
  /// Shutdown: a Cat1 stop if the drives are enabled (controlled stop, then
  /// disable), waits (bounded: 5 s) for rest, ends the thread. Idempotent.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }

  /// Supervisor thread. False when the command ring is full (nothing sent).
  bool send(const MotionCommand& cmd) noexcept { return commands_.try_push(cmd); }
  /// Supervisor thread. False when nothing is waiting.
  bool poll_event(MotionEvent& out) noexcept { return events_.try_pop(out); }
  bool poll_stop(StopEvent& out) noexcept { return stops_.try_pop(out); }
  bool poll_telemetry(TelemetrySample& out) noexcept { return telemetry_.try_pop(out); }
  /// Every event of every cycle_read, in order (drive_events_dropped counts
  /// those lost to a full ring).
  bool poll_drive_event(DriveEventRecord& out) noexcept { return drive_events_.try_pop(out); }
  /// The drive system, for describing its events (DriveSystem::describe) off the loop thread.
  const hw::DriveSystem& drives() const noexcept { return drives_; }

  /// Inputs, any thread.
  void set_estop(bool pressed) noexcept { estop_.store(pressed, std::memory_order_release); }
  void set_link_lost(bool lost) noexcept { link_lost_.store(lost, std::memory_order_release); }

  LoopStats stats() const noexcept;
  const LoopOptions& options() const noexcept { return options_; }
  /// Start-up warnings (no SCHED_FIFO, no mlockall, no affinity). Call after
  /// start() returned (it waits until the thread has tried).
  std::vector<std::string> warnings() const;
  /// The controller, for inspection in tests after stop() (not while running).
  const Controller& controller() const noexcept { return *controller_; }

 private:
  void run() noexcept;
  void setup_thread() noexcept;
  /// After the step: begin the drives' power change the controller asked for
  /// (or report at once why it cannot begin).
  void begin_power_change(DriveRequest request) noexcept;
  /// Before the step: a power change that ended in this read, to the controller.
  void finish_power_change(const hw::CycleStatus& status) noexcept;
  void cycle(std::int64_t stamp_ns) noexcept;

  hw::DriveSystem& drives_;
  LoopOptions options_;
  std::unique_ptr<Controller> controller_;
  std::size_t dof_ = 0;

  SpscRing<MotionCommand> commands_{kCommandCapacity};
  SpscRing<MotionEvent> events_{kEventCapacity};
  SpscRing<StopEvent> stops_{kStopCapacity};
  SpscRing<TelemetrySample> telemetry_{kTelemetryCapacity};
  SpscRing<DriveEventRecord> drive_events_{kDriveEventCapacity};

  std::atomic<bool> estop_{false};
  std::atomic<bool> link_lost_{false};
  std::atomic<bool> running_{false};
  std::atomic<bool> quit_{false};
  std::atomic<bool> shutdown_requested_{false};
  std::atomic<bool> setup_done_{false};
  std::thread thread_;
  std::vector<std::string> warnings_;  // written by the thread before setup_done_, read after

  // statistics (written by the loop thread only)
  std::atomic<std::uint64_t> cycles_{0}, overruns_{0}, events_dropped_{0}, telemetry_dropped_{0};
  std::atomic<std::uint64_t> drive_events_dropped_{0};
  std::atomic<double> compute_max_{0.0}, compute_sum_{0.0}, latency_max_{0.0}, latency_sum_{0.0};
  std::atomic<double> sync_after_wake_max_{0.0};
  std::array<std::atomic<std::uint64_t>, LoopStats::kBins> compute_hist_{};
  std::array<std::atomic<std::uint64_t>, LoopStats::kBins> latency_hist_{};
  std::atomic<bool> realtime_{false};
  std::atomic<bool> memory_locked_{false};
  std::atomic<std::uint64_t> missed_streak_max_{0};
  std::uint32_t missed_streak_ = 0;  ///< loop thread: periods missed in a row so far
  DriveRequest power_request_ = DriveRequest::None;  ///< loop thread: the power change running
  std::int64_t last_wake_ns_ = 0;
  std::atomic<double> power_gap_max_{0.0};
  std::atomic<std::uint32_t> power_cycles_last_{0};

  // cycle scratch (loop thread only)
  hw::JointFeedback fb_{};
  hw::FtReading ft_{};
  hw::JointTargets targets_{};
  CycleInputs in_{};
  CycleOutputs out_{};
  int telemetry_counter_ = 0;
  bool shutdown_issued_ = false;
};

}  // namespace foresight::control
