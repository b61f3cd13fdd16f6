#pragma once
// A trajectory prepared for the real-time loop: the clamped cubic spline
// through the samples (C2: position, velocity and acceleration continuous at
// every sample; common/trajectory.hpp hermite::, the interpolant validate()
// bounds over every segment), evaluable at any time, so any cycle rate can run
// samples taken at any rate (the ground plans at 100 Hz; the loop runs at 500 Hz).
//
// Stored as cubic Hermite segments: the samples and the spline's velocity at
// each (hermite::spline_velocities, one O(n) tridiagonal solve per joint here,
// at preparation), zero at the first and last sample (the arm starts and ends
// at rest). Before the start the first sample holds, after the end the last one.
//
// Set-up (NOT real-time; allocates, throws std::invalid_argument): the constructor. It
// does not apply the remote's trajectory rules: the daemon runs
// foresight::validate() (common/trajectory.hpp) first; the constructor only
// checks what evaluation needs (>= 2 samples, joints <= kMaxJoints, finite,
// strictly increasing time).
// Real-time (const, noexcept, no allocation): evaluate(), check_start().
// A PreparedTrajectory is immutable after construction, so the supervisor
// may share it with the loop by pointer (MotionCommand::trajectory).

#include <cstddef>
#include <cstdint>
#include <vector>

#include "foresight/common/trajectory.hpp"
#include "foresight/control/rt_types.hpp"

namespace foresight::control {

class PreparedTrajectory {
 public:
  /// Throws std::invalid_argument: "trajectory: N samples (need at least 2)",
  /// "trajectory: N joints (at most 8)", "trajectory: non-finite value at row R",
  /// "trajectory: time not increasing at row R".
  explicit PreparedTrajectory(const Trajectory& trajectory, std::uint64_t trajectory_id = 0);

  std::size_t joints() const noexcept { return joints_; }
  std::size_t samples() const noexcept { return time_s_.size(); }
  double duration_s() const noexcept { return time_s_.back() - time_s_.front(); }
  std::uint64_t id() const noexcept { return id_; }
  /// The first sample's joints (where the arm must be to start).
  const JointArray& start() const noexcept { return start_; }
  const JointArray& end() const noexcept { return end_; }

  /// Position and velocity at t seconds after the first sample. `hint` is the
  /// caller's segment cursor (start it at 0; monotonic t makes every call
  /// O(1)); any value is safe. RT-safe.
  void evaluate(double t_s, std::size_t& hint, JointArray& q, JointArray& dq) const noexcept;

  /// Largest |q_i - start_i|; the joint index in *joint. RT-safe.
  double start_error(const JointArray& q, int* joint = nullptr) const noexcept;

 private:
  std::size_t joints_ = 0;
  std::uint64_t id_ = 0;
  std::vector<double> time_s_;    // samples, relative to the first (first = 0)
  std::vector<JointArray> q_;     // samples
  std::vector<JointArray> v_;     // the spline's velocities at the samples
  JointArray start_{};
  JointArray end_{};
};

}  // namespace foresight::control
