#include "foresight/common/trajectory.hpp"

#include "foresight/common/number_list.hpp"

#include <openssl/evp.h>

#include <bit>
#include <charconv>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "foresight/common/error.hpp"
#include "foresight/common/atomic_file.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight {

namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

bool parse_double(std::string_view s, double& out) {
  s = trim(s);
  if (s.empty()) return false;
  // strtod accepts nan/inf, which validate() then reports with row and joint.
  std::string tmp(s);
  char* end = nullptr;
  out = std::strtod(tmp.c_str(), &end);
  return end == tmp.c_str() + tmp.size();
}

// Built with append: "q" + std::to_string(j) trips GCC 12's -Wrestrict false positive.
std::string qname(int j) {
  std::string s = "q";
  s.append(std::to_string(j));
  return s;
}

std::string fmt(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

namespace {

/// Parses a trajectory CSV line by line (bounded line length and row count,
/// limits::kMaxTrajectorySamples), so a file is never held whole in memory.
Trajectory parse_trajectory_stream(std::istream& in, const std::string& source) {
  LineReader reader(in, source);
  std::string line;
  int joints = -1;
  std::vector<double> values;
  Trajectory traj;
  while (reader.next(line)) {
    const int line_no = reader.line_no();
    const std::string_view l = trim(line);
    if (l.empty() || l.front() == '#') continue;
    const auto fields = split_commas(l);
    if (joints < 0) {  // header
      if (fields.size() < 2 || trim(fields[0]) != "t")
        throw InputError(source, line_no, "expected the header t,q1,...,qN");
      for (std::size_t j = 1; j < fields.size(); ++j)
        if (trim(fields[j]) != qname(static_cast<int>(j)))
          throw InputError(source, line_no,
                           "header column " + std::to_string(j + 1) + " is '" + std::string(trim(fields[j])) +
                               "', expected '" + qname(static_cast<int>(j)) + "'");
      joints = static_cast<int>(fields.size()) - 1;
      continue;
    }
    if (static_cast<int>(fields.size()) != joints + 1)
      throw InputError(source, line_no,
                       "expected " + std::to_string(joints + 1) + " columns (t,q1..q" + std::to_string(joints) +
                           "), found " + std::to_string(fields.size()));
    if (traj.samples() >= limits::kMaxTrajectorySamples)
      throw InputError(source, line_no,
                       "more than " + std::to_string(limits::kMaxTrajectorySamples) +
                           " samples (the most a trajectory may have)");
    for (std::size_t j = 0; j < fields.size(); ++j) {
      double v = 0.0;
      if (!parse_double(fields[j], v))
        throw InputError(source, line_no,
                         "column " + std::to_string(j + 1) + " ('" + std::string(trim(fields[j])) + "') is not a number");
      if (j == 0)
        traj.time_s.push_back(v);
      else
        values.push_back(v);
    }
  }
  if (joints < 0) throw InputError(source, "empty trajectory file: expected the header t,q1,...,qN");
  if (traj.time_s.empty()) throw InputError(source, "trajectory has no samples");
  traj.positions_rad = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      values.data(), static_cast<Eigen::Index>(traj.time_s.size()), joints);
  return traj;
}

}  // namespace

Trajectory parse_trajectory_csv(const std::string& text, const std::string& source) {
  std::istringstream in(text);
  return parse_trajectory_stream(in, source);
}

Trajectory read_trajectory_csv(const std::string& path) {
  require_input_file(path, "cannot open trajectory file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open trajectory file");
  return parse_trajectory_stream(in, path);
}

std::string to_csv(const Trajectory& traj) {
  std::string out = "t";
  for (int j = 1; j <= traj.joints(); ++j) (out += ',') += qname(j);
  out += '\n';
  char buf[40];
  for (int i = 0; i < traj.samples(); ++i) {
    std::snprintf(buf, sizeof buf, "%.17g", traj.time_s[i]);
    out += buf;
    for (int j = 0; j < traj.joints(); ++j) {
      std::snprintf(buf, sizeof buf, ",%.17g", traj.positions_rad(i, j));
      out += buf;
    }
    out += '\n';
  }
  return out;
}

void write_trajectory_csv(const std::string& path, const Trajectory& traj) { write_file_atomic(path, to_csv(traj)); }

TrajectoryLimits TrajectoryLimits::from_model(const RobotModel& model) {
  TrajectoryLimits l;
  l.joints = model.dof();
  l.joint_limits = model.limits();
  return l;
}

const char* to_string(Violation::Rule rule) {
  switch (rule) {
    case Violation::Rule::JointCount: return "joint_count";
    case Violation::Rule::TooFewSamples: return "too_few_samples";
    case Violation::Rule::TooManySamples: return "too_many_samples";
    case Violation::Rule::Duration: return "duration";
    case Violation::Rule::NonFinite: return "non_finite";
    case Violation::Rule::TimeNotIncreasing: return "time_not_increasing";
    case Violation::Rule::SampleGap: return "sample_gap";
    case Violation::Rule::PositionLimit: return "position_limit";
    case Violation::Rule::VelocityLimit: return "velocity_limit";
    case Violation::Rule::AccelerationLimit: return "acceleration_limit";
  }
  return "unknown";
}

namespace hermite {

std::vector<double> spline_velocities(const double* t, const double* q, std::size_t n) {
  std::vector<double> m(n, 0.0);
  if (n < 3) return m;
  // Unknowns m_1 .. m_{n-2}; row i: lower h_i, diagonal 2 (h_{i-1} + h_i),
  // upper h_{i-1}, right side 3 (h_i d_{i-1} + h_{i-1} d_i) (m_0 = m_{n-1} = 0).
  // Forward sweep: c[i] the eliminated upper coefficient, m[i] the right side.
  std::vector<double> c(n, 0.0);
  for (std::size_t i = 1; i + 1 < n; ++i) {
    const double h0 = t[i] - t[i - 1], h1 = t[i + 1] - t[i];
    const double rhs = 3.0 * (h1 * (q[i] - q[i - 1]) / h0 + h0 * (q[i + 1] - q[i]) / h1);
    const double lower = i > 1 ? h1 : 0.0;
    const double denom = 2.0 * (h0 + h1) - lower * c[i - 1];
    c[i] = h0 / denom;
    m[i] = (rhs - lower * m[i - 1]) / denom;
  }
  for (std::size_t i = n - 2; i > 1; --i) m[i - 1] -= c[i - 1] * m[i];
  return m;
}

Extremes extremes(double p0, double p1, double m0, double m1, double h) noexcept {
  // P(s) = a s^3 + b s^2 + c s + p0 on s in [0, 1]; velocity P'/h, acceleration P''/h^2.
  const double c = h * m0;
  const double b = 3.0 * (p1 - p0) - h * (2.0 * m0 + m1);
  const double a = 2.0 * (p0 - p1) + h * (m0 + m1);
  Extremes e;
  e.q_min = std::min(p0, p1);
  e.q_max = std::max(p0, p1);
  auto at = [&](double s) { return ((a * s + b) * s + c) * s + p0; };
  auto take_root = [&](double s) {
    if (s > 0.0 && s < 1.0) {
      const double q = at(s);
      e.q_min = std::min(e.q_min, q);
      e.q_max = std::max(e.q_max, q);
    }
  };
  const double scale = std::abs(a) + std::abs(b) + std::abs(c);
  if (std::abs(a) <= 1e-12 * scale) {  // P' = 2b s + c
    if (b != 0.0) take_root(-c / (2.0 * b));
  } else {
    const double disc = 4.0 * b * b - 12.0 * a * c;
    if (disc >= 0.0) {
      const double r = std::sqrt(disc);
      take_root((-2.0 * b + r) / (6.0 * a));
      take_root((-2.0 * b - r) / (6.0 * a));
    }
  }
  e.v_abs = std::max(std::abs(m0), std::abs(m1));
  if (std::abs(a) > 1e-12 * scale) {
    const double s = -b / (3.0 * a);  // the vertex of P'
    if (s > 0.0 && s < 1.0) e.v_abs = std::max(e.v_abs, std::abs(c - b * b / (3.0 * a)) / h);
  }
  e.a_abs = std::max(std::abs(acceleration(p0, p1, m0, m1, h, 0.0)), std::abs(acceleration(p0, p1, m0, m1, h, 1.0)));
  return e;
}

}  // namespace hermite

namespace {

/// One validation: the trajectory's shape, then one pass over the rows (the
/// samples' rules), then the interpolant the remote executes. Every
/// violation is counted; only the first max_listed_violations are kept, and
/// their messages are built only then (7e6 violations took minutes).
class Validator {
 public:
  using R = Violation::Rule;

  Validator(const Trajectory& traj, const TrajectoryLimits& lim)
      : traj_(traj), lim_(lim), n_(traj.samples()), dof_(traj.joints()), slack_(1.0 + lim.rate_tolerance) {}

  std::vector<Violation> run(std::size_t* total) {
    if (shape_ok()) {
      rows();
      interpolant();
    }
    std::stable_sort(out_.begin(), out_.end(), [](const Violation& x, const Violation& y) { return x.row < y.row; });
    if (total != nullptr) *total = count_;
    return std::move(out_);
  }

 private:
  template <class Message>
  void add(R rule, int row, int joint, double value, double limit, Message&& message) {
    ++count_;
    if (row >= 1 && joint >= 1 && !flagged_.empty() && !executed_)  // the sample rules' only
      flagged_[static_cast<std::size_t>(row - 1) * static_cast<std::size_t>(dof_) + static_cast<std::size_t>(joint - 1)] = 1;
    if (out_.size() < lim_.max_listed_violations) out_.push_back({rule, row, joint, value, limit, message()});
  }

  /// The counts, the sample count and the duration; false when nothing can
  /// be checked row by row.
  bool shape_ok() {
    if (static_cast<int>(traj_.positions_rad.rows()) != n_)
      add(R::JointCount, -1, -1, static_cast<double>(traj_.positions_rad.rows()), n_, [&] {
        return "position rows (" + std::to_string(traj_.positions_rad.rows()) + ") differ from time samples (" +
               std::to_string(n_) + ")";
      });
    if (dof_ != lim_.joints) {
      add(R::JointCount, -1, -1, dof_, lim_.joints, [&] {
        return "trajectory has " + std::to_string(dof_) + " joints, the robot has " + std::to_string(lim_.joints);
      });
      return false;  // nothing else can be checked joint by joint
    }
    if (count_ > 0) return false;
    if (static_cast<int>(lim_.joint_limits.size()) != dof_)
      throw std::invalid_argument("TrajectoryLimits: joint_limits has " + std::to_string(lim_.joint_limits.size()) +
                                  " entries for " + std::to_string(dof_) + " joints");
    if (n_ < lim_.min_samples)
      add(R::TooFewSamples, -1, -1, n_, lim_.min_samples, [&] {
        return "trajectory has " + std::to_string(n_) + " samples, at least " + std::to_string(lim_.min_samples) +
               " needed";
      });
    if (n_ > lim_.max_samples)
      add(R::TooManySamples, -1, -1, n_, lim_.max_samples, [&] {
        return "trajectory has " + std::to_string(n_) + " samples, at most " + std::to_string(lim_.max_samples) +
               " allowed";
      });
    if (n_ > 0 && std::isfinite(traj_.duration_s()) && traj_.duration_s() > lim_.max_duration_s)
      add(R::Duration, -1, -1, traj_.duration_s(), lim_.max_duration_s, [&] {
        return "duration " + fmt(traj_.duration_s()) + " s exceeds " + fmt(lim_.max_duration_s) + " s";
      });
    return true;
  }

  /// Interval (i-1, i): both rows finite and time strictly increasing.
  bool interval_ok(int i) const {
    return i > 0 && row_ok_[i] && row_ok_[i - 1] && traj_.time_s[i] > traj_.time_s[i - 1];
  }

  /// One pass over the rows: the row's own checks, then the rates of the
  /// interval ending at it (only across rows that are finite and strictly
  /// increasing in time).
  void rows() {
    // (row, joint) pairs a sample rule flagged: the interpolant check leaves them be.
    flagged_.assign(static_cast<std::size_t>(std::max(n_, 0)) * static_cast<std::size_t>(dof_), 0);
    row_ok_.assign(n_, true);  // finite t and q
    for (int i = 0; i < n_; ++i) {
      row_values(i);
      row_timing(i);
      if (interval_ok(i)) row_rates(i);
    }
  }

  void row_values(int i) {
    auto row = [i] { return "row " + std::to_string(i + 1); };  // built only for a violation
    if (!std::isfinite(traj_.time_s[i])) {
      add(R::NonFinite, i + 1, 0, traj_.time_s[i], 0.0, [&] { return row() + ": t is not finite"; });
      row_ok_[i] = false;
    }
    for (int j = 0; j < dof_; ++j) {
      const double q = traj_.positions_rad(i, j);
      auto where = [&] { return row() + ", joint " + qname(j + 1); };
      if (!std::isfinite(q)) {
        add(R::NonFinite, i + 1, j + 1, q, 0.0, [&] { return where() + ": position is not finite"; });
        row_ok_[i] = false;
        continue;
      }
      const JointLimits& jl = lim_.joint_limits[j];
      if (q < jl.lower_rad || q > jl.upper_rad)
        add(R::PositionLimit, i + 1, j + 1, q, q < jl.lower_rad ? jl.lower_rad : jl.upper_rad, [&] {
          return where() + ": position " + fmt(q) + " rad outside [" + fmt(jl.lower_rad) + ", " + fmt(jl.upper_rad) +
                 "] rad";
        });
    }
  }

  void row_timing(int i) {
    if (!(i > 0 && row_ok_[i] && row_ok_[i - 1])) return;
    const double dt = traj_.time_s[i] - traj_.time_s[i - 1];
    if (!(dt > 0.0))
      add(R::TimeNotIncreasing, i + 1, 0, traj_.time_s[i], traj_.time_s[i - 1], [&] {
        return "row " + std::to_string(i + 1) + ": t = " + fmt(traj_.time_s[i]) + " s does not increase (previous " +
               fmt(traj_.time_s[i - 1]) + " s)";
      });
    else if (dt > lim_.max_sample_interval_s)
      add(R::SampleGap, i + 1, 0, dt, lim_.max_sample_interval_s, [&] {
        return "row " + std::to_string(i + 1) + ": " + fmt(dt) + " s since the previous sample exceeds " +
               fmt(lim_.max_sample_interval_s) + " s";
      });
  }

  void row_rates(int i) {
    const double dt = traj_.time_s[i] - traj_.time_s[i - 1];
    for (int j = 0; j < dof_; ++j) {
      const JointLimits& jl = lim_.joint_limits[j];
      const double v = (traj_.positions_rad(i, j) - traj_.positions_rad(i - 1, j)) / dt;
      if (std::abs(v) > jl.velocity_rad_s * slack_)
        add(R::VelocityLimit, i + 1, j + 1, v, jl.velocity_rad_s, [&] {
          return "row " + std::to_string(i + 1) + ", joint " + qname(j + 1) + ": velocity " + fmt(v) +
                 " rad/s exceeds limit " + fmt(jl.velocity_rad_s) + " rad/s";
        });
      if (i >= 2 && interval_ok(i - 1)) {
        const double dt0 = traj_.time_s[i - 1] - traj_.time_s[i - 2];
        const double v0 = (traj_.positions_rad(i - 1, j) - traj_.positions_rad(i - 2, j)) / dt0;
        const double a = (v - v0) / (0.5 * (dt + dt0));
        if (std::abs(a) > jl.acceleration_rad_s2 * slack_)
          add(R::AccelerationLimit, i, j + 1, a, jl.acceleration_rad_s2, [&] {
            return "row " + std::to_string(i) + ", joint " + qname(j + 1) + ": acceleration " + fmt(a) +
                   " rad/s^2 exceeds limit " + fmt(jl.acceleration_rad_s2) + " rad/s^2";
          });
      }
    }
  }

  /// Rows around a segment whose flags it shares: the spline spreads a
  /// sample's error over its neighbours, decaying by 2 - sqrt(3) = 0.27 a
  /// sample (to 3e-5 in 8); beyond, a violation has a cause of its own.
  static constexpr int kSpread = 8;

  bool near_flagged(int i, int j) const {
    for (int r = std::max(0, i - kSpread); r <= std::min(n_ - 1, i + 1 + kSpread); ++r)
      if (flagged_[static_cast<std::size_t>(r) * static_cast<std::size_t>(dof_) + static_cast<std::size_t>(j)]) return true;
    return false;
  }

  /// What the remote executes: the interpolant over every segment (i, i+1),
  /// from rest at the first sample to rest at the last: its position,
  /// velocity and acceleration extremes (the acceleration is linear in a
  /// segment: its extremes are at the samples, where it jumps from and to 0
  /// at the first and the last). Only when every row is finite and time
  /// increases (else the trajectory is refused already and there is no
  /// interpolant). A joint a sample rule flagged near the segment (kSpread
  /// rows) is not reported twice: the trajectory is refused already.
  void interpolant() {
    for (int i = 0; i < n_; ++i)
      if (!row_ok_[i] || (i > 0 && !interval_ok(i))) return;
    executed_ = true;
    Eigen::MatrixXd m(n_, dof_);  // the spline's velocity at every sample
    for (int j = 0; j < dof_; ++j) {
      const std::vector<double> v =
          hermite::spline_velocities(traj_.time_s.data(), traj_.positions_rad.col(j).data(), static_cast<std::size_t>(n_));
      m.col(j) = Eigen::Map<const Eigen::VectorXd>(v.data(), n_);
    }
    for (int i = 0; i + 1 < n_; ++i) {
      const double h = traj_.time_s[i + 1] - traj_.time_s[i];
      for (int j = 0; j < dof_; ++j) {
        if (near_flagged(i, j)) continue;
        const JointLimits& jl = lim_.joint_limits[j];
        const hermite::Extremes e =
            hermite::extremes(traj_.positions_rad(i, j), traj_.positions_rad(i + 1, j), m(i, j), m(i + 1, j), h);
        auto where = [&] {
          return "between rows " + std::to_string(i + 1) + " and " + std::to_string(i + 2) + ", joint " + qname(j + 1);
        };
        if (e.q_min < jl.lower_rad || e.q_max > jl.upper_rad) {
          const double q = e.q_min < jl.lower_rad ? e.q_min : e.q_max;
          add(R::PositionLimit, i + 2, j + 1, q, q < jl.lower_rad ? jl.lower_rad : jl.upper_rad, [&] {
            return where() + ": the executed position reaches " + fmt(q) + " rad, outside [" + fmt(jl.lower_rad) +
                   ", " + fmt(jl.upper_rad) + "] rad";
          });
        }
        if (e.v_abs > jl.velocity_rad_s * slack_)
          add(R::VelocityLimit, i + 2, j + 1, e.v_abs, jl.velocity_rad_s, [&] {
            return where() + ": the executed velocity reaches " + fmt(e.v_abs) + " rad/s, over the limit " +
                   fmt(jl.velocity_rad_s) + " rad/s";
          });
        if (e.a_abs > jl.acceleration_rad_s2 * slack_)
          add(R::AccelerationLimit, i + 2, j + 1, e.a_abs, jl.acceleration_rad_s2, [&] {
            return where() + ": the executed acceleration reaches " + fmt(e.a_abs) + " rad/s^2, over the limit " +
                   fmt(jl.acceleration_rad_s2) + " rad/s^2";
          });
      }
    }
  }

  const Trajectory& traj_;
  const TrajectoryLimits& lim_;
  const int n_, dof_;
  const double slack_;
  std::vector<Violation> out_;
  std::size_t count_ = 0;
  std::vector<char> flagged_;
  bool executed_ = false;  ///< checking the interpolant (its violations flag nothing)
  std::vector<bool> row_ok_;
};

}  // namespace

std::vector<Violation> validate(const Trajectory& traj, const TrajectoryLimits& lim, std::size_t* total) {
  return Validator(traj, lim).run(total);
}

TrajectoryHash trajectory_hash(const Trajectory& traj) {
  static_assert(std::endian::native == std::endian::little, "canonical encoding assumes a little-endian host");
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  if (ctx == nullptr || EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) != 1) {
    EVP_MD_CTX_free(ctx);
    throw std::runtime_error("trajectory_hash: cannot initialise SHA-256");
  }
  auto feed = [&](const void* p, std::size_t n) { EVP_DigestUpdate(ctx, p, n); };
  feed("FSTRAJ1", 7);
  const std::uint32_t joints = static_cast<std::uint32_t>(traj.joints());
  const std::uint32_t samples = static_cast<std::uint32_t>(traj.samples());
  feed(&joints, 4);
  feed(&samples, 4);
  for (int i = 0; i < traj.samples(); ++i) {
    feed(&traj.time_s[i], 8);
    for (int j = 0; j < traj.joints(); ++j) {
      const double q = traj.positions_rad(i, j);
      feed(&q, 8);
    }
  }
  TrajectoryHash h{};
  unsigned int len = 0;
  EVP_DigestFinal_ex(ctx, h.data(), &len);
  EVP_MD_CTX_free(ctx);
  return h;
}

std::string to_hex(const TrajectoryHash& hash) {
  static const char* digits = "0123456789abcdef";
  std::string s;
  s.reserve(64);
  for (std::uint8_t b : hash) {
    s += digits[b >> 4];
    s += digits[b & 15];
  }
  return s;
}

}  // namespace foresight
