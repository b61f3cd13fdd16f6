#pragma once
// Conversions between the wire types (common/protocol, generated from the IDL)
// and the plain types the daemon speaks (control/command.hpp), and the
// hostile-sample checks a command's payload must pass before it is converted.
// Both links use these (library foresight_link_codec), so the ground encodes
// exactly what the remote decodes.
//
// Not real-time: the control types own strings and vectors.

#include <cstdint>
#include <string>

#include "foresight/control/command.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/messages.hpp"

namespace foresight::remote_link {

/// What the payload checks need to know about the arm.
struct PayloadLimits {
  int joints = 7;  ///< a GotoJoint target must have exactly this many angles
};

/// The verdict on a command's payload: Reason::None when it may be converted.
struct PayloadVerdict {
  control::Reason code = control::Reason::None;
  std::string reason;  ///< names the field, e.g. "goto_joint.q_rad[3] is not finite"
  bool ok() const noexcept { return code == control::Reason::None; }
};

/// Hostile-sample checks on a received command's payload (after the envelope
/// checks): a known kind, every number finite, sizes (joint count, parameter
/// names), enums in range, strings printable ASCII and non-empty where a name
/// is required, speed fractions in (0, 1], timeouts >= 0, a unit quaternion.
PayloadVerdict check_payload(const protocol::msg::Command& command, const PayloadLimits& limits);

/// The received command as the daemon's type (envelope + payload). Call only
/// after check_payload() passed. `received_ns` is the remote's clock.
control::Command to_control(const protocol::msg::Command& command, std::int64_t received_ns);

/// The envelope only (ids, kind as received, times), payload NoPayload: for
/// rejections, whose payload may be unreadable.
control::Command envelope_of(const protocol::msg::Command& command, std::int64_t received_ns);

/// Fills the payload of `out` (out->payload._d and _u) from `kind` and
/// `payload`. Throws std::invalid_argument when the payload alternative does
/// not belong to `kind`, std::length_error when a string or sequence exceeds
/// its protocol bound.
void fill_payload(protocol::msg::Command& out, control::CommandKind kind, const control::Payload& payload);

/// Ack, both ways. to_wire throws std::length_error beyond MAX_JOINTS joints.
void to_wire(protocol::msg::CommandAck& out, const control::Ack& ack);
control::Ack from_wire(const protocol::msg::CommandAck& ack);

/// Reports, both ways.
void to_wire(protocol::msg::JointState& out, const control::JointReport& report);
void to_wire(protocol::msg::Wrench& out, const control::WrenchReport& report) noexcept;
void to_wire(protocol::msg::ToolState& out, const control::ToolReport& report) noexcept;
void to_wire(protocol::msg::ControllerStatus& out, const control::StatusReport& report);
control::JointReport from_wire(const protocol::msg::JointState& state);
control::WrenchReport from_wire(const protocol::msg::Wrench& wrench) noexcept;
control::ToolReport from_wire(const protocol::msg::ToolState& tool) noexcept;
control::StatusReport from_wire(const protocol::msg::ControllerStatus& status);

/// As control::is_terminal, without linking the daemon's library: Rejected,
/// Completed, Failed, Canceled.
bool is_final(control::AckState state) noexcept;

/// Names without the control library (its to_string lives with the daemon).
const char* name_of(control::CommandKind kind) noexcept;
const char* name_of(control::AckState state) noexcept;
const char* name_of(control::Reason code) noexcept;

}  // namespace foresight::remote_link
