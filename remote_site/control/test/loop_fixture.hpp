#pragma once
// Test helpers for the ControlLoop thread against the simulated drives (the
// SimRig of remote_site/sim/test): the remote.yaml a loaded test machine
// needs, a deadline-bounded wait, and a collector of what the loop reports.

#include <chrono>
#include <cstdint>
#include <vector>

#include "foresight/control/control_loop.hpp"
#include "foresight/test/eventually.hpp"
#include "sim_fixture.hpp"

namespace foresight::control::test {

/// Polls `pred` every millisecond until it holds or `seconds` pass.
template <class Pred>
bool eventually(Pred pred, double seconds) {
  return foresight::test::eventually(std::move(pred), seconds, std::chrono::milliseconds(1));
}

/// config/remote.yaml with generous timeouts: the loop runs SCHED_FIFO where
/// permitted, the simulator thread does not, and ctest runs beside builds on
/// 2 cores: a descheduled simulator must not look like a silent drive.
inline hw::RemoteConfig loop_test_config() {
  hw::RemoteConfig c = foresight::test::project_config();
  c.tpdo_miss_limit = 250;          // 0.5 s
  c.heartbeat_consumer_s = 1.0;
  return c;
}

struct Collector {
  explicit Collector(ControlLoop& l) : loop(l) {}
  ControlLoop& loop;
  std::vector<MotionEvent> events;
  std::vector<StopEvent> stops;
  TelemetrySample last{};
  std::size_t samples = 0;
  void drain() {
    MotionEvent e;
    while (loop.poll_event(e)) events.push_back(e);
    StopEvent s;
    while (loop.poll_stop(s)) stops.push_back(s);
    TelemetrySample t;
    while (loop.poll_telemetry(t)) {
      last = t;
      ++samples;
    }
  }
  const MotionEvent* final_of(std::uint64_t id) {
    drain();
    for (const auto& e : events)
      if (e.command_id == id && is_final(e.kind)) return &e;
    return nullptr;
  }
};

}  // namespace foresight::control::test
