// BM_Insertion (compiled into bench_control): the insertion success rate of
// the controller's `insert` algorithm (control::Controller, the code that runs
// on the robot) against the simulated plant in-process, over randomized
// starts after the issue: the tool starts 1 cm in front of the hole with a
// lateral error up to 3 mm (uniform over the disk) and a tilt up to 1 deg
// (uniform magnitude, random axis), into the 30 mm hole with the 28 mm socket
// (1 mm radial clearance).
//
// Kinematic plant: the measured joints are the commanded joints of the
// previous cycle; the F/T reading is sim::Plant's (ContactModel of the socket
// against the ORU face, rim, wall and bottom, plus the tool's weight and the
// sensor bias), tared at the start pose like the real decoder. 500 Hz.
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
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/control/controller.hpp"
#include "foresight/sim/plant.hpp"

namespace {

using namespace foresight;

struct InsertionWorld {
  RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  sim::PlantParams params = sim::load_plant_params(FORESIGHT_CONFIG_DIR "/scene.yaml");
  std::unique_ptr<sim::Plant> plant = std::make_unique<sim::Plant>(robot, oru, base_T_oru, params);
  KinematicsWorkspace ws{robot};
  Eigen::VectorXd q_nominal;

  InsertionWorld() {
    IkOptions opt;
    opt.centre_joints = true;
    const IkResult ik = inverse_kinematics(robot, ws, base_T_oru * Pose(Eigen::Translation3d(0.0, 0.0, -0.01)),
                                           robot.mid_configuration(), opt);
    q_nominal = ik.success ? ik.q : robot.mid_configuration();
  }

  control::ControllerConfig controller_config() const {
    control::ControllerConfig c;
    c.cycle_rate_hz = 500.0;
    c.tool.mass_kg = plant->tool_mass_kg();
    const Eigen::Vector3d& com = plant->tool_com_sensor_m();
    c.tool.com_sensor_m = {com.x(), com.y(), com.z()};
    c.tool.sensor_T_tip = plant->sensor_T_tip();
    return c;
  }
};

struct Outcome {
  bool completed = false;
  bool in_hole = false;
  double peak_force_n = 0.0;
  double sim_s = 0.0;
  bool touched_face = false;  ///< the end face landed on the ORU face or rim
  bool searched = false;      ///< the spiral search ran
  control::Reason code = control::Reason::None;
  std::array<char, 96> text{};
};

/// What to insert: the tool into the ORU's hole, or the carried ORU into
/// its slot (the tool latched in the ORU at q_grip, the screw free).
struct InsertSpec {
  double depth_m = 0.07;
  bool carry_oru = false;
  Eigen::VectorXd q_grip;
};

/// One insertion from joints q0. Returns the outcome.
Outcome insert_once(InsertionWorld& w, const Eigen::VectorXd& q0, const InsertSpec& spec) {
  Outcome o;
  sim::Plant& plant = *w.plant;
  plant.reset();
  const auto dof = static_cast<std::size_t>(w.robot.dof());
  control::Controller ctl(w.robot, w.controller_config());
  control::CycleInputs in;
  control::CycleOutputs out;
  in.joints = dof;
  std::vector<double> q(dof), qd(dof, 0.0);
  sim::LstToolState tool;  // latch open: the plant is only contact
  if (spec.carry_oru) {
    // Grip the fastened ORU, loosen the screw: it follows the tool from here.
    for (std::size_t j = 0; j < dof; ++j) q[j] = spec.q_grip[static_cast<Eigen::Index>(j)];
    tool.engaged_turns = 8.0;
    plant.step(q, qd, tool);
    tool.latched = true;
    plant.step(q, qd, tool);
    tool.engaged_turns = 0.0;
    plant.step(q, qd, tool);
  }
  for (std::size_t j = 0; j < dof; ++j) in.q[j] = q0[static_cast<Eigen::Index>(j)];
  const double dt = 1.0 / 500.0;

  // The F/T reading: the plant's, tared at the start pose (no contact there).
  control::Wrench6 tare{};
  auto read = [&](bool first) {
    for (std::size_t j = 0; j < dof; ++j) q[j] = in.q[j];
    const sim::PlantStep r = plant.step(q, qd, tool);
    if (first) tare = r.wrench_ft;
    for (std::size_t i = 0; i < 6; ++i) in.wrench_ft[i] = r.wrench_ft[i] - tare[i];
    in.ft_fresh = true;
    return r;
  };
  read(true);

  std::uint64_t cycle = 0;
  auto step = [&] {
    in.cycle = ++cycle;
    in.stamp_ns = static_cast<std::int64_t>(cycle) * 2'000'000;
    ctl.step(in, out);
    if (out.drive_request == control::DriveRequest::Enable) {
      in.drives_enabled = true;
      ctl.drive_request_done(control::DriveRequest::Enable, true, "", out.q_cmd);
    }
  };

  control::MotionCommand enable;
  enable.command_id = 1;
  enable.kind = control::MotionCommandKind::Enable;
  ctl.command(enable);
  for (int i = 0; i < 50 && ctl.mode() != control::ControllerMode::Idle; ++i) {
    read(false);
    step();
  }

  control::MotionCommand ins;
  ins.command_id = 2;
  ins.kind = control::MotionCommandKind::RunAlgorithm;
  ins.algorithm.kind = control::AlgorithmKind::Insert;
  ins.algorithm.insert.depth_m = spec.depth_m;
  ctl.command(ins);
  const int max_cycles = static_cast<int>((ins.algorithm.insert.timeout_s + 5.0) * 500.0);
  const std::uint64_t start_cycle = cycle;
  bool done = false;
  sim::PlantStep last;
  for (int k = 0; k < max_cycles && !done; ++k) {
    for (std::size_t j = 0; j < dof; ++j) {
      const double qn = out.q_cmd[j];
      qd[j] = k == 0 ? 0.0 : (qn - in.q[j]) / dt;
      in.q[j] = qn;  // kinematic plant: measured = commanded
    }
    last = read(false);
    const sim::ContactResult& c = spec.carry_oru ? last.slot_contact : last.tool_contact;
    o.peak_force_n = std::max(o.peak_force_n, c.sensor.force_n.norm());
    o.touched_face = o.touched_face || c.face_contacts > 0;
    step();
    o.searched = o.searched || ctl.algorithm().phase() == 1;
    for (std::size_t e = 0; e < out.event_count; ++e) {
      const control::MotionEvent& ev = out.events[e];
      if (ev.command_id != ins.command_id || !control::is_final(ev.kind)) continue;
      done = true;
      o.completed = ev.kind == control::MotionEventKind::Completed;
      o.code = ev.code;
      o.text = ev.text;
    }
    if (out.stop != nullptr && !done) {
      done = true;
      o.code = control::Reason::Faulted;
      control::set_text(o.text, out.stop->text.data());
    }
  }
  o.sim_s = static_cast<double>(cycle - start_cycle) * dt;
  if (spec.carry_oru) {
    o.in_hole = last.state == sim::OruState::Seated;
    o.peak_force_n = std::max(o.peak_force_n, 0.0);
  } else {
    o.in_hole = last.tool_contact.tip_in_hole() && last.tool_contact.insertion_depth_m >= w.params.grasp_depth_m;
  }
  return o;
}

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
  IkOptions opt;
  opt.position_tolerance_m = 1e-6;
  opt.rotation_tolerance_rad = 1e-6;
  for (const Pose& target : base_T_tip_starts) {
    const IkResult ik = inverse_kinematics(w.robot, w.ws, target, w.q_nominal, opt);
    if (!ik.success) {
      state.SkipWithError("IK failed for a start pose");
      return;
    }
    q_starts.push_back(ik.q);
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
      const Outcome o = insert_once(w, q0, spec);
      ++runs;
      peak = std::max(peak, o.peak_force_n);
      peak_sum += o.peak_force_n;
      touched += o.touched_face ? 1 : 0;
      searched += o.searched ? 1 : 0;
      if (o.completed && o.in_hole) {
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
  spec.depth_m = 0.07;
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
  IkOptions opt;
  opt.position_tolerance_m = 1e-6;
  opt.rotation_tolerance_rad = 1e-6;
  const IkResult grip = inverse_kinematics(w.robot, w.ws, w.base_T_oru * oru_T_grip, w.q_nominal, opt);
  if (!grip.success) {
    state.SkipWithError("IK failed for the grip pose");
    return;
  }
  std::vector<Pose> starts;
  for (const Pose& slot_T_back : random_starts(static_cast<int>(state.range(0)), 0.01, 20261202u))
    starts.push_back(plant.base_T_slot() * slot_T_back * back_T_tip);
  InsertSpec spec;
  spec.depth_m = 0.11;
  spec.carry_oru = true;
  spec.q_grip = grip.q;
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
