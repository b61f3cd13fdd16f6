#pragma once
// The last word on what the drives are commanded: every powered cycle, each
// joint's command is limited in acceleration and jerk (and, while the limiter
// is catching up, in velocity), as libfranka's rate limiter does before a
// command leaves the controller. What the motion generators produce
// (trajectories, compliance, algorithms) passes unchanged while it stays
// inside the limits; a harsh command (a jump, a corner the interpolant takes
// at 100x the acceleration limit) is followed by the fastest motion inside
// them instead, braking early enough to meet the target without overshoot
// (the catch-up velocity is at most sqrt(2 a |lag|) above the target's own).
//
// A target that itself moves faster than the velocity limit is not limited:
// the command is broken, and the controller's check stops the arm (cat 2, the
// command dropped) as before. docs/control.md, "The rate limiter".
//
// Set-up: configure(). Real-time (noexcept, no allocation): everything else.

#include <cstddef>
#include <cstdint>

#include "foresight/control/rt_types.hpp"

namespace foresight::control {

struct RateLimits {
  JointArray velocity{};      ///< rad/s
  JointArray acceleration{};  ///< rad/s^2
  JointArray jerk{};          ///< rad/s^3
};

class JointRateLimiter {
 public:
  /// Throws std::invalid_argument when a limit of the first `joints` is not
  /// finite and positive or dt is not.
  void configure(std::size_t joints, const RateLimits& limits, double dt);

  /// At rest at q (the drives off, a new hold after power-up).
  void reset(const JointArray& q) noexcept;
  /// Take `command` as sent without limiting it (controlled stops shape their
  /// own deceleration): the state follows it, so limiting resumes smoothly.
  void follow(const JointArray& command) noexcept;
  /// The target of this cycle in, the command to send out (may alias).
  /// Returns the joints limited this cycle (bit j = joint j + 1).
  /// `scale` multiplies the acceleration and jerk limits (>= 1: a looser set,
  /// e.g. for the force loop of compliant modes).
  std::uint32_t apply(const JointArray& target, JointArray& command, double scale = 1.0) noexcept;

  /// The joints whose target of the last apply() moved faster than the
  /// velocity limit (passed on unlimited), and that target speed per joint.
  std::uint32_t too_fast() const noexcept { return too_fast_; }
  const JointArray& target_speed() const noexcept { return target_speed_; }
  const JointArray& velocity() const noexcept { return v_; }
  const JointArray& acceleration() const noexcept { return a_; }
  /// The target minus the command sent, per joint (0 while not limiting).
  const JointArray& lag() const noexcept { return lag_; }
  const RateLimits& limits() const noexcept { return lim_; }

 private:
  std::size_t joints_ = 0;
  double dt_ = 0.002;
  RateLimits lim_{};
  JointArray q_{}, v_{}, a_{}, target_prev_{}, lag_{}, target_speed_{};
  std::uint32_t too_fast_ = 0;
  std::uint32_t engaged_ = 0;  ///< bit j: joint j is catching up with its target
  bool have_state_ = false;
};

}  // namespace foresight::control
