#pragma once
// The simulated physical plant of the remote site: what makes the simulated
// drives, F/T sensor and LST one physical arm touching one ORU.
//
// At every SYNC (on the simulator thread, through SimFtSensor's wrench
// source) the plant takes the simulated joint angles and rates, computes the
// tool tip pose and twist (FK and Jacobian on the common kinematics, its own
// workspace), the contact of the LST with the ORU (ContactModel), and returns
// the wrench the F/T sensor measures, in the sensor frame `ft_sensor` about
// its origin:
//
//   wrench = contact(tool, ORU)            (not while the ORU is carried: then
//                                            tool and ORU are one rigid body)
//          + latch hold                     (the closed latch holds the tool at
//                                            its grasp depth in a fastened ORU)
//          + tool weight                    (mass and centre of mass below the
//                                            sensor: the URDF links after
//                                            `ft_sensor`, else plant.tool_*)
//          + ORU weight + contact(ORU, slot)  (while the ORU follows the tool)
//          + sensor bias                    (constant, plant.sensor_bias)
//
// The ORU is a carried object. Its states (OruState):
//
//   Fastened --(gripped AND screw free)--> Seated (loose in its slot, held
//   by the tool) --(pulled out > 5 mm, screw still free)--> Carried --(back
//   in the slot to depth)--> Seated --(screw tightened to seating)--> Fastened
//   Carried --(latch opened)--> Dropped (the ORU falls: terminal until reset)
//
// (A loosened ORU still in its slot is Seated, so re-tightening it in place
// without pulling it out fastens it again.)
// "Gripped": the LST latch closed while the tool tip was in the hole to at
// least grasp_depth_m (a latch closed outside the hole grips nothing; opening
// the latch releases). "Screw free": the screw model's engaged turns are 0
// (LstToolState::screw_free). While Carried, and while Seated with the screw
// still free, the ORU follows the tool with tip_T_oru frozen at the moment it
// came free; once the screw starts to engage in the slot the ORU stays where
// it is (the slot and the screw hold it). The LST socket is on the bolt
// (LstServer::set_socket_engaged) when the tip is in the hole to grasp depth
// and the ORU is not Carried (a carried ORU's loose screw spins with the
// socket).
//
// Re-insertion is a contact task like the tool's: the ORU's back is a
// cylinder of slot.guide_diameter_m entering a bore of that diameter plus
// 2 x slot.radial_clearance_m and slot.depth_m deep (a ContactModel with the
// slot's geometry). The slot frame is fixed by the ORU's home pose
// (config/scene.yaml object_pose): the seated ORU's back face lies on the
// bore bottom.
//
// Threading: step() and the SYNC callback run on the simulator thread (one
// thread at a time; the plant has its own kinematics workspace). truth() and
// the other queries are thread-safe (a mutex guards the ground-truth
// snapshot; this is a simulator, not real-time code, though step() does not
// allocate). Set-up (constructor, loaders, attach) may throw.

#include <Eigen/Core>
#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/sim/contact_model.hpp"
#include "foresight/sim/screw_model.hpp"

namespace foresight::sim {

class CanSimulator;
class LstServer;

enum class OruState { Fastened, Carried, Seated, Dropped };
const char* to_string(OruState s) noexcept;

/// The `slot:` section of config/scene.yaml: the bore the ORU's back enters.
struct SlotParams {
  double guide_diameter_m = 0.38;      ///< the ORU's back, a cylinder about the hole axis
  double radial_clearance_m = 0.001;   ///< bore radius - guide radius
  double depth_m = 0.10;               ///< bore depth = how deep the seated ORU sits
  double seat_tolerance_m = 0.002;     ///< Seated when the back is this close to the bottom
  double face_stiffness_n_per_m = 2.0e5;
  double bottom_stiffness_n_per_m = 2.0e5;
  double wall_stiffness_n_per_m2 = 5.0e6;
  double friction_coefficient = 0.3;
};

/// The `plant:` section of config/scene.yaml.
struct PlantParams {
  ContactParams contact;  ///< tool/ORU contact (the `contact:` section)
  SlotParams slot;
  /// Tool below the sensor: used when the URDF has no mass after `ft_sensor`.
  double tool_mass_kg = 2.6;
  Eigen::Vector3d tool_com_sensor_m{0.015, 0.0, 0.125};  ///< centre of mass in the sensor frame
  bool tool_from_urdf = true;  ///< take mass and centre of mass from the URDF when it has them
  std::array<double, 6> sensor_bias{};  ///< N, N*m, added to every reading
  double oru_mass_kg = 5.0;
  Eigen::Vector3d oru_com_m{0.0, 0.05, 0.175};  ///< in the `oru` frame (default: the box centre)
  double grasp_depth_m = 0.05;   ///< tip depth in the hole at which the latch grips
  double latch_stiffness_n_per_m = 1.0e5;  ///< the latch holding the tool in a fastened ORU
  double screw_engaged_turns = 8.0;  ///< turns that seat the screw (lst_sim.screw.engaged_turns)
};

/// Read `contact:`, `slot:`, `plant:` and `lst_sim.screw.engaged_turns` of a
/// scene file (slot and plant are optional, defaults as above). Throws
/// InputError naming file, line and key.
PlantParams load_plant_params(const std::string& scene_yaml_path);

/// Check the parameters; throws std::invalid_argument naming the field.
void validate(const PlantParams& params);

/// Ground truth (any thread).
struct PlantTruth {
  OruState state = OruState::Fastened;
  bool gripped = false;          ///< latch closed on the ORU
  bool socket_engaged = false;   ///< socket on the bolt (screw turns with it)
  Pose base_T_tip = Pose::Identity();
  Pose base_T_oru = Pose::Identity();       ///< where the ORU is now
  Pose base_T_oru_home = Pose::Identity();  ///< its pose fastened in the slot
  double tip_depth_m = 0.0;      ///< tool tip depth along the hole axis (oru frame z)
  double oru_slot_depth_m = 0.0; ///< the ORU's back depth in its bore (depth_m = fully in)
  /// Alignment of the ORU against its slot (home pose): position error (m)
  /// and rotation angle (rad) of home^-1 * now.
  double alignment_error_m = 0.0;
  double alignment_error_rad = 0.0;
  std::array<double, 6> wrench_ft{};  ///< the last reading handed to the sensor (before quantization)
  std::uint64_t steps = 0;
};

/// One step's result (the wrench and what it was made of).
struct PlantStep {
  std::array<double, 6> wrench_ft{};  ///< total, sensor frame
  Wrench contact_ft;                  ///< tool/ORU contact + latch hold
  Wrench slot_ft;                     ///< ORU/slot contact (carried or seated)
  Wrench weight_ft;                   ///< tool (+ carried ORU) weight
  ContactResult tool_contact;
  ContactResult slot_contact;
  OruState state = OruState::Fastened;
  bool socket_engaged = false;
};

class Plant {
 public:
  /// Validates (throws std::invalid_argument), lays out the contact models
  /// and the tool's mass properties from the URDF (links after `ft_sensor`).
  /// base_T_oru_home: the ORU fastened in its slot (scene object_pose).
  Plant(const RobotModel& robot, const ObjectModel& oru, const Pose& base_T_oru_home, const PlantParams& params);
  ~Plant();
  Plant(const Plant&) = delete;
  Plant& operator=(const Plant&) = delete;

  /// robot.urdf, oru.yaml and scene.yaml (object_pose and the sections of
  /// load_plant_params). Throws InputError.
  static std::unique_ptr<Plant> from_files(const std::string& urdf_path, const std::string& oru_yaml_path,
                                           const std::string& scene_yaml_path);

  /// Make the simulator physical: the F/T sensor's wrench source becomes
  /// this plant (joint angles and rates from `sim`, the latch and screw from
  /// `tool` when given; the socket engagement is written back to it). Both
  /// must outlive the plant or detach(). Set-up; throws std::logic_error when
  /// `sim` has no F/T sensor or its drive count is not the robot's dof.
  void attach(CanSimulator& sim, LstServer* tool = nullptr);
  /// Clear the wrench source. Idempotent; also done by the destructor.
  void detach();

  /// One step of the physics for joints q (rad) moving at qd (rad/s) and the
  /// tool's state; updates the ORU state and the ground truth. Simulator
  /// thread (or a benchmark's); no allocation. q, qd sized dof.
  PlantStep step(std::span<const double> q, std::span<const double> qd, const LstToolState& tool) noexcept;

  /// Ground truth snapshot. Any thread.
  PlantTruth truth() const;
  OruState oru_state() const;

  /// Mass properties of the tool below the sensor actually used.
  double tool_mass_kg() const { return tool_mass_kg_; }
  const Eigen::Vector3d& tool_com_sensor_m() const { return tool_com_sensor_m_; }
  /// sensor_T_tip from the URDF (FK of `ft_sensor` and of the tip).
  const Pose& sensor_T_tip() const { return sensor_T_tip_; }
  const PlantParams& params() const { return params_; }
  const ContactModel& tool_contact_model() const { return tool_contact_; }
  const ContactModel& slot_contact_model() const { return slot_contact_; }
  /// base_T_slot: the bore's entrance frame (z into the panel).
  const Pose& base_T_slot() const { return base_T_slot_; }
  /// oru_T_back: the ORU's back face centre (the "tip" of the slot contact).
  const Pose& oru_T_back() const { return oru_T_back_; }
  const RobotModel& robot() const { return robot_; }

  /// Test/demo control: put the ORU back in its slot, fastened, released.
  void reset();
  /// Fault injection: the ORU is stuck in its slot (corroded guides): it
  /// does not come free even gripped with the screw loose, so pulling meets
  /// the latch hold. Any thread.
  void set_oru_stuck(bool stuck) { oru_stuck_ = stuck; }

 private:
  void add_wrench_at(const Eigen::Vector3d& force_base, const Eigen::Vector3d& point_base, const Pose& base_T_sensor,
                     Wrench& out) const noexcept;

  RobotModel robot_;
  PlantParams params_;
  ContactModel tool_contact_;
  ContactModel slot_contact_;
  Pose base_T_oru_home_;
  Pose base_T_slot_;
  Pose oru_T_back_;
  Pose sensor_T_tip_;
  int sensor_link_ = -1;
  double tool_mass_kg_ = 0.0;
  Eigen::Vector3d tool_com_sensor_m_ = Eigen::Vector3d::Zero();

  // Simulator-thread state.
  KinematicsWorkspace ws_;
  Eigen::VectorXd q_, qd_;
  Eigen::Matrix<double, 6, Eigen::Dynamic> J_;
  std::vector<double> q_buf_, qd_buf_;
  OruState state_ = OruState::Fastened;
  Pose base_T_oru_;
  Pose tip_T_oru_ = Pose::Identity();  ///< frozen while the ORU follows the tool
  bool follows_tool_ = false;
  bool gripped_ = false;
  bool prev_latched_ = false;
  double grip_depth_m_ = 0.0;          ///< tip depth when the latch closed
  bool socket_engaged_ = false;
  std::atomic<bool> reset_requested_{false};
  std::atomic<bool> oru_stuck_{false};

  // Ground truth for other threads.
  mutable std::mutex truth_mu_;
  PlantTruth truth_;

  CanSimulator* sim_ = nullptr;
  LstServer* tool_ = nullptr;
};

}  // namespace foresight::sim
