// The one name table of the plain command types (command.hpp).
#include "foresight/protocol/command.hpp"

#include <algorithm>
#include <cstdio>

namespace foresight::protocol {

const char* to_string(CommandKind kind) noexcept {
  switch (kind) {
    case CommandKind::Trajectory: return "trajectory";
    case CommandKind::InvokeAlgorithm: return "invoke_algorithm";
    case CommandKind::Request: return "request";
    case CommandKind::Camera: return "camera";
    case CommandKind::GotoJoint: return "goto_joint";
    case CommandKind::GotoCart: return "goto_cart";
    case CommandKind::Abort: return "abort";
    case CommandKind::TakeControl: return "take_control";
    case CommandKind::ReleaseControl: return "release_control";
    case CommandKind::Recover: return "recover";
  }
  return "unknown";
}

const char* to_string(AckState state) noexcept {
  switch (state) {
    case AckState::Received: return "received";
    case AckState::Rejected: return "rejected";
    case AckState::Queued: return "queued";
    case AckState::Executing: return "executing";
    case AckState::Completed: return "completed";
    case AckState::Failed: return "failed";
    case AckState::Canceled: return "canceled";
  }
  return "unknown";
}

bool is_terminal(AckState state) noexcept {
  return state == AckState::Rejected || state == AckState::Completed || state == AckState::Failed ||
         state == AckState::Canceled;
}

const char* to_string(Reason reason) noexcept {
  switch (reason) {
    case Reason::None: return "none";
    case Reason::VersionMismatch: return "version_mismatch";
    case Reason::BadSequence: return "bad_sequence";
    case Reason::Expired: return "expired";
    case Reason::BadArgument: return "bad_argument";
    case Reason::JointCount: return "joint_count";
    case Reason::UnknownTrajectory: return "unknown_trajectory";
    case Reason::IncompleteUpload: return "incomplete_upload";
    case Reason::HashMismatch: return "hash_mismatch";
    case Reason::ValidationFailed: return "validation_failed";
    case Reason::StartMismatch: return "start_mismatch";
    case Reason::Unreachable: return "unreachable";
    case Reason::UnknownAlgorithm: return "unknown_algorithm";
    case Reason::Busy: return "busy";
    case Reason::Faulted: return "faulted";
    case Reason::Aborted: return "aborted";
    case Reason::Timeout: return "timeout";
    case Reason::ForceLimit: return "force_limit";
    case Reason::ToolFault: return "tool_fault";
    case Reason::Internal: return "internal";
    case Reason::NotInControl: return "not_in_control";
  }
  return "unknown";
}

const char* to_string(StopCategory category) noexcept {
  switch (category) {
    case StopCategory::None: return "none";
    case StopCategory::Cat0: return "cat0";
    case StopCategory::Cat1: return "cat1";
    case StopCategory::Cat2: return "cat2";
  }
  return "unknown";
}

const char* to_string(ControllerMode mode) noexcept {
  switch (mode) {
    case ControllerMode::Disabled: return "disabled";
    case ControllerMode::Idle: return "idle";
    case ControllerMode::Trajectory: return "trajectory";
    case ControllerMode::Goto: return "goto";
    case ControllerMode::Algorithm: return "algorithm";
    case ControllerMode::Stopping: return "stopping";
    case ControllerMode::Stopped: return "stopped";
    case ControllerMode::Fault: return "fault";
  }
  return "unknown";
}

const char* to_string(UploadState state) noexcept {
  switch (state) {
    case UploadState::Assembling: return "assembling";
    case UploadState::Committed: return "committed";
    case UploadState::Rejected: return "rejected";
    case UploadState::Discarded: return "discarded";
  }
  return "unknown";
}

bool ParticipantGuid::known() const noexcept {
  return std::any_of(bytes.begin(), bytes.end(), [](std::uint8_t b) { return b != 0; });
}

std::string ParticipantGuid::hex() const {
  if (!known()) return "unknown";
  std::string out;
  char b[4];
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    if (i > 0 && i % 4 == 0) out += '.';
    std::snprintf(b, sizeof b, "%02x", bytes[i]);
    out += b;
  }
  return out;
}

}  // namespace foresight::protocol
