// bench_hw: one control cycle's CAN exchange for 7 CiA 402 drives + the F/T
// sensor over the mock bus (config/remote.yaml: two 1 Mbit/s buses at 500 Hz),
// and the frames per cycle against each bus's budget.
//
//   BM_CycleMaster     master side only: cycle_read (decode 7 TPDOs + 2 F/T
//                      frames) + cycle_write (7 RPDOs + 2 SYNCs), manual time
//   BM_CycleRoundTrip  write -> simulated drives answer -> read, one thread
//   BM_CycleThreaded   write, then read until all 9 answers are in, with the
//                      simulator on its own thread (latency of the exchange)
// Counters: frames/cycle (sent + received), per-bus worst-case load at the
// configured rate, and the single-bus 1 kHz case the bus-load check refuses.

#include <benchmark/benchmark.h>

#include <chrono>
#include <thread>

#include "foresight/hw/drive_system.hpp"
#include "foresight/sim/can_simulator.hpp"

using namespace foresight;

namespace {

struct Rig {
  hw::RemoteConfig config = hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  std::unique_ptr<sim::CanSimulator> sim;
  std::unique_ptr<hw::DriveSystem> drives;
  hw::JointTargets targets;
  hw::JointFeedback fb;
  hw::FtReading ft;

  explicit Rig(bool keep_sim_thread = false) {
    auto buses = sim::make_mock_buses(config);
    sim = sim::CanSimulator::from_config(config, std::move(buses.far));
    sim->start();
    drives = std::make_unique<hw::DriveSystem>(config, std::move(buses.master));
    drives->configure();
    drives->enable();
    if (!keep_sim_thread) {
      sim->stop();  // from here on the benchmark thread steps the simulator
      sim->process(5);
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    drives->cycle_read(fb, ft);
    for (std::size_t j = 0; j < fb.count; ++j) targets.position_rad[j] = fb.joints[j].position_rad;
  }
};

void add_bus_counters(benchmark::State& state, const hw::RemoteConfig& config) {
  int frames = 0;
  for (const hw::BusLoad& l : hw::compute_bus_loads(config)) {
    state.counters["load_" + l.bus + "_pct"] = l.load * 100.0;
    state.counters["bits_per_cycle_" + l.bus] = l.bits_per_cycle;
    frames += l.frames_per_cycle;
  }
  state.counters["frames_per_cycle_budgeted"] = frames;
  // The same 7 drives + F/T on one 1 Mbit/s bus at 1 kHz (refused at start-up).
  hw::RemoteConfig one = config;
  one.cycle_rate_hz = 1000;
  for (auto& d : one.drives) d.bus = one.buses[0].name;
  one.ft.bus = one.buses[0].name;
  state.counters["load_single_bus_1kHz_pct"] = hw::compute_bus_loads(one)[0].load * 100.0;
}

void BM_CycleMaster(benchmark::State& state) {
  Rig rig;
  long frames_rx = 0, cycles = 0, events = 0;
  for (auto _ : state) {
    rig.sim->process(0);  // the far end answers the previous SYNC (not timed)
    const auto t0 = std::chrono::steady_clock::now();
    const hw::CycleStatus s = rig.drives->cycle_read(rig.fb, rig.ft);
    rig.drives->cycle_write(rig.targets);
    const auto t1 = std::chrono::steady_clock::now();
    state.SetIterationTime(std::chrono::duration<double>(t1 - t0).count());
    frames_rx += s.frames_received;
    events += s.event_count;
    ++cycles;
  }
  const double tx_per_cycle = static_cast<double>(rig.config.drives.size() + rig.config.buses.size());
  state.counters["frames_rx_per_cycle"] = static_cast<double>(frames_rx) / cycles;
  state.counters["frames_tx_per_cycle"] = tx_per_cycle;
  state.counters["events"] = static_cast<double>(events);
  add_bus_counters(state, rig.config);
}
BENCHMARK(BM_CycleMaster)->UseManualTime()->Unit(benchmark::kMicrosecond);

void BM_CycleRoundTrip(benchmark::State& state) {
  Rig rig;
  long frames_rx = 0, cycles = 0;
  for (auto _ : state) {
    rig.drives->cycle_write(rig.targets);
    rig.sim->process(0);
    const hw::CycleStatus s = rig.drives->cycle_read(rig.fb, rig.ft);
    frames_rx += s.frames_received;
    ++cycles;
  }
  state.counters["frames_rx_per_cycle"] = static_cast<double>(frames_rx) / cycles;
  add_bus_counters(state, rig.config);
}
BENCHMARK(BM_CycleRoundTrip)->Unit(benchmark::kMicrosecond);

void BM_CycleThreaded(benchmark::State& state) {
  Rig rig(true);
  long timeouts = 0;
  for (auto _ : state) {
    rig.drives->cycle_write(rig.targets);
    int got = 0;
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(20);
    while (got < 9 && std::chrono::steady_clock::now() < end) got += rig.drives->cycle_read(rig.fb, rig.ft).frames_received;
    if (got < 9) ++timeouts;
  }
  state.counters["timeouts"] = static_cast<double>(timeouts);
  add_bus_counters(state, rig.config);
}
BENCHMARK(BM_CycleThreaded)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
