#pragma once
// The protocol's message types (generated from idl/foresight_msgs.idl by
// idlc into plain C structs) under C++ names, and for each one its topic
// descriptor, default topic name and default QoS. Writer<T>, Reader<T> and
// Topic<T> take these defaults, so `Writer<msg::Command> w(participant);`
// is all a link needs.

#include <cstdint>

#include "foresight/common/joints.hpp"
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
using DriveState = foresight_msg_DriveState;
using DriveStatus = foresight_msg_DriveStatus;
using QueuedCommand = foresight_msg_QueuedCommand;
using LoopTiming = foresight_msg_LoopTiming;
using RateLimit = foresight_msg_RateLimit;
using ToolDirection = foresight_msg_ToolDirection;
using Side = foresight_msg_HeartbeatSide;
using Sha256 = foresight_msg_Sha256;

inline constexpr unsigned kProtocolVersion = foresight_msg_CURRENT_PROTOCOL_VERSION;
inline constexpr unsigned kMaxJoints = foresight_msg_MAX_JOINTS;
inline constexpr unsigned kMaxQueue = foresight_msg_MAX_QUEUE;
inline constexpr unsigned kMaxChunkValues = foresight_msg_MAX_CHUNK_VALUES;
inline constexpr unsigned kMaxChunks = foresight_msg_MAX_CHUNKS;
inline constexpr unsigned kMaxParams = foresight_msg_MAX_PARAMS;
static_assert(kMaxJoints == foresight::kMaxJoints, "the IDL's MAX_JOINTS is the system's bound (common/joints.hpp)");
}  // namespace msg

/// Per topic type: descriptor(), the default topic name and QoS profile.
template <class T>
struct MessageTraits;  // only the specialisations below exist

/// min_dheader: for an appendable type whose received samples Reader<T>
/// checks before Cyclone builds them, the smallest DHEADER (serialized size
/// of the members) it accepts; 0 = no check. Command needs it: Cyclone DDS
/// 0.10.2 accepts (dds_stream_normalize) a Command whose DHEADER ends before
/// the payload union, then abort()s building the sample at dds_take (it
/// cannot default-initialise an absent union): one such sample from any
/// participant would kill the daemon (found by fuzz/fuzz_dds_samples). In
/// XCDR2, 8-byte members align to 4: protocol_version (2) + 2 padding + five
/// 8-byte members = 44 bytes, then the union's 1-byte discriminator.
#define FORESIGHT_PROTOCOL_MESSAGE(TYPE, TOPIC, QOS, MIN_DHEADER)                            \
  template <>                                                                                \
  struct MessageTraits<foresight_msg_##TYPE> {                                               \
    static const dds_topic_descriptor_t* descriptor() noexcept { return &foresight_msg_##TYPE##_desc; } \
    static constexpr const char* type_name = #TYPE;                                          \
    static constexpr const char* topic = TOPIC;                                              \
    static constexpr std::uint32_t min_dheader = MIN_DHEADER;                                \
    static Qos qos() { return QOS; }                                                         \
  };

FORESIGHT_PROTOCOL_MESSAGE(Command, topics::kCommand, qos::command(), 45)
FORESIGHT_PROTOCOL_MESSAGE(CommandAck, topics::kCommandAck, qos::command_ack(), 0)
FORESIGHT_PROTOCOL_MESSAGE(TrajectoryChunk, topics::kTrajectoryChunk, qos::trajectory_chunk(), 0)
FORESIGHT_PROTOCOL_MESSAGE(TrajectoryStatus, topics::kTrajectoryStatus, qos::trajectory_status(), 0)
FORESIGHT_PROTOCOL_MESSAGE(JointState, topics::kJointState, qos::telemetry(), 0)
FORESIGHT_PROTOCOL_MESSAGE(Wrench, topics::kWrench, qos::telemetry(), 0)
FORESIGHT_PROTOCOL_MESSAGE(ToolState, topics::kToolState, qos::telemetry(), 0)
FORESIGHT_PROTOCOL_MESSAGE(ControllerStatus, topics::kControllerStatus, qos::controller_status(), 0)
FORESIGHT_PROTOCOL_MESSAGE(Heartbeat, topics::kHeartbeat, qos::heartbeat(), 0)
FORESIGHT_PROTOCOL_MESSAGE(Ping, topics::kPing, qos::ping(), 0)
FORESIGHT_PROTOCOL_MESSAGE(Pong, topics::kPong, qos::ping(), 0)

#undef FORESIGHT_PROTOCOL_MESSAGE

template <class T>
concept Message = requires { MessageTraits<T>::descriptor(); };

}  // namespace foresight::protocol
