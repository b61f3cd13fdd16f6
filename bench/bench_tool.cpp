// LST tool link and contact physics: Modbus round trips against the simulated
// tool (TCP on 127.0.0.1, RTU over a pty) and one contact-wrench evaluation.
#include <benchmark/benchmark.h>

#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/hw/lst_tool.hpp"
#include "foresight/sim/contact_model.hpp"
#include "foresight/sim/lst_server.hpp"

using namespace foresight;

namespace {

hw::LstToolConfig tcp_client(int port) {
  hw::LstToolConfig c;
  c.port = port;
  c.response_timeout_s = 0.5;
  return c;
}

}  // namespace

// One FC 04 read of the 8 status registers, decoded: the tool thread's poll.
static void BM_ModbusReadStatus(benchmark::State& state) {
  sim::LstServer server(sim::LstServerOptions{});
  hw::LstTool tool(tcp_client(server.port()));
  hw::LstStatus s;
  if (tool.read_status(s)) {
    state.SkipWithError(tool.last_error_message().c_str());
    return;
  }
  for (auto _ : state) {
    if (tool.read_status(s)) {
      state.SkipWithError(tool.last_error_message().c_str());
      break;
    }
    benchmark::DoNotOptimize(s);
  }
}
BENCHMARK(BM_ModbusReadStatus)->Unit(benchmark::kMicrosecond)->UseRealTime();

// A run command: FC 16 (speed, torque limit) + FC 15 (RUN, DIRECTION).
static void BM_ModbusRunCommand(benchmark::State& state) {
  sim::LstServer server(sim::LstServerOptions{});
  hw::LstTool tool(tcp_client(server.port()));
  for (auto _ : state) {
    if (tool.run(hw::LstDirection::Tighten, 0.0, 10.0)) {
      state.SkipWithError(tool.last_error_message().c_str());
      break;
    }
  }
}
BENCHMARK(BM_ModbusRunCommand)->Unit(benchmark::kMicrosecond)->UseRealTime();

static void BM_ModbusReadStatusRtuPty(benchmark::State& state) {
  sim::LstServerOptions o;
  o.transport = sim::LstServerOptions::Transport::Rtu;
  sim::LstServer server(o);
  hw::LstToolConfig c;
  c.transport = hw::LstToolConfig::Transport::Rtu;
  c.device = server.device_path();
  c.response_timeout_s = 0.5;
  hw::LstTool tool(c);
  hw::LstStatus s;
  for (auto _ : state) {
    if (tool.read_status(s)) {
      state.SkipWithError(tool.last_error_message().c_str());
      break;
    }
    benchmark::DoNotOptimize(s);
  }
}
BENCHMARK(BM_ModbusReadStatusRtuPty)->Unit(benchmark::kMicrosecond)->UseRealTime();

// One contact evaluation with the tool 6 cm in the hole and touching the wall
// (64 end-face points + 50 shaft slices), as the plant simulator calls it per cycle.
static void BM_ContactWrench(benchmark::State& state) {
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  const sim::ContactModel model(oru, sim::load_contact_params(FORESIGHT_CONFIG_DIR "/scene.yaml"));
  const Pose base_T_tip = base_T_oru * Pose(Eigen::Translation3d(model.clearance_m() + 2e-4, 0.0, 0.06));
  sim::Twist v;
  v.v_m_s = Eigen::Vector3d(0.01, 0.0, 0.0);
  for (auto _ : state) {
    const sim::ContactResult r = model.compute(base_T_tip, base_T_oru, v);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_ContactWrench)->Unit(benchmark::kMicrosecond);

static void BM_ScrewStep(benchmark::State& state) {
  sim::LstMechanism m(sim::LstMechanismParams{});
  sim::LstCommand cmd;
  cmd.run = true;
  cmd.loosen = true;
  cmd.speed_rad_s = 1e-6;  // stays engaged for the whole run
  cmd.torque_limit_nm = 40.0;
  for (auto _ : state) {
    m.step(cmd, 1e-3);
    benchmark::DoNotOptimize(m.state());
  }
}
BENCHMARK(BM_ScrewStep);

BENCHMARK_MAIN();
