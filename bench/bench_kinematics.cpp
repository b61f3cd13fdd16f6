// Kinematics of the 7-DOF arm (config/robot.urdf): FK, Jacobian, gravity
// torques per call, and IK on random reachable targets (FK of random in-limit
// configurations) from random seeds, against plain KDL ChainIkSolverPos_LMA
// on the same targets and seeds. Counters: success_rate (within 1 mm and
// 0.1 deg; ours also within the joint limits), per-call median_us / p99_us.

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <kdl/chainiksolverpos_lma.hpp>
#include <random>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"

using namespace foresight;

namespace {

constexpr int kSamples = 1000;
constexpr double kPositionTolM = 1e-3;
constexpr double kRotationTolRad = 0.1 * M_PI / 180.0;

const RobotModel& arm() {
  static const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  return model;
}

std::vector<Eigen::VectorXd> random_configurations(const RobotModel& m, unsigned seed, int count) {
  std::mt19937 rng(seed);
  std::vector<Eigen::VectorXd> qs;
  for (int k = 0; k < count; ++k) {
    Eigen::VectorXd q(m.dof());
    for (int i = 0; i < m.dof(); ++i)
      q[i] = std::uniform_real_distribution<double>(m.limits()[i].lower_rad, m.limits()[i].upper_rad)(rng);
    qs.push_back(q);
  }
  return qs;
}

struct IkProblems {
  std::vector<Pose> targets;
  std::vector<Eigen::VectorXd> seeds;
};

const IkProblems& problems() {
  static const IkProblems p = [] {
    IkProblems out;
    KinematicsWorkspace ws(arm());
    for (const auto& q : random_configurations(arm(), 101, kSamples)) out.targets.push_back(forward_kinematics(arm(), ws, q));
    out.seeds = random_configurations(arm(), 202, kSamples);
    return out;
  }();
  return p;
}

void set_time_counters(benchmark::State& state, std::vector<double>& times_us) {
  std::sort(times_us.begin(), times_us.end());
  state.counters["median_us"] = times_us[times_us.size() / 2];
  state.counters["p99_us"] = times_us[times_us.size() * 99 / 100];
}

void BM_ForwardKinematics(benchmark::State& state) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  const auto qs = random_configurations(m, 1, 1024);
  std::size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(forward_kinematics(m, ws, qs[k++ & 1023]));
  }
}
BENCHMARK(BM_ForwardKinematics);

void BM_Jacobian(benchmark::State& state) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  const auto qs = random_configurations(m, 2, 1024);
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, m.dof());
  std::size_t k = 0;
  for (auto _ : state) {
    jacobian(m, ws, qs[k++ & 1023], J);
    benchmark::DoNotOptimize(J.data());
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_Jacobian);

void BM_GravityTorques(benchmark::State& state) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  const auto qs = random_configurations(m, 3, 1024);
  Eigen::VectorXd tau(m.dof());
  std::size_t k = 0;
  for (auto _ : state) {
    gravity_torques(m, ws, qs[k++ & 1023], tau);
    benchmark::DoNotOptimize(tau.data());
    benchmark::ClobberMemory();
  }
}
BENCHMARK(BM_GravityTorques);

/// Our IK; one iteration = one solve. The success rate covers every solve run.
void BM_InverseKinematics(benchmark::State& state) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  const IkProblems& p = problems();
  IkOptions options;
  options.centre_joints = state.range(0) != 0;
  std::vector<double> times_us;
  long solved = 0, runs = 0;
  std::size_t k = 0;
  for (auto _ : state) {
    const std::size_t i = k++ % kSamples;
    options.random_seed = static_cast<unsigned>(i);
    const auto t0 = std::chrono::steady_clock::now();
    const IkResult r = inverse_kinematics(m, ws, p.targets[i], p.seeds[i], options);
    times_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    state.PauseTiming();
    const Pose T = forward_kinematics(m, ws, r.q);
    ++runs;
    if ((T.translation() - p.targets[i].translation()).norm() <= kPositionTolM &&
        rotation_distance(T.linear(), p.targets[i].linear()) <= kRotationTolRad && m.within_limits(r.q))
      ++solved;
    state.ResumeTiming();
  }
  state.counters["success_rate"] = static_cast<double>(solved) / static_cast<double>(runs);
  set_time_counters(state, times_us);
}
BENCHMARK(BM_InverseKinematics)->Arg(0)->ArgName("centre_joints")->Iterations(kSamples)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_InverseKinematics)->Arg(1)->ArgName("centre_joints")->Iterations(kSamples)->Unit(benchmark::kMicrosecond);

/// The peer: plain KDL Levenberg-Marquardt (default settings) on the same
/// targets and seeds. It knows no joint limits: in_limits_rate says how often
/// its answer would have been usable.
void BM_KdlLmaIk(benchmark::State& state) {
  const RobotModel& m = arm();
  KinematicsWorkspace ws(m);
  const IkProblems& p = problems();
  const KDL::Chain chain = m.chain();
  KDL::ChainIkSolverPos_LMA solver(chain);
  KDL::JntArray q_init(m.dof()), q_out(m.dof());
  std::vector<double> times_us;
  long solved = 0, in_limits = 0, runs = 0;
  std::size_t k = 0;
  for (auto _ : state) {
    const std::size_t i = k++ % kSamples;
    const Pose& target = p.targets[i];
    KDL::Frame f;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) f.M(r, c) = target.linear()(r, c);
      f.p(r) = target.translation()[r];
    }
    q_init.data = p.seeds[i];
    const auto t0 = std::chrono::steady_clock::now();
    solver.CartToJnt(q_init, f, q_out);
    times_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    state.PauseTiming();
    const Pose T = forward_kinematics(m, ws, q_out.data);
    ++runs;
    if ((T.translation() - target.translation()).norm() <= kPositionTolM &&
        rotation_distance(T.linear(), target.linear()) <= kRotationTolRad) {
      ++solved;
      Eigen::VectorXd q_wrapped = q_out.data;  // be generous: 370 deg counts as 10 deg
      for (int j = 0; j < m.dof(); ++j) q_wrapped[j] = std::remainder(q_wrapped[j], 2.0 * M_PI);
      if (m.within_limits(q_wrapped)) ++in_limits;
    }
    state.ResumeTiming();
  }
  state.counters["success_rate"] = static_cast<double>(solved) / static_cast<double>(runs);
  state.counters["in_limits_rate"] = static_cast<double>(in_limits) / static_cast<double>(runs);
  set_time_counters(state, times_us);
}
BENCHMARK(BM_KdlLmaIk)->Iterations(kSamples)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
