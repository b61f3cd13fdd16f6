#pragma once
// One insertion on the simulated plant, in-process and faster than real time:
// the controller's `insert` algorithm (control::Controller, the code that runs
// on the robot) against sim::Plant at 500 Hz, from the arm at rest at given
// joints to the algorithm's end (Completed, or its failure reason).
// bench_control's BM_Insertion / BM_OruInsertion and `foresight-remote
// simulate-insertions` (daemon/simulate_insertions.hpp) all run this one.
//
// Kinematic plant: the measured joints are the commanded joints of the
// previous cycle; the F/T reading is sim::Plant's (the contact model of the
// socket against the ORU face, rim, wall and bottom, or of the carried ORU in
// its slot, plus the tool's weight and the sensor bias), tared at the start
// pose like the real decoder. The drives are enabled, then the insert runs.
//
// Success: the algorithm reports Completed AND the true tip is in the hole at
// least PlantParams::grasp_depth_m (5 cm) deep (the carried ORU: the plant
// reports it Seated).
//
// Set-up code, not real-time: allocates; the files throw InputError.

#include <Eigen/Core>
#include <array>
#include <memory>
#include <optional>
#include <string>

#include "foresight/common/insert_capture.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/control/controller.hpp"
#include "foresight/control/rt_types.hpp"
#include "foresight/sim/plant.hpp"

namespace foresight::sim_insertion {

/// The models the world is made of.
struct WorldFiles {
  std::string robot_urdf;   ///< robot.urdf
  std::string object_yaml;  ///< oru.yaml: the ORU model (hole, tags)
  std::string scene_yaml;   ///< scene.yaml: the ORU's true pose (object_pose) and the plant's sections
};

/// robot.urdf, oru.yaml and scene.yaml in `config_dir`.
WorldFiles default_files(const std::string& config_dir);

/// The robot, the ORU at its true pose and the plant, with the nominal start
/// joints: IK with centred joints for the tip 1 cm in front of the hole
/// entrance (the mid configuration when that fails). Holds references into
/// itself: neither copied nor moved.
struct World {
  explicit World(const WorldFiles& files);
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  RobotModel robot;
  ObjectModel oru;
  Pose base_T_oru;  ///< the ORU's true pose in the robot base (scene.yaml object_pose)
  sim::PlantParams params;
  std::unique_ptr<sim::Plant> plant;
  KinematicsWorkspace ws;
  Eigen::VectorXd q_nominal;

  /// The controller's configuration: 500 Hz, the plant tool's mass
  /// properties and sensor_T_tip.
  control::ControllerConfig controller_config() const;

  /// The joints at which the tool tip is at base_T_tip: IK seeded at
  /// q_nominal to 1e-6 m / 1e-6 rad; nullopt when IK finds none (the start
  /// is out of the arm's reach).
  std::optional<Eigen::VectorXd> start_joints(const Pose& base_T_tip);
};

/// What to insert: the tool into the ORU's hole, or the carried ORU into its
/// slot (the tool latched in the ORU at q_grip, the screw free).
struct InsertSpec {
  InsertParams params{};           ///< the insert's parameters (common/insert_capture.hpp)
  bool carry_oru = false;
  Eigen::VectorXd q_grip;          ///< carry_oru: the joints with the tool in the fastened ORU
};

struct Outcome {
  bool completed = false;     ///< the algorithm reported Completed
  bool in_hole = false;       ///< the tip at least grasp_depth_m deep in the hole (carried: the ORU Seated)
  double peak_force_n = 0.0;  ///< largest true contact force (N)
  double sim_s = 0.0;         ///< simulated time from the command to the algorithm's end (s)
  bool touched_face = false;  ///< the end face landed on the ORU face or rim
  bool searched = false;      ///< the spiral search ran
  control::Reason code = control::Reason::None;  ///< the final event's code (Faulted on a safety stop)
  std::array<char, 96> text{};                   ///< the final event's text

  bool success() const noexcept { return completed && in_hole; }
};

/// One insertion from joints q0 (the arm at rest there): resets the plant,
/// enables the drives, runs the insert to its final event (or timeout_s +
/// 5 s of simulated time). world.plant holds the end state for its truth().
Outcome run_insertion(World& world, const Eigen::VectorXd& q0, const InsertSpec& spec);

}  // namespace foresight::sim_insertion
