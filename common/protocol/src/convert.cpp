#include "foresight/protocol/convert.hpp"

#include <cctype>
#include <cmath>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>
#include <stdexcept>
#include <type_traits>

#include "foresight/protocol/codec.hpp"
#include "foresight/protocol/commands.hpp"
#include "foresight/protocol/trajectory_upload.hpp"
#include "foresight/common/format.hpp"

namespace foresight::protocol {

// The plain enums mirror the IDL's order and values (command.hpp).
static_assert(static_cast<int>(CommandKind::Abort) == foresight_msg_CMD_ABORT);
// Drive states travel as their CiA 402 value (the remote's supervisor checks its own enum against these).
static_assert(kDriveStateUnknown == foresight_msg_DRIVE_UNKNOWN && foresight_msg_DRIVE_FAULT == 7 &&
              foresight_msg_DRIVE_OPERATION_ENABLED == 4 && foresight_msg_DRIVE_QUICK_STOP_ACTIVE == 5);
static_assert(static_cast<int>(CommandKind::TakeControl) == foresight_msg_CMD_TAKE_CONTROL);
static_assert(static_cast<int>(CommandKind::ReleaseControl) == foresight_msg_CMD_RELEASE_CONTROL);
static_assert(static_cast<int>(CommandKind::Recover) == foresight_msg_CMD_RECOVER);
static_assert(static_cast<int>(AckState::Canceled) == foresight_msg_ACK_CANCELED);
static_assert(static_cast<int>(Reason::Internal) == foresight_msg_REASON_INTERNAL);
static_assert(static_cast<int>(Reason::NotInControl) == foresight_msg_REASON_NOT_IN_CONTROL);
static_assert(static_cast<int>(StopCategory::Cat2) == foresight_msg_STOP_CAT2);
static_assert(static_cast<int>(ControllerMode::Fault) == foresight_msg_MODE_FAULT);
static_assert(static_cast<int>(RequestWhat::Trajectories) == foresight_msg_REQUEST_TRAJECTORIES);
static_assert(static_cast<int>(CameraAction::Grab) == foresight_msg_CAMERA_GRAB);
static_assert(static_cast<int>(UploadState::Discarded) == foresight_msg_UPLOAD_DISCARDED);

namespace {

PayloadVerdict bad(std::string reason, Reason code = Reason::BadArgument) {
  return PayloadVerdict{code, std::move(reason)};
}

bool finite_all(std::span<const double> values, std::size_t& first_bad) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) {
      first_bad = i;
      return false;
    }
  }
  return true;
}

/// Printable ASCII only (no control characters, no bytes >= 0x80): names end
/// up in logs, the journal and file names.
bool printable(std::string_view s) {
  for (const char c : s) {
    if (c < 0x20 || c > 0x7e) return false;
  }
  return true;
}

std::optional<PayloadVerdict> check_name(std::string_view value, const std::string& field, bool required) {
  if (required && value.empty()) return bad(field + " is empty");
  if (!printable(value)) return bad(field + " has a non-printable character");
  return std::nullopt;
}

std::optional<PayloadVerdict> check_number(double value, const std::string& field) {
  if (!std::isfinite(value)) return bad(field + " is not finite");
  return std::nullopt;
}

std::optional<PayloadVerdict> check_speed(double value, const std::string& field) {
  if (auto v = check_number(value, field)) return v;
  if (!(value > 0.0 && value <= 1.0)) return bad(field + " " + std::to_string(value) + " is not in (0, 1]");
  return std::nullopt;
}

std::optional<PayloadVerdict> check_non_negative(double value, const std::string& field) {
  if (auto v = check_number(value, field)) return v;
  if (value < 0.0) return bad(field + " " + std::to_string(value) + " is negative");
  return std::nullopt;
}

}  // namespace

PayloadVerdict check_payload(const msg::Command& c, const PayloadLimits& limits) {
  const auto& u = c.payload._u;
  std::size_t at = 0;
  // Enum fields first, as raw integers (loading an unknown value as the enum is UB).
  char why[96];
  if (const char* e = protocol::enum_error(c, why, sizeof why)) return bad(e);
  switch (protocol::raw(c.payload._d)) {
    case foresight_msg_CMD_TRAJECTORY: {
      const auto& p = u.trajectory;
      if (p.trajectory_id == 0) return bad("trajectory.trajectory_id is 0", Reason::UnknownTrajectory);
      if (auto v = check_non_negative(p.start_tolerance_rad, "trajectory.start_tolerance_rad")) return *v;
      if (auto v = check_non_negative(p.upload_wait_s, "trajectory.upload_wait_s")) return *v;
      return {};
    }
    case foresight_msg_CMD_INVOKE_ALGORITHM: {
      const auto& p = u.algorithm;
      if (auto v = check_name(text(p.name), "algorithm.name", true)) return *v;
      const auto params = view(p.params);
      for (std::size_t i = 0; i < params.size(); ++i) {
        const std::string field = "algorithm.params[" + std::to_string(i) + "]";
        if (auto v = check_name(text(params[i].name), field + ".name", true)) return *v;
        if (auto v = check_number(params[i].value, field + ".value")) return *v;
      }
      if (auto v = check_non_negative(p.timeout_s, "algorithm.timeout_s")) return *v;
      return {};
    }
    case foresight_msg_CMD_REQUEST:
      return {};  // request.what checked by enum_error
    case foresight_msg_CMD_CAMERA: {
      const auto& p = u.camera;
      if (auto v = check_name(text(p.camera), "camera.camera", true)) return *v;
      if (auto v = check_number(p.pan_rad, "camera.pan_rad")) return *v;
      if (auto v = check_number(p.tilt_rad, "camera.tilt_rad")) return *v;
      if (auto v = check_non_negative(p.focal_px, "camera.focal_px")) return *v;
      return {};
    }
    case foresight_msg_CMD_GOTO_JOINT: {
      const auto& p = u.goto_joint;
      const auto q = view(p.q_rad);
      if (static_cast<int>(q.size()) != limits.joints) {
        return bad("goto_joint.q_rad has " + std::to_string(q.size()) + " angles; the arm has " +
                       std::to_string(limits.joints) + " joints",
                   Reason::JointCount);
      }
      if (!finite_all(q, at)) return bad("goto_joint.q_rad[" + std::to_string(at) + "] is not finite");
      if (auto v = check_speed(p.speed_fraction, "goto_joint.speed_fraction")) return *v;
      return {};
    }
    case foresight_msg_CMD_GOTO_CART: {
      const auto& p = u.goto_cart;
      if (auto v = check_name(text(p.frame), "goto_cart.frame", true)) return *v;
      if (!finite_all(p.position_m, at)) return bad("goto_cart.position_m[" + std::to_string(at) + "] is not finite");
      if (!finite_all(p.orientation_xyzw, at)) {
        return bad("goto_cart.orientation_xyzw[" + std::to_string(at) + "] is not finite");
      }
      const double* o = p.orientation_xyzw;
      const double norm = std::sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2] + o[3] * o[3]);
      if (std::abs(norm - 1.0) > 1e-6) {
        return bad("goto_cart.orientation_xyzw has norm " + std::to_string(norm) + ", not a unit quaternion");
      }
      if (auto v = check_speed(p.speed_fraction, "goto_cart.speed_fraction")) return *v;
      return {};
    }
    case foresight_msg_CMD_ABORT: {
      const auto& p = u.abort;
      if (!printable(text(p.reason))) return bad("abort.reason has a non-printable character");
      return {};
    }
    case foresight_msg_CMD_TAKE_CONTROL:
    case foresight_msg_CMD_RELEASE_CONTROL:
    case foresight_msg_CMD_RECOVER:
      return {};
  }
  return bad("unknown kind " + std::to_string(protocol::raw(c.payload._d)));
}

Command envelope_of(const msg::Command& c, std::int64_t received_ns) {
  Command out;
  out.session_id = c.session_id;
  out.command_id = c.command_id;
  out.sequence_number = c.sequence_number;
  out.issued_ns = c.issued_ns;
  out.received_ns = received_ns;
  out.kind = static_cast<CommandKind>(protocol::raw(c.payload._d));  // fixed underlying type: any value
  out.payload = NoPayload{};
  out.after_command_id = c.after_command_id;
  return out;
}

Command from_wire(const msg::Command& c, std::int64_t received_ns) {
  Command out = envelope_of(c, received_ns);
  const auto& u = c.payload._u;
  switch (protocol::raw(c.payload._d)) {  // check_payload() has checked every enum field
    case foresight_msg_CMD_TRAJECTORY: {
      RunTrajectory p;
      p.trajectory_id = u.trajectory.trajectory_id;
      p.content_hash = protocol::get_hash(u.trajectory.content_hash);
      p.compliant = u.trajectory.compliant;
      p.start_tolerance_rad = u.trajectory.start_tolerance_rad;
      p.upload_wait_s = u.trajectory.upload_wait_s;
      out.payload = p;
      break;
    }
    case foresight_msg_CMD_INVOKE_ALGORITHM: {
      InvokeAlgorithm p;
      p.name = std::string(text(u.algorithm.name));
      for (const auto& nv : view(u.algorithm.params)) p.params.push_back({std::string(text(nv.name)), nv.value});
      p.timeout_s = u.algorithm.timeout_s;
      out.payload = std::move(p);
      break;
    }
    case foresight_msg_CMD_REQUEST:
      out.payload = Request{static_cast<RequestWhat>(protocol::raw(u.request.what))};
      break;
    case foresight_msg_CMD_CAMERA: {
      CameraCommand p;
      p.camera = std::string(text(u.camera.camera));
      p.action = static_cast<CameraAction>(protocol::raw(u.camera.action));
      p.pan_rad = u.camera.pan_rad;
      p.tilt_rad = u.camera.tilt_rad;
      p.focal_px = u.camera.focal_px;
      out.payload = std::move(p);
      break;
    }
    case foresight_msg_CMD_GOTO_JOINT: {
      GotoJoint p;
      const auto q = view(u.goto_joint.q_rad);
      p.q_rad.assign(q.begin(), q.end());
      p.speed_fraction = u.goto_joint.speed_fraction;
      out.payload = std::move(p);
      break;
    }
    case foresight_msg_CMD_GOTO_CART: {
      GotoCart p;
      p.frame = std::string(text(u.goto_cart.frame));
      const double* o = u.goto_cart.orientation_xyzw;
      const double* x = u.goto_cart.position_m;
      p.base_T_frame = Pose::Identity();
      p.base_T_frame.linear() = Eigen::Quaterniond(o[3], o[0], o[1], o[2]).normalized().toRotationMatrix();
      p.base_T_frame.translation() = Eigen::Vector3d(x[0], x[1], x[2]);
      p.speed_fraction = u.goto_cart.speed_fraction;
      out.payload = std::move(p);
      break;
    }
    case foresight_msg_CMD_ABORT: {
      Abort p;
      p.target_command_id = u.abort.target_command_id;
      p.category = static_cast<StopCategory>(protocol::raw(u.abort.category));
      p.reason = std::string(text(u.abort.reason));
      out.payload = std::move(p);
      break;
    }
    default:
      break;  // no payload
  }
  return out;
}

namespace {
template <class T>
const T& payload_as(const Payload& payload, CommandKind kind) {
  const T* p = std::get_if<T>(&payload);
  if (p == nullptr) {
    const std::string name = upper(std::string("CMD_") + to_string(kind));  // the IDL's name, as the wire knows it
    throw std::invalid_argument("command " + name + ": the payload is of another kind");
  }
  return *p;
}
}  // namespace

void fill_payload(msg::Command& out, CommandKind kind, const Payload& payload) {
  auto& u = out.payload._u;
  out.payload._d = static_cast<msg::CommandKind>(kind);
  switch (kind) {
    case CommandKind::Trajectory: {
      const auto& p = payload_as<RunTrajectory>(payload, kind);
      u.trajectory.trajectory_id = p.trajectory_id;
      protocol::set_hash(u.trajectory.content_hash, p.content_hash);
      u.trajectory.compliant = p.compliant;
      u.trajectory.start_tolerance_rad = p.start_tolerance_rad;
      u.trajectory.upload_wait_s = p.upload_wait_s;
      return;
    }
    case CommandKind::InvokeAlgorithm: {
      const auto& p = payload_as<InvokeAlgorithm>(payload, kind);
      protocol::set_text(u.algorithm.name, p.name, "algorithm name");
      std::vector<msg::NamedValue> params(p.params.size());
      for (std::size_t i = 0; i < p.params.size(); ++i) {
        protocol::set_text(params[i].name, p.params[i].name, "algorithm parameter name");
        params[i].value = p.params[i].value;
      }
      protocol::assign(u.algorithm.params, std::span<const msg::NamedValue>(params), msg::kMaxParams,
                       "algorithm parameters");
      u.algorithm.timeout_s = p.timeout_s;
      return;
    }
    case CommandKind::Request:
      u.request.what = static_cast<foresight_msg_RequestWhat>(payload_as<Request>(payload, kind).what);
      return;
    case CommandKind::Camera: {
      const auto& p = payload_as<CameraCommand>(payload, kind);
      protocol::set_text(u.camera.camera, p.camera, "camera name");
      u.camera.action = static_cast<foresight_msg_CameraAction>(p.action);
      u.camera.pan_rad = p.pan_rad;
      u.camera.tilt_rad = p.tilt_rad;
      u.camera.focal_px = p.focal_px;
      return;
    }
    case CommandKind::GotoJoint: {
      const auto& p = payload_as<GotoJoint>(payload, kind);
      protocol::assign(u.goto_joint.q_rad, std::span<const double>(p.q_rad), msg::kMaxJoints, "goto joint angles");
      u.goto_joint.speed_fraction = p.speed_fraction;
      return;
    }
    case CommandKind::GotoCart: {
      const auto& p = payload_as<GotoCart>(payload, kind);
      protocol::set_text(u.goto_cart.frame, p.frame, "goto frame");
      const Eigen::Quaterniond q(p.base_T_frame.rotation());
      const Eigen::Vector3d x = p.base_T_frame.translation();
      for (int i = 0; i < 3; ++i) u.goto_cart.position_m[i] = x[i];
      u.goto_cart.orientation_xyzw[0] = q.x();
      u.goto_cart.orientation_xyzw[1] = q.y();
      u.goto_cart.orientation_xyzw[2] = q.z();
      u.goto_cart.orientation_xyzw[3] = q.w();
      u.goto_cart.speed_fraction = p.speed_fraction;
      return;
    }
    case CommandKind::Abort: {
      const auto& p = payload_as<Abort>(payload, kind);
      u.abort.target_command_id = p.target_command_id;
      u.abort.category = static_cast<msg::StopCategory>(p.category);
      protocol::set_text_truncated(u.abort.reason, p.reason);
      return;
    }
    case CommandKind::TakeControl:
    case CommandKind::ReleaseControl:
    case CommandKind::Recover:
      (void)payload_as<NoPayload>(payload, kind);
      return;
  }
  throw std::invalid_argument("command kind " + std::to_string(static_cast<unsigned>(kind)) + " is unknown");
}

void to_wire(msg::CommandAck& out, const Ack& a) {
  out.session_id = a.session_id;
  out.command_id = a.command_id;
  out.sequence_number = a.sequence_number;
  protocol::set_raw(out.kind, static_cast<std::uint32_t>(a.kind));  // may echo an unknown kind being rejected
  out.state = static_cast<msg::AckState>(a.state);
  out.code = static_cast<msg::ReasonCode>(a.code);
  protocol::set_text_truncated(out.reason, a.reason);
  out.stamp_ns = a.stamp_ns != 0 ? a.stamp_ns : protocol::now_ns();
  protocol::assign(out.final_q_rad, std::span<const double>(a.final_q_rad), msg::kMaxJoints, "ack final_q_rad");
}

Ack from_wire(const msg::CommandAck& a) {
  Ack out;
  out.session_id = a.session_id;
  out.command_id = a.command_id;
  out.sequence_number = a.sequence_number;
  // Raw integers into the fixed-width control enums (no UB for any value;
  // the ground checks enum_error() before trusting them).
  out.kind = static_cast<CommandKind>(protocol::raw(a.kind));
  out.state = static_cast<AckState>(protocol::raw(a.state));
  out.code = static_cast<Reason>(protocol::raw(a.code));
  out.reason = std::string(text(a.reason));
  out.stamp_ns = a.stamp_ns;
  const auto q = view(a.final_q_rad);
  out.final_q_rad.assign(q.begin(), q.end());
  return out;
}

void to_wire(msg::JointState& out, const JointReport& r) {
  out.stamp_ns = r.stamp_ns;
  out.cycle = r.cycle;
  protocol::assign(out.q_rad, std::span<const double>(r.q_rad), msg::kMaxJoints, "joint state q_rad");
  protocol::assign(out.dq_rad_s, std::span<const double>(r.dq_rad_s), msg::kMaxJoints, "joint state dq_rad_s");
  protocol::assign(out.torque_nm, std::span<const double>(r.torque_nm), msg::kMaxJoints, "joint state torque_nm");
}

void to_wire(msg::Wrench& out, const WrenchReport& r) noexcept {
  out.stamp_ns = r.stamp_ns;
  for (int i = 0; i < 3; ++i) {
    out.force_tool_n[i] = r.force_tool_n[static_cast<std::size_t>(i)];
    out.torque_tool_nm[i] = r.torque_tool_nm[static_cast<std::size_t>(i)];
  }
  out.saturated = r.saturated;
}

void to_wire(msg::ToolState& out, const ToolReport& r) noexcept {
  out.stamp_ns = r.stamp_ns;
  out.latched = r.latched;
  out.running = r.running;
  out.direction = static_cast<foresight_msg_ToolDirection>(r.direction);
  out.turns = r.turns;
  out.torque_nm = r.torque_nm;
  out.fault_bits = r.fault_bits;
}

void to_wire(msg::ControllerStatus& out, const StatusReport& r) {
  out.stamp_ns = r.stamp_ns;
  out.mode = static_cast<msg::ControllerMode>(r.mode);
  out.active_command_id = r.active_command_id;
  out.active_trajectory_id = r.active_trajectory_id;
  out.last_sequence = r.last_sequence;
  out.stop_category = static_cast<msg::StopCategory>(r.stop_category);
  protocol::set_text_truncated(out.stop_reason, r.stop_reason);
  out.fault_bits = r.fault_bits;
  protocol::set_text_truncated(out.fault_text, r.fault_text);
  std::array<msg::DriveStatus, msg::kMaxJoints> drives{};
  const std::size_t n = std::min<std::size_t>(r.drives.size(), drives.size());
  for (std::size_t j = 0; j < n; ++j) {
    const DriveReport& d = r.drives[j];
    drives[j].joint = static_cast<std::uint16_t>(d.joint);
    drives[j].node_id = static_cast<std::uint8_t>(d.node_id);
    drives[j].state = static_cast<msg::DriveState>(std::min<std::uint8_t>(d.state, kDriveStateUnknown));
    drives[j].powered = d.powered;
  }
  protocol::assign(out.drives, std::span<const msg::DriveStatus>(drives.data(), n), msg::kMaxJoints, "status drives");
  const LoopTiming& l = r.loop;
  out.loop = {l.realtime,          l.memory_locked,         l.realtime_required,     l.cycles,
              l.overruns,          l.missed_streak_max,     l.max_missed_cycles,     l.wakeup_latency_p99_us,
              l.wakeup_latency_max_us, l.compute_p99_us,    l.compute_max_us};
  const RateLimitReport& rl = r.rate_limit;
  out.rate_limit = {rl.cycles, rl.limiting, rl.last_joint_mask, rl.last_command_id, rl.last_max_lag_rad};
  std::array<msg::QueuedCommand, msg::kMaxQueue> queue{};
  const std::size_t nq = std::min<std::size_t>(r.queue.size(), queue.size());
  for (std::size_t i = 0; i < nq; ++i) {
    const QueuedCommand& q = r.queue[i];
    queue[i] = {q.command_id, static_cast<msg::CommandKind>(q.kind), q.after_command_id,
                static_cast<foresight_msg_AckState>(q.state)};
  }
  protocol::assign(out.queue, std::span<const msg::QueuedCommand>(queue.data(), nq), msg::kMaxQueue, "status queue");
}

JointReport from_wire(const msg::JointState& s) {
  JointReport out;
  out.stamp_ns = s.stamp_ns;
  out.cycle = s.cycle;
  const auto q = view(s.q_rad), dq = view(s.dq_rad_s), t = view(s.torque_nm);
  out.q_rad.assign(q.begin(), q.end());
  out.dq_rad_s.assign(dq.begin(), dq.end());
  out.torque_nm.assign(t.begin(), t.end());
  return out;
}

WrenchReport from_wire(const msg::Wrench& w) noexcept {
  WrenchReport out;
  out.stamp_ns = w.stamp_ns;
  for (std::size_t i = 0; i < 3; ++i) {
    out.force_tool_n[i] = w.force_tool_n[i];
    out.torque_tool_nm[i] = w.torque_tool_nm[i];
  }
  out.saturated = w.saturated;
  return out;
}

ToolReport from_wire(const msg::ToolState& t) noexcept {
  ToolReport out;
  out.stamp_ns = t.stamp_ns;
  out.latched = t.latched;
  out.running = t.running;
  out.direction = static_cast<int>(protocol::raw(t.direction));
  out.turns = t.turns;
  out.torque_nm = t.torque_nm;
  out.fault_bits = t.fault_bits;
  return out;
}

StatusReport from_wire(const msg::ControllerStatus& s) {
  StatusReport out;
  out.stamp_ns = s.stamp_ns;
  out.mode = static_cast<ControllerMode>(protocol::raw(s.mode));
  out.active_command_id = s.active_command_id;
  out.active_trajectory_id = s.active_trajectory_id;
  out.last_sequence = s.last_sequence;
  out.stop_category = static_cast<StopCategory>(protocol::raw(s.stop_category));
  out.stop_reason = std::string(text(s.stop_reason));
  out.fault_bits = s.fault_bits;
  out.fault_text = std::string(text(s.fault_text));
  for (const auto& d : view(s.drives))
    out.drives.push_back({d.joint, d.node_id, static_cast<std::uint8_t>(protocol::raw(d.state)), d.powered});
  const msg::LoopTiming& l = s.loop;
  out.loop = {l.realtime,          l.memory_locked,         l.realtime_required,     l.cycles,
              l.overruns,          l.missed_streak_max,     l.max_missed_cycles,     l.wakeup_latency_p99_us,
              l.wakeup_latency_max_us, l.compute_p99_us,    l.compute_max_us};
  const msg::RateLimit& rl = s.rate_limit;
  out.rate_limit = {rl.cycles, rl.limiting, rl.last_joint_mask, rl.last_command_id, rl.last_max_lag_rad};
  for (const auto& q : view(s.queue))  // enums checked by enum_error
    out.queue.push_back({q.command_id, static_cast<CommandKind>(protocol::raw(q.kind)), q.after_command_id,
                         static_cast<AckState>(protocol::raw(q.state))});
  return out;
}

}  // namespace foresight::protocol
