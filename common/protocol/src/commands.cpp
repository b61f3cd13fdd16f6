#include "foresight/protocol/commands.hpp"

#include <cstdint>
#include <random>

#include "foresight/protocol/codec.hpp"

namespace foresight::protocol {

std::uint64_t random_id() {
  std::random_device device;
  std::uint64_t id = 0;
  while (id == 0) id = (static_cast<std::uint64_t>(device()) << 32) ^ device();
  return id;
}

CommandSequencer::CommandSequencer() : CommandSequencer(random_id()) {}
CommandSequencer::CommandSequencer(std::uint64_t session_id) : session_id_(session_id) {}

Sample<msg::Command> CommandSequencer::next(msg::CommandKind kind, double lifetime_s) {
  Sample<msg::Command> c;
  ++sequence_;
  c->protocol_version = static_cast<std::uint16_t>(msg::kProtocolVersion);
  c->session_id = session_id_;
  c->sequence_number = sequence_;
  c->command_id = sequence_;  // unique within the session; (session_id, command_id) is unique overall
  c->issued_ns = now_ns();
  c->expires_ns = lifetime_s > 0.0 ? c->issued_ns + static_cast<std::int64_t>(lifetime_s * 1e9) : 0;
  c->payload._d = kind;
  return c;
}

bool CommandChecker::Verdict::ok() const noexcept { return code == foresight_msg_REASON_NONE; }

CommandChecker::Verdict CommandChecker::check(const msg::Command& c, std::int64_t now, std::int64_t offset) {
  Verdict v;
  v.code = foresight_msg_REASON_NONE;
  const std::string name = "command " + std::to_string(c.command_id) + ": ";
  if (c.protocol_version != msg::kProtocolVersion) {
    v.code = foresight_msg_REASON_VERSION_MISMATCH;
    v.reason = name + "protocol version " + std::to_string(c.protocol_version) + ", this remote speaks " +
               std::to_string(msg::kProtocolVersion);
    return v;
  }
  // Every enum field checked as a raw integer before anything reads it as an
  // enum (a hostile participant can send any value: loading it is UB).
  char why[96];
  if (const char* bad = enum_error(c, why, sizeof why)) {
    v.code = foresight_msg_REASON_BAD_ARGUMENT;
    v.reason = name + bad;
    return v;
  }
  const bool same_session = c.session_id == session_id_;
  if (same_session && c.sequence_number <= last_sequence_) {
    v.code = foresight_msg_REASON_BAD_SEQUENCE;
    v.reason = name + "sequence " + std::to_string(c.sequence_number) + " is not after " +
               std::to_string(last_sequence_) + " (replayed or reordered)";
    return v;
  }
  // now and offset are ours; expires_ns is the sender's and may be anything:
  // compared without arithmetic on it, the age computed in double (no
  // signed overflow whatever it holds; found by fuzz_dds_samples).
  std::int64_t ground_now = 0;
  if (__builtin_sub_overflow(now, offset, &ground_now)) ground_now = offset < 0 ? INT64_MAX : INT64_MIN;
  if (c.expires_ns != 0 && ground_now > c.expires_ns) {
    v.code = foresight_msg_REASON_EXPIRED;
    v.reason = name + "expired " +
               std::to_string((static_cast<double>(ground_now) - static_cast<double>(c.expires_ns)) * 1e-9) + " s ago";
    return v;
  }
  session_id_ = c.session_id;
  last_sequence_ = c.sequence_number;
  return v;
}

void fill_ack(msg::CommandAck& ack, const msg::Command& c, msg::AckState state, msg::ReasonCode code,
              std::string_view reason, std::span<const double> final_q_rad) {
  ack.session_id = c.session_id;
  ack.command_id = c.command_id;
  ack.sequence_number = c.sequence_number;
  set_raw(ack.kind, raw(c.payload._d));  // echoed raw: it may be an unknown kind being rejected
  ack.state = state;
  ack.code = code;
  set_text_truncated(ack.reason, reason);
  ack.stamp_ns = now_ns();
  assign(ack.final_q_rad, final_q_rad, msg::kMaxJoints, "final_q_rad");
}

bool is_terminal(msg::AckState state) noexcept {
  return state == foresight_msg_ACK_REJECTED || state == foresight_msg_ACK_COMPLETED ||
         state == foresight_msg_ACK_FAILED || state == foresight_msg_ACK_CANCELED;
}

}  // namespace foresight::protocol
