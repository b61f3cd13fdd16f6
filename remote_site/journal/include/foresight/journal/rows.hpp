#pragma once
// The journal's row types: plain values, no dependency on the controller or
// the DDS libraries (the daemon's supervisor converts its own types to these).
//
// Stamps are nanoseconds since the Unix epoch (CLOCK_REALTIME, UTC) so that
// `foresight-remote journal --since 2026-12-01T16:00:00Z` means wall time; a
// row recorded with stamp_ns == 0 is stamped by the journal when written.
//
// `detail` and `evidence` are JSON text (an object, by convention); the
// reader embeds them as JSON when they parse and as a string when not.
// Identifiers are stored as SQLite INTEGER (signed 64-bit): a uint64 above
// 2^63 reads back unchanged through this API but shows negative in the
// sqlite3 shell.

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "foresight/common/joints.hpp"

namespace foresight::journal {

/// One state change of one command: RECEIVED (with the payload summary in
/// `detail`), then REJECTED, or QUEUED / EXECUTING / COMPLETED / FAILED /
/// CANCELED (the final ones with the actual final joints in `detail`).
struct CommandRow {
  std::int64_t stamp_ns = 0;
  std::uint64_t session_id = 0;
  std::uint64_t command_id = 0;
  std::uint64_t sequence_number = 0;
  std::string kind;    ///< e.g. "TRAJECTORY", "INVOKE_ALGORITHM", "GOTO_JOINT"
  std::string state;   ///< one of kCommandStates
  std::string code;    ///< validation / outcome code, e.g. "NONE", "HASH_MISMATCH"
  std::string reason;  ///< human-readable, with the row and joint where it applies
  std::string detail;  ///< JSON text: payload summary or final joints
};

/// The states a CommandRow may carry (the protocol's AckState names).
inline constexpr std::array<const char*, 7> kCommandStates = {"RECEIVED",  "REJECTED", "QUEUED",  "EXECUTING",
                                                              "COMPLETED", "FAILED",   "CANCELED"};

/// A fault and its evidence (the cause, the cycle, the last samples).
struct FaultRow {
  std::int64_t stamp_ns = 0;
  std::uint64_t cycle = 0;
  int category = 0;       ///< IEC 60204-1 stop category: 0, 1 or 2
  std::string cause;      ///< short machine-readable cause, e.g. "following_error"
  std::string text;       ///< human-readable
  std::string evidence;   ///< JSON text: the last samples, the joint, the limit ...
};

/// The verdict on one trajectory upload (COMMITTED, REJECTED, DISCARDED ...).
struct UploadRow {
  std::int64_t stamp_ns = 0;
  std::uint64_t trajectory_id = 0;
  std::string state;
  std::string code;
  std::string reason;
  std::string hash_hex;  ///< SHA-256 of the content, lower-case hex
  std::uint32_t samples = 0;
  std::uint32_t joints = 0;
};

/// Free-form daemon events: start, stop, config, link_up, link_down ...
struct EventRow {
  std::int64_t stamp_ns = 0;
  std::string kind;
  std::string text;
  std::string detail;  ///< JSON text or empty
};

/// One telemetry sample. Fixed size and trivially copyable: it travels through
/// the lock-free queue without allocation.
struct TelemetryRow {
  static constexpr std::size_t kMaxJoints = foresight::kMaxJoints;  // common/joints.hpp
  std::int64_t stamp_ns = 0;
  std::uint64_t cycle = 0;
  std::uint8_t mode = 0;         ///< the controller's mode (its enum value)
  std::uint8_t joint_count = 0;  ///< entries of q_rad / q_cmd_rad in use
  std::array<double, kMaxJoints> q_rad{};
  std::array<double, kMaxJoints> q_cmd_rad{};
  std::array<double, 6> wrench{};  ///< force (N) then torque (N·m), tool frame
};

}  // namespace foresight::journal
