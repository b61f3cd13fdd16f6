#pragma once
// The ground station's DDS side: one participant, a CommandSequencer (this
// process's session), our heartbeat, the DelayMonitor, and a thread that
// collects acks, upload status, telemetry and the remote's heartbeat.
//
//   send(kind, payload)          -> the command id (the ack topic echoes it)
//   wait_final(id, timeout)      -> every ack seen for it, up to a terminal one
//   execute(kind, payload, ...)  -> send + wait_final with a timeout derived
//                                   from the measured delay
//   upload(trajectory, timeout)  -> chunks out, waits for COMMITTED/REJECTED,
//                                   the remote's hash beside the local one
//   joint_state(), wrench(), tool(), status() -> the latest, with its age on
//                                   the ground clock (clock offset applied)
//   dropped()                    -> received samples refused, by reason
//
// Threads: every public method is thread-safe. Not real-time. Construction
// and send()/upload() may throw (DDS set-up, bad payload); waits return
// results, never throw on timeout.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "foresight/common/trajectory.hpp"
#include "foresight/protocol/command.hpp"
#include "foresight/ground_link/delay_monitor.hpp"

namespace foresight::ground_link {

struct Config {
  int domain = 0;                       ///< DDS domain id
  double heartbeat_period_s = 0.25;
  double remote_loss_s = 2.0;           ///< no remote heartbeat this long: remote_alive() false
  DelayMonitor::Config delay{};
  /// Commands expire this long after issue (0 = never). Keep it above the
  /// worst one-way delay.
  double command_lifetime_s = 0.0;
  std::size_t ack_history = 1024;       ///< commands whose acks are remembered (oldest dropped)
  double timeout_margin_s = 5.0;        ///< added to every derived timeout
  /// Round trip assumed before any pong arrived (for derived timeouts).
  double default_rtt_s = 1.0;
  /// DDS Security: the folder made by scripts/make_dds_security.sh ("" =
  /// off) and this station's identity in it ("observer": telemetry only).
  std::string security_dir;
  std::string security_identity = "ground";
  /// Watch only: no command or chunk writer (a secure "observer" may not
  /// create them); send(), execute() and upload() throw std::logic_error,
  /// except for ABORT, which goes on topics::kAbort (the one topic an
  /// observer may write besides pings and heartbeats).
  bool read_only = false;
  /// The arm's joint count: a JointState of another length is dropped
  /// (0 = any length, as long as its sequences agree).
  std::size_t joints = 0;
};
// The remote this station listens to is the participant of the first
// remote sample heard (its heartbeat, status, telemetry or an ack); samples of
// the remote's topics from any other participant are ignored and counted
// (DroppedSamples::foreign; the operator is warned once per participant). A
// remote silent for remote_loss_s (restarted: a new participant) is learned
// anew from the next remote sample, with a warning. Without DDS Security the
// first sample may itself be an impostor's; with it, only the `remote`
// identity may write those topics.

/// Received samples dropped instead of used, by reason (the remote is not
/// trusted: protocol::joint_state_error).
struct DroppedSamples {
  std::uint64_t joint_state_joint_count = 0;  ///< q_rad empty or not Config::joints long
  std::uint64_t joint_state_length = 0;       ///< dq_rad_s / torque_nm not as long as q_rad
  std::uint64_t joint_state_not_finite = 0;   ///< NaN or infinity in q_rad, dq_rad_s, torque_nm
  std::uint64_t joint_state() const noexcept {
    return joint_state_joint_count + joint_state_length + joint_state_not_finite;
  }
  /// Samples (acks, upload status, telemetry, status, heartbeats) written by
  /// another participant than the remote this station listens to: ignored.
  std::uint64_t foreign = 0;
};

/// Every ack seen for one command, in arrival order.
struct CommandResult {
  std::uint64_t command_id = 0;
  std::vector<protocol::Ack> acks;
  bool finished = false;  ///< a terminal ack arrived (else the wait timed out)
  /// The terminal ack's (or the last ack's) state, code and reason.
  protocol::AckState state = protocol::AckState::Received;
  protocol::Reason code = protocol::Reason::None;
  std::string reason;
  std::vector<double> final_q_rad;
  double elapsed_s = 0.0;  ///< from send (or the wait's start) to the terminal ack
  /// True only for COMPLETED.
  bool succeeded() const noexcept { return finished && state == protocol::AckState::Completed; }
};

struct UploadResult {
  std::uint64_t trajectory_id = 0;
  protocol::UploadState state = protocol::UploadState::Assembling;  ///< Assembling = timed out
  protocol::Reason code = protocol::Reason::None;
  std::string reason;
  TrajectoryHash local_hash{};
  TrajectoryHash remote_hash{};  ///< from the COMMITTED (or REJECTED) status
  std::uint32_t chunk_count = 0;
  double elapsed_s = 0.0;        ///< first chunk written -> final status
  bool committed() const noexcept {
    return state == protocol::UploadState::Committed && local_hash == remote_hash;
  }
  std::chrono::steady_clock::time_point started_{};  ///< first chunk written (GroundLink::wait_upload)
};

/// A telemetry value with its age: ground now - (remote stamp - clock offset).
template <class T>
struct Timed {
  T value;
  std::int64_t received_ns = 0;  ///< ground clock
  double age_s = 0.0;            ///< computed when read
};

class GroundLink {
 public:
  /// Set-up: participant, writers, readers, delay monitor, link thread.
  /// Throws protocol::ProtocolError.
  explicit GroundLink(Config config);
  ~GroundLink();
  GroundLink(const GroundLink&) = delete;
  GroundLink& operator=(const GroundLink&) = delete;

  /// Waits until the remote's command, chunk and heartbeat readers matched
  /// ours (not when read-only) and a first pong arrived (bounded by
  /// `timeout`). False on timeout.
  bool wait_for_remote(std::chrono::nanoseconds timeout);

  /// Sends one command; returns its id. `lifetime_s` < 0 uses
  /// Config::command_lifetime_s. `after_command_id` (0: none) chains it: the
  /// remote starts it only once that command (of this session) COMPLETED,
  /// and cancels it when that one does not. Throws std::invalid_argument
  /// (payload not of `kind`), std::length_error (a bound),
  /// protocol::ProtocolError (write).
  std::uint64_t send(protocol::CommandKind kind, const protocol::Payload& payload = protocol::NoPayload{},
                     double lifetime_s = -1.0, std::uint64_t after_command_id = 0);
  /// Every ack of `command_id` until a terminal one or `timeout`.
  CommandResult wait_final(std::uint64_t command_id, std::chrono::nanoseconds timeout);
  /// send() then wait_final() with timeout_for(expected_duration_s).
  CommandResult execute(protocol::CommandKind kind, const protocol::Payload& payload = protocol::NoPayload{},
                        double expected_duration_s = 0.0);
  /// 1.5 x expected_duration_s + 3 x the window's p99 round trip
  /// (default_rtt_s before any) + timeout_margin_s.
  std::chrono::nanoseconds timeout_for(double expected_duration_s) const;

  /// Splits, writes every chunk and waits for COMMITTED or REJECTED of this
  /// upload (bounded by `timeout`). `trajectory_id` 0 = a fresh random id.
  /// Throws std::invalid_argument (make_chunks) or protocol::ProtocolError.
  UploadResult upload(const Trajectory& trajectory, std::chrono::nanoseconds timeout,
                      std::uint64_t trajectory_id = 0);
  /// upload() in two halves, for a RUN that goes out before the upload
  /// committed (RunTrajectory::upload_wait_s): start_upload writes every
  /// chunk and returns at once (state Assembling); wait_upload waits for
  /// this upload's COMMITTED or REJECTED (bounded by `timeout`, counted
  /// from the first chunk written) and fills `r` in.
  UploadResult start_upload(const Trajectory& trajectory, std::uint64_t trajectory_id = 0);
  void wait_upload(UploadResult& r, std::chrono::nanoseconds timeout);

  /// The latest valid JointState: q_rad, dq_rad_s (the drives' velocity
  /// actual 0x606C where mapped, else differentiated; docs/protocol.md) and
  /// torque_nm, all of one length.
  std::optional<Timed<protocol::JointReport>> joint_state() const;
  /// Samples dropped so far, by reason.
  DroppedSamples dropped() const;
  /// The participant this station takes for the remote (unknown before its first sample).
  protocol::ParticipantGuid remote_participant() const;
  std::optional<Timed<protocol::WrenchReport>> wrench() const;
  std::optional<Timed<protocol::ToolReport>> tool() const;
  std::optional<Timed<protocol::StatusReport>> status() const;

  /// A remote heartbeat within Config::remote_loss_s.
  bool remote_alive() const;
  /// Seconds since the last remote heartbeat (infinity before the first).
  double remote_silence_s() const;
  std::uint64_t remote_boot_id() const;

  DelayMonitor& delay() noexcept;
  const DelayMonitor& delay() const noexcept;
  std::uint64_t session_id() const noexcept;
  const protocol::Participant& participant() const noexcept;
  /// With DDS Security: this station is its identity (Config::security_identity),
  /// and the remote binds control to it, not to this process.
  bool secured() const noexcept;
  /// The DDS Security identity ("" without security).
  std::string identity() const;

  /// Stops our heartbeat (the remote then sees a link loss); tests and the
  /// link-loss drill. resume_heartbeat() starts it again.
  void pause_heartbeat() noexcept;
  void resume_heartbeat() noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace foresight::ground_link
