#include "foresight/common/plan.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "foresight/common/input_limits.hpp"
#include "foresight/common/kinematics.hpp"

namespace foresight {

namespace {

constexpr double kPeakVel = 1.875;                 // max ds/dtau of the quintic
const double kPeakAcc = 10.0 / std::sqrt(3.0);     // max |d2s/dtau2|

std::string mm_deg(double m, double rad) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.2f mm, %.3f deg", m * 1e3, rad * 180.0 / M_PI);
  return buf;
}

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

/// Samples per segment for a duration: at least 2, duration rounded up to the
/// sample period. InputError naming the goal and the options behind it when
/// the segment is longer than a trajectory may be (a tiny limit fraction or
/// tool speed; the count would overflow an int).
int sample_count(double duration_s, double rate_hz, const std::string& goal, const char* options) {
  const TrajectoryLimits longest;
  const std::optional<int> n = limits::sample_count(duration_s - 1e-9 / rate_hz, rate_hz);
  if (!(duration_s <= longest.max_duration_s) || !n || *n > limits::kMaxTrajectorySamples)
    throw InputError("goal '" + goal + "': the move would last " + num(duration_s) + " s, longer than a trajectory may (" +
                     num(longest.max_duration_s) + " s): " + options + " too small");
  return std::max(2, *n);
}

/// InputError unless lo < v <= hi (or lo <= v when lo_inclusive).
void check_option(double v, double lo, double hi, bool lo_inclusive, const char* name, const char* unit) {
  if ((lo_inclusive ? v >= lo : v > lo) && v <= hi) return;
  const std::string u = *unit != '\0' ? std::string(" ") + unit : std::string();
  throw InputError(std::string("plan option ") + name + " = " + num(v) + u + " is not in " +
                   (lo_inclusive ? "[" : "(") + num(lo) + ", " + num(hi) + "]" + u);
}

/// Appends samples k = 1..n (k/n of the segment) produced by q_at(tau).
template <typename F>
void append(Trajectory& traj, std::vector<Eigen::VectorXd>& rows, double t0, int n, double rate_hz, F q_at) {
  if (traj.samples() + static_cast<long long>(n) > limits::kMaxTrajectorySamples)
    throw InputError("the plan would have more than " + std::to_string(limits::kMaxTrajectorySamples) +
                     " samples (the most a trajectory may have): fewer goals, a lower rate_hz or a shorter dwell_s");
  for (int k = 1; k <= n; ++k) {
    traj.time_s.push_back(t0 + k / rate_hz);
    rows.push_back(q_at(static_cast<double>(k) / n));
  }
}

/// Largest |qdot| / limit over consecutive rows [first-1, last].
double peak_velocity_fraction(const std::vector<Eigen::VectorXd>& rows, std::size_t first, double rate_hz,
                              const std::vector<JointLimits>& lim) {
  double worst = 0.0;
  for (std::size_t i = std::max<std::size_t>(first, 1); i < rows.size(); ++i)
    for (Eigen::Index j = 0; j < rows[i].size(); ++j)
      worst = std::max(worst, std::abs(rows[i][j] - rows[i - 1][j]) * rate_hz / lim[j].velocity_rad_s);
  return worst;
}

}  // namespace

const char* to_string(SegmentKind kind) { return kind == SegmentKind::Joint ? "joint" : "linear"; }

double min_jerk(double tau) {
  tau = std::clamp(tau, 0.0, 1.0);
  return tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau));
}

Plan plan_motion(const RobotModel& model, const Eigen::VectorXd& q_start, const std::vector<Goal>& goals,
                 const PlanOptions& o) {
  // Options are input: each in its physical range (InputError, the CLI exits 2).
  const double longest_s = TrajectoryLimits{}.max_duration_s;
  check_option(o.rate_hz, 0.0, 1000.0, false, "rate_hz", "Hz");
  check_option(o.limit_fraction, 0.0, 1.0, false, "limit_fraction", "");
  check_option(o.tool_speed_m_s, 0.0, 10.0, false, "tool_speed_m_s", "m/s");
  check_option(o.tool_accel_m_s2, 0.0, 100.0, false, "tool_accel_m_s2", "m/s^2");
  check_option(o.tool_rate_rad_s, 0.0, 10.0, false, "tool_rate_rad_s", "rad/s");
  check_option(o.dwell_s, 0.0, longest_s, true, "dwell_s", "s");
  check_option(o.min_segment_s, 0.0, longest_s, false, "min_segment_s", "s");
  if (q_start.size() != model.dof())
    throw PlanError("start joints: " + std::to_string(q_start.size()) + " values, the arm has " +
                    std::to_string(model.dof()));
  const auto& lim = model.limits();
  for (int j = 0; j < model.dof(); ++j)
    if (!(q_start[j] >= lim[j].lower_rad - 1e-9 && q_start[j] <= lim[j].upper_rad + 1e-9))
      throw PlanError("start joints: " + model.joint_names()[j] + " is outside its limits");
  if (goals.empty()) throw PlanError("no goals to plan to");

  KinematicsWorkspace ws(model);
  IkOptions ik;  // goals: seeded from the current joints, with restarts
  ik.position_tolerance_m = o.position_tolerance_m;
  ik.rotation_tolerance_rad = o.rotation_tolerance_rad;
  IkOptions ik_line = ik;  // along a line: no restarts, stay on the arm's configuration branch
  ik_line.max_restarts = 0;
  // Converged far below the tolerance asked of the goals: what is left of the
  // IK residual jitters from sample to sample, and the spline the remote runs
  // through the samples turns 1e-5 m of jitter into 2.5 rad/s^2 of joint
  // acceleration (joint 1 of the hole_entrance line, against its 2 rad/s^2).
  ik_line.position_tolerance_m = std::min(o.position_tolerance_m, 1e-9);
  ik_line.rotation_tolerance_rad = std::min(o.rotation_tolerance_rad, 1e-9);
  Plan plan;
  std::vector<Eigen::VectorXd> rows{q_start};
  plan.trajectory.time_s.push_back(0.0);
  Eigen::VectorXd q = q_start;
  double t = 0.0;

  for (const Goal& g : goals) {
    PlannedSegment seg;
    seg.goal = g.name;
    seg.kind = g.kind;
    seg.start_s = t;
    const std::size_t first_row = rows.size();
    if (g.kind == SegmentKind::Joint) {
      Eigen::VectorXd q_goal;
      if (g.is_pose) {
        const IkResult r = inverse_kinematics(model, ws, g.base_T_tip, q, ik);
        if (!r.success)
          throw PlanError("goal '" + g.name + "': inverse kinematics did not reach it (residual " +
                          mm_deg(r.position_error_m, r.rotation_error_rad) + ")");
        q_goal = r.q;
      } else {
        if (g.q.size() != model.dof())
          throw PlanError("goal '" + g.name + "': " + std::to_string(g.q.size()) + " joint values, the arm has " +
                          std::to_string(model.dof()));
        for (int j = 0; j < model.dof(); ++j)
          if (!(g.q[j] >= lim[j].lower_rad - 1e-9 && g.q[j] <= lim[j].upper_rad + 1e-9))
            throw PlanError("goal '" + g.name + "': " + model.joint_names()[j] + " is outside its limits");
        q_goal = g.q;
      }
      const Eigen::VectorXd dq = q_goal - q;
      double T = o.min_segment_s;
      for (int j = 0; j < model.dof(); ++j) {
        const double d = std::abs(dq[j]);
        // The acceleration with room for what the executed spline adds to
        // the sampled quintic's peak (3 h^2 / T^2 of it, h the sample period):
        // T^2 = T_a^2 + 4 h^2 keeps it under the limit.
        T = std::max({T, kPeakVel * d / (o.limit_fraction * lim[j].velocity_rad_s),
                      std::sqrt(kPeakAcc * d / (o.limit_fraction * lim[j].acceleration_rad_s2) +
                                4.0 / (o.rate_hz * o.rate_hz))});
      }
      const int n = sample_count(T, o.rate_hz, g.name, "limit_fraction");
      const Eigen::VectorXd q0 = q;
      append(plan.trajectory, rows, t, n, o.rate_hz, [&](double tau) -> Eigen::VectorXd {
        return tau >= 1.0 ? q_goal : Eigen::VectorXd(q0 + dq * min_jerk(tau));  // the goal exactly
      });
      seg.duration_s = n / o.rate_hz;
      q = q_goal;
    } else {
      if (!g.is_pose) throw PlanError("goal '" + g.name + "': a linear move needs a tool pose, not joint angles");
      const Pose A = forward_kinematics(model, ws, q);
      const Pose& B = g.base_T_tip;
      const Eigen::Vector3d dp = B.translation() - A.translation();
      const Eigen::AngleAxisd rot(A.linear().transpose() * B.linear());
      const double L = dp.norm(), theta = std::abs(rot.angle());
      double T = std::max({o.min_segment_s, kPeakVel * L / o.tool_speed_m_s, std::sqrt(kPeakAcc * L / o.tool_accel_m_s2),
                           kPeakVel * theta / o.tool_rate_rad_s});
      std::vector<Eigen::VectorXd> path;
      for (int attempt = 0;; ++attempt) {
        const int n = sample_count(T, o.rate_hz, g.name, "tool_speed_m_s / tool_accel_m_s2 / tool_rate_rad_s");
        path.clear();
        Eigen::VectorXd qk = q;
        for (int k = 1; k <= n; ++k) {
          const double s = min_jerk(static_cast<double>(k) / n);
          Pose P = Pose::Identity();
          P.translation() = A.translation() + s * dp;
          P.linear() = A.linear() * Eigen::AngleAxisd(s * rot.angle(), rot.axis()).toRotationMatrix();
          const IkResult r = inverse_kinematics(model, ws, P, qk, ik_line);
          if (!r.success) {
            char where[64];
            std::snprintf(where, sizeof where, "%.0f%%", 100.0 * k / n);
            throw PlanError("goal '" + g.name + "': the straight line leaves the arm's reach at " + where +
                            " of the move (IK residual " + mm_deg(r.position_error_m, r.rotation_error_rad) + ")");
          }
          if ((r.q - qk).cwiseAbs().maxCoeff() > o.max_joint_step_rad)
            throw PlanError("goal '" + g.name + "': the straight line needs a joint jump of " +
                            std::to_string((r.q - qk).cwiseAbs().maxCoeff()) +
                            " rad between samples (near a singularity or a joint limit)");
          qk = r.q;
          path.push_back(qk);
        }
        // Joint velocity and acceleration along the sampled path against the
        // limit fraction, and what the remote executes (the interpolant
        // through the path, from rest to rest) against the limits themselves
        // (the spline amplifies the IK's sample-to-sample noise up to 3x, more
        // than the fraction's margin on a line near the limits).
        double worst_v = 0.0, worst_a = 0.0;
        std::vector<double> times(static_cast<std::size_t>(n) + 1), column(times.size());
        for (std::size_t k = 0; k < times.size(); ++k) times[k] = static_cast<double>(k) / o.rate_hz;
        for (int j = 0; j < model.dof(); ++j) {
          const JointLimits& l = lim[static_cast<std::size_t>(j)];
          column[0] = q[j];
          for (int k = 0; k < n; ++k) column[static_cast<std::size_t>(k) + 1] = path[static_cast<std::size_t>(k)][j];
          const std::vector<double> m = hermite::spline_velocities(times.data(), column.data(), column.size());
          double v_prev = 0.0;
          for (std::size_t k = 0; k + 1 < column.size(); ++k) {
            const double v = (column[k + 1] - column[k]) * o.rate_hz;
            const hermite::Extremes e = hermite::extremes(column[k], column[k + 1], m[k], m[k + 1], 1.0 / o.rate_hz);
            worst_v = std::max({worst_v, std::abs(v) / (o.limit_fraction * l.velocity_rad_s), e.v_abs / l.velocity_rad_s});
            worst_a = std::max({worst_a, std::abs(v - v_prev) * o.rate_hz / (o.limit_fraction * l.acceleration_rad_s2),
                                e.a_abs / l.acceleration_rad_s2});
            v_prev = v;
          }
          worst_a = std::max(worst_a, std::abs(v_prev) * o.rate_hz / (o.limit_fraction * l.acceleration_rad_s2));
        }
        if ((worst_v <= 1.0 && worst_a <= 1.0) || attempt == 8) {
          if (worst_v > 1.0 || worst_a > 1.0)
            throw PlanError("goal '" + g.name + "': the straight line cannot be timed within the joint limits");
          break;
        }
        T *= std::max({worst_v, std::sqrt(worst_a), 1.05});
      }
      if (plan.trajectory.samples() + static_cast<long long>(path.size()) > limits::kMaxTrajectorySamples)
        throw InputError("the plan would have more than " + std::to_string(limits::kMaxTrajectorySamples) +
                         " samples (the most a trajectory may have): fewer goals or a lower rate_hz");
      for (std::size_t k = 0; k < path.size(); ++k) {
        plan.trajectory.time_s.push_back(t + static_cast<double>(k + 1) / o.rate_hz);
        rows.push_back(path[k]);
      }
      seg.duration_s = static_cast<double>(path.size()) / o.rate_hz;
      q = path.back();
    }
    t += seg.duration_s;
    if (o.dwell_s > 0.0) {
      const int n = sample_count(o.dwell_s, o.rate_hz, g.name, "dwell_s");
      const Eigen::VectorXd hold = q;
      append(plan.trajectory, rows, t, n, o.rate_hz, [&](double) -> Eigen::VectorXd { return hold; });
      t += n / o.rate_hz;
    }
    seg.q_end = q;
    seg.peak_velocity_fraction = peak_velocity_fraction(rows, first_row, o.rate_hz, lim);
    if (g.is_pose) {
      const Pose tip = forward_kinematics(model, ws, q);
      seg.position_error_m = (tip.translation() - g.base_T_tip.translation()).norm();
      seg.rotation_error_rad = rotation_distance(tip.linear(), g.base_T_tip.linear());
    }
    plan.segments.push_back(seg);
  }

  plan.trajectory.positions_rad.resize(static_cast<Eigen::Index>(rows.size()), model.dof());
  for (std::size_t i = 0; i < rows.size(); ++i) plan.trajectory.positions_rad.row(static_cast<Eigen::Index>(i)) = rows[i].transpose();
  return plan;
}

}  // namespace foresight
