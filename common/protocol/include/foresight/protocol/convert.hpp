#pragma once
// Conversions between the wire types (generated from the IDL, messages.hpp)
// and the plain types both sides speak (command.hpp), and the hostile-sample
// checks a command's payload must pass before it is converted. Both links use
// these, so the ground encodes exactly what the remote decodes.
//
// Not real-time: the plain types own strings and vectors.

#include <cstdint>
#include <string>

#include "foresight/protocol/command.hpp"
#include "foresight/protocol/dds.hpp"
#include "foresight/protocol/messages.hpp"

namespace foresight::protocol {

/// What the payload checks need to know about the arm.
struct PayloadLimits {
  int joints = 7;  ///< a GotoJoint target must have exactly this many angles
};

/// The verdict on a command's payload: Reason::None when it may be converted.
struct PayloadVerdict {
  Reason code = Reason::None;
  std::string reason;  ///< names the field, e.g. "goto_joint.q_rad[3] is not finite"
  bool ok() const noexcept { return code == Reason::None; }
};

/// Hostile-sample checks on a received command's payload (after the envelope
/// checks): a known kind, every number finite, sizes (joint count, parameter
/// names), enums in range, strings printable ASCII and non-empty where a name
/// is required, speed fractions in (0, 1], timeouts >= 0, a unit quaternion.
PayloadVerdict check_payload(const msg::Command& command, const PayloadLimits& limits);

/// The received command as the plain type (envelope + payload). Call only
/// after check_payload() passed. `received_ns` is the remote's clock.
Command from_wire(const msg::Command& command, std::int64_t received_ns);

/// The envelope only (ids, kind as received, times), payload NoPayload: for
/// rejections, whose payload may be unreadable.
Command envelope_of(const msg::Command& command, std::int64_t received_ns);

/// Fills the payload of `out` (out->payload._d and _u) from `kind` and
/// `payload`. Throws std::invalid_argument when the payload alternative does
/// not belong to `kind`, std::length_error when a string or sequence exceeds
/// its protocol bound.
void fill_payload(msg::Command& out, CommandKind kind, const Payload& payload);

/// Ack, both ways. to_wire throws std::length_error beyond MAX_JOINTS joints.
void to_wire(msg::CommandAck& out, const Ack& ack);
Ack from_wire(const msg::CommandAck& ack);

/// Reports, both ways.
void to_wire(msg::JointState& out, const JointReport& report);
void to_wire(msg::Wrench& out, const WrenchReport& report) noexcept;
void to_wire(msg::ToolState& out, const ToolReport& report) noexcept;
void to_wire(msg::ControllerStatus& out, const StatusReport& report);
JointReport from_wire(const msg::JointState& state);
WrenchReport from_wire(const msg::Wrench& wrench) noexcept;
ToolReport from_wire(const msg::ToolState& tool) noexcept;
StatusReport from_wire(const msg::ControllerStatus& status);

}  // namespace foresight::protocol
