#pragma once
// Every DDS topic name of the protocol, in one place. docs/protocol.md lists
// who writes and who reads each one. Names use '/' like ROS 2 so tools show
// them grouped.

namespace foresight::protocol::topics {

// Ground -> remote
inline constexpr const char* kCommand = "foresight/command";
inline constexpr const char* kTrajectoryChunk = "foresight/trajectory/chunk";
inline constexpr const char* kPing = "foresight/ping";
/// ABORT only (Command samples of kind ABORT; anything else is REJECTED):
/// with DDS Security an observer may write this topic and not kCommand, so it
/// can stop the arm and do nothing else.
inline constexpr const char* kAbort = "foresight/abort";

// Remote -> ground
inline constexpr const char* kCommandAck = "foresight/command/ack";
inline constexpr const char* kTrajectoryStatus = "foresight/trajectory/status";
inline constexpr const char* kJointState = "foresight/telemetry/joint_state";
inline constexpr const char* kWrench = "foresight/telemetry/wrench";
inline constexpr const char* kToolState = "foresight/telemetry/tool_state";
inline constexpr const char* kControllerStatus = "foresight/status";
inline constexpr const char* kPong = "foresight/pong";

// Both directions (keyed by Side)
inline constexpr const char* kHeartbeat = "foresight/heartbeat";

}  // namespace foresight::protocol::topics
