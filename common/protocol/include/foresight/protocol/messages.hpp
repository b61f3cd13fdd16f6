#pragma once
// The protocol's message types (generated from idl/foresight_msgs.idl by
// idlc into plain C structs) under C++ names, and for each one its topic
// descriptor, default topic name and default QoS. Writer<T>, Reader<T> and
// Topic<T> take these defaults, so `Writer<msg::Command> w(participant);`
// is all a link needs.

#include "foresight/protocol/qos.hpp"
#include "foresight/protocol/topics.hpp"
#include "foresight_msgs.h"

namespace foresight::protocol {

namespace msg {
// Topic types
using Command = foresight_msg_Command;
using CommandAck = foresight_msg_CommandAck;
using TrajectoryChunk = foresight_msg_TrajectoryChunk;
using TrajectoryStatus = foresight_msg_TrajectoryStatus;
using JointState = foresight_msg_JointState;
using Wrench = foresight_msg_Wrench;
using ToolState = foresight_msg_ToolState;
using ControllerStatus = foresight_msg_ControllerStatus;
using Heartbeat = foresight_msg_Heartbeat;
using Ping = foresight_msg_Ping;
using Pong = foresight_msg_Pong;
// Nested types
using CommandPayload = foresight_msg_CommandPayload;
using CommandKind = foresight_msg_CommandKind;
using RunTrajectory = foresight_msg_RunTrajectory;
using InvokeAlgorithm = foresight_msg_InvokeAlgorithm;
using NamedValue = foresight_msg_NamedValue;
using Request = foresight_msg_ReportRequest;
using CameraCommand = foresight_msg_CameraCommand;
using GotoJoint = foresight_msg_GotoJoint;
using GotoCart = foresight_msg_GotoCart;
using Abort = foresight_msg_AbortCommand;
using AckState = foresight_msg_AckState;
using ReasonCode = foresight_msg_ReasonCode;
using UploadState = foresight_msg_UploadState;
using StopCategory = foresight_msg_StopCategory;
using ControllerMode = foresight_msg_ControllerMode;
using ToolDirection = foresight_msg_ToolDirection;
using Side = foresight_msg_HeartbeatSide;
using Sha256 = foresight_msg_Sha256;

inline constexpr unsigned kProtocolVersion = foresight_msg_CURRENT_PROTOCOL_VERSION;
inline constexpr unsigned kMaxJoints = foresight_msg_MAX_JOINTS;
inline constexpr unsigned kMaxChunkValues = foresight_msg_MAX_CHUNK_VALUES;
inline constexpr unsigned kMaxChunks = foresight_msg_MAX_CHUNKS;
inline constexpr unsigned kMaxParams = foresight_msg_MAX_PARAMS;
}  // namespace msg

/// Per topic type: descriptor(), the default topic name and QoS profile.
template <class T>
struct MessageTraits;  // only the specialisations below exist

#define FORESIGHT_PROTOCOL_MESSAGE(TYPE, TOPIC, QOS)                                         \
  template <>                                                                                \
  struct MessageTraits<foresight_msg_##TYPE> {                                               \
    static const dds_topic_descriptor_t* descriptor() noexcept { return &foresight_msg_##TYPE##_desc; } \
    static constexpr const char* type_name = #TYPE;                                          \
    static constexpr const char* topic = TOPIC;                                              \
    static Qos qos() { return QOS; }                                                         \
  };

FORESIGHT_PROTOCOL_MESSAGE(Command, topics::kCommand, qos::command())
FORESIGHT_PROTOCOL_MESSAGE(CommandAck, topics::kCommandAck, qos::command_ack())
FORESIGHT_PROTOCOL_MESSAGE(TrajectoryChunk, topics::kTrajectoryChunk, qos::trajectory_chunk())
FORESIGHT_PROTOCOL_MESSAGE(TrajectoryStatus, topics::kTrajectoryStatus, qos::trajectory_status())
FORESIGHT_PROTOCOL_MESSAGE(JointState, topics::kJointState, qos::telemetry())
FORESIGHT_PROTOCOL_MESSAGE(Wrench, topics::kWrench, qos::telemetry())
FORESIGHT_PROTOCOL_MESSAGE(ToolState, topics::kToolState, qos::telemetry())
FORESIGHT_PROTOCOL_MESSAGE(ControllerStatus, topics::kControllerStatus, qos::controller_status())
FORESIGHT_PROTOCOL_MESSAGE(Heartbeat, topics::kHeartbeat, qos::heartbeat())
FORESIGHT_PROTOCOL_MESSAGE(Ping, topics::kPing, qos::ping())
FORESIGHT_PROTOCOL_MESSAGE(Pong, topics::kPong, qos::ping())

#undef FORESIGHT_PROTOCOL_MESSAGE

template <class T>
concept Message = requires { MessageTraits<T>::descriptor(); };

}  // namespace foresight::protocol
