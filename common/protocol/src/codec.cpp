#include "foresight/protocol/codec.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>

namespace foresight::protocol {

namespace {

/// "<field> <raw>" into buf when the raw value is past `last`, else nullptr.
template <class E>
const char* past(const E& field, E last, const char* name, char* buf, std::size_t size) noexcept {
  const std::uint32_t v = raw(field);
  if (v <= static_cast<std::uint32_t>(last)) return nullptr;
  if (std::strcmp(name, "kind") == 0)
    std::snprintf(buf, size, "unknown kind %u", static_cast<unsigned>(v));
  else
    std::snprintf(buf, size, "%s %u is unknown", name, static_cast<unsigned>(v));
  return buf;
}

}  // namespace

const char* enum_error(const msg::Command& c, char* buf, std::size_t size) noexcept {
  if (const char* e = past(c.payload._d, foresight_msg_CMD_RECOVER, "kind", buf, size)) return e;
  const auto& u = c.payload._u;
  switch (raw(c.payload._d)) {
    case foresight_msg_CMD_REQUEST:
      return past(u.request.what, foresight_msg_REQUEST_TRAJECTORIES, "request.what", buf, size);
    case foresight_msg_CMD_CAMERA:
      return past(u.camera.action, foresight_msg_CAMERA_GRAB, "camera.action", buf, size);
    case foresight_msg_CMD_ABORT:
      return past(u.abort.category, foresight_msg_STOP_CAT2, "abort.category", buf, size);
    default:
      return nullptr;
  }
}

const char* enum_error(const msg::CommandAck& a, char* buf, std::size_t size) noexcept {
  if (const char* e = past(a.kind, foresight_msg_CMD_RECOVER, "kind", buf, size)) return e;
  if (const char* e = past(a.state, foresight_msg_ACK_CANCELED, "state", buf, size)) return e;
  return past(a.code, foresight_msg_REASON_NOT_IN_CONTROL, "code", buf, size);
}

const char* enum_error(const msg::TrajectoryStatus& s, char* buf, std::size_t size) noexcept {
  if (const char* e = past(s.state, foresight_msg_UPLOAD_DISCARDED, "state", buf, size)) return e;
  return past(s.code, foresight_msg_REASON_NOT_IN_CONTROL, "code", buf, size);
}

const char* enum_error(const msg::ToolState& t, char* buf, std::size_t size) noexcept {
  return past(t.direction, foresight_msg_TOOL_LOOSEN, "direction", buf, size);
}

const char* enum_error(const msg::ControllerStatus& s, char* buf, std::size_t size) noexcept {
  if (const char* e = past(s.mode, foresight_msg_MODE_FAULT, "mode", buf, size)) return e;
  if (const char* e = past(s.stop_category, foresight_msg_STOP_CAT2, "stop_category", buf, size)) return e;
  for (const auto& d : view(s.drives))
    if (const char* e = past(d.state, foresight_msg_DRIVE_UNKNOWN, "drives[].state", buf, size)) return e;
  for (const auto& q : view(s.queue)) {
    if (const char* e = past(q.kind, foresight_msg_CMD_RECOVER, "queue[].kind", buf, size)) return e;
    if (const char* e = past(q.state, foresight_msg_ACK_CANCELED, "queue[].state", buf, size)) return e;
  }
  return nullptr;
}

const char* enum_error(const msg::Heartbeat& h, char* buf, std::size_t size) noexcept {
  return past(h.side, foresight_msg_SIDE_REMOTE, "side", buf, size);
}

const char* joint_state_error(const msg::JointState& s, std::size_t expected_joints, JointStateDefect& defect,
                              char* buf, std::size_t size) noexcept {
  defect = JointStateDefect::None;
  const auto q = view(s.q_rad), dq = view(s.dq_rad_s), tq = view(s.torque_nm);
  if (q.empty() || (expected_joints != 0 && q.size() != expected_joints)) {
    defect = JointStateDefect::JointCount;
    if (q.empty())
      std::snprintf(buf, size, "q_rad is empty");
    else
      std::snprintf(buf, size, "q_rad has %zu joints; the arm has %zu", q.size(), expected_joints);
    return buf;
  }
  const struct {
    std::span<const double> values;
    const char* name;
  } seqs[] = {{q, "q_rad"}, {dq, "dq_rad_s"}, {tq, "torque_nm"}};
  for (const auto& f : seqs) {
    if (f.values.size() != q.size()) {
      defect = JointStateDefect::Length;
      std::snprintf(buf, size, "%s has %zu values for %zu joints", f.name, f.values.size(), q.size());
      return buf;
    }
  }
  for (const auto& f : seqs) {
    for (std::size_t i = 0; i < f.values.size(); ++i) {
      if (!std::isfinite(f.values[i])) {
        defect = JointStateDefect::NotFinite;
        std::snprintf(buf, size, "%s[%zu] is not finite", f.name, i);
        return buf;
      }
    }
  }
  return nullptr;
}

const char* to_string(JointStateDefect defect) noexcept {
  switch (defect) {
    case JointStateDefect::None: return "none";
    case JointStateDefect::JointCount: return "joint_count";
    case JointStateDefect::Length: return "length";
    case JointStateDefect::NotFinite: return "not_finite";
  }
  return "?";
}

const char* drive_state_name(msg::DriveState value) noexcept {
  switch (value) {
    case foresight_msg_DRIVE_NOT_READY_TO_SWITCH_ON: return "not_ready_to_switch_on";
    case foresight_msg_DRIVE_SWITCH_ON_DISABLED: return "switch_on_disabled";
    case foresight_msg_DRIVE_READY_TO_SWITCH_ON: return "ready_to_switch_on";
    case foresight_msg_DRIVE_SWITCHED_ON: return "switched_on";
    case foresight_msg_DRIVE_OPERATION_ENABLED: return "operation_enabled";
    case foresight_msg_DRIVE_QUICK_STOP_ACTIVE: return "quick_stop_active";
    case foresight_msg_DRIVE_FAULT_REACTION_ACTIVE: return "fault_reaction_active";
    case foresight_msg_DRIVE_FAULT: return "fault";
    case foresight_msg_DRIVE_UNKNOWN: return "unknown";
  }
  return "unknown";
}

}  // namespace foresight::protocol
