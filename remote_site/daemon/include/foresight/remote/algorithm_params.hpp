#pragma once
// INVOKE_ALGORITHM parameters (name = value pairs from the ground) into the
// controller's fixed-size algorithm parameters. The parameter names are the
// fields of control::GuardedMoveParams / InsertParams / PullOutParams
// (rt_types.hpp; docs/control.md); guarded_move's direction is direction_x,
// direction_y, direction_z and its frame frame_base (0: tool, 1: base).
// Not real-time.

#include <string>

#include "foresight/control/command.hpp"
#include "foresight/control/rt_types.hpp"

namespace foresight::remote {

/// "" when `invoke` names an RT algorithm with valid parameters (checked as
/// the controller will check them), else the reason: "unknown algorithm 'x'",
/// "insert: unknown parameter 'q' (expected one of: ...)", "insert: parameter
/// 'depth_m' is not finite", or the controller's range message.
std::string parse_algorithm(const control::InvokeAlgorithm& invoke, control::AlgorithmParams& out);

}  // namespace foresight::remote
