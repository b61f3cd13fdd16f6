#pragma once
// A joint-space trajectory and the rules a trajectory must pass before the
// remote runs it (docs/architecture.md, "Rules"). Both sides use the same
// code: the ground checks before sending, the remote checks again on arrival
// (the remote never trusts the ground). Nothing here is for the control loop:
// validation and I/O allocate.
//
// CSV form: a header `t,q1,...,qN`, then one sample a row: t in seconds
// (strictly increasing), joint angles in radians.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "foresight/common/input_limits.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight {

/// The largest start tolerance either side accepts, rad: a trajectory runs only
/// when its first sample is this close to the arm on every joint (the remote's
/// configured default is at most this; a command may ask for less). The
/// residual offset is faded out, so a larger one would be a jump: plan an
/// approach segment instead (a GOTO_JOINT to the first sample).
inline constexpr double kMaxStartToleranceRad = 0.02;

/// The interpolant the remote runs between samples, one code for both sides
/// (validate() bounds it; the control loop's PreparedTrajectory evaluates it):
/// the clamped cubic spline through the samples, C2 (position, velocity and
/// acceleration continuous at every sample), with zero velocity at the first
/// and the last sample: the arm is at rest before and after. Written as cubic
/// Hermite segments whose tangents are the spline's velocities at the samples
/// (spline_velocities, one tridiagonal solve when the trajectory is validated
/// or prepared); evaluate() and acceleration() are real-time safe.
namespace hermite {
/// The velocities at the samples (t strictly increasing, q, both n >= 2
/// long) of the clamped cubic spline: m[0] = m[n-1] = 0 and, at every
/// interior sample, the acceleration continuous:
///   h_i m_{i-1} + 2 (h_{i-1} + h_i) m_i + h_{i-1} m_{i+1} = 3 (h_i d_{i-1} + h_{i-1} d_i),
///   h_i = t_{i+1} - t_i, d_i = (q_{i+1} - q_i) / h_i.
/// O(n) (Thomas algorithm; the system is strictly diagonally dominant).
/// Allocates: never in the control cycle.
std::vector<double> spline_velocities(const double* t, const double* q, std::size_t n);
/// Position and velocity at s in [0, 1] of the segment of h seconds from
/// (p0, tangent m0) to (p1, m1).
inline void evaluate(double p0, double p1, double m0, double m1, double h, double s, double& q, double& dq) noexcept {
  const double s2 = s * s, s3 = s2 * s;
  q = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * h * m1;
  dq = ((6 * s2 - 6 * s) * p0 + (-6 * s2 + 6 * s) * p1) / h + (3 * s2 - 4 * s + 1) * m0 + (3 * s2 - 2 * s) * m1;
}
/// Acceleration at s in [0, 1] of the same segment (linear in s).
inline double acceleration(double p0, double p1, double m0, double m1, double h, double s) noexcept {
  return ((12 * s - 6) * (p0 - p1) / h + (6 * s - 4) * m0 + (6 * s - 2) * m1) / h;
}
/// The extremes of a segment over all of it (not only at samples): what the
/// loop commands at any cycle rate stays within them.
struct Extremes {
  double q_min = 0.0, q_max = 0.0;  ///< rad
  double v_abs = 0.0;               ///< max |velocity|, rad/s
  double a_abs = 0.0;               ///< max |acceleration|, rad/s^2 (at an end: it is linear)
};
Extremes extremes(double p0, double p1, double m0, double m1, double h) noexcept;
}  // namespace hermite

struct Trajectory {
  std::vector<double> time_s;    ///< one per sample, strictly increasing
  Eigen::MatrixXd positions_rad; ///< samples x joints

  int samples() const { return static_cast<int>(time_s.size()); }
  int joints() const { return static_cast<int>(positions_rad.cols()); }
  double duration_s() const { return time_s.empty() ? 0.0 : time_s.back() - time_s.front(); }
};

/// Parse CSV text; `source` names the file in errors. Throws InputError with
/// the line number: missing/invalid header, wrong column count, a field that
/// is not a number (non-finite numbers such as "nan" parse, and are left for
/// validate() to report with row and joint), no samples, more than
/// limits::kMaxTrajectorySamples samples, a line longer than kMaxLineBytes.
Trajectory parse_trajectory_csv(const std::string& text, const std::string& source);
/// Read a CSV file, streamed line by line (memory bounded by the samples
/// kept). Throws InputError (file cannot be opened, or as above).
Trajectory read_trajectory_csv(const std::string& path);
/// CSV text with full double precision (round-trips exactly).
std::string to_csv(const Trajectory& trajectory);
/// Write CSV atomically (write_file_atomic: the old file survives a failed write).
void write_trajectory_csv(const std::string& path, const Trajectory& trajectory);

/// What a trajectory must respect.
struct TrajectoryLimits {
  int joints = 0;
  std::vector<JointLimits> joint_limits;  ///< one per joint
  int min_samples = 2;
  int max_samples = 200000;               ///< 2000 s at 100 Hz
  double max_duration_s = 1800.0;
  double max_sample_interval_s = 1.0;     ///< no long gaps between samples
  /// Relative slack on velocity/acceleration limits for finite differencing.
  double rate_tolerance = 1e-9;
  /// validate() keeps the first this many violations (counting the rest).
  std::size_t max_listed_violations = limits::kMaxListedViolations;

  /// Joint count and limits from the URDF model.
  static TrajectoryLimits from_model(const RobotModel& model);
};

struct Violation {
  enum class Rule {
    JointCount,          ///< trajectory has the wrong number of joints
    TooFewSamples,
    TooManySamples,
    Duration,
    NonFinite,           ///< NaN or infinity in t or q
    TimeNotIncreasing,
    SampleGap,           ///< interval longer than max_sample_interval_s
    PositionLimit,
    VelocityLimit,
    AccelerationLimit,
  };
  Rule rule;
  int row = -1;     ///< 1-based sample (data row) number; -1 for whole-trajectory rules
  int joint = -1;   ///< 1-based joint number; -1 when not about one joint (0 = the time column)
  double value = 0.0;
  double limit = 0.0;
  std::string message;  ///< readable, names the row, joint, value and limit
};

const char* to_string(Violation::Rule rule);

/// The violations, in row order (an empty result means the trajectory
/// passes): the first limits.max_listed_violations of them; `total`, when
/// given, receives how many there are in all (say "and N more"). Linear in
/// the samples, whatever the number of violations.
/// Velocities are finite differences between consecutive samples (reported at
/// the later row); accelerations are differences of consecutive velocities
/// over the mean interval (reported at the middle row). Rate rules are
/// skipped for rows whose times or values are non-finite or not increasing.
/// Then what the remote will execute, when every row is finite and time
/// increases: the interpolant (hermite::, the clamped spline, from rest before
/// the first sample to rest after the last) between every two samples, its
/// position, velocity and acceleration extremes over the whole segment against
/// the same limits ("between rows R and R+1, joint qJ: the executed velocity
/// reaches ..."; reported at the later row, PositionLimit, VelocityLimit or
/// AccelerationLimit), for the joints and rows the sample rules left
/// unflagged. The acceleration is bounded at the URDF (planning) limit, so
/// the remote's rate limiter (1.5x) never acts on a validated trajectory.
std::vector<Violation> validate(const Trajectory& trajectory, const TrajectoryLimits& limits,
                                std::size_t* total = nullptr);

using TrajectoryHash = std::array<std::uint8_t, 32>;

/// SHA-256 over a canonical little-endian encoding: "FSTRAJ1", joints
/// (uint32), samples (uint32), then per sample t, q1..qN as IEEE-754 doubles.
/// Both sides compute it; the ground sends it with an upload and the remote
/// refuses a trajectory whose content does not match.
TrajectoryHash trajectory_hash(const Trajectory& trajectory);
std::string to_hex(const TrajectoryHash& hash);

}  // namespace foresight
