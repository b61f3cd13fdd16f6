#pragma once
// Command bookkeeping both links need: the ground numbers its commands
// (CommandSequencer), the remote checks the envelope (CommandChecker) and
// answers with acks (fill_ack). Not real-time (strings, random_device).

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/messages.hpp"

namespace foresight::protocol {

/// A random non-zero 64-bit id (session_id, boot_id, trajectory_id).
std::uint64_t random_id();

/// Ground side: stamps commands with this process's session id, strictly
/// increasing sequence numbers (1, 2, ...) and unique command ids.
class CommandSequencer {
 public:
  CommandSequencer();  ///< session_id = random_id()
  explicit CommandSequencer(std::uint64_t session_id);

  /// A zeroed command of `kind` with the envelope filled in: protocol
  /// version, session, next sequence number and command id, issued_ns = now,
  /// expires_ns = now + lifetime_s (0 = never expires). Fill the payload
  /// (`c->payload._u.<kind>`) and write it.
  Sample<msg::Command> next(msg::CommandKind kind, double lifetime_s = 0.0);

  std::uint64_t session_id() const noexcept { return session_id_; }
  std::uint64_t last_sequence() const noexcept { return sequence_; }

 private:
  std::uint64_t session_id_;
  std::uint64_t sequence_ = 0;
};

/// Remote side: the envelope checks every command must pass before its
/// payload is looked at. A new session_id (a restarted ground) starts a new
/// sequence.
class CommandChecker {
 public:
  struct Verdict {
    msg::ReasonCode code{};  ///< REASON_NONE when accepted
    std::string reason;
    bool ok() const noexcept;
  };
  /// `remote_minus_ground_ns`: the clock offset, to compare expires_ns
  /// (ground clock) with `now_ns` (remote clock). An accepted command
  /// advances the expected sequence; a rejected one does not.
  Verdict check(const msg::Command& command, std::int64_t now_ns, std::int64_t remote_minus_ground_ns = 0);

  std::uint64_t last_sequence() const noexcept { return last_sequence_; }

 private:
  std::uint64_t session_id_ = 0;
  std::uint64_t last_sequence_ = 0;
};

/// Fills `ack` for `command`: session, id, sequence and kind echoed, state,
/// code, reason (cut at the bound with "..."), stamp = now, final joint
/// angles (throws std::length_error beyond MAX_JOINTS).
void fill_ack(msg::CommandAck& ack, const msg::Command& command, msg::AckState state,
              msg::ReasonCode code = msg::ReasonCode{}, std::string_view reason = {},
              std::span<const double> final_q_rad = {});

/// REJECTED, COMPLETED, FAILED, CANCELED: no further ack follows.
bool is_terminal(msg::AckState state) noexcept;

}  // namespace foresight::protocol
