#pragma once
// The master (foresight_hw, the code that runs on the robot) against the
// simulated drives and F/T sensor on mock buses, from config/remote.yaml.

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <thread>
#include <vector>

#include "foresight/hw/drive_system.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/test/eventually.hpp"

namespace foresight::test {

using hw::CycleStatus;
using hw::DriveSystem;
using hw::HwEvent;
using hw::HwFault;
using hw::JointFeedback;
using hw::JointTargets;
using hw::FtReading;
using Clock = std::chrono::steady_clock;

/// config/remote.yaml, with a TPDO miss limit of 25 cycles (50 ms) instead of
/// 5: ctest runs tests in parallel on 2 shared cores, and a descheduled
/// simulator thread must not look like a silent drive.
inline hw::RemoteConfig project_config() {
  hw::RemoteConfig c = hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  c.tpdo_miss_limit = 25;
  return c;
}

struct SimRig {
  hw::RemoteConfig config;
  std::unique_ptr<sim::CanSimulator> sim;
  std::unique_ptr<DriveSystem> drives;
  JointFeedback fb;
  FtReading ft;
  JointTargets targets;
  Clock::time_point deadline;

  explicit SimRig(hw::RemoteConfig c, std::map<std::string, JointLimits> limits = {},
                  std::function<void(sim::CanSimulator&)> before_start = {})
      : config(std::move(c)) {
    auto buses = sim::make_mock_buses(config);
    sim = sim::CanSimulator::from_config(config, std::move(buses.far));
    if (before_start) before_start(*sim);
    sim->start();
    drives = std::make_unique<DriveSystem>(config, std::move(buses.master), std::move(limits));
  }
  ~SimRig() {
    if (sim) sim->stop();
  }

  void bring_up() {
    drives->configure();
    drives->enable();
    // The controller starts from where the arm is: the targets enable() holds.
    drives->held_targets(targets);
    deadline = Clock::now();
    cycle();
  }

  /// Deterministic stepping: after bring-up, the simulator thread stops and
  /// every cycle() reads, writes and lets the simulator answer in this thread
  /// at a simulated time that advances one period (+ jitter) per cycle, so
  /// timing is counted in cycles, never in milliseconds of scheduling.
  bool stepping = false;
  Clock::time_point sim_now{};
  std::chrono::nanoseconds next_jitter{0};  ///< added to the period after the next cycle only
  /// The control loop's order: the SYNC right after the read (send_sync),
  /// then the computation, then the RPDOs. Off: cycle_write sends both.
  bool sync_at_wake = false;

  void bring_up_stepped() {
    drives->configure();
    go_stepped();
  }
  /// After configure(): enable on the simulator thread, then step.
  void go_stepped() {
    drives->enable();
    sim->stop();  // joined: from here on only this thread touches the simulator
    drives->held_targets(targets);
    stepping = true;
    sim_now = Clock::now();
    cycle();
  }

  /// After configure(): step from here with the drives still disabled (a
  /// power change is then stepped by cycle(): begin_enable / begin_disable).
  void go_stepped_disabled() {
    sim->stop();
    drives->held_targets(targets);
    stepping = true;
    sim_now = Clock::now();
    cycle();
  }

  std::chrono::nanoseconds period() const {
    return std::chrono::nanoseconds(static_cast<long>(1e9 / config.cycle_rate_hz));
  }

  /// One real-time period: read, then write the current targets.
  CycleStatus cycle() {
    if (stepping) {
      const CycleStatus s = drives->cycle_read(fb, ft, sim_now);
      if (sync_at_wake) drives->send_sync();
      drives->cycle_write(targets, sim_now);
      sim->process_at(sim_now);  // the nodes take the RPDOs and SYNC, and answer
      sim_now += period() + next_jitter;
      next_jitter = std::chrono::nanoseconds{0};
      return s;
    }
    std::this_thread::sleep_until(deadline);
    deadline += period();
    // A cycle this thread missed (descheduled on a loaded machine) is skipped,
    // as the control loop skips it: catching up would send a burst of SYNCs
    // faster than the simulator thread answers, and its drives would look
    // silent (TpdoMissing in a CI run of Plant.LatchAndLoosenThroughTheLstFreeTheOru).
    if (const auto now = Clock::now(); deadline < now) deadline = now;
    const CycleStatus s = drives->cycle_read(fb, ft);
    drives->cycle_write(targets);
    return s;
  }

  /// Run cycles until pred(status) or max_cycles; returns the status that matched
  /// (or the last one), and the cycle count in *n.
  CycleStatus run_until(const std::function<bool(const CycleStatus&)>& pred, int max_cycles, int* n = nullptr) {
    CycleStatus s;
    for (int i = 0; i < max_cycles; ++i) {
      s = cycle();
      if (pred(s)) {
        if (n) *n = i + 1;
        return s;
      }
    }
    if (n) *n = max_cycles;
    return s;
  }

  /// Run cycles until one reports an event that requires a stop (or
  /// max_cycles): that cycle's status and its stop events; the count in *n.
  struct Stopped {
    CycleStatus status;
    std::vector<HwEvent> stops;
  };
  Stopped run_until_stop(int max_cycles, int* n = nullptr) {
    Stopped r;
    r.status = run_until(
        [&](const CycleStatus& st) {
          for (std::size_t i = 0; i < st.event_count; ++i)
            if (hw::requires_stop(st.events[i].fault)) r.stops.push_back(st.events[i]);
          return !r.stops.empty();
        },
        max_cycles, n);
    return r;
  }
};

inline const HwEvent* find_event(const CycleStatus& s, HwFault f) {
  for (std::size_t i = 0; i < s.event_count; ++i)
    if (s.events[i].fault == f) return &s.events[i];
  return nullptr;
}

}  // namespace foresight::test
