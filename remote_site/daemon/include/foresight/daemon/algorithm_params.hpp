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

namespace foresight::daemon {

/// "" when `invoke` names an RT algorithm with valid parameters (each in its
/// range, then checked as the controller will check them), else the reason:
/// "unknown algorithm 'x'", "insert: unknown parameter 'q' (expected one of:
/// ...)", "insert: parameter 'depth_m' is not finite", "insert: depth_m 1 out
/// of range [0.001, 0.2] m", or the controller's own message.
std::string parse_algorithm(const protocol::InvokeAlgorithm& invoke, control::AlgorithmParams& out);

/// An algorithm's or a tool step's timeout_s: 0 (its default) up to this.
inline constexpr double kMaxAlgorithmTimeoutS = 600.0;
/// ": timeout_s <v> out of range [0, 600] s (0: the default)", for a refusal.
std::string fmt_timeout(double timeout_s);

}  // namespace foresight::daemon
