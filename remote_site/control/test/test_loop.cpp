// The ControlLoop thread against the simulated CiA 402 drives and F/T sensor
// on mock CAN buses (the SimRig of remote_site/sim/test): enable through the
// loop, run a trajectory, hold, an E-stop with its evidence, shutdown.

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "control_fixture.hpp"
#include "foresight/control/control_loop.hpp"
#include "sim_fixture.hpp"

namespace foresight::control::test {
namespace {

using Clock = std::chrono::steady_clock;

/// Poll `pred` every millisecond until it holds or `seconds` pass.
template <class Pred>
bool eventually(Pred pred, double seconds) {
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  while (Clock::now() < deadline) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return pred();
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

TEST(ControlLoop, EnablesRunsATrajectoryHoldsAndStopsOnEStop) {
  hw::RemoteConfig config = foresight::test::project_config();
  foresight::test::SimRig rig(config, hw::joint_limits_by_name(robot()));
  rig.drives->configure();

  ControllerConfig cc;
  cc.cycle_rate_hz = config.cycle_rate_hz;
  auto loop = std::make_unique<ControlLoop>(*rig.drives, robot(), cc);
  loop->start();
  for (const auto& w : loop->warnings()) std::printf("loop warning: %s\n", w.c_str());
  Collector col(*loop);

  // Disabled at start: the loop cycles (heartbeat, SYNC) with the drives off.
  ASSERT_TRUE(eventually([&] { col.drain(); return col.samples > 5; }, 10.0));
  EXPECT_EQ(col.last.mode, ControllerMode::Disabled);
  EXPECT_FALSE(col.last.drives_enabled);

  MotionCommand en;
  en.command_id = 1;
  en.kind = MotionCommandKind::Enable;
  ASSERT_TRUE(loop->send(en));
  ASSERT_TRUE(eventually([&] { return col.final_of(1) != nullptr; }, 15.0));
  ASSERT_EQ(col.final_of(1)->kind, MotionEventKind::Completed) << col.final_of(1)->text.data();
  ASSERT_TRUE(eventually([&] { col.drain(); return col.last.mode == ControllerMode::Idle && col.last.drives_enabled; }, 5.0));

  // A 2 s move of three joints from where the arm is (100 Hz samples).
  const JointArray q0 = col.last.q_cmd;
  JointArray q1 = q0;
  q1[0] += 0.15;
  q1[1] += 0.10;
  q1[3] -= 0.10;
  Trajectory t;
  for (int i = 0; i <= 200; ++i) t.time_s.push_back(i * 0.01);
  t.positions_rad.resize(201, 7);
  for (int i = 0; i <= 200; ++i) {
    const double s = i / 200.0, b = s * s * (3 - 2 * s);
    for (int j = 0; j < 7; ++j) {
      const auto u = static_cast<std::size_t>(j);
      t.positions_rad(i, j) = q0[u] + b * (q1[u] - q0[u]);
    }
  }
  const PreparedTrajectory traj(t, 42);
  MotionCommand run;
  run.command_id = 2;
  run.kind = MotionCommandKind::RunTrajectory;
  run.trajectory = &traj;
  ASSERT_TRUE(loop->send(run));
  ASSERT_TRUE(eventually([&] { return col.final_of(2) != nullptr; }, 30.0));
  const MotionEvent done = *col.final_of(2);
  ASSERT_EQ(done.kind, MotionEventKind::Completed) << done.text.data();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NEAR(done.final_q[j], q1[j], 0.01) << "joint " << j + 1;

  // Holding: after settling, the measured joints stay at the end.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  col.drain();
  const TelemetrySample held = col.last;
  EXPECT_EQ(held.mode, ControllerMode::Idle);
  for (std::size_t j = 0; j < 7; ++j) EXPECT_NEAR(held.q[j], q1[j], 2e-3) << "joint " << j + 1;
  EXPECT_TRUE(col.stops.empty());

  // E-stop: Cat0 with its evidence; the drives end disabled.
  loop->set_estop(true);
  ASSERT_TRUE(eventually([&] { col.drain(); return !col.stops.empty(); }, 5.0));
  EXPECT_EQ(col.stops[0].cause, StopCause::EStop);
  EXPECT_EQ(col.stops[0].category, StopCategory::Cat0);
  EXPECT_GT(col.stops[0].evidence_count, 0u);
  ASSERT_TRUE(eventually([&] { col.drain(); return col.last.mode == ControllerMode::Fault && !col.last.drives_enabled; }, 10.0));

  // Recover after release: enabled and holding again.
  loop->set_estop(false);
  MotionCommand rec;
  rec.command_id = 3;
  rec.kind = MotionCommandKind::Recover;
  ASSERT_TRUE(loop->send(rec));
  ASSERT_TRUE(eventually([&] { return col.final_of(3) != nullptr; }, 15.0));
  EXPECT_EQ(col.final_of(3)->kind, MotionEventKind::Completed) << col.final_of(3)->text.data();

  const LoopStats st = loop->stats();
  std::printf("cycles %llu overruns %llu compute mean %.1f us max %.1f us p99 %.0f us; wake-up latency mean %.1f us p99 %.0f us max %.1f us; SCHED_FIFO %s\n",
              static_cast<unsigned long long>(st.cycles), static_cast<unsigned long long>(st.overruns),
              st.compute_us_mean, st.compute_us_max, LoopStats::percentile_us(st.compute_hist, 0.99),
              st.wakeup_latency_us_mean, LoopStats::percentile_us(st.latency_hist, 0.99), st.wakeup_latency_us_max,
              st.realtime ? "yes" : "no");
  EXPECT_GT(st.cycles, 1000u);
  EXPECT_EQ(st.events_dropped, 0u);

  // Shutdown: Cat1 stop, drives disabled, thread ends.
  loop->stop();
  EXPECT_FALSE(loop->running());
  EXPECT_EQ(loop->controller().mode(), ControllerMode::Fault);
}

}  // namespace
}  // namespace foresight::control::test
