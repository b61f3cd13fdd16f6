// bench_control: one control cycle's compute for the 7-joint arm, the code
// that runs in the real-time loop: DriveSystem::cycle_read (decode 7 TPDOs +
// 2 F/T frames from the mock CAN buses) -> Controller::step (interpolation,
// F/T compensation + filter, admittance, FK/Jacobian, damped least squares,
// safety checks, telemetry) -> DriveSystem::cycle_write (7 RPDOs + 2 SYNCs).
// The simulated drives answer between iterations (not timed).
//
//   BM_ControlCycle/0  stiff trajectory (interpolation only)
//   BM_ControlCycle/1  compliant trajectory (+ admittance, Jacobian, DLS)
//   BM_ControlCycle/2  insert algorithm (+ Cartesian tracking, FK of the command)
// Counters: median_us, p99_us, max_us (per-cycle, from every iteration).
//   BM_ControllerStep/0,1  Controller::step alone (stiff / compliant trajectory)
// BM_Insertion (bench_insertion.cpp, by the plant's owner) is linked in when
// present; this file provides main().

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <vector>

#include "foresight/common/robot_model.hpp"
#include "foresight/control/control_loop.hpp"
#include "foresight/control/controller.hpp"
#include "foresight/hw/drive_system.hpp"
#include "foresight/sim/can_simulator.hpp"

using namespace foresight;

namespace {

const RobotModel& robot() {
  static const RobotModel m = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  return m;
}

void BM_ControlCycle(benchmark::State& state) {
  const int mode = static_cast<int>(state.range(0));
  hw::RemoteConfig config = hw::load_remote_config(FORESIGHT_CONFIG_DIR "/remote.yaml");
  config.tpdo_miss_limit = 1000;  // the benchmark thread may be descheduled between iterations
  auto buses = sim::make_mock_buses(config);
  auto simulator = sim::CanSimulator::from_config(config, std::move(buses.far));
  simulator->start();
  hw::DriveSystem drives(config, std::move(buses.master), hw::joint_limits_by_name(robot()));
  drives.configure();
  drives.enable();
  simulator->stop();  // from here the benchmark thread steps the simulator
  simulator->process(5);

  control::ControllerConfig cc;
  cc.cycle_rate_hz = config.cycle_rate_hz;
  control::Controller ctl(robot(), cc);
  hw::JointFeedback fb;
  hw::FtReading ft;
  hw::JointTargets targets;
  control::CycleInputs in;
  control::CycleOutputs out;
  drives.held_targets(targets);
  control::JointArray held{};
  for (std::size_t j = 0; j < 7; ++j) held[j] = targets.position_rad[j];

  // Bring the controller up: first cycle, Enable (the drives already are).
  {
    const hw::CycleStatus s = drives.cycle_read(fb, ft);
    control::fill_cycle_inputs(s, fb, ft, in);
    ctl.step(in, out);
    control::MotionCommand en;
    en.command_id = 1;
    en.kind = control::MotionCommandKind::Enable;
    ctl.command(en);
    ctl.step(in, out);
    ctl.drive_request_done(control::DriveRequest::Enable, true, "", held);
    drives.cycle_write(targets);
    simulator->process(0);
  }

  // A slow 100 s trajectory from where the arm is (100 Hz samples).
  Trajectory t;
  const int n = 10001;
  t.positions_rad.resize(n, 7);
  for (int i = 0; i < n; ++i) {
    const double ts = i * 0.01;
    t.time_s.push_back(ts);
    for (int j = 0; j < 7; ++j)
      t.positions_rad(i, j) = held[static_cast<std::size_t>(j)] + 0.1 * std::pow(std::sin(M_PI * ts / 100.0), 2);
  }
  const control::PreparedTrajectory traj(t);
  control::MotionCommand c;
  c.command_id = 2;
  if (mode == 2) {
    c.kind = control::MotionCommandKind::RunAlgorithm;
    c.algorithm.kind = control::AlgorithmKind::Insert;
    c.algorithm.insert.depth_m = 0.2;
    c.algorithm.insert.speed_m_s = 0.001;
    c.algorithm.insert.timeout_s = 1000.0;
  } else {
    c.kind = control::MotionCommandKind::RunTrajectory;
    c.trajectory = &traj;
    c.compliant = mode == 1;
  }
  ctl.command(c);

  std::vector<double> us;
  us.reserve(static_cast<std::size_t>(state.max_iterations));
  for (auto _ : state) {
    simulator->process(0);  // the far end answers the previous SYNC (not timed)
    const auto t0 = std::chrono::steady_clock::now();
    const hw::CycleStatus s = drives.cycle_read(fb, ft);
    control::fill_cycle_inputs(s, fb, ft, in);
    ctl.step(in, out);
    for (std::size_t j = 0; j < 7; ++j) targets.position_rad[j] = out.q_cmd[j];
    drives.cycle_write(targets);
    const auto t1 = std::chrono::steady_clock::now();
    const double dt = std::chrono::duration<double>(t1 - t0).count();
    state.SetIterationTime(dt);
    us.push_back(dt * 1e6);
  }
  if (ctl.mode() != (mode == 2 ? control::ControllerMode::Algorithm : control::ControllerMode::Trajectory))
    state.SkipWithError("the controller left its mode during the benchmark (a stop?)");
  std::sort(us.begin(), us.end());
  if (!us.empty()) {
    state.counters["median_us"] = us[us.size() / 2];
    state.counters["p99_us"] = us[std::min(us.size() - 1, us.size() * 99 / 100)];
    state.counters["max_us"] = us.back();
  }
}
BENCHMARK(BM_ControlCycle)->Arg(0)->Arg(1)->Arg(2)->Iterations(20000)->UseManualTime()->Unit(benchmark::kMicrosecond);

// Controller::step alone (no CAN): the share of the cycle that is the
// controller's. The measured joints follow the command one cycle late.
void BM_ControllerStep(benchmark::State& state) {
  const int mode = static_cast<int>(state.range(0));
  control::ControllerConfig cc;
  control::Controller ctl(robot(), cc);
  control::CycleInputs in;
  control::CycleOutputs out;
  in.joints = 7;
  const double q0[7] = {0.0, 0.6, 0.0, -1.2, 0.0, 0.9, 0.0};
  control::JointArray held{};
  for (std::size_t j = 0; j < 7; ++j) held[j] = in.q[j] = q0[j];
  ctl.step(in, out);
  control::MotionCommand en;
  en.command_id = 1;
  en.kind = control::MotionCommandKind::Enable;
  ctl.command(en);
  ctl.step(in, out);
  ctl.drive_request_done(control::DriveRequest::Enable, true, "", held);
  in.drives_enabled = true;
  Trajectory t;
  t.positions_rad.resize(10001, 7);
  for (int i = 0; i < 10001; ++i) {
    t.time_s.push_back(i * 0.01);
    for (int j = 0; j < 7; ++j) t.positions_rad(i, j) = q0[j] + 0.1 * std::pow(std::sin(M_PI * i * 0.01 / 100.0), 2);
  }
  const control::PreparedTrajectory traj(t);
  control::MotionCommand c;
  c.command_id = 2;
  c.kind = control::MotionCommandKind::RunTrajectory;
  c.trajectory = &traj;
  c.compliant = mode == 1;
  ctl.command(c);
  for (auto _ : state) {
    ctl.step(in, out);
    in.q = out.q_cmd;
    ++in.cycle;
    benchmark::DoNotOptimize(out.q_cmd);
  }
}
BENCHMARK(BM_ControllerStep)->Arg(0)->Arg(1)->Iterations(20000)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
