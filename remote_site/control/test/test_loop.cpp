// The ControlLoop thread against the simulated CiA 402 drives and F/T sensor
// on mock CAN buses (the SimRig of remote_site/sim/test): enable through the
// loop, run a trajectory, hold, an E-stop with its evidence, shutdown.

#include <gtest/gtest.h>

#include "foresight/test/eventually.hpp"

#include <chrono>
#include <thread>

#include "control_fixture.hpp"
#include "foresight/control/control_loop.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/sim/contact_model.hpp"
#include "loop_fixture.hpp"
#include "sim_fixture.hpp"

namespace foresight::control::test {
namespace {

using Clock = std::chrono::steady_clock;

TEST(ControlLoop, EnablesRunsATrajectoryHoldsAndStopsOnEStop) {
  hw::RemoteConfig config = loop_test_config();
  foresight::test::SimRig rig(config, hw::joint_limits_by_name(robot()), [](sim::CanSimulator& s) {
    s.ft_sensor()->set_offset({4.0, -3.0, 2.0, 0.1, -0.05, 0.02});  // gauge zero offset: tare removes it
  });
  rig.drives->configure();

  ControllerConfig cc;
  cc.cycle_rate_hz = config.cycle_rate_hz;
  cc.tool.mass_kg = 0.0;  // the simulated sensor does not weigh the tool
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

  // Tare through the loop: the offset disappears from the compensated wrench;
  // then a known wrench reads back in the tool frame (sensor -> tip: +0.295 m z).
  col.drain();
  EXPECT_GT(std::abs(col.last.wrench_tool[0]), 3.0);
  MotionCommand tare;
  tare.command_id = 10;
  tare.kind = MotionCommandKind::Tare;
  tare.tare_samples = 20;
  ASSERT_TRUE(loop->send(tare));
  ASSERT_TRUE(eventually([&] { return col.final_of(10) != nullptr; }, 10.0));
  EXPECT_EQ(col.final_of(10)->kind, MotionEventKind::Completed);
  ASSERT_TRUE(eventually([&] {
    col.drain();
    double m = 0.0;
    for (double w : col.last.wrench_tool) m = std::max(m, std::abs(w));
    return m < 0.05;
  }, 5.0));
  rig.sim->ft_sensor()->set_true_wrench({0.0, 5.0, -10.0, 0.0, 0.0, 0.0});
  ASSERT_TRUE(eventually([&] { col.drain(); return std::abs(col.last.wrench_tool[2] + 10.0) < 0.05; }, 5.0));
  EXPECT_NEAR(col.last.wrench_tool[1], 5.0, 0.05);
  EXPECT_NEAR(col.last.wrench_tool[3], 0.295 * 5.0, 0.01);  // moment about the tip: -(p x F)_x = 0.295 Fy
  rig.sim->ft_sensor()->set_true_wrench({0.0, 0.0, 0.0, 0.0, 0.0, 0.0});

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
  // The SYNC's time after the wake-up is measured (issue 25, item 6; that it
  // changes nothing the drives see: HarshBus.TheSyncAtTheWakeUpChangesNothingTheDrivesSee).
  std::printf("SYNC after the wake-up: at most %.1f us\n", st.sync_after_wake_us_max);
  EXPECT_GT(st.sync_after_wake_us_max, 0.0);

  // Shutdown: Cat1 stop, drives disabled, thread ends.
  loop->stop();
  EXPECT_FALSE(loop->running());
  EXPECT_EQ(loop->controller().mode(), ControllerMode::Fault);
}

// Off the simulator the daemon requires real time: a loop without its memory
// locked (here: not asked to lock it) refuses to enable, names why, and the
// drives never power up (their own record). Recover is refused the same way.
TEST(ControlLoop, RequiringRealTimeAnEnableWithoutItFailsAndNoDrivePowersUp) {
  hw::RemoteConfig config = loop_test_config();
  foresight::test::SimRig rig(config, hw::joint_limits_by_name(robot()));
  rig.drives->configure();
  for (std::size_t j = 0; j < rig.sim->drive_count(); ++j) rig.sim->drive(j).clear_power_record();

  ControllerConfig cc;
  cc.cycle_rate_hz = config.cycle_rate_hz;
  cc.tool.mass_kg = 0.0;
  LoopOptions lo;
  lo.require_realtime = true;
  lo.lock_memory = false;
  auto loop = std::make_unique<ControlLoop>(*rig.drives, robot(), cc, lo);
  loop->start();
  Collector col(*loop);
  EXPECT_FALSE(loop->stats().memory_locked);
  const bool fifo = loop->stats().realtime;
  const std::string why = std::string("not real time (") + (fifo ? "" : "no SCHED_FIFO, ") +
                          "no mlockall): drives stay off; see --allow-non-rt";
  for (const auto kind : {MotionCommandKind::Enable, MotionCommandKind::Recover}) {
    MotionCommand en;
    en.command_id = kind == MotionCommandKind::Enable ? 1 : 2;
    en.kind = kind;
    ASSERT_TRUE(loop->send(en));
    ASSERT_TRUE(eventually([&] { return col.final_of(en.command_id) != nullptr; }, 15.0));
    const MotionEvent e = *col.final_of(en.command_id);
    EXPECT_EQ(e.kind, MotionEventKind::Failed);
    EXPECT_NE(std::string(e.text.data()).find(why), std::string::npos) << e.text.data();
  }
  col.drain();
  EXPECT_FALSE(col.last.drives_enabled);
  loop->stop();
  for (std::size_t j = 0; j < rig.sim->drive_count(); ++j) {
    const sim::DrivePowerRecord r = rig.sim->drive(j).power_record();
    EXPECT_FALSE(r.powered) << "drive " << j + 1;
    EXPECT_EQ(r.states_seen & (1u << static_cast<unsigned>(hw::canopen::PowerState::OperationEnabled)), 0u)
        << "drive " << j + 1;
  }
}

// Issue 25, item 5: power changes are part of the cycle. The enable and the
// disable are stepped by the loop's own cycles (the period grid goes on: the
// longest gap between two cycles while enabling is measured), every drive
// event on the way reaches the drive event ring (what the daemon journals),
// and the E-stop, read every cycle, aborts an enable into category 0: the
// drives' own record shows every drive unpowered within the category 0
// deadline of the loop reading it.
TEST(ControlLoop, PowerChangesRunInTheCycleAndAnEStopDuringAnEnableIsCategoryZero) {
  hw::RemoteConfig config = loop_test_config();
  foresight::test::SimRig rig(config, hw::joint_limits_by_name(robot()));
  rig.drives->configure();
  ControllerConfig cc;
  cc.cycle_rate_hz = config.cycle_rate_hz;
  cc.tool.mass_kg = 0.0;
  auto loop = std::make_unique<ControlLoop>(*rig.drives, robot(), cc);
  loop->start();
  Collector col(*loop);
  auto send = [&](std::uint64_t id, MotionCommandKind kind) {
    MotionCommand c;
    c.command_id = id;
    c.kind = kind;
    ASSERT_TRUE(loop->send(c));
    ASSERT_TRUE(eventually([&] { return col.final_of(id) != nullptr; }, 15.0));
  };

  send(1, MotionCommandKind::Enable);
  ASSERT_EQ(col.final_of(1)->kind, MotionEventKind::Completed) << col.final_of(1)->text.data();
  const LoopStats st = loop->stats();
  std::printf("enable through the loop: %u cycles; the longest gap between two cycles while enabling %.0f us "
              "(period %.0f us); missed periods in a row at most %llu\n",
              st.power_change_cycles_last, st.power_change_gap_us_max, 1e6 / config.cycle_rate_hz,
              static_cast<unsigned long long>(st.missed_streak_max));
  EXPECT_GE(st.power_change_cycles_last, 9u);  // the sequence's four steps, each answered
  EXPECT_GT(st.power_change_gap_us_max, 0.0);
  // The cycle went on: no stall of the enable's length (it was one phase
  // of ~25 ms without a controller step); a loaded test machine may delay
  // a wake-up by a few periods.
  EXPECT_LT(st.power_change_gap_us_max, 10 * 1e6 / config.cycle_rate_hz);
  // Every drive's way to Operation enabled, as events in the ring.
  std::array<std::vector<std::uint32_t>, 7> chain;
  DriveEventRecord r;
  while (loop->poll_drive_event(r))
    if (r.event.fault == hw::HwFault::PowerStateChanged && r.event.joint >= 0)
      chain[static_cast<std::size_t>(r.event.joint)].push_back(r.event.code);
  for (std::size_t j = 0; j < 7; ++j) {
    ASSERT_FALSE(chain[j].empty()) << "joint " << j + 1;
    EXPECT_EQ(chain[j].back(), static_cast<std::uint32_t>(hw::canopen::PowerState::OperationEnabled)) << j;
  }

  send(2, MotionCommandKind::Disable);
  ASSERT_EQ(col.final_of(2)->kind, MotionEventKind::Completed) << col.final_of(2)->text.data();
  for (std::size_t j = 0; j < 7; ++j) EXPECT_FALSE(rig.sim->drive(j).power_record().powered) << j;

  // Joint 7 stops answering: the enable waits for it (up to the step
  // deadline) while the other six reach Operation enabled; then the E-stop.
  rig.sim->drive(6).stop_answering(true);
  for (std::size_t j = 0; j < 7; ++j) rig.sim->drive(j).clear_power_record();
  MotionCommand en;
  en.command_id = 3;
  en.kind = MotionCommandKind::Enable;
  ASSERT_TRUE(loop->send(en));
  ASSERT_TRUE(eventually([&] {
    for (std::size_t j = 0; j < 6; ++j)
      if (rig.sim->drive(j).power_state() != hw::canopen::PowerState::OperationEnabled) return false;
    return true;
  }, 5.0));
  ASSERT_EQ(col.final_of(3), nullptr);  // still enabling
  const std::uint64_t sync_at_estop = rig.sim->drive(0).sync_count();
  loop->set_estop(true);
  ASSERT_TRUE(eventually([&] { return col.final_of(3) != nullptr; }, 5.0));
  EXPECT_EQ(col.final_of(3)->kind, MotionEventKind::Failed);
  EXPECT_STREQ(col.final_of(3)->text.data(), "E-stop pressed during the enable: drives powered off (category 0)");
  ASSERT_EQ(col.stops.size(), 1u);
  EXPECT_EQ(col.stops[0].cause, StopCause::EStop);
  EXPECT_EQ(col.stops[0].category, StopCategory::Cat0);
  EXPECT_STREQ(col.stops[0].text.data(), "E-stop pressed during the enable");
  // The loop reads the input at its next cycle k and sends Disable Voltage
  // in it; the drives latch it at SYNC k+1 (one more when the simulator had
  // not yet taken the SYNC the test counted from). The command's failure is
  // decided in cycle k: the simulator thread may take SYNC k+1 after it.
  ASSERT_TRUE(eventually([&] {
    for (std::size_t j = 0; j < 6; ++j)
      if (rig.sim->drive(j).power_record().powered) return false;
    return true;
  }, 5.0));
  for (std::size_t j = 0; j < 6; ++j) {
    const sim::DrivePowerRecord p = rig.sim->drive(j).power_record();
    EXPECT_FALSE(p.powered) << j;
    EXPECT_LE(p.power_off_sync - sync_at_estop, 3u) << j;
  }
  EXPECT_FALSE(rig.sim->drive(6).power_record().powered);
  ASSERT_TRUE(eventually([&] { col.drain(); return col.last.mode == ControllerMode::Fault; }, 5.0));
  loop->set_estop(false);
  rig.sim->drive(6).stop_answering(false);
  loop->stop();
  EXPECT_EQ(loop->controller().mode(), ControllerMode::Fault);
  EXPECT_EQ(loop->stats().drive_events_dropped, 0u);
}

// The whole chain: the insert algorithm in the loop thread, the simulated
// drives (second-order position loops) on the mock CAN buses, the contact
// model feeding the simulated F/T node, read back through the CAN decoder.
TEST(ControlLoop, InsertsThroughTheSimulatedDrivesAndSensor) {
  hw::RemoteConfig config = loop_test_config();
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  auto contact = std::make_shared<sim::ContactModel>(oru, sim::load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  const Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  // 1 cm in front of the hole, 2.5 mm off the axis, tilted 1 deg.
  const Pose start = base_T_oru * Eigen::Translation3d(0.0025, 0.0, -0.010) *
                     Eigen::AngleAxisd(M_PI / 180.0, Eigen::Vector3d::UnitY());
  KinematicsWorkspace ws(robot());
  const IkResult ik = inverse_kinematics(robot(), ws, start, robot().mid_configuration());
  ASSERT_TRUE(ik.success);

  foresight::test::SimRig rig(config, hw::joint_limits_by_name(robot()),
                              [&](sim::CanSimulator& s) { place_arm(s, config, ik.q, contact, base_T_oru); });
  rig.drives->configure();

  ControllerConfig cc;
  cc.cycle_rate_hz = config.cycle_rate_hz;
  cc.tool.mass_kg = 0.0;  // the simulated sensor reads contact only
  auto loop = std::make_unique<ControlLoop>(*rig.drives, robot(), cc);
  loop->start();
  Collector col(*loop);
  MotionCommand en;
  en.command_id = 1;
  en.kind = MotionCommandKind::Enable;
  ASSERT_TRUE(loop->send(en));
  ASSERT_TRUE(eventually([&] { return col.final_of(1) != nullptr; }, 15.0));
  ASSERT_EQ(col.final_of(1)->kind, MotionEventKind::Completed) << col.final_of(1)->text.data();

  MotionCommand ins;
  ins.command_id = 2;
  ins.kind = MotionCommandKind::RunAlgorithm;
  ins.algorithm.kind = AlgorithmKind::Insert;
  ins.algorithm.insert.depth_m = 0.05;
  ASSERT_TRUE(loop->send(ins));
  ASSERT_TRUE(eventually([&] { return col.final_of(2) != nullptr; }, 60.0));
  const MotionEvent done = *col.final_of(2);
  for (const auto& st : col.stops) ADD_FAILURE() << "stop: " << st.text.data();
  ASSERT_EQ(done.kind, MotionEventKind::Completed) << done.text.data();
  std::vector<double> q_now(config.drives.size());
  rig.sim->joint_positions_rad(q_now);
  const Eigen::Map<const Eigen::VectorXd> q(q_now.data(), static_cast<Eigen::Index>(q_now.size()));
  const sim::ContactResult r = contact->compute(forward_kinematics(robot(), ws, q), base_T_oru);
  EXPECT_GT(r.insertion_depth_m, 0.038);
  EXPECT_LT(r.tip_radial_offset_m, contact->clearance_m() + 5e-4);
  std::printf("insert through the loop: depth %.1f mm, peak %.1f N (%s)\n", 1e3 * r.insertion_depth_m, done.peak_force_n,
              done.text.data());
  loop->stop();
}

}  // namespace
}  // namespace foresight::control::test
