#pragma once
// The plain command, ack and report types the daemon consumes and produces
// are the protocol's (foresight/protocol/command.hpp, shared with the ground);
// the control code names them in its own namespace.

#include "foresight/protocol/command.hpp"

namespace foresight::control {

using protocol::Abort;
using protocol::Ack;
using protocol::AckState;
using protocol::CameraAction;
using protocol::CameraCommand;
using protocol::Command;
using protocol::CommandKind;
using protocol::ControllerMode;
using protocol::DriveReport;
using protocol::GotoCart;
using protocol::GotoJoint;
using protocol::InvokeAlgorithm;
using protocol::is_terminal;
using protocol::JointReport;
using protocol::kDriveStateUnknown;
using protocol::NamedValue;
using protocol::NoPayload;
using protocol::Payload;
using protocol::Reason;
using protocol::Request;
using protocol::RequestWhat;
using protocol::RunTrajectory;
using protocol::StatusReport;
using protocol::StopCategory;
using protocol::to_string;
using protocol::ToolReport;
using protocol::UploadState;
using protocol::WrenchReport;

}  // namespace foresight::control
