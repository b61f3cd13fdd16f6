#pragma once
// The commands, acknowledgements and reports both sides speak, as plain C++
// types (library foresight_protocol_types: no DDS). The ground
// builds them and reads them; the remote's daemon consumes and produces them;
// foresight/protocol/convert.hpp turns them into the IDL's wire types and back.
//
// Mirrors idl/foresight_msgs.idl: the enums keep the IDL's order and values so
// the conversion is a static_cast (checked by static_asserts in convert.cpp).
// One name table: to_string() here (snake case, as the CLI and the journal
// print them).
//
// Not real-time: these types own strings and vectors (the remote's real-time
// loop has fixed-size types of its own).

#include <array>
#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include "foresight/common/pose.hpp"
#include "foresight/common/trajectory.hpp"

namespace foresight::protocol {

/// A DDS participant's GUID (16 bytes: its prefix and entity id): who wrote a
/// sample, as the remote binds the commanding session to the participant that
/// took control, and the journal records each command's writer
/// (protocol::writer_participant in dds.hpp reads it off a taken sample).
struct ParticipantGuid {
  std::array<std::uint8_t, 16> bytes{};
  /// False when all zero (the writer was not found).
  bool known() const noexcept;
  /// 32 hex digits in groups of 8 ("0110a4c1.5e3f0001.00000000.000001c1"), "unknown" when not known.
  std::string hex() const;
  friend bool operator==(const ParticipantGuid&, const ParticipantGuid&) = default;
  friend auto operator<=>(const ParticipantGuid&, const ParticipantGuid&) = default;
};

enum class CommandKind : std::uint8_t {
  Trajectory = 0,
  InvokeAlgorithm,
  Request,
  Camera,
  GotoJoint,
  GotoCart,
  Abort,
  TakeControl,     ///< this ground session becomes the commander
  ReleaseControl,  ///< it gives control up
  Recover,         ///< leave STOPPED/FAULT: fault reset, enable drives, hold
};
const char* to_string(CommandKind kind) noexcept;

enum class AckState : std::uint8_t { Received = 0, Rejected, Queued, Executing, Completed, Failed, Canceled };
const char* to_string(AckState state) noexcept;
/// Rejected, Completed, Failed, Canceled: no further ack follows.
bool is_terminal(AckState state) noexcept;

enum class Reason : std::uint16_t {
  None = 0,
  VersionMismatch,
  BadSequence,
  Expired,
  BadArgument,
  JointCount,
  UnknownTrajectory,
  IncompleteUpload,
  HashMismatch,
  ValidationFailed,
  StartMismatch,
  Unreachable,
  UnknownAlgorithm,
  Busy,
  Faulted,
  Aborted,
  Timeout,
  ForceLimit,
  ToolFault,
  Internal,
  NotInControl,  ///< another ground session holds control
};
const char* to_string(Reason reason) noexcept;

/// IEC 60204-1 stop categories.
enum class StopCategory : std::uint8_t { None = 0, Cat0, Cat1, Cat2 };
const char* to_string(StopCategory category) noexcept;

enum class ControllerMode : std::uint8_t { Disabled = 0, Idle, Trajectory, Goto, Algorithm, Stopping, Stopped, Fault };
const char* to_string(ControllerMode mode) noexcept;

// ---- payloads ------------------------------------------------------------------

struct RunTrajectory {
  std::uint64_t trajectory_id = 0;
  TrajectoryHash content_hash{};
  bool compliant = false;
  double start_tolerance_rad = 0.0;  ///< 0 = the daemon's default
  /// 0: the upload must be committed when RUN arrives. > 0: RUN may overtake
  /// its upload; the remote waits this long (bounded) for it to commit.
  double upload_wait_s = 0.0;
};

struct NamedValue {
  std::string name;
  double value = 0.0;
};

struct InvokeAlgorithm {
  std::string name;  ///< guarded_move, insert, latch, unlatch, loosen, tighten, pull_out
  std::vector<NamedValue> params;
  double timeout_s = 0.0;  ///< 0 = the algorithm's default
};

enum class RequestWhat : std::uint8_t { Status = 0, JointState, Wrench, ToolState, Trajectories };
struct Request {
  RequestWhat what = RequestWhat::Status;
};

enum class CameraAction : std::uint8_t { Select = 0, Point, Grab };
struct CameraCommand {
  std::string camera;
  CameraAction action = CameraAction::Select;
  double pan_rad = 0.0;
  double tilt_rad = 0.0;
  double focal_px = 0.0;
};

struct GotoJoint {
  std::vector<double> q_rad;
  double speed_fraction = 0.5;
};

struct GotoCart {
  std::string frame;  ///< URDF link, e.g. "lst_tip"
  Pose base_T_frame = Pose::Identity();
  double speed_fraction = 0.5;
};

struct Abort {
  std::uint64_t target_command_id = 0;  ///< 0 = whatever runs and everything queued
  StopCategory category = StopCategory::Cat2;
  std::string reason;
};

struct NoPayload {};

using Payload = std::variant<RunTrajectory, InvokeAlgorithm, Request, CameraCommand, GotoJoint, GotoCart, Abort,
                             NoPayload>;

/// One command as the link hands it to the daemon, after the envelope checks
/// (version, sequence, expiry) passed.
struct Command {
  std::uint64_t session_id = 0;
  std::uint64_t command_id = 0;
  std::uint64_t sequence_number = 0;
  std::int64_t issued_ns = 0;   ///< ground clock
  std::int64_t received_ns = 0; ///< remote clock
  CommandKind kind = CommandKind::Request;
  Payload payload = NoPayload{};
  /// A chain: the command of the same session this one follows (0: none).
  std::uint64_t after_command_id = 0;
};

/// One state change of a command (RECEIVED ... COMPLETED).
struct Ack {
  std::uint64_t session_id = 0;
  std::uint64_t command_id = 0;
  std::uint64_t sequence_number = 0;
  CommandKind kind = CommandKind::Request;
  AckState state = AckState::Received;
  Reason code = Reason::None;
  std::string reason;
  std::int64_t stamp_ns = 0;        ///< remote clock
  std::vector<double> final_q_rad;  ///< Completed / Failed / Canceled
};

// ---- reports ---------------------------------------------------------------------

struct JointReport {
  std::int64_t stamp_ns = 0;
  std::uint64_t cycle = 0;
  std::vector<double> q_rad, dq_rad_s, torque_nm;
};

/// Wrist wrench in the tool frame, bias and tool gravity compensated.
struct WrenchReport {
  std::int64_t stamp_ns = 0;
  std::array<double, 3> force_tool_n{};
  std::array<double, 3> torque_tool_nm{};
  bool saturated = false;
};

struct ToolReport {
  std::int64_t stamp_ns = 0;
  bool latched = false;
  bool running = false;
  int direction = 0;  ///< 0 stopped, 1 tighten, 2 loosen (IDL ToolDirection)
  double turns = 0.0;
  double torque_nm = 0.0;
  std::uint32_t fault_bits = 0;
};

/// A drive's power state in telemetry and status: its CiA 402 state's number
/// (the IDL's DriveState: 0 not ready to switch on ... 7 fault), or this while
/// the drive is silent.
inline constexpr std::uint8_t kDriveStateUnknown = 8;

/// One drive as it reported itself (StatusReport::drives).
struct DriveReport {
  int joint = 0;                            ///< 1-based
  int node_id = 0;                          ///< CANopen node id
  std::uint8_t state = kDriveStateUnknown;  ///< CiA 402 state number (the IDL's DriveState)
  bool powered = false;                     ///< power stage energised
};

/// The remote's control loop: its real-time grant and its timing since start.
struct LoopTiming {
  bool realtime = false;           ///< SCHED_FIFO granted
  bool memory_locked = false;      ///< mlockall granted
  bool realtime_required = false;  ///< the drives are enabled only with both (off the simulator, no --allow-non-rt)
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;      ///< cycles that ended after the next deadline
  std::uint32_t missed_streak_max = 0;  ///< most periods missed in a row
  std::uint32_t max_missed_cycles = 0;  ///< missed in a row that stop the arm (category 1); 0: never
  double wakeup_latency_p99_us = 0.0;
  double wakeup_latency_max_us = 0.0;
  double compute_p99_us = 0.0;
  double compute_max_us = 0.0;
};

/// The remote's rate limiter (the last limit on every command it sends the
/// drives: acceleration and jerk): how often it acted and its last episode.
struct RateLimitReport {
  std::uint64_t cycles = 0;           ///< control cycles it changed a command since start
  bool limiting = false;              ///< limiting now (an episode ends 200 ms after its last limited cycle)
  std::uint32_t last_joint_mask = 0;  ///< the last episode's joints (bit j = joint j + 1)
  std::uint64_t last_command_id = 0;  ///< the command running when it began (0: none)
  double last_max_lag_rad = 0.0;      ///< the largest target - command of that episode
};

/// A command the remote holds: running (Executing) or waiting (Queued).
struct QueuedCommand {
  std::uint64_t command_id = 0;
  CommandKind kind = CommandKind::Request;
  std::uint64_t after_command_id = 0;  ///< the chain's predecessor (0: none)
  AckState state = AckState::Queued;
};

struct StatusReport {
  std::int64_t stamp_ns = 0;
  ControllerMode mode = ControllerMode::Disabled;
  std::uint64_t active_command_id = 0;
  std::uint64_t active_trajectory_id = 0;
  std::uint64_t last_sequence = 0;
  StopCategory stop_category = StopCategory::None;
  std::string stop_reason;
  std::uint32_t fault_bits = 0;
  std::string fault_text;
  std::vector<DriveReport> drives;  ///< one per joint, joint order
  LoopTiming loop;
  RateLimitReport rate_limit;
  std::vector<QueuedCommand> queue;  ///< the running command first, then the queued ones in order
};

/// An upload's state as the link reports it on the trajectory status topic.
enum class UploadState : std::uint8_t { Assembling = 0, Committed, Rejected, Discarded };

const char* to_string(UploadState state) noexcept;

}  // namespace foresight::protocol
