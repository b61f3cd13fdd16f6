#pragma once
// The simulated far end of the CAN buses: simulated nodes (drives, F/T
// sensor) attached to the far ends of mock buses. Run it on its own thread
// (start/stop), or step it from the caller's thread (process) for
// deterministic single-threaded use (benchmarks; tests with process_at). Not real-time code.
//
//   auto [master, far] = make_mock_buses(config);
//   auto sim = CanSimulator::from_config(config, std::move(far));
//   sim->start();                                  // power-on: boot-up messages
//   hw::DriveSystem drives(config, std::move(master));
//   drives.configure(); drives.enable(); ... cycle_read / cycle_write ...

#include <atomic>
#include <deque>
#include <random>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "foresight/hw/can_bus.hpp"
#include "foresight/hw/remote_config.hpp"
#include "foresight/sim/sim_drive.hpp"
#include "foresight/sim/sim_ft_sensor.hpp"

namespace foresight::sim {

/// Both ends of one mock bus per configured bus: {master ends, far ends}.
/// Every bus must have interface "mock" (throws hw::CanError naming it otherwise).
struct MockBuses {
  std::vector<std::unique_ptr<hw::CanBus>> master;
  std::vector<std::unique_ptr<hw::CanBus>> far;
};
MockBuses make_mock_buses(const hw::RemoteConfig& config);

/// What one simulated bus does to frames (seeded: a run is reproducible up to
/// thread timing). Loss applies both ways; delay and jitter to frames the
/// nodes send (FIFO: CAN does not reorder); SYNC loss to the master's SYNCs
/// (a lost SYNC is not looped back either).
struct BusImpairment {
  double loss = 0.0;           ///< probability a data frame is lost, each way
  double sync_loss = 0.0;      ///< extra probability a SYNC is lost
  double delay_s = 0.0;        ///< added to every node frame
  double jitter_s = 0.0;       ///< + uniform [0, jitter_s)
  std::uint64_t seed = 1;
};

class CanSimulator {
 public:
  CanSimulator();
  ~CanSimulator();
  CanSimulator(const CanSimulator&) = delete;
  CanSimulator& operator=(const CanSimulator&) = delete;

  /// One simulated node per configured drive (same node ids, counts per rev)
  /// and the F/T sensor with the configured scales.
  static std::unique_ptr<CanSimulator> from_config(const hw::RemoteConfig& config,
                                                   std::vector<std::unique_ptr<hw::CanBus>> far_ends);

  // ---- building (before start) ----------------------------------------------
  std::size_t add_bus(std::unique_ptr<hw::CanBus> far_end);
  SimDrive& add_drive(std::size_t bus, const SimDriveParams& params);
  SimFtSensor& add_ft_sensor(std::size_t bus, const SimFtParams& params);

  // ---- running ------------------------------------------------------------------
  /// Power on every node (boot-up messages) and run on a thread until stop().
  /// rt_priority > 0: the thread asks for SCHED_FIFO at that priority, as the
  /// drives' own processors never wait for a busy host; without the
  /// permission it runs as a normal thread (realtime() says which; the
  /// answer comes once the thread has started).
  void start(int rt_priority = 0);
  /// 1: the thread runs SCHED_FIFO, 0: normal thread, -1: not started yet.
  int realtime() const noexcept { return realtime_.load(); }
  void stop();
  /// Single-threaded use: power on (first call), handle every frame waiting
  /// on the buses (waiting up to timeout_ms for the first), tick heartbeats.
  /// Each frame reaches the nodes at the moment the master wrote it (the
  /// bus's kernel stamp), so SYNC physics counts the master's real periods
  /// even when this thread lags and reads two SYNCs at once.
  void process(int timeout_ms = 0);
  /// Single-threaded and deterministic: as process(0), at the simulated time
  /// `now` (non-decreasing; SYNC physics, heartbeats and frame delays count
  /// from it, never from the wall clock). Tests step the master and the
  /// simulator in one thread with it, so timing is counted in cycles.
  void process_at(Clock::time_point now);

  /// Send a raw frame on a bus from the far end (malformed-frame injection,
  /// error frames: can_id | CAN_ERR_FLAG). Any thread.
  void inject(std::size_t bus, const can_frame& f);
  /// Frame loss, delay and jitter on one bus from now on. Any thread.
  void set_impairment(std::size_t bus, const BusImpairment& imp);
  /// The master's controller goes bus-off: a CAN_ERR_BUSOFF error frame, then
  /// nothing passes either way until recover_bus(). Any thread.
  void inject_bus_off(std::size_t bus);
  /// Error passive (CAN_ERR_CRTL, TX and RX passive); traffic still passes.
  void inject_error_passive(std::size_t bus);
  /// Controller restarted: CAN_ERR_RESTARTED, traffic passes again.
  void recover_bus(std::size_t bus);
  /// Frames lost by the impairment so far (both directions, all buses).
  std::uint64_t frames_lost() const { return frames_lost_.load(); }

  SimDrive& drive(std::size_t i) { return *drives_.at(i).node; }
  /// Simulated joint angles (rad) of the drives built by from_config, in
  /// config order, converted with the configured scaling (for a contact
  /// model: FK of these gives the simulated tool pose). Any thread; not RT.
  /// Throws std::logic_error for drives added without a DriveConfig.
  void joint_positions_rad(std::span<double> out) const;
  /// Simulated joint velocities (rad/s), same order and scaling as
  /// joint_positions_rad (the plant's tool twist). Any thread; not RT.
  void joint_velocities_rad_s(std::span<double> out) const;
  std::size_t drive_count() const { return drives_.size(); }
  SimFtSensor* ft_sensor() { return ft_.get(); }
  std::uint64_t frames_received() const { return frames_in_.load(); }
  std::uint64_t frames_sent() const { return frames_out_.load(); }
  std::uint64_t frames_dropped() const { return frames_dropped_.load(); }

 private:
  struct Bus;
  struct DriveEntry {
    std::size_t bus;
    std::unique_ptr<SimDrive> node;
    bool has_scaling = false;
    hw::DriveConfig scaling;
  };
  void power_on();
  void run();
  void dispatch(std::size_t bus, const can_frame& f, Clock::time_point now);
  // process() (frames at their bus stamps: `stamped`) and process_at() (all at `now`).
  void step(Clock::time_point now, bool stamped);

  std::vector<std::unique_ptr<Bus>> buses_;
  std::vector<DriveEntry> drives_;
  std::unique_ptr<SimFtSensor> ft_;
  std::size_t ft_bus_ = 0;
  std::mutex step_mu_;  // one process() at a time
  bool powered_ = false;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<int> realtime_{-1};
  std::atomic<std::uint64_t> frames_in_{0}, frames_out_{0}, frames_dropped_{0}, frames_lost_{0};
};

}  // namespace foresight::sim
