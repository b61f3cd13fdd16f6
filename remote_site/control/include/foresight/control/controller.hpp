#pragma once
// The per-cycle control logic, without threads and without CAN: the loop
// (control_loop.hpp) reads the drives, calls Controller::step(), writes the
// drives. Tests drive step() directly with synthetic inputs.
//
//   modes (command.hpp ControllerMode):
//     Disabled  drives not enabled; q_cmd follows q (nothing jumps at enable)
//     Idle      holding the last commanded pose (stiff, or compliant on Hold{compliant})
//     Trajectory  running a PreparedTrajectory (optionally compliant; the
//               daemon's GOTO moves are trajectories too: Goto is not used here)
//     Algorithm   running guarded_move / insert / pull_out (algorithms.hpp)
//     Stopping  controlled stop. During a trajectory (unless the trajectory's
//               own command broke a joint limit) the stop stays on the path:
//               the trajectory's time scaling ramps to zero, as fast as the
//               joint closest to its acceleration limit allows, so the joints
//               decelerate together along the planned path and the motion's
//               Canceled event comes at rest. During an algorithm its
//               Cartesian reference decelerates along the twist it had
//               (stop_cart_decel_*, the joints' limits; compliance on top),
//               Canceled at rest. Otherwise every joint decelerates at
//               stop_decel_fraction of its URDF acceleration limit to rest
//     Stopped   after a Cat2 stop: holding, powered; leaves only on Recover
//     Fault     after a Cat0/Cat1 stop: drives disabled; leaves only on Recover
//
//   stops (IEC 60204-1), every one with a StopEvent (cause, cycle, evidence):
//     Cat0 (quick stop now, then drives off): E-stop (configurable), drive
//          faults (CycleStatus.stop_required with a drive/bus event), Stop{Cat0}
//     Cat1 (controlled stop, then drives off): following error, F/T sensor
//          faults/saturation/missing, Stop{Cat1}
//     Cat2 (controlled stop, hold powered): joint position/velocity limit of
//          the command (the offending command is dropped; position limits by
//          braking distance), force/torque safety limits of a stiff motion,
//          link loss with policy Stop, Stop{Cat2}
//     Not a stop: a force/torque limit in a compliant mode (an algorithm, a
//          compliant trajectory or hold) backs off: the motion FAILS with
//          ForceLimit and the arm holds compliantly at the measured pose; a
//          contact still over the limit 200 ms later is Cat1
//   Link loss with policy FinishThenHold: what runs runs to its end, then the
//   arm holds; new motions are rejected (NotInControl) while the link is lost.
//
// Drive power: the controller never calls the drives. It asks through
// CycleOutputs::drive_request (Enable / Disable); whoever runs the drives
// (ControlLoop, or a test) performs it and reports back with
// drive_request_done(). Cat0, and Cat1 once the arm is at rest, additionally
// set CycleOutputs::power_off for the drive system's request_power_off():
// Disable Voltage goes to every drive in the same cycle, before the stepped
// disable confirms it. The loop steps an Enable in its own cycles, so step()
// runs during it: the E-stop or the drives' safe torque off abort it into
// category 0, a lost link with policy Stop leaves the drives off; its
// command then fails with why (watch_power_change).
//
// Set-up (allocates, throws std::invalid_argument naming the field): the
// constructor. Real-time (noexcept, no allocation, no locks, no logging):
// command(), step(), drive_request_done(), and every accessor.

#include <array>
#include <cstdint>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/control/algorithms.hpp"
#include "foresight/control/compliance.hpp"
#include "foresight/control/payload.hpp"
#include "foresight/control/rate_limiter.hpp"
#include "foresight/control/rt_types.hpp"
#include "foresight/control/trajectory_executor.hpp"

namespace foresight::control {

enum class LinkLossPolicy : std::uint8_t { FinishThenHold = 0, Stop };

struct ControllerConfig {
  double cycle_rate_hz = 500.0;
  ToolParams tool{};                       ///< the tool's mass and centre of mass: what hangs on the sensor alone
  /// The carried ORU (its mass, its centre of mass in the sensor frame as the
  /// tool holds it): added to the tool's while SetPayload says it is latched.
  PayloadMass oru{};
  /// Tare only out of contact: refused while the compensated force is above
  /// this (after the first tare or identification: before, the reading has
  /// no zero to judge contact by).
  double tare_max_force_n = 10.0;
  WrenchFilterParams filter{};
  AdmittanceParams admittance{};           ///< default compliance (Hold{compliant}, compliant trajectories)
  double start_tolerance_rad = 0.01;       ///< a trajectory must start this close to the commanded joints
  // Safety limits, checked every cycle.
  double position_margin_rad = 0.0;        ///< q_cmd must stay inside [lower + m, upper - m]
  double velocity_limit_fraction = 1.0;    ///< of the URDF joint velocity limit
  /// Following error: |q_cmd(k - following_error_delay_cycles) - q(k)| per
  /// joint, the command compared with what the measurement can show of it
  /// (the loop's latency: 1 when the next cycle's reading sees the command,
  /// 3 on the bus, docs/hardware.md "Frame order and loop delay"), Cat1 over
  /// the limit: following_error_joint_rad[j] where set (> 0; the daemon: 0.8 x
  /// the drive's own window 0x6065, so the master stops the arm before the
  /// drive faults), else following_error_rad.
  double following_error_rad = 0.05;
  JointArray following_error_joint_rad{};
  int following_error_delay_cycles = 1;   ///< 1..kFollowingErrorHistory
  double force_limit_n = 150.0;            ///< |F| of the compensated contact force
  double torque_limit_nm = 15.0;           ///< |T| about the tip
  double stop_decel_fraction = 1.0;        ///< controlled stops: of the URDF acceleration limits
  /// A controlled stop of an algorithm decelerates its Cartesian reference
  /// along the direction it was moving, at most this fast (and no joint faster
  /// than its stop_decel_fraction of the URDF limit).
  double stop_cart_decel_m_s2 = 1.0;
  double stop_cart_decel_rad_s2 = 2.0;
  /// The rate limiter (rate_limiter.hpp) on every command of a stiff motion
  /// or hold (trajectories, GOTOs, the stiff hold; compliant modes below):
  /// acceleration at most this multiple of the URDF (planning) limit
  /// (validate() bounds a trajectory's executed acceleration at 1x: a
  /// validated one passes untouched), jerk at most
  /// rate_limit_jerk_per_s x the URDF acceleration limit (1000/s: the
  /// acceleration may change by 2x its planning limit in a 2 ms cycle),
  /// velocity at most the velocity limit.
  double rate_limit_acceleration_fraction = 1.5;
  double rate_limit_jerk_per_s = 1000.0;
  /// The same limiter inside the force loop of compliant modes (algorithms,
  /// compliant trajectories and holds), at this multiple of the URDF
  /// acceleration limit (jerk scaled alike; at least the stiff fraction), with
  /// anti-windup: what the limited command achieves becomes the admittance's
  /// state (Admittance::take_back).
  double rate_limit_compliant_acceleration_fraction = 10.0;
  StopCategory estop_category = StopCategory::Cat0;
  LinkLossPolicy link_loss = LinkLossPolicy::FinishThenHold;
  int sensor_fault_cycles = 5;             ///< F/T saturated or faulty this many cycles in a row: Cat1
  double velocity_filter_hz = 50.0;        ///< dq telemetry low-pass (joints without a fresh drive velocity)
  /// Telemetry dq of a joint is the drive's own velocity actual (0x606C,
  /// CycleInputs::dq_drive) while that value answered a SYNC at most this many
  /// cycles ago; otherwise (never mapped, TPDO2 lost) the differentiated,
  /// low-passed measured position. 0 = never the drive's. The daemon sets
  /// 2 x velocity_tpdo_every (one lost TPDO2 tolerated).
  int drive_velocity_max_age_cycles = 10;
};

/// What the loop read this cycle.
struct CycleInputs {
  std::uint64_t cycle = 0;
  std::int64_t stamp_ns = 0;
  std::size_t joints = 0;              ///< must equal the model's dof (else: Cat0, DriveFault)
  JointArray q{};                      ///< measured joint positions
  JointArray torque{};
  JointArray dq_drive{};               ///< drives' velocity actual 0x606C, joint side (hw JointState::velocity_rad_s)
  /// The cycle whose read delivered dq_drive[j] (hw JointState::velocity_cycle); 0 = none (TPDO2 not mapped).
  std::array<std::uint64_t, kMaxJoints> dq_drive_cycle{};
  bool drives_enabled = false;         ///< every drive in Operation enabled
  /// Per joint, the drive's reported power state (hw::canopen::PowerState value,
  /// kDriveStateUnknown when silent): passed through to telemetry.
  std::array<std::uint8_t, kMaxJoints> drive_state{};
  Wrench6 wrench_ft{};                 ///< hw::FtReading::wrench_ft (sensor frame, bias removed)
  bool ft_fresh = false;
  std::uint8_t ft_saturated_mask = 0;
  bool ft_fault = false;
  bool ft_tare_in_progress = false;
  bool hw_stop_required = false;       ///< hw::CycleStatus::stop_required
  bool hw_drive_fault = false;         ///< a stop-requiring event came from a drive or bus (else F/T)
  std::uint8_t hw_fault = 0;           ///< hw::HwFault of the first stop-requiring event
  std::uint8_t hw_node = 0;
  std::int8_t hw_joint = -1;
  std::uint32_t hw_code = 0;
  bool estop = false;                  ///< E-stop input (true = pressed)
  /// The E-stop as the drives report it: safe torque off active
  /// (hw::CycleStatus::safe_torque_off), on the drive of `sto_joint`.
  bool safe_torque_off = false;
  std::int8_t sto_joint = -1;
  bool link_lost = false;              ///< link-loss input
  /// Control periods missed in a row before this cycle (ControlLoop) and the
  /// count that is a category 1 stop (0: never).
  std::uint32_t missed_cycles = 0;
  std::uint32_t missed_cycles_limit = 0;
};

enum class DriveRequest : std::uint8_t { None = 0, Enable, Disable };

/// What the loop must do this cycle.
struct CycleOutputs {
  static constexpr std::size_t kMaxEvents = 8;
  JointArray q_cmd{};                  ///< targets for cycle_write
  bool power_off = false;              ///< call DriveSystem::request_power_off() (Cat0; Cat1 at rest)
  int tare_samples = 0;                ///< > 0: call DriveSystem::request_tare(tare_samples)
  DriveRequest drive_request = DriveRequest::None;  ///< perform, then drive_request_done()
  std::size_t event_count = 0;
  std::array<MotionEvent, kMaxEvents> events{};
  const StopEvent* stop = nullptr;     ///< a new stop this cycle (valid until the next step)
  TelemetrySample telemetry{};
};

class Controller {
 public:
  /// Set-up. Throws std::invalid_argument: dof > kMaxJoints, a bad config
  /// field (named), the model without an "ft_sensor" link.
  Controller(const RobotModel& model, const ControllerConfig& config);

  /// Hand over a command (the loop pops them from its ring before step()).
  /// Its events come out of the next step(). RT-safe.
  void command(const MotionCommand& cmd) noexcept;

  /// One control cycle. RT-safe.
  void step(const CycleInputs& in, CycleOutputs& out) noexcept;

  /// The drive request of a previous step was performed: ok, or failed with
  /// `text` (the HwError's message, truncated). `held` = the targets the
  /// drives hold now (hw::DriveSystem::held_targets). RT-safe.
  void drive_request_done(DriveRequest request, bool ok, const char* text, const JointArray& held) noexcept;

  ControllerMode mode() const noexcept { return mode_; }
  const StopEvent& last_stop() const noexcept { return stop_; }
  const ControllerConfig& config() const noexcept { return config_; }
  const RobotModel& model() const noexcept { return model_; }
  std::size_t joints() const noexcept { return dof_; }
  /// Commanded tip pose (base frame): FK of the last command, computed on demand. RT-safe.
  const Pose& commanded_tip_now() noexcept;
  /// Measured tip pose of the last cycle (base frame).
  const Pose& measured_tip() const noexcept { return base_T_tip_; }
  const AlgorithmRunner& algorithm() const noexcept { return algo_; }
  const WrenchCompensator& compensator() const noexcept { return comp_; }
  /// The payload parts: the tool's, the ORU's (identify_payload updates the
  /// one it identified), and whether the ORU is latched.
  const PayloadMass& tool_payload() const noexcept { return tool_payload_; }
  const PayloadMass& oru_payload() const noexcept { return oru_payload_; }
  bool oru_latched() const noexcept { return oru_latched_; }
  const Admittance& admittance() const noexcept { return adm_; }
  const JointRateLimiter& rate_limiter() const noexcept { return limiter_; }

 private:
  enum class Active : std::uint8_t { None, Hold, Trajectory, Algorithm, Enable, Disable, Recover, Tare };
  void emit(std::uint64_t id, MotionCommandKind cmd, MotionEventKind kind, Reason code, const char* text) noexcept;
  void finish_active(MotionEventKind kind, Reason code, const char* text) noexcept;
  void begin_stop(StopCause cause, StopCategory cat, int joint, double value, double limit,
                  const char* text) noexcept;
  void hold_here() noexcept;
  bool check_safety(const CycleInputs& in) noexcept;
  void controlled_stop_step() noexcept;
  /// A stop on the trajectory's path: the time scaling ramps to zero.
  void path_stop_step() noexcept;
  /// A stop of an algorithm: its Cartesian reference decelerates along its
  /// own twist (the same scaling ramp), compliance on top.
  void cartesian_stop_step() noexcept;
  /// The running motion's CANCELED, deferred to rest by a stop on the path.
  void cancel_at_rest() noexcept;
  /// A force or torque limit in a compliant mode: the running motion FAILS
  /// (ForceLimit) and the arm holds compliantly at the measured tip pose; if the
  /// contact is still over the limit kBackoffTimeS later, Cat1.
  void back_off(const char* text) noexcept;
  static constexpr double kBackoffTimeS = 0.2;
  /// Cat0, and Cat1 at rest: power_off this cycle, mode Fault, then disable().
  void power_off() noexcept;
  /// Rest reached by a controlled stop: Cat1 powers off, Cat2 holds.
  void stop_at_rest() noexcept;
  /// The trajectory's command at its time t (start offset faded, compliance on top).
  void follow_trajectory_at(double t) noexcept;
  /// Admittance step on the shaped wrench, then joints: tracking = one DLS
  /// step from the previous command towards reference + offset; otherwise
  /// q_seed (the reference joints) + DLS(J(q_seed)) x offset.
  void compliant_offset_to_joints(const Pose& base_T_ref_tip, const JointArray& q_seed, bool tracking) noexcept;
  /// Anti-windup after the limiter cut a compliant command: the offset from
  /// compliant_ref_ that the command carries bounds the admittance's step.
  void take_back_limited() noexcept;
  void record_evidence(const CycleInputs& in) noexcept;

  // The cycle's steps (step() calls them in this order).
  /// The measured joints, their filtered velocity and the tip; the sensor's pose.
  Pose measure(const CycleInputs& in, bool joints_ok) noexcept;
  /// No power-up while the E-stop is pressed.
  void refuse_enable_in_estop(const CycleInputs& in) noexcept;
  /// An enable the loop steps: the E-stop (category 0) or the link (policy
  /// Stop) aborts it; its command then fails with why.
  void watch_power_change(const CycleInputs& in) noexcept;
  /// Tare: ask, then wait for the decoder to finish.
  void step_tare(const CycleInputs& in, CycleOutputs& out, const Pose& base_T_sensor) noexcept;
  /// The mode's command (q_cmd_).
  void generate_motion() noexcept;
  void step_trajectory() noexcept;
  void step_algorithm() noexcept;
  /// identify_payload: the identifier's joints; its result applied at the end.
  void step_identify() noexcept;
  /// The compensator's payload: the tool, plus the ORU while latched.
  void apply_payload() noexcept;
  /// |F| of the compensated, filtered contact wrench.
  double force_norm() const noexcept;
  /// The rate limiter on a stiff command, and a command too fast for it; the
  /// joints it limited (a mask).
  std::uint32_t limit_rate(const CycleInputs& in) noexcept;
  /// The drives' requests, the command and its velocity, the stop, the
  /// telemetry and the events.
  void write_outputs(const CycleInputs& in, CycleOutputs& out, bool joints_ok, std::uint32_t limited) noexcept;

  const RobotModel& model_;
  ControllerConfig config_;
  KinematicsWorkspace ws_;
  std::size_t dof_ = 0;
  int ft_link_ = -1;
  int tip_link_ = -1;
  double dt_ = 0.002;
  JointArray lower_{}, upper_{}, vmax_{}, amax_{};

  ControllerMode mode_ = ControllerMode::Disabled;
  Active active_ = Active::None;
  std::uint64_t active_id_ = 0;
  MotionCommandKind active_cmd_ = MotionCommandKind::Hold;
  bool hold_compliant_ = false;
  bool traj_compliant_ = false;
  bool drives_enabled_ = false;
  bool drive_request_pending_ = false;
  DriveRequest pending_request_ = DriveRequest::None;
  StopCategory pending_stop_category_ = StopCategory::None;  // Stopping -> what after rest
  bool link_lost_ = false;
  int sensor_bad_cycles_ = 0;
  int tare_request_ = 0;
  int tare_wait_cycles_ = 0;
  std::uint64_t tare_id_ = 0;
  bool tare_seen_ = false;
  bool estop_ = false;
  bool power_off_now_ = false;
  bool drive_request_issued_ = false;
  bool enable_aborted_ = false;                 // watch_power_change: the enable's answer is this failure
  std::array<char, 96> enable_abort_text_{};

  const PreparedTrajectory* traj_ = nullptr;
  double traj_t_ = 0.0;
  std::size_t traj_hint_ = 0;
  JointArray traj_offset_{};  // command - first sample at the start, faded out
  double traj_fade_s_ = 1.0;
  bool backoff_active_ = false;  // back_off(): waiting for the contact to fall below the limit
  int backoff_cycles_ = 0;
  bool stop_on_path_ = false;   // Stopping along traj_ (path_stop_step)
  bool stop_cartesian_ = false; // Stopping along the algorithm's reference (cartesian_stop_step)
  double path_scale_ = 1.0;     // d(trajectory time)/dt or of the reference's twist, ramping 1 -> 0
  Pose algo_ref_ = Pose::Identity();       // the algorithm's reference tip pose, this cycle
  Pose algo_ref_prev_ = Pose::Identity();  // and the cycle before (its twist)
  Vector6 stop_twist_ = Vector6::Zero();   // the reference's twist when the stop began (base; v, w)
  JointArray stop_dq_{};                   // the joints' commanded velocity then
  Reason path_cancel_code_ = Reason::Aborted;
  std::array<char, 96> path_cancel_text_{};  // the Canceled event's text, sent at rest

  JointArray q_{}, q_prev_{}, dq_{}, q_cmd_{}, q_cmd_prev_{}, q_hold_{}, v_cmd_{};
  static constexpr std::size_t kFollowingErrorHistory = 8;
  std::array<JointArray, kFollowingErrorHistory> cmd_history_{};  // the commands sent, newest at cmd_head_
  std::size_t cmd_head_ = 0;
  JointArray fe_limit_{};  // per joint
  bool have_q_ = false;
  Pose base_T_tip_ = Pose::Identity();
  Pose base_T_tip_cmd_ = Pose::Identity();
  bool tip_cmd_valid_ = false;
  Pose sensor_T_tip_ = Pose::Identity();  // from the model (fixed joints)
  Pose base_T_hold_ = Pose::Identity();  // reference tip pose of a compliant hold
  Pose compliant_ref_ = Pose::Identity();  // the reference the admittance's offset was added to this cycle
  JointVector qv_, qv2_, dqv_;
  Jacobian J_;

  WrenchCompensator comp_;
  Admittance adm_;
  JointRateLimiter limiter_;
  bool limiter_applied_ = false;  // this cycle's command came out of limiter_.apply()
  double compliant_scale_ = 1.0;  // the compliant modes' limits over the stiff ones
  std::uint64_t rate_limited_cycles_ = 0;
  std::array<std::uint32_t, kMaxJoints> rate_limited_joint_cycles_{};
  AlgorithmRunner algo_;
  PayloadIdentifier ident_;
  bool identifying_ = false;     // the running algorithm is identify_payload (stiff, in joint space)
  PayloadMass tool_payload_{}, oru_payload_{};
  bool oru_latched_ = false;
  bool zeroed_ = false;          // a tare or an identification set the reading's zero
  Eigen::Matrix3d base_R_sensor_ = Eigen::Matrix3d::Identity();
  Wrench6 ft_reading_{};
  bool ft_fresh_ = false;

  std::array<MotionEvent, CycleOutputs::kMaxEvents> pending_events_{};
  std::size_t pending_event_count_ = 0;
  StopEvent stop_{};
  bool stop_new_ = false;
  std::array<EvidenceSample, StopEvent::kEvidence> evidence_{};
  std::size_t evidence_head_ = 0;
  std::size_t evidence_count_ = 0;
  std::uint64_t cycle_ = 0;
  std::int64_t stamp_ns_ = 0;
  Wrench6 wrench_tool_{};
  Wrench6 shaped_{};
};

}  // namespace foresight::control
