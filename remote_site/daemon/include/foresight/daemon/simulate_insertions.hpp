#pragma once
// `foresight-remote simulate-insertions --batch FILE [--json]`: a batch of
// insertions, each the controller's `insert` (control::Controller, the code
// that runs on the robot) on the simulated plant in-process, faster than real
// time (sim_insertion::run_insertion, ~10-80 ms of compute each). The ground
// (`foresight eval insertion`) runs it as a child process: it links no remote
// library. docs/control.md "Simulated insertions" holds the contract:
//
//   batch file (JSON):
//     {"object": "config/oru.yaml",          optional; default the config's oru.yaml
//      "tag": "hole_entrance",               optional; a tag of the object model
//      "params": {"depth_m": 0.06, "timeout_s": 30},   optional; INVOKE_ALGORITHM's
//                                            insert parameters, checked by parse_algorithm
//      "trials": [{"id": 7, "tag_T_tip": [[4 numbers] x 4 rows]}, ...]}   1..10000
//   tag_T_tip: the true tool tip at the insert's start, in the TRUE tag frame
//   (lateral x, y; axial z along the hole axis; tilt). The arm starts at rest
//   at the joints (IK, World::start_joints) where the tip is at
//   base_T_oru * oru_T_tag * tag_T_tip; the insert runs to its end.
//
//   output (--json, stdout, one line):
//     {"trials": N, "results": [{"id", "success", "completed", "in_hole",
//      "reason", "peak_force_n", "sim_s", "searched", "face_contact"}, ...],
//      "success_rate": s, "compute_s": t}
//   success = completed AND in_hole; reason = the final event's code
//   (protocol::to_string: none, unreachable, force_limit, timeout, faulted) or
//   "unreachable_start" when IK finds no joints for the start.
//
// Bad input: InputError "<FILE>: <key or trials[i].key>: <what>" (exit 2).
// Set-up code, not real-time.

#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "foresight/common/insert_capture.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/control/rt_types.hpp"
#include "foresight/sim_insertion/sim_insertion.hpp"

namespace foresight::daemon {

/// The most trials one batch may hold.
inline constexpr std::size_t kMaxInsertionTrials = 10000;
/// tag_T_tip's rotation: |R^T R - I| (largest entry) at most this, det R > 0.
inline constexpr double kRigidTolerance = 1e-6;

struct InsertionTrial {
  std::int64_t id = 0;
  Pose tag_T_tip = Pose::Identity();  ///< re-orthonormalized
};

struct InsertionBatch {
  sim_insertion::WorldFiles files;      ///< object_yaml from the file, the rest the config's
  std::string tag = "hole_entrance";
  Pose oru_T_tag = Pose::Identity();    ///< the tag's pose in the object model
  InsertParams params{};                ///< the insert's, parse_algorithm's defaults and ranges
  std::vector<InsertionTrial> trials;
};

/// Reads and checks the batch file `path`; `defaults` are the config's
/// robot.urdf, oru.yaml and scene.yaml. InputError naming the file and the
/// key or trial (exit 2): malformed JSON, an unknown key, a tag not in the
/// object model, an unknown or out-of-range insert parameter, a trial list
/// empty or longer than kMaxInsertionTrials, a trial without an integer id, a
/// tag_T_tip that is not 4 x 4 numbers or not rigid.
InsertionBatch read_insertion_batch(const std::string& path, const sim_insertion::WorldFiles& defaults);

struct InsertionResult {
  std::int64_t id = 0;
  bool success = false;        ///< completed && in_hole
  bool completed = false;
  bool in_hole = false;
  std::string reason = "none";  ///< protocol::to_string(code), or "unreachable_start"
  std::string text;            ///< the controller's final text (the text table shows it)
  double peak_force_n = 0.0;
  double sim_s = 0.0;
  bool searched = false;
  bool face_contact = false;
};

struct InsertionReport {
  std::vector<InsertionResult> results;
  double success_rate = 0.0;
  double compute_s = 0.0;  ///< wall clock for the whole batch (models, IK, insertions)
};

/// Runs every trial of the batch, one after another, on one world.
InsertionReport simulate_insertions(const InsertionBatch& batch);

/// The --json output (one line) and the text table.
std::string insertion_report_json(const InsertionReport& report);
std::string insertion_report_text(const InsertionReport& report);

/// The subcommand: read, run, print. 0; 2 with "foresight-remote: error:
/// <message>" on `err` for bad input; 1 when the simulation fails.
int run_simulate_insertions_command(const std::string& batch_path, const std::string& config_dir, bool json,
                                    std::ostream& out, std::ostream& err);

}  // namespace foresight::daemon
