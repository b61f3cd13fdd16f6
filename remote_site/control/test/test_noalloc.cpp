// The control cycle never touches the heap: 10,000 cycles of every mode
// (disabled, stiff and compliant hold, identify_payload, trajectory, compliant
// trajectory, guarded_move, insert with spiral search, pull_out, controlled stop,
// stopped, fault) and the commands that start and end them, counted with the
// shared counter (foresight/test/allocation_counter.hpp: a replaced operator
// new AND malloc, since Eigen and KDL allocate through malloc; under ASan/TSan
// the sanitizer's own malloc hook, so this test runs in the sanitizer builds
// too). The counter is armed only around Controller::step() and
// Controller::command() on the test thread; the test's plant and bookkeeping
// run unarmed.

#include <gtest/gtest.h>

#include <memory>
#include <optional>

#include "control_fixture.hpp"
#include "foresight/control/control_loop.hpp"
#include "foresight/common/spsc_ring.hpp"
#include "foresight/sim/can_simulator.hpp"
#include "foresight/test/allocation_counter.hpp"

namespace {
// One counter per test (armed and paused by arm()); created paused.
std::optional<foresight::test::AllocationCounter> g_counter;
void reset_counter() {
  g_counter.reset();
  g_counter.emplace();
  g_counter->pause();
}
long allocations() { return g_counter->count(); }
}  // namespace

namespace foresight::control::test {
namespace {

void arm(bool on) {
  if (on)
    g_counter->resume();
  else
    g_counter->pause();
}

Trajectory long_trajectory(const JointArray& from, double duration_s) {
  Trajectory t;
  const int n = static_cast<int>(duration_s * 100.0) + 1;
  t.positions_rad.resize(n, 7);
  for (int i = 0; i < n; ++i) {
    const double ts = i / 100.0;
    t.time_s.push_back(ts);
    for (int j = 0; j < 7; ++j)
      t.positions_rad(i, j) = from[static_cast<std::size_t>(j)] + 0.05 * std::pow(std::sin(M_PI * ts / duration_s), 2);
  }
  return t;
}

JointArray ik(const Pose& target) {
  KinematicsWorkspace ws(robot());
  const IkResult r = inverse_kinematics(robot(), ws, target, robot().mid_configuration());
  EXPECT_TRUE(r.success);
  JointArray q{};
  for (int j = 0; j < 7; ++j) q[static_cast<std::size_t>(j)] = r.q(j);
  return q;
}

TEST(ControlNoAlloc, CounterSeesAllocations) {
  reset_counter();
  arm(true);
  auto* v = new std::vector<double>(100);
  Eigen::VectorXd x(50);
  x.setZero();
  arm(false);
  delete v;
  EXPECT_EQ(allocations(), 3);
}

TEST(ControlNoAlloc, EveryModeFor10000Cycles) {
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const sim::ContactModel contact(oru, sim::load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  const Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  const JointArray q_face = ik(base_T_oru * Eigen::Translation3d(0.0045, 0.0, -0.01) *
                               Eigen::AngleAxisd(M_PI / 180.0, Eigen::Vector3d::UnitY()));
  const JointArray q_far = ik(base_T_oru * Eigen::Translation3d(0.0, 0.0, -0.3));
  const PreparedTrajectory traj(long_trajectory(q_far, 21.0));

  Bench b(q_far);
  b.contact = &contact;
  b.base_T_oru = base_T_oru;
  b.last_tip = b.tip(b.q_arm);
  b.arm = arm;
  reset_counter();
  const auto run = [&](const char* what, int cycles) {
    const long before = allocations();
    for (int k = 0; k < cycles; ++k) b.step();
    EXPECT_EQ(allocations() - before, 0) << what;
  };
  const auto command = [&](MotionCommandKind kind, auto&& fill) {
    MotionCommand c;
    c.kind = kind;
    fill(c);
    return b.send(c);
  };
  const auto none = [](MotionCommand&) {};

  run("disabled", 10000);
  b.enable();
  run("hold", 10000);
  command(MotionCommandKind::SetPayload, [](MotionCommand& c) { c.oru_latched = true; });
  const auto identify_id = command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) {
    c.algorithm.kind = AlgorithmKind::IdentifyPayload;
  });
  run("identify_payload (6 poses, least squares) then hold", 10000);
  bool identified = false;
  for (const auto& e : b.events)
    identified = identified || (e.command_id == identify_id && e.kind == MotionEventKind::Completed);
  EXPECT_TRUE(identified);
  command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) {  // refused: too small to excite
    c.algorithm.kind = AlgorithmKind::IdentifyPayload;
    c.algorithm.identify_payload.angle_rad = 0.001;
  });
  command(MotionCommandKind::SetPayload, [](MotionCommand& c) { c.oru_latched = false; });
  command(MotionCommandKind::Hold, [](MotionCommand& c) { c.compliant = true; });
  run("compliant hold", 10000);
  command(MotionCommandKind::Hold, none);
  command(MotionCommandKind::RunTrajectory, [&](MotionCommand& c) { c.trajectory = &traj; });
  run("trajectory", 10000);
  command(MotionCommandKind::Hold, none);  // cancels
  run("hold back at the face", 10);
  // Return along the same trajectory's end half is not needed: start a new
  // compliant run from where the arm is by re-preparing (outside the count).
  {
    Trajectory t2 = long_trajectory(b.out.q_cmd, 21.0);
    const PreparedTrajectory traj2(t2);
    command(MotionCommandKind::RunTrajectory, [&](MotionCommand& c) {
      c.trajectory = &traj2;
      c.compliant = true;
    });
    run("compliant trajectory", 10000);
    command(MotionCommandKind::Hold, none);
    run("hold", 10);
  }
  // Back to the face for the contact algorithms (a plain trajectory).
  {
    Trajectory back;
    back.time_s = {0.0, 4.0};
    back.positions_rad.resize(2, 7);
    for (int j = 0; j < 7; ++j) {
      back.positions_rad(0, j) = b.out.q_cmd[static_cast<std::size_t>(j)];
      back.positions_rad(1, j) = q_face[static_cast<std::size_t>(j)];
    }
    const PreparedTrajectory tb(back);
    command(MotionCommandKind::RunTrajectory, [&](MotionCommand& c) { c.trajectory = &tb; });
    run("trajectory back", 2500);
  }
  const auto insert_id = command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) {
    c.algorithm.kind = AlgorithmKind::Insert;
    c.algorithm.insert.depth_m = 0.06;
  });
  run("insert (spiral search, entry, depth) then compliant hold", 10000);
  bool inserted = false;
  for (const auto& e : b.events) inserted = inserted || (e.command_id == insert_id && e.kind == MotionEventKind::Completed);
  EXPECT_TRUE(inserted);
  command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) {
    c.algorithm.kind = AlgorithmKind::PullOut;
    c.algorithm.pull_out.distance_m = 0.07;
  });
  run("pull_out then hold", 10000);
  command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) {
    c.algorithm.kind = AlgorithmKind::GuardedMove;
    c.algorithm.guarded_move.force_threshold_n = 8.0;
    c.algorithm.guarded_move.max_distance_m = 0.05;
  });
  run("guarded_move then hold", 10000);
  // A controlled stop of an algorithm: its reference decelerates on its line.
  command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) {
    c.algorithm.kind = AlgorithmKind::GuardedMove;
    c.algorithm.guarded_move.direction = {0.0, 0.0, -1.0};  // away from the face
    c.algorithm.guarded_move.speed_m_s = 0.05;
    c.algorithm.guarded_move.max_distance_m = 0.03;
  });
  const std::uint64_t limited_before = b.out.telemetry.rate_limited_cycles;
  run("guarded_move away (its start is rate limited, the admittance takes it back)", 100);
  EXPECT_GT(b.out.telemetry.rate_limited_cycles, limited_before);
  command(MotionCommandKind::Stop, [](MotionCommand& c) { c.category = StopCategory::Cat2; });
  run("algorithm stopping on its reference, stopped", 1000);
  command(MotionCommandKind::Recover, none);
  run("recovered", 10);
  // Rejections format text (snprintf) in the cycle thread too.
  command(MotionCommandKind::RunTrajectory, [&](MotionCommand& c) { c.trajectory = &traj; });
  command(MotionCommandKind::RunAlgorithm, [](MotionCommand& c) { c.algorithm.insert.depth_m = -1; c.algorithm.kind = AlgorithmKind::Insert; });
  command(MotionCommandKind::Tare, [](MotionCommand& c) { c.tare_samples = 10; });  // refused: compliant hold
  command(MotionCommandKind::Hold, none);
  command(MotionCommandKind::Tare, [](MotionCommand& c) { c.tare_samples = 10; });
  run("tare", 100);
  command(MotionCommandKind::Stop, [](MotionCommand& c) { c.category = StopCategory::Cat2; });
  run("stopping, stopped", 10000);
  command(MotionCommandKind::Recover, none);
  run("recovered", 10);
  b.in.estop = true;
  run("E-stop: Cat0, fault", 10000);
  b.in.estop = false;
  command(MotionCommandKind::Recover, none);
  run("recovered", 100);
  EXPECT_EQ(b.ctl->mode(), ControllerMode::Idle);
  EXPECT_EQ(b.stops.size(), 3u);
  if (HasFailure()) {
    for (const auto& s : b.stops) std::printf("stop %s %s at %llu\n", to_string(s.cause), s.text.data(), static_cast<unsigned long long>(s.cycle));
    for (const auto& e : b.events)
      std::printf("event %llu %s %s %s at %llu\n", static_cast<unsigned long long>(e.command_id), to_string(e.command),
                  to_string(e.kind), e.text.data(), static_cast<unsigned long long>(e.cycle));
  }
}

// The loop body as ControlLoop runs it: cycle_read on the real DriveSystem
// (mock CAN), fill_cycle_inputs, command hand-over through the ring, step,
// cycle_write, events and telemetry into their rings. The simulated drives
// answer between cycles from this thread, unarmed.
/// The real DriveSystem configured against the simulated drives (started on
/// their own thread for the bring-up).
struct CanMaster {
  std::unique_ptr<sim::CanSimulator> simulator;
  std::unique_ptr<hw::DriveSystem> drives;
  CanMaster() {
    hw::RemoteConfig config = hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
    config.tpdo_miss_limit = 1000;
    auto buses = sim::make_mock_buses(config);
    simulator = sim::CanSimulator::from_config(config, std::move(buses.far));
    simulator->start();
    drives = std::make_unique<hw::DriveSystem>(config, std::move(buses.master), hw::joint_limits_by_name(robot()));
    drives->configure();
  }
};

TEST(ControlNoAlloc, LoopBodyWithTheCanMaster) {
  CanMaster master;
  hw::DriveSystem& drives = *master.drives;
  sim::CanSimulator* simulator = master.simulator.get();
  drives.enable();
  simulator->stop();
  simulator->process(5);
  Controller ctl(robot(), ControllerConfig{});
  auto commands = std::make_unique<SpscRing<MotionCommand>>(64);
  auto events = std::make_unique<SpscRing<MotionEvent>>(256);
  auto telemetry = std::make_unique<SpscRing<TelemetrySample>>(1024);
  hw::JointFeedback fb;
  hw::FtReading ft;
  hw::JointTargets targets;
  drives.held_targets(targets);
  JointArray held{};
  for (std::size_t j = 0; j < 7; ++j) held[j] = targets.position_rad[j];
  CycleInputs in;
  CycleOutputs out;
  Trajectory t;
  t.positions_rad.resize(3001, 7);
  for (int i = 0; i < 3001; ++i) {
    t.time_s.push_back(i * 0.01);
    for (int j = 0; j < 7; ++j)
      t.positions_rad(i, j) = held[static_cast<std::size_t>(j)] + 0.05 * std::pow(std::sin(M_PI * i / 3000.0), 2);
  }
  const PreparedTrajectory traj(t);
  MotionCommand en;
  en.command_id = 1;
  en.kind = MotionCommandKind::Enable;
  commands->try_push(en);
  MotionCommand run;
  run.command_id = 2;
  run.kind = MotionCommandKind::RunTrajectory;
  run.trajectory = &traj;
  run.compliant = true;
  reset_counter();
  long allocated = 0;
  std::size_t popped = 0;
  for (int k = 0; k < 10000; ++k) {
    simulator->process(0);
    if (k == 5) commands->try_push(run);
    arm(true);
    const hw::CycleStatus s = drives.cycle_read(fb, ft);
    drives.send_sync();  // as ControlLoop::cycle: the SYNC before the computation
    fill_cycle_inputs(s, fb, ft, in);
    MotionCommand c;
    while (commands->try_pop(c)) ctl.command(c);
    ctl.step(in, out);
    if (out.drive_request == DriveRequest::Enable)  // already enabled above (set-up)
      ctl.drive_request_done(DriveRequest::Enable, true, "", held);
    for (std::size_t j = 0; j < 7; ++j) targets.position_rad[j] = out.q_cmd[j];
    drives.cycle_write(targets);
    for (std::size_t i = 0; i < out.event_count; ++i) events->try_push(out.events[i]);
    telemetry->try_push(out.telemetry);
    arm(false);
    allocated = allocations();
    MotionEvent e;
    while (events->try_pop(e)) ++popped;
    TelemetrySample ts;
    while (telemetry->try_pop(ts)) {
    }
    ASSERT_EQ(allocated, 0) << "cycle " << k;
  }
  EXPECT_EQ(ctl.mode(), ControllerMode::Trajectory);
  EXPECT_GE(popped, 3u);  // enable started + completed, trajectory started
}

// Issue 25, item 5: the power changes run in the cycle. The loop body as
// ControlLoop runs it with the drives configured but off: Enable (the
// CiA 402 sequence stepped by cycle_write, judged by cycle_read, reported
// to the controller), Disable, and Enable again with a drive in Fault (its
// one fault reset), every cycle armed: no allocation anywhere on the way.
TEST(ControlNoAlloc, PowerChangesSteppedByTheCycle) {
  CanMaster master;
  hw::DriveSystem& drives = *master.drives;
  sim::CanSimulator* simulator = master.simulator.get();
  simulator->stop();
  simulator->process(5);
  Controller ctl(robot(), ControllerConfig{});
  hw::JointFeedback fb;
  hw::FtReading ft;
  hw::JointTargets targets;
  drives.held_targets(targets);
  CycleInputs in;
  CycleOutputs out;
  DriveRequest running = DriveRequest::None;
  int finished = 0;
  std::uint64_t id = 0;
  auto command = [&](MotionCommandKind kind) {
    MotionCommand c;
    c.command_id = ++id;
    c.kind = kind;
    return c;
  };
  reset_counter();
  for (int k = 0; k < 600; ++k) {
    simulator->process(0);
    if (k == 300) simulator->drive(2).inject_fault(0x2310);
    std::optional<MotionCommand> c;
    if (k == 0 || k == 350) c = command(MotionCommandKind::Enable);
    if (k == 200) c = command(MotionCommandKind::Disable);
    arm(true);
    const hw::CycleStatus s = drives.cycle_read(fb, ft);
    drives.send_sync();
    if (running != DriveRequest::None && s.power.finished) {  // ControlLoop::finish_power_change
      char text[96] = "";
      const bool ok = s.power.phase != hw::PowerPhase::Failed;
      if (!ok) drives.describe_power_failure(s.power.cause, text, sizeof text);
      drives.held_targets(targets);
      JointArray held{};
      for (std::size_t j = 0; j < 7; ++j) held[j] = targets.position_rad[j];
      ctl.drive_request_done(running, ok, text, held);
      running = DriveRequest::None;
      ++finished;
    }
    fill_cycle_inputs(s, fb, ft, in);
    if (c) ctl.command(*c);
    ctl.step(in, out);
    if (out.drive_request == DriveRequest::Enable) {  // ControlLoop::begin_power_change
      hw::HwEvent refused;
      if (drives.begin_enable(&refused)) running = DriveRequest::Enable;
    } else if (out.drive_request == DriveRequest::Disable && drives.begin_disable()) {
      running = DriveRequest::Disable;
    }
    for (std::size_t j = 0; j < 7; ++j) targets.position_rad[j] = out.q_cmd[j];
    drives.cycle_write(targets);
    arm(false);
    ASSERT_EQ(allocations(), 0) << "cycle " << k;
    if (k == 150) {
      ASSERT_EQ(ctl.mode(), ControllerMode::Idle);
    }
    if (k == 300) {
      ASSERT_EQ(ctl.mode(), ControllerMode::Disabled);
    }
  }
  EXPECT_EQ(finished, 3);
  EXPECT_EQ(ctl.mode(), ControllerMode::Idle);
  EXPECT_EQ(simulator->drive(2).power_state(), hw::canopen::PowerState::OperationEnabled);
}

}  // namespace
}  // namespace foresight::control::test
