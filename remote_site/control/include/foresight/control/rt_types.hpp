#pragma once
// Fixed-size, trivially copyable messages between the supervisor thread (the
// daemon) and the real-time loop (ControlLoop), carried by SpscRings:
//
//   supervisor -> loop : MotionCommand
//   loop -> supervisor : MotionEvent (command lifecycle), StopEvent (every
//                        stop with its evidence), TelemetrySample
//
// No pointers that own, no strings, no vectors: copying one never allocates.
// Everything here is usable from real-time code. Units SI (rad, m, N, N m, s).

#include <array>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "foresight/common/insert_capture.hpp"  // InsertParams: the ground computes its capture region
#include "foresight/common/joints.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/control/command.hpp"

namespace foresight::control {

class PreparedTrajectory;  // trajectory_executor.hpp

/// Joints the real-time types carry (common/joints.hpp; set-up refuses more).
using foresight::kMaxJoints;
using JointArray = std::array<double, kMaxJoints>;
/// Fx Fy Fz [N], Tx Ty Tz [N m].
using Wrench6 = std::array<double, 6>;
using Vec3 = std::array<double, 3>;

/// Copy a NUL-terminated message into a fixed char buffer (truncating). RT-safe.
template <std::size_t N>
inline void set_text(std::array<char, N>& dst, const char* src) noexcept {
  std::size_t i = 0;
  if (src != nullptr)
    for (; i + 1 < N && src[i] != '\0'; ++i) dst[i] = src[i];
  dst[i] = '\0';
}

/// A pose as plain numbers (Eigen's types are not trivially copyable).
struct RtPose {
  Vec3 xyz_m{};
  std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major 3x3
};
RtPose to_rt(const Pose& pose) noexcept;
Pose from_rt(const RtPose& pose) noexcept;

// ---- algorithms -------------------------------------------------------------------
// Parameters, defaults and success/failure criteria: algorithms.hpp and
// docs/control.md.

enum class AlgorithmKind : std::uint8_t { None = 0, GuardedMove, Insert, PullOut, IdentifyPayload };
const char* to_string(AlgorithmKind kind) noexcept;
/// "guarded_move", "insert", "pull_out", "identify_payload" -> kind; None when unknown.
AlgorithmKind algorithm_from_name(const char* name) noexcept;

/// Frame a direction or a compliance is expressed in. Tool = the tool tip
/// frame (lst_tip) frozen at the algorithm's start; Base = the robot base.
enum class TaskFrame : std::uint8_t { Tool = 0, Base };

struct GuardedMoveParams {
  Vec3 direction{0.0, 0.0, 1.0};   ///< unit vector of the motion (normalized at start)
  TaskFrame frame = TaskFrame::Tool;
  double speed_m_s = 0.01;
  double force_threshold_n = 10.0;  ///< success: contact force against the motion >= this
  double max_distance_m = 0.10;     ///< failure (Unreachable): travelled this far without contact
  double timeout_s = 0.0;           ///< 0: 2 x max_distance / speed + 2 s
};

struct PullOutParams {
  double distance_m = 0.05;            ///< success: tip moved this far along -z of the tool from the start
  double speed_m_s = 0.01;
  double max_force_n = 80.0;           ///< failure (ForceLimit)
  double lateral_stiffness_n_m = 400.0;
  double rotational_stiffness_nm_rad = 20.0;
  double timeout_s = 0.0;              ///< 0: 2 x distance / speed + 2 s
};

/// identify_payload (payload.hpp): static poses reached by stiff wrist
/// rotations of +-angle_rad from where the arm holds, the F/T averaged at rest
/// in each, then least squares for mass, centre of mass and the reading's offset.
struct IdentifyPayloadParams {
  double angle_rad = 0.2;           ///< wrist rotation of each pose from the start (about 11 degrees)
  double move_s = 2.0;              ///< each move between poses (smooth, stiff)
  double settle_s = 0.5;            ///< at the pose and still this long before averaging
  double window_s = 0.5;            ///< F/T averaged over this window at rest
  double max_contact_n = 5.0;       ///< refused at the start when the compensated force is above this
  double max_condition = 100.0;     ///< refused when the poses' regressor is worse conditioned
  double max_residual_n = 1.0;      ///< refused when the fit leaves more (RMS per pose): contact
};

struct AlgorithmParams {
  AlgorithmKind kind = AlgorithmKind::None;
  GuardedMoveParams guarded_move{};
  InsertParams insert{};
  PullOutParams pull_out{};
  IdentifyPayloadParams identify_payload{};
};

// ---- supervisor -> loop -------------------------------------------------------------

enum class MotionCommandKind : std::uint8_t {
  RunTrajectory = 0,  ///< trajectory: run a PreparedTrajectory (start-within-tolerance checked)
  RunAlgorithm,       ///< algorithm: run an RT algorithm (guarded_move, insert, pull_out)
  Hold,               ///< end what runs (Canceled) and hold; compliant = admittance hold
  Stop,               ///< controlled/immediate stop with `category` (Cat0/1/2); cause Command
  Recover,            ///< after a stop: (re-)enable the drives if needed, then hold (Idle)
  Enable,             ///< enable the drives (from Disabled), then hold
  Disable,            ///< hold still then disable the drives (from Idle/Stopped only)
  Tare,               ///< tare the F/T sensor over tare_samples (a stiff hold out of contact; resets the admittance)
  SetPayload,         ///< the tool latched (oru_latched) or let go of the ORU: the payload the compensator removes
};
const char* to_string(MotionCommandKind kind) noexcept;

struct MotionCommand {
  std::uint64_t command_id = 0;
  MotionCommandKind kind = MotionCommandKind::Hold;
  /// RunTrajectory: non-owning; the supervisor keeps it alive (and
  /// unchanged) until this command's final event (Completed/Failed/Canceled/
  /// Rejected) has been popped.
  const PreparedTrajectory* trajectory = nullptr;
  bool compliant = false;              ///< RunTrajectory / Hold: admittance on top of the reference
  double start_tolerance_rad = 0.0;    ///< RunTrajectory: 0 = ControllerConfig default
  AlgorithmParams algorithm{};         ///< RunAlgorithm
  StopCategory category = StopCategory::Cat2;  ///< Stop
  int tare_samples = 50;               ///< Tare
  bool oru_latched = false;            ///< SetPayload: the carried ORU hangs on the tool (its weight on the sensor)
};

// ---- loop -> supervisor ----------------------------------------------------------------

enum class MotionEventKind : std::uint8_t {
  Started = 0,  ///< accepted and running (hold, trajectory, algorithm, enable...)
  Completed,    ///< final: success (final_q = actual joints)
  Failed,       ///< final: the motion or algorithm failed (code, text)
  Canceled,     ///< final: superseded by Hold/Stop/another command, or a safety stop
  Rejected,     ///< final: refused before anything moved (code, text)
};
const char* to_string(MotionEventKind kind) noexcept;
bool is_final(MotionEventKind kind) noexcept;

struct MotionEvent {
  std::uint64_t command_id = 0;
  MotionCommandKind command = MotionCommandKind::Hold;
  MotionEventKind kind = MotionEventKind::Started;
  Reason code = Reason::None;
  std::uint64_t cycle = 0;
  std::int64_t stamp_ns = 0;  ///< CLOCK_MONOTONIC (the loop's clock)
  std::size_t joints = 0;
  JointArray final_q{};       ///< measured joints at the event
  /// Algorithm outcome numbers (0 otherwise): distance travelled along the
  /// task axis, peak contact force, spiral radius reached.
  double distance_m = 0.0;
  double peak_force_n = 0.0;
  double spiral_radius_m = 0.0;
  /// identify_payload (Completed) and SetPayload: the payload the compensator
  /// removes now (tool, plus the ORU while latched), its centre of mass in the
  /// sensor frame; identify_payload: the fit's condition number.
  double payload_mass_kg = 0.0;
  Vec3 payload_com_m{};
  double payload_condition = 0.0;
  std::array<char, 96> text{};  ///< readable reason ("insert: force limit 81.2 N > 80 N")
};

/// Why the controller stopped.
enum class StopCause : std::uint8_t {
  None = 0,
  Command,            ///< MotionCommand Stop (the ground's ABORT) or shutdown
  EStop,              ///< the E-stop input
  LinkLoss,           ///< the link-loss input with policy Stop (or nothing committed to finish)
  JointPositionLimit, ///< commanded joint outside its URDF range (minus margin)
  JointVelocityLimit, ///< commanded joint speed above its URDF limit
  FollowingError,     ///< |q_cmd - q| above the limit
  ForceLimit,         ///< compensated contact force above the safety limit
  TorqueLimit,        ///< compensated contact torque above the safety limit
  DriveFault,         ///< the drive system required a stop (CycleStatus.stop_required: EMCY, heartbeat, bus...)
  SensorFault,        ///< F/T sensor fault, saturation or missing samples
  Overrun,            ///< the control loop missed LoopOptions::max_missed_cycles periods in a row
};
const char* to_string(StopCause cause) noexcept;

/// One cycle of evidence.
struct EvidenceSample {
  std::uint64_t cycle = 0;
  JointArray q{};
  JointArray q_cmd{};
  Wrench6 wrench_tool{};  ///< compensated contact wrench, tool frame, about the tip
};

struct StopEvent {
  static constexpr std::size_t kEvidence = 32;  ///< 64 ms at 500 Hz
  StopCause cause = StopCause::None;
  StopCategory category = StopCategory::None;
  std::uint64_t cycle = 0;
  std::int64_t stamp_ns = 0;
  std::uint64_t command_id = 0;  ///< what was running (0: nothing)
  std::int8_t joint = -1;        ///< the joint concerned (0-based), -1 when not one joint
  double value = 0.0;            ///< the offending value (rad, rad/s, N, N m; hw: EMCY code)
  double limit = 0.0;            ///< the limit it broke
  std::uint8_t hw_fault = 0;     ///< hw::HwFault of the first stop-requiring event (DriveFault/SensorFault)
  std::uint8_t hw_node = 0;
  std::uint32_t hw_code = 0;
  std::size_t joints = 0;
  std::size_t evidence_count = 0;  ///< samples in evidence, oldest first, the last is the stop cycle
  std::array<EvidenceSample, kEvidence> evidence{};
  std::array<char, 96> text{};     ///< "following error joint 3: 0.061 rad > 0.05 rad"
};

struct TelemetrySample {
  std::int64_t stamp_ns = 0;  ///< CLOCK_MONOTONIC at the cycle start
  std::uint64_t cycle = 0;
  std::size_t joints = 0;
  JointArray q{};        ///< measured
  /// Measured velocity, rad/s: per joint the drive's own velocity actual
  /// (0x606C, TPDO2 every velocity_tpdo_every-th SYNC, so up to that many
  /// cycles older than q) where it is fresh (ControllerConfig::
  /// drive_velocity_max_age_cycles), else q differentiated and low-passed.
  JointArray dq{};
  std::uint32_t dq_drive_mask = 0;  ///< bit j: dq[j] is the drive's 0x606C (else differentiated)
  JointArray torque{};   ///< drive torque actual, joint side
  JointArray q_cmd{};    ///< commanded this cycle
  Wrench6 wrench_tool{}; ///< contact wrench: bias and tool gravity compensated, filtered; tool frame about the tip
  bool ft_saturated = false;
  bool drives_enabled = false;
  /// Per joint, the drive's own reported power state (kDriveStateUnknown when silent).
  std::array<std::uint8_t, kMaxJoints> drive_state{};
  ControllerMode mode = ControllerMode::Disabled;
  std::uint64_t active_command_id = 0;
  AlgorithmKind algorithm = AlgorithmKind::None;
  StopCategory stop_category = StopCategory::None;  ///< of the last stop (None after Recover)
  StopCause stop_cause = StopCause::None;
  /// The rate limiter (rate_limiter.hpp): the joints it limited this cycle
  /// (bit j = joint j + 1), the cycles it limited any joint since start, and
  /// per joint (a reader diffs two samples to see what acted between them).
  std::uint32_t rate_limited_mask = 0;
  std::uint64_t rate_limited_cycles = 0;
  std::array<std::uint32_t, kMaxJoints> rate_limited_joint_cycles{};
  JointArray rate_limit_lag{};  ///< target - command per joint this cycle, rad
};

static_assert(std::is_trivially_copyable_v<MotionCommand>);
static_assert(std::is_trivially_copyable_v<MotionEvent>);
static_assert(std::is_trivially_copyable_v<StopEvent>);
static_assert(std::is_trivially_copyable_v<TelemetrySample>);

}  // namespace foresight::control
