// PreparedTrajectory: the C2 interpolant of common/trajectory.hpp (hermite::,
// the clamped cubic spline validate() bounds), prepared for the loop.
#include "foresight/control/trajectory_executor.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace foresight::control {

PreparedTrajectory::PreparedTrajectory(const Trajectory& trajectory, std::uint64_t trajectory_id)
    : id_(trajectory_id) {
  const int n = trajectory.samples();
  const int nj = trajectory.joints();
  if (n < 2 || trajectory.positions_rad.rows() != n)
    throw std::invalid_argument("trajectory: " + std::to_string(n) + " samples (need at least 2)");
  if (nj < 1 || static_cast<std::size_t>(nj) > kMaxJoints)
    throw std::invalid_argument("trajectory: " + std::to_string(nj) + " joints (at most " +
                                std::to_string(kMaxJoints) + ")");
  joints_ = static_cast<std::size_t>(nj);
  const auto N = static_cast<std::size_t>(n);
  time_s_.resize(N);
  q_.assign(N, JointArray{});
  v_.assign(N, JointArray{});
  for (std::size_t i = 0; i < N; ++i) {
    const double t = trajectory.time_s[i];
    bool finite = std::isfinite(t);
    for (std::size_t j = 0; j < joints_; ++j) {
      const double q = trajectory.positions_rad(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j));
      finite = finite && std::isfinite(q);
      q_[i][j] = q;
    }
    if (!finite) throw std::invalid_argument("trajectory: non-finite value at row " + std::to_string(i + 1));
    time_s_[i] = t - trajectory.time_s[0];
    if (i > 0 && !(time_s_[i] > time_s_[i - 1]))
      throw std::invalid_argument("trajectory: time not increasing at row " + std::to_string(i + 1));
  }
  std::vector<double> column(N);
  for (std::size_t j = 0; j < joints_; ++j) {
    for (std::size_t i = 0; i < N; ++i) column[i] = q_[i][j];
    const std::vector<double> m = hermite::spline_velocities(time_s_.data(), column.data(), N);
    for (std::size_t i = 0; i < N; ++i) v_[i][j] = m[i];
  }
  start_ = q_.front();
  end_ = q_.back();
}

void PreparedTrajectory::evaluate(double t_s, std::size_t& hint, JointArray& q, JointArray& dq) const noexcept {
  const std::size_t n = time_s_.size();
  if (!(t_s > 0.0)) {  // also NaN
    q = q_.front();
    dq = JointArray{};
    hint = 0;
    return;
  }
  if (t_s >= time_s_.back()) {
    q = q_.back();
    dq = JointArray{};
    hint = n - 2;
    return;
  }
  std::size_t i = hint < n - 1 ? hint : 0;
  if (time_s_[i] > t_s) i = 0;
  // Monotone time: usually the same or the next segment; else binary search.
  if (!(t_s < time_s_[i + 1])) {
    if (i + 2 < n && t_s < time_s_[i + 2]) {
      ++i;
    } else {
      std::size_t lo = 0, hi = n - 1;  // time_s_[lo] <= t < time_s_[hi]
      while (hi - lo > 1) {
        const std::size_t mid = (lo + hi) / 2;
        if (time_s_[mid] <= t_s)
          lo = mid;
        else
          hi = mid;
      }
      i = lo;
    }
  }
  hint = i;
  const double h = time_s_[i + 1] - time_s_[i];
  const double s = (t_s - time_s_[i]) / h;
  for (std::size_t j = 0; j < joints_; ++j)
    hermite::evaluate(q_[i][j], q_[i + 1][j], v_[i][j], v_[i + 1][j], h, s, q[j], dq[j]);
  for (std::size_t j = joints_; j < kMaxJoints; ++j) q[j] = dq[j] = 0.0;
}

double PreparedTrajectory::start_error(const JointArray& q, int* joint) const noexcept {
  double worst = 0.0;
  int wj = -1;
  for (std::size_t j = 0; j < joints_; ++j) {
    const double e = std::abs(q[j] - start_[j]);
    if (!(e <= worst)) {  // NaN counts as worst
      worst = std::isnan(e) ? INFINITY : e;
      wj = static_cast<int>(j);
    }
  }
  if (joint != nullptr) *joint = wj;
  return worst;
}

}  // namespace foresight::control
