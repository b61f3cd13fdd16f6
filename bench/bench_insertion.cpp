// BM_Insertion (compiled into bench_control): the insertion success rate of
// the controller's `insert` algorithm (control::Controller, the code that runs
// on the robot) against the simulated plant in-process, over randomized
// starts after the issue: the tool starts 1 cm in front of the hole with a
// lateral error up to 3 mm (uniform over the disk) and a tilt up to 1 deg
// (uniform magnitude, random axis), into the 30 mm hole with the 28 mm socket
// (1 mm radial clearance).
//
// Each insertion is sim_insertion::run_insertion (remote_site/sim_insertion:
// the kinematic plant, the F/T reading tared at the start pose, 500 Hz; the
// code `foresight-remote simulate-insertions` runs), each start's joints
// World::start_joints.
//
// Success: the algorithm reports Completed AND the true tip is in the hole at
// least plant.grasp_depth_m (5 cm) deep. Counters:
//   success_rate           successes / starts
//   face_contact_rate      starts whose end face landed on the ORU face/rim
//   spiral_search_rate     starts that needed the spiral search
//   peak_force_n           largest true contact force over all starts (N)
//   peak_force_mean_n      mean over starts of each start's peak force (N)
//   seconds_per_insertion  mean simulated time of a successful insertion (s)
//   compute_ms_per_insertion  wall-clock compute per insertion (ms)
// Self-contained: registers itself; bench_control.cpp provides main().
#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/sim/plant.hpp"
#include "foresight/sim_insertion/sim_insertion.hpp"

namespace {

using namespace foresight;
using sim_insertion::InsertSpec;
using sim_insertion::Outcome;

/// The world of config/ (robot.urdf, oru.yaml, scene.yaml).
struct InsertionWorld : sim_insertion::World {
  InsertionWorld() : sim_insertion::World(sim_insertion::default_files(FORESIGHT_CONFIG_DIR)) {}
};

/// Random start errors after the issue: lateral up to 3 mm (uniform over the
/// disk), tilt up to 1 deg (uniform magnitude, random axis), `standoff_m` in
/// front of the entrance. Pose of the inserted part's leading frame in the
/// frame of what it enters.
std::vector<Pose> random_starts(int n, double standoff_m, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Pose> out;
  for (int i = 0; i < n; ++i) {
    const double r = 0.003 * std::sqrt(u01(rng));
    const double phi = 2.0 * std::numbers::pi * u01(rng);
    const double tilt = (1.0 * std::numbers::pi / 180.0) * u01(rng);
    const double axis_phi = 2.0 * std::numbers::pi * u01(rng);
    Pose p(Eigen::Translation3d(r * std::cos(phi), r * std::sin(phi), -standoff_m));
    p.linear() =
        Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(axis_phi), std::sin(axis_phi), 0.0)).toRotationMatrix();
    out.push_back(p);
  }
  return out;
}

/// Run the insertion from every start (joints for base_T_tip_starts) and set
/// the counters.
void run_insertions(benchmark::State& state, InsertionWorld& w, const std::vector<Pose>& base_T_tip_starts,
                    const InsertSpec& spec, const char* label) {
  std::vector<Eigen::VectorXd> q_starts;
  for (const Pose& target : base_T_tip_starts) {
    const std::optional<Eigen::VectorXd> q0 = w.start_joints(target);
    if (!q0) {
      state.SkipWithError("IK failed for a start pose");
      return;
    }
    q_starts.push_back(*q0);
  }
  int successes = 0, completed_out = 0, runs = 0, printed = 0, touched = 0, searched = 0;
  double peak = 0.0, peak_sum = 0.0, t_sum = 0.0, align_sum = 0.0, align_max = 0.0;
  double lateral_max = 0.0, axial_sum = 0.0, tilt_max = 0.0;
  double wall_s = 0.0;
  for (auto _ : state) {
    successes = completed_out = runs = touched = searched = 0;
    peak = peak_sum = t_sum = align_sum = align_max = 0.0;
    lateral_max = axial_sum = tilt_max = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    for (const Eigen::VectorXd& q0 : q_starts) {
      const Outcome o = sim_insertion::run_insertion(w, q0, spec);
      ++runs;
      peak = std::max(peak, o.peak_force_n);
      peak_sum += o.peak_force_n;
      touched += o.touched_face ? 1 : 0;
      searched += o.searched ? 1 : 0;
      if (o.success()) {
        ++successes;
        t_sum += o.sim_s;
        const sim::PlantTruth t = w.plant->truth();
        align_sum += t.alignment_error_m;
        align_max = std::max(align_max, t.alignment_error_m);
        const Eigen::Vector3d e = (t.base_T_oru_home.inverse(Eigen::Isometry) * t.base_T_oru).translation();
        lateral_max = std::max(lateral_max, e.head<2>().norm());
        axial_sum += std::abs(e.z());
        tilt_max = std::max(tilt_max, t.alignment_error_rad);
      } else {
        if (o.completed) ++completed_out;
        if (printed++ < 5)
          std::fprintf(stderr, "%s: start %d failed (completed %d, in place %d): %s\n", label, runs, o.completed,
                       o.in_hole, o.text.data());
      }
      benchmark::DoNotOptimize(o);
    }
    wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  state.counters["starts"] = runs;
  state.counters["success_rate"] = runs ? static_cast<double>(successes) / runs : 0.0;
  state.counters["completed_outside_hole"] = completed_out;
  state.counters["face_contact_rate"] = runs ? static_cast<double>(touched) / runs : 0.0;
  state.counters["spiral_search_rate"] = runs ? static_cast<double>(searched) / runs : 0.0;
  state.counters["peak_force_n"] = peak;
  state.counters["peak_force_mean_n"] = runs ? peak_sum / runs : 0.0;
  state.counters["seconds_per_insertion"] = successes ? t_sum / successes : 0.0;
  state.counters["compute_ms_per_insertion"] = runs ? 1e3 * wall_s / runs : 0.0;
  if (spec.carry_oru) {
    state.counters["oru_alignment_mean_mm"] = successes ? 1e3 * align_sum / successes : 0.0;
    state.counters["oru_alignment_max_mm"] = 1e3 * align_max;
    state.counters["oru_lateral_max_mm"] = 1e3 * lateral_max;  // at the ORU's front (hole entrance)
    state.counters["oru_axial_mean_mm"] = successes ? 1e3 * axial_sum / successes : 0.0;
    state.counters["oru_tilt_max_deg"] = tilt_max * 180.0 / std::numbers::pi;
  }
}

/// The tool into the ORU's hole: 1 cm in front of the entrance to the
/// tool_inserted depth (6 cm).
void BM_Insertion(benchmark::State& state) {
  InsertionWorld w;
  std::vector<Pose> starts;
  for (const Pose& oru_T_tip : random_starts(static_cast<int>(state.range(0)), 0.01, 20261201u))
    starts.push_back(w.base_T_oru * oru_T_tip);
  InsertSpec spec;
  spec.params.depth_m = 0.07;
  run_insertions(state, w, starts, spec, "BM_Insertion");
}

/// The carried ORU back into its slot (the bore 1 mm wider than the ORU's
/// back): its back 1 cm in front of the bore with the same random errors, to
/// the bottom (11 cm). The reading is tared with the ORU carried (its weight
/// removed), as the controller would after picking it up. Success: Completed
/// and the plant reports the ORU Seated (back within 2 mm of the bottom);
/// oru_alignment_*_mm: its position error against the slot then (at the
/// ORU frame origin, the front face's hole entrance), split into lateral,
/// axial (short of the bottom) and tilt.
void BM_OruInsertion(benchmark::State& state) {
  InsertionWorld w;
  const sim::Plant& plant = *w.plant;
  const Pose oru_T_grip(Eigen::Translation3d(0.0, 0.0, 0.06));
  const Pose back_T_tip = plant.oru_T_back().inverse(Eigen::Isometry) * oru_T_grip;
  const std::optional<Eigen::VectorXd> q_grip = w.start_joints(w.base_T_oru * oru_T_grip);
  if (!q_grip) {
    state.SkipWithError("IK failed for the grip pose");
    return;
  }
  std::vector<Pose> starts;
  for (const Pose& slot_T_back : random_starts(static_cast<int>(state.range(0)), 0.01, 20261202u))
    starts.push_back(plant.base_T_slot() * slot_T_back * back_T_tip);
  InsertSpec spec;
  spec.params.depth_m = 0.11;
  spec.carry_oru = true;
  spec.q_grip = *q_grip;
  run_insertions(state, w, starts, spec, "BM_OruInsertion");
}

/// One plant step (what the simulated F/T node costs per SYNC): FK,
/// Jacobian, the tool/ORU contact (tool 6 cm in the hole, on the wall), or
/// with arg 1 the carried ORU 5 cm into its slot, 2 mm off axis (1 mm into the wall)
/// (48 x 64 end-face points + 50 slices on the 0.38 m guide).
void BM_PlantStep(benchmark::State& state) {
  InsertionWorld w;
  const bool carried = state.range(0) != 0;
  IkOptions opt;
  const Pose oru_T_grip(Eigen::Translation3d(0.0005, 0.0, 0.06));
  const IkResult grip = inverse_kinematics(w.robot, w.ws, w.base_T_oru * oru_T_grip, w.q_nominal, opt);
  const IkResult out = inverse_kinematics(
      w.robot, w.ws, w.base_T_oru * Pose(Eigen::Translation3d(0.0025, 0.0, 0.01)), w.q_nominal, opt);
  if (!grip.success || !out.success) {
    state.SkipWithError("IK failed");
    return;
  }
  std::vector<double> q(grip.q.data(), grip.q.data() + grip.q.size());
  const std::vector<double> qd(q.size(), 0.01);
  sim::LstToolState tool;
  tool.engaged_turns = 8.0;
  w.plant->step(q, qd, tool);
  if (carried) {
    tool.latched = true;
    w.plant->step(q, qd, tool);
    tool.engaged_turns = 0.0;
    w.plant->step(q, qd, tool);
    q.assign(out.q.data(), out.q.data() + out.q.size());
    w.plant->step(q, qd, tool);
  }
  for (auto _ : state) benchmark::DoNotOptimize(w.plant->step(q, qd, tool));
  state.counters["slot_wall_contacts"] = w.plant->step(q, qd, tool).slot_contact.wall_contacts;
}

}  // namespace

BENCHMARK(BM_Insertion)->Arg(200)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_OruInsertion)->Arg(20)->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_PlantStep)->ArgName("carried")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);
