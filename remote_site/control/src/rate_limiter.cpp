// JointRateLimiter: acceleration and jerk limits on the command, every cycle.
#include "foresight/control/rate_limiter.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace foresight::control {

namespace {
bool finite_pos(double v) { return std::isfinite(v) && v > 0.0; }
double clamp_abs(double v, double limit) { return std::clamp(v, -limit, limit); }
constexpr double kCaughtUpRad = 1e-7;
}  // namespace

void JointRateLimiter::configure(std::size_t joints, const RateLimits& limits, double dt) {
  if (joints > kMaxJoints) throw std::invalid_argument("rate limiter: " + std::to_string(joints) + " joints");
  if (!finite_pos(dt)) throw std::invalid_argument("rate limiter: the cycle time must be > 0");
  for (std::size_t j = 0; j < joints; ++j) {
    const std::string joint = "rate limiter: joint " + std::to_string(j + 1);
    if (!finite_pos(limits.velocity[j])) throw std::invalid_argument(joint + ": velocity limit must be > 0");
    if (!finite_pos(limits.acceleration[j])) throw std::invalid_argument(joint + ": acceleration limit must be > 0");
    if (!finite_pos(limits.jerk[j])) throw std::invalid_argument(joint + ": jerk limit must be > 0");
  }
  joints_ = joints;
  lim_ = limits;
  dt_ = dt;
  have_state_ = false;
}

void JointRateLimiter::reset(const JointArray& q) noexcept {
  q_ = q;
  target_prev_ = q;
  v_ = JointArray{};
  a_ = JointArray{};
  lag_ = JointArray{};
  engaged_ = 0;
  have_state_ = true;
}

void JointRateLimiter::follow(const JointArray& command) noexcept {
  if (!have_state_) {
    reset(command);
    return;
  }
  for (std::size_t j = 0; j < joints_; ++j) {
    if (!std::isfinite(command[j])) continue;
    const double v = (command[j] - q_[j]) / dt_;
    a_[j] = (v - v_[j]) / dt_;
    v_[j] = v;
    q_[j] = command[j];
    target_prev_[j] = command[j];
    lag_[j] = 0.0;
  }
  engaged_ = 0;
}

std::uint32_t JointRateLimiter::apply(const JointArray& target, JointArray& command, double scale) noexcept {
  if (!have_state_) reset(target);
  constexpr double kSlack = 1.0 + 1e-9;
  std::uint32_t limited = 0;
  too_fast_ = 0;
  for (std::size_t j = 0; j < joints_; ++j) {
    const double t = target[j];
    if (!std::isfinite(t)) {  // the controller's safety check refuses it; the state stays
      command[j] = t;
      continue;
    }
    const double V = lim_.velocity[j], A = lim_.acceleration[j] * scale, J = lim_.jerk[j] * scale;
    const std::uint32_t bit = std::uint32_t{1} << j;
    const double v_des = (t - q_[j]) / dt_;
    const double a_des = (v_des - v_[j]) / dt_;
    const double j_des = (a_des - a_[j]) / dt_;
    target_speed_[j] = std::abs((t - target_prev_[j]) / dt_);
    if (target_speed_[j] > V * kSlack) {
      // The target itself faster than the limit: a broken command, passed on
      // as it is (too_fast()) for the controller to stop the arm and drop it
      // (the state stays at what was sent).
      too_fast_ |= bit;
      command[j] = t;
      continue;
    }
    const bool feasible = std::abs(a_des) <= A * kSlack && std::abs(j_des) <= J * kSlack;
    if ((engaged_ & bit) == 0 && feasible) {  // inside the limits: as is
      q_[j] = t;
      a_[j] = a_des;
      v_[j] = v_des;
      target_prev_[j] = t;
      lag_[j] = 0.0;
      command[j] = t;
      continue;
    }
    limited |= bit;
    // The target's own velocity, and the gap that moving at it would leave.
    const double vt = clamp_abs((t - target_prev_[j]) / dt_, V);
    const double gap = (t - q_[j]) - vt * dt_;
    // Closing speed from which a deceleration at A stops on the gap: the
    // distance run while the acceleration turns round at the jerk limit
    // (t_r = (|a| + A) / J), the discrete steps' half cycle, then the ramp:
    // w (t_r + dt / 2) + w^2 / 2A = |gap|.
    const double c = (std::abs(a_[j]) + A) / J + 0.5 * dt_;
    const double w = std::min(std::abs(gap) / dt_, A * (std::sqrt(c * c + 2.0 * std::abs(gap) / A) - c));
    const double v_goal = clamp_abs(vt + std::copysign(w, gap), V);
    double a = (v_goal - v_[j]) / dt_;
    a = std::clamp(a, a_[j] - J * dt_, a_[j] + J * dt_);
    a = clamp_abs(a, A);
    const double v = clamp_abs(v_[j] + a * dt_, V);
    const double q = q_[j] + v * dt_;
    a_[j] = (v - v_[j]) / dt_;
    v_[j] = v;
    q_[j] = q;
    target_prev_[j] = t;
    lag_[j] = t - q;
    // Caught up (within 0.1 urad, moving with it): on the target from the next cycle.
    if (std::abs(lag_[j]) <= kCaughtUpRad && std::abs(v - vt) <= A * dt_)
      engaged_ &= ~bit;
    else
      engaged_ |= bit;
    command[j] = q;
  }
  return limited;
}

}  // namespace foresight::control
