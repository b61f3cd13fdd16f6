#pragma once
// The remote site's DDS side: one participant, one thread serving a WaitSet.
//
//   Command  -> envelope checks (version, per-session sequence, expiry) and
//               hostile-sample checks -> Handlers::on_command, with either the
//               command or its rejection (code + reason). The link NEVER acks
//               by itself: the daemon journals durably first, then calls ack()
//               (RECEIVED, then REJECTED or QUEUED -> EXECUTING -> final).
//   TrajectoryChunk -> TrajectoryAssembler; a whole upload -> verify() against
//               the robot model's TrajectoryLimits -> TrajectoryStatus
//               (ASSEMBLING progress, COMMITTED with the remote's hash,
//               REJECTED with the reason, DISCARDED when evicted) and
//               Handlers::on_upload. At most Config::max_committed committed
//               uploads are kept (the oldest is discarded).
//   Ping     -> Pong at once (t2 on arrival, t3 just before the write), by
//               default from a Cyclone listener (Config::pong_in_listener).
//   ROS 2 (Config::ros2): joint state and wrench also as ROS 2 types.
//   Heartbeat: the remote's own every heartbeat_period_s; no ground heartbeat
//               for link_loss_s -> Handlers::on_link(Lost); the next one ->
//               on_link(Regained). The daemon applies the link-loss policy.
//
// Threads: the handlers run ON THE LINK THREAD, one at a time, and must not
// block long (pings and heartbeats wait behind them) and must not throw (an
// exception is caught, logged and counted). ack(), publish(), committed() and
// stats() are thread-safe and never throw; call them from any thread,
// including from inside a handler. Nothing here is real-time: the daemon's
// control loop hands reports to a non-real-time thread that calls publish().

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/command.hpp"

namespace foresight::remote_link {

struct Config {
  int domain = 0;                          ///< DDS domain id
  double heartbeat_period_s = 0.25;        ///< our heartbeat; also the link thread's wake-up period
  double link_loss_s = 2.0;                ///< no ground heartbeat this long -> on_link(Lost)
  TrajectoryLimits trajectory_limits;      ///< from the robot model (TrajectoryLimits::from_model)
  std::size_t max_committed = 8;           ///< committed uploads kept; the oldest is discarded
  std::size_t max_pending_uploads = 4;     ///< uploads assembling at once
  std::size_t max_pending_per_session = 2; ///< of them, from one ground session
  /// An upload still assembling whose last chunk is this old is rejected
  /// (INCOMPLETE_UPLOAD) and its data freed: a half upload holds no slot for ever.
  double upload_idle_timeout_s = 60.0;
  /// Sessions of one writer (participant; with DDS Security the station, whose
  /// every CLI process is a session) whose sequence is tracked; past it the
  /// least recently used is forgotten (retired, below).
  std::size_t max_sessions = 64;
  /// A session without a command for this long is forgotten. A forgotten
  /// session (expired, or pushed out by its participant's max_sessions) is
  /// retired: any later command of it is REJECTED BAD_SEQUENCE, so forgetting
  /// never lets a replay of its old commands pass (a ground process starts a
  /// new session; the last 65,536 retired sessions are remembered).
  double session_idle_s = 3600.0;
  /// Commands one participant may send: a token bucket per writer
  /// participant (command_burst deep, refilled at max_commands_per_s).
  /// Beyond it a command is dropped unanswered before anything else reads
  /// it (a flood costs the remote a map lookup a sample, no ack, no journal
  /// row) and counted: LinkEvent::RateLimited once a second per participant.
  /// The commander's ABORT always passes. 0: no limit.
  double max_commands_per_s = 50.0;
  double command_burst = 100.0;
  /// The remote's clock minus the ground's, for the expiry check (expires_ns
  /// is on the ground's clock). 0: both synchronized (NTP/PTP).
  std::int64_t clock_offset_ns = 0;
  /// Answer pings in a Cyclone listener (on its receive thread: a take and
  /// a write, nothing else) instead of on the link thread: no thread switch
  /// in the measured round trip. false: the link thread answers, first thing
  /// after every wake-up.
  bool pong_in_listener = true;
  /// DDS Security: the folder made by scripts/make_dds_security.sh ("" =
  /// off) and this side's identity in it. docs/protocol.md, "Security".
  std::string security_dir;
  std::string security_identity = "remote";
  /// ROS 2 visibility: publish(JointReport) also writes
  /// sensor_msgs/JointState on rt/joint_states and publish(WrenchReport)
  /// geometry_msgs/WrenchStamped on rt/wrench (protocol/ros2.hpp), so ROS 2
  /// tools see the robot with no bridge.
  bool ros2 = false;
  std::vector<std::string> ros2_joint_names;  ///< empty: joint1 .. jointN
  std::string ros2_wrench_frame = "lst_tip";  ///< the frame the wrench is expressed in
};

/// A command as received: accepted (code None; `command` complete) or
/// rejected by the link (code and reason; `command` has the envelope only,
/// payload NoPayload, kind as received even when unknown). Either way the
/// daemon journals it and acks RECEIVED then, for a rejection, REJECTED.
struct CommandEvent {
  protocol::Command command;
  protocol::Reason code = protocol::Reason::None;
  std::string reason;
  /// The same (session, command id, sequence) as a command that already
  /// passed the envelope checks (accepted, or rejected for its payload):
  /// code BadSequence; the daemon re-sends that command's last ack instead
  /// of a rejection (a re-sent command is idempotent).
  bool duplicate = false;
  /// The participant whose writer sent it (unknown when discovery no longer
  /// has the writer): the daemon binds the commanding session to it.
  protocol::ParticipantGuid writer;
  bool accepted() const noexcept { return code == protocol::Reason::None; }
};

/// One upload's state change.
struct UploadEvent {
  std::uint64_t trajectory_id = 0;
  std::uint64_t session_id = 0;
  protocol::UploadState state = protocol::UploadState::Assembling;
  std::uint32_t chunks_received = 0;
  std::uint32_t chunk_count = 0;
  protocol::Reason code = protocol::Reason::None;
  std::string reason;
  TrajectoryHash hash{};  ///< Committed: the remote's own over what arrived; Rejected by verify: the same
  std::shared_ptr<const Trajectory> trajectory;  ///< Committed only
};

struct LinkEvent {
  /// CommanderLeft: the participant set_commander() named has no command
  /// writer on the domain any more (its process ended or its lease expired).
  /// RateLimited: `dropped` commands of `participant` were dropped over the
  /// last `silence_s` seconds (Config::max_commands_per_s).
  enum class Kind { Lost, Regained, CommanderLeft, RateLimited };
  Kind kind = Kind::Lost;
  protocol::ParticipantGuid participant;  ///< CommanderLeft: the one that left; RateLimited: the sender
  std::uint64_t dropped = 0;              ///< RateLimited
  double silence_s = 0.0;            ///< since the last ground heartbeat (Lost) / how long it was lost (Regained)
  std::uint64_t ground_boot_id = 0;  ///< of the last ground heartbeat (a change means a restarted ground)
};

struct Handlers {
  std::function<void(const CommandEvent&)> on_command;
  std::function<void(const UploadEvent&)> on_upload;  ///< optional
  std::function<void(const LinkEvent&)> on_link;      ///< optional
};

struct LinkStats {
  std::uint64_t commands = 0;          ///< command samples taken
  std::uint64_t rejected = 0;          ///< rejected by the link (envelope or payload)
  std::uint64_t acks_written = 0;
  std::uint64_t write_failures = 0;    ///< acks and reports that Cyclone refused
  std::uint64_t pings = 0;
  std::uint64_t chunks = 0;
  std::uint64_t uploads_committed = 0;
  std::uint64_t uploads_rejected = 0;
  std::uint64_t handler_exceptions = 0;
  /// Heartbeats and chunks dropped because another participant than the
  /// commander's wrote them (set_commander): they keep no link, hold no slot.
  std::uint64_t foreign_heartbeats = 0;
  std::uint64_t foreign_chunks = 0;
  std::uint64_t rate_limited = 0;      ///< commands dropped by the per-participant rate limit
  bool link_up = false;                ///< a commander's (or, with none, a ground) heartbeat within link_loss_s
};

class RemoteLink {
 public:
  /// Set-up: creates the participant, readers and writers. Throws
  /// protocol::ProtocolError (DDS) or std::invalid_argument (no on_command
  /// handler, a non-positive period, no joints in the limits). No handler
  /// runs before start(): commands arriving meanwhile wait in DDS (reliable,
  /// keep-all), so the handlers may use this object.
  RemoteLink(Config config, Handlers handlers);
  /// Starts the link thread (idempotent).
  void start();
  /// Stops and joins the link thread, then deletes the entities.
  ~RemoteLink();
  RemoteLink(const RemoteLink&) = delete;
  RemoteLink& operator=(const RemoteLink&) = delete;

  /// Publishes one ack. False when it could not be written (bad size, DDS
  /// error); counted in stats().write_failures.
  bool ack(const protocol::Ack& ack) noexcept;

  bool publish(const protocol::JointReport& report) noexcept;
  bool publish(const protocol::WrenchReport& report) noexcept;
  bool publish(const protocol::ToolReport& report) noexcept;
  bool publish(const protocol::StatusReport& report) noexcept;
  /// Re-publishes the TrajectoryStatus of every kept upload (REQUEST_TRAJECTORIES).
  void republish_uploads() noexcept;

  /// The participant in control (the daemon's TAKE_CONTROL; unknown: nobody).
  /// While one is set, only its heartbeats keep the link up or restore it and
  /// only its chunks are assembled: another participant's are dropped and
  /// counted (stats().foreign_heartbeats, foreign_chunks).
  void set_commander(const protocol::ParticipantGuid& participant) noexcept;

  /// A committed upload by id (nullptr when unknown or discarded).
  std::shared_ptr<const Trajectory> committed(std::uint64_t trajectory_id) const noexcept;
  LinkStats stats() const noexcept;
  std::uint64_t boot_id() const noexcept;

  /// Stops the link thread early (idempotent; the destructor calls it).
  void stop() noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace foresight::remote_link
