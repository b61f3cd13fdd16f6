// Names and conversions of the real-time message types (rt_types.hpp).
#include "foresight/control/rt_types.hpp"

#include <cstring>

namespace foresight::control {

RtPose to_rt(const Pose& pose) noexcept {
  RtPose out;
  for (int i = 0; i < 3; ++i) out.xyz_m[static_cast<std::size_t>(i)] = pose.translation()(i);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out.rotation[static_cast<std::size_t>(3 * r + c)] = pose.linear()(r, c);
  return out;
}

Pose from_rt(const RtPose& pose) noexcept {
  Pose out = Pose::Identity();
  for (int i = 0; i < 3; ++i) out.translation()(i) = pose.xyz_m[static_cast<std::size_t>(i)];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out.linear()(r, c) = pose.rotation[static_cast<std::size_t>(3 * r + c)];
  return out;
}

const char* to_string(AlgorithmKind kind) noexcept {
  switch (kind) {
    case AlgorithmKind::None: return "none";
    case AlgorithmKind::GuardedMove: return "guarded_move";
    case AlgorithmKind::Insert: return "insert";
    case AlgorithmKind::PullOut: return "pull_out";
    case AlgorithmKind::IdentifyPayload: return "identify_payload";
  }
  return "unknown";
}

AlgorithmKind algorithm_from_name(const char* name) noexcept {
  if (name == nullptr) return AlgorithmKind::None;
  if (std::strcmp(name, "guarded_move") == 0) return AlgorithmKind::GuardedMove;
  if (std::strcmp(name, "insert") == 0) return AlgorithmKind::Insert;
  if (std::strcmp(name, "pull_out") == 0) return AlgorithmKind::PullOut;
  if (std::strcmp(name, "identify_payload") == 0) return AlgorithmKind::IdentifyPayload;
  return AlgorithmKind::None;
}

const char* to_string(MotionCommandKind kind) noexcept {
  switch (kind) {
    case MotionCommandKind::RunTrajectory: return "run_trajectory";
    case MotionCommandKind::RunAlgorithm: return "run_algorithm";
    case MotionCommandKind::Hold: return "hold";
    case MotionCommandKind::Stop: return "stop";
    case MotionCommandKind::Recover: return "recover";
    case MotionCommandKind::Enable: return "enable";
    case MotionCommandKind::Disable: return "disable";
    case MotionCommandKind::Tare: return "tare";
    case MotionCommandKind::SetPayload: return "set_payload";
  }
  return "unknown";
}

const char* to_string(MotionEventKind kind) noexcept {
  switch (kind) {
    case MotionEventKind::Started: return "started";
    case MotionEventKind::Completed: return "completed";
    case MotionEventKind::Failed: return "failed";
    case MotionEventKind::Canceled: return "canceled";
    case MotionEventKind::Rejected: return "rejected";
  }
  return "unknown";
}

bool is_final(MotionEventKind kind) noexcept { return kind != MotionEventKind::Started; }

const char* to_string(StopCause cause) noexcept {
  switch (cause) {
    case StopCause::None: return "none";
    case StopCause::Command: return "command";
    case StopCause::EStop: return "estop";
    case StopCause::LinkLoss: return "link_loss";
    case StopCause::JointPositionLimit: return "joint_position_limit";
    case StopCause::JointVelocityLimit: return "joint_velocity_limit";
    case StopCause::FollowingError: return "following_error";
    case StopCause::ForceLimit: return "force_limit";
    case StopCause::TorqueLimit: return "torque_limit";
    case StopCause::DriveFault: return "drive_fault";
    case StopCause::SensorFault: return "sensor_fault";
    case StopCause::Overrun: return "overrun";
  }
  return "unknown";
}

}  // namespace foresight::control
