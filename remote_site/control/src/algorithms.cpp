// guarded_move, insert, pull_out as real-time state machines (algorithms.hpp).
#include "foresight/control/algorithms.hpp"

#include <cmath>
#include <cstdio>

namespace foresight::control {

namespace {
constexpr double kTwoPi = 6.28318530717958647692;

bool finite_pos(double v) { return std::isfinite(v) && v > 0.0; }
bool finite_nonneg(double v) { return std::isfinite(v) && v >= 0.0; }

void fail_arg(Reason& code, std::array<char, 96>& text, const char* what) noexcept {
  code = Reason::BadArgument;
  set_text(text, what);
}
}  // namespace

bool AlgorithmRunner::start(const AlgorithmParams& params, const Pose& base_T_tip, double cycle_rate_hz,
                            Reason& code, std::array<char, 96>& text) noexcept {
  code = Reason::None;
  text[0] = '\0';
  if (!finite_pos(cycle_rate_hz)) {
    fail_arg(code, text, "cycle rate must be > 0");
    return false;
  }
  switch (params.kind) {
    case AlgorithmKind::GuardedMove: {
      const auto& p = params.guarded_move;
      const Eigen::Vector3d d(p.direction[0], p.direction[1], p.direction[2]);
      if (!d.allFinite() || d.norm() < 1e-9) return fail_arg(code, text, "guarded_move: direction must be a non-zero vector"), false;
      if (!finite_pos(p.speed_m_s)) return fail_arg(code, text, "guarded_move: speed_m_s must be > 0"), false;
      if (!finite_pos(p.force_threshold_n)) return fail_arg(code, text, "guarded_move: force_threshold_n must be > 0"), false;
      if (!finite_pos(p.max_distance_m)) return fail_arg(code, text, "guarded_move: max_distance_m must be > 0"), false;
      if (!finite_nonneg(p.timeout_s)) return fail_arg(code, text, "guarded_move: timeout_s must be >= 0"), false;
      dir_task_ = d.normalized();
      timeout_s_ = p.timeout_s > 0.0 ? p.timeout_s : 2.0 * p.max_distance_m / p.speed_m_s + 2.0;
      break;
    }
    case AlgorithmKind::Insert: {
      const auto& p = params.insert;
      if (!finite_pos(p.depth_m)) return fail_arg(code, text, "insert: depth_m must be > 0"), false;
      if (!finite_nonneg(p.depth_tolerance_m)) return fail_arg(code, text, "insert: depth_tolerance_m must be >= 0"), false;
      if (!finite_pos(p.speed_m_s)) return fail_arg(code, text, "insert: speed_m_s must be > 0"), false;
      if (!finite_pos(p.contact_force_n)) return fail_arg(code, text, "insert: contact_force_n must be > 0"), false;
      if (!finite_pos(p.max_force_n) || p.max_force_n <= p.contact_force_n)
        return fail_arg(code, text, "insert: max_force_n must be > contact_force_n"), false;
      if (!finite_pos(p.lateral_stiffness_n_m) || !finite_pos(p.search_stiffness_n_m) ||
          !finite_pos(p.rotational_stiffness_nm_rad) || !finite_pos(p.axial_stiffness_n_m))
        return fail_arg(code, text, "insert: stiffnesses must be > 0"), false;
      if (!finite_pos(p.stall_time_s) || !finite_pos(p.stall_progress_m) || !finite_pos(p.entered_progress_m))
        return fail_arg(code, text, "insert: stall_time_s, stall_progress_m, entered_progress_m must be > 0"), false;
      if (!finite_pos(p.spiral_pitch_m) || !finite_pos(p.spiral_speed_m_s) || !finite_pos(p.spiral_max_radius_m))
        return fail_arg(code, text, "insert: spiral parameters must be > 0"), false;
      if (!finite_pos(p.timeout_s)) return fail_arg(code, text, "insert: timeout_s must be > 0"), false;
      if (!finite_nonneg(p.lateral_damping_n_s_m) || !finite_nonneg(p.rotational_damping_nm_s_rad))
        return fail_arg(code, text, "insert: dampings must be >= 0 (0: the controller's)"), false;
      dir_task_ = Eigen::Vector3d::UnitZ();
      timeout_s_ = p.timeout_s;
      break;
    }
    case AlgorithmKind::PullOut: {
      const auto& p = params.pull_out;
      if (!finite_pos(p.distance_m)) return fail_arg(code, text, "pull_out: distance_m must be > 0"), false;
      if (!finite_pos(p.speed_m_s)) return fail_arg(code, text, "pull_out: speed_m_s must be > 0"), false;
      if (!finite_pos(p.max_force_n)) return fail_arg(code, text, "pull_out: max_force_n must be > 0"), false;
      if (!finite_pos(p.lateral_stiffness_n_m) || !finite_pos(p.rotational_stiffness_nm_rad))
        return fail_arg(code, text, "pull_out: stiffnesses must be > 0"), false;
      if (!finite_nonneg(p.timeout_s)) return fail_arg(code, text, "pull_out: timeout_s must be >= 0"), false;
      dir_task_ = -Eigen::Vector3d::UnitZ();
      timeout_s_ = p.timeout_s > 0.0 ? p.timeout_s : 2.0 * p.distance_m / p.speed_m_s + 2.0;
      break;
    }
    case AlgorithmKind::None:
    default:
      code = Reason::UnknownAlgorithm;
      set_text(text, "unknown algorithm");
      return false;
  }
  params_ = params;
  base_T_start_ = base_T_tip;
  if (params.kind == AlgorithmKind::GuardedMove && params.guarded_move.frame == TaskFrame::Base)
    base_R_task_.setIdentity();
  else
    base_R_task_ = base_T_tip.linear();
  dt_ = 1.0 / cycle_rate_hz;
  t_ = 0.0;
  s_ref_ = 0.0;
  lateral_ref_.setZero();
  phase_ = 0;
  stall_timer_ = 0.0;
  stall_depth_ = 0.0;
  contact_depth_ = NAN;
  theta_ = 0.0;
  spiral_r_ = 0.0;
  distance_m_ = 0.0;
  peak_force_n_ = 0.0;
  peak_torque_nm_ = 0.0;
  out_ = AlgorithmStep{};
  out_.status = AlgorithmStatus::Running;
  out_.base_T_ref = base_T_tip;
  out_.admittance = base_;
  out_.admittance.frame = TaskFrame::Tool;
  return true;
}

void AlgorithmRunner::finish(AlgorithmStatus status, Reason code, const char* text) noexcept {
  out_.status = status;
  out_.code = code;
  set_text(out_.text, text);
}

const AlgorithmStep& AlgorithmRunner::step(const Pose& base_T_tip, const Wrench6& wrench_tool) noexcept {
  if (out_.status != AlgorithmStatus::Running) return out_;
  t_ += dt_;
  // Contact force in the task frame (the tip frame at the start, or base).
  const Eigen::Vector3d f_tip(wrench_tool[0], wrench_tool[1], wrench_tool[2]);
  const Eigen::Vector3d f_task = base_R_task_.transpose() * (base_T_tip.linear() * f_tip);
  const double f_norm = f_task.norm();
  if (std::isfinite(f_norm) && f_norm > peak_force_n_) peak_force_n_ = f_norm;
  const double t_norm = Eigen::Vector3d(wrench_tool[3], wrench_tool[4], wrench_tool[5]).norm();
  if (std::isfinite(t_norm) && t_norm > peak_torque_nm_) peak_torque_nm_ = t_norm;
  switch (params_.kind) {
    case AlgorithmKind::GuardedMove: step_guarded(base_T_tip, f_task); break;
    case AlgorithmKind::Insert: step_insert(base_T_tip, f_task); break;
    case AlgorithmKind::PullOut: step_pull_out(base_T_tip, f_task); break;
    case AlgorithmKind::None:
    case AlgorithmKind::IdentifyPayload:  // the Controller runs it (payload.hpp)
      finish(AlgorithmStatus::Failed, Reason::UnknownAlgorithm, "unknown algorithm");
      break;
  }
  return out_;
}

void AlgorithmRunner::step_guarded(const Pose& tip, const Eigen::Vector3d& f_task) noexcept {
  const auto& p = params_.guarded_move;
  const Eigen::Vector3d d_task = base_R_task_.transpose() * (tip.translation() - base_T_start_.translation());
  distance_m_ = d_task.dot(dir_task_);
  const double f_against = -f_task.dot(dir_task_);
  char buf[96];
  // Stiff in every axis: contact builds force gently (reference speed x stiffness N/s).
  out_.admittance.stiffness = {2000.0, 2000.0, 2000.0, 50.0, 50.0, 50.0};
  if (f_task.norm() > 4.0 * p.force_threshold_n) {
    std::snprintf(buf, sizeof buf, "guarded_move: force %.1f N > %.1f N (hard contact)", f_task.norm(),
                  4.0 * p.force_threshold_n);
    return finish(AlgorithmStatus::Failed, Reason::ForceLimit, buf);
  }
  if (f_against >= p.force_threshold_n) {
    // The reference stays where it is: the hold keeps the contact at about
    // the threshold force (moving it back to the measured pose would jump).
    std::snprintf(buf, sizeof buf, "guarded_move: contact %.1f N after %.1f mm", f_against, 1e3 * distance_m_);
    return finish(AlgorithmStatus::Succeeded, Reason::None, buf);
  }
  if (t_ > timeout_s_) {
    std::snprintf(buf, sizeof buf, "guarded_move: timeout %.1f s", timeout_s_);
    return finish(AlgorithmStatus::Failed, Reason::Timeout, buf);
  }
  if (s_ref_ >= p.max_distance_m && distance_m_ >= p.max_distance_m - 0.001) {
    std::snprintf(buf, sizeof buf, "guarded_move: no contact within %.1f mm", 1e3 * p.max_distance_m);
    return finish(AlgorithmStatus::Failed, Reason::Unreachable, buf);
  }
  s_ref_ = std::min(p.max_distance_m, s_ref_ + p.speed_m_s * dt_);
  out_.base_T_ref.translation() = base_T_start_.translation() + base_R_task_ * (dir_task_ * s_ref_);
}

void AlgorithmRunner::step_insert(const Pose& tip, const Eigen::Vector3d& f_task) noexcept {
  const auto& p = params_.insert;
  const Eigen::Vector3d d_task = base_R_task_.transpose() * (tip.translation() - base_T_start_.translation());
  const double depth = d_task.z();
  distance_m_ = depth;
  const double push = -f_task.z();  // the ORU pushing back along -z
  char buf[96];
  if (f_task.norm() > p.max_force_n) {
    std::snprintf(buf, sizeof buf, "insert: force limit %.1f N > %.1f N at depth %.1f mm", f_task.norm(),
                  p.max_force_n, 1e3 * depth);
    return finish(AlgorithmStatus::Failed, Reason::ForceLimit, buf);
  }
  if (depth >= p.depth_m) {
    std::snprintf(buf, sizeof buf, "insert: depth %.1f mm reached (search radius %.1f mm; peak %.1f N, %.2f N m)",
                  1e3 * depth, 1e3 * spiral_r_, peak_force_n_, peak_torque_nm_);
    return finish(AlgorithmStatus::Succeeded, Reason::None, buf);
  }
  if (t_ > p.timeout_s) {
    std::snprintf(buf, sizeof buf, "insert: timeout %.1f s at depth %.1f mm", p.timeout_s, 1e3 * depth);
    return finish(AlgorithmStatus::Failed, Reason::Timeout, buf);
  }
  if (std::isnan(contact_depth_) && push > 0.3 * p.contact_force_n) contact_depth_ = depth;

  // Stall: pushing without progress.
  bool stalled = false;
  if (push > 0.7 * p.contact_force_n) {
    stall_timer_ += dt_;
    if (stall_timer_ >= p.stall_time_s) {
      stalled = depth - stall_depth_ < p.stall_progress_m;
      stall_timer_ = 0.0;
      stall_depth_ = depth;
    }
  } else {
    stall_timer_ = 0.0;
    stall_depth_ = depth;
  }

  if (phase_ == 0 && stalled) {
    if (!std::isnan(contact_depth_) && depth - contact_depth_ > p.entered_progress_m) {
      phase_ = 2;  // stalled inside the hole: handled below
    } else {
      phase_ = 1;  // on the face beside the hole: search
      contact_depth_ = depth;
      theta_ = 0.0;
    }
  }
  if (phase_ == 1) {
    if (depth > contact_depth_ + p.entered_progress_m) {
      phase_ = 2;  // dropped in: keep this lateral reference
    } else {
      const double r_eff = std::max(spiral_r_, 0.5 * p.spiral_pitch_m);
      theta_ += p.spiral_speed_m_s * dt_ / r_eff;
      spiral_r_ = p.spiral_pitch_m * theta_ / kTwoPi;
      if (spiral_r_ > p.spiral_max_radius_m) {
        std::snprintf(buf, sizeof buf, "insert: not entered within search radius %.1f mm",
                      1e3 * p.spiral_max_radius_m);
        return finish(AlgorithmStatus::Failed, Reason::Unreachable, buf);
      }
      lateral_ref_ = Eigen::Vector2d(spiral_r_ * std::cos(theta_), spiral_r_ * std::sin(theta_));
    }
  } else if (phase_ == 2 && stalled) {
    if (depth >= p.depth_m - p.depth_tolerance_m) {
      std::snprintf(buf, sizeof buf, "insert: bottomed out at %.1f mm (target %.1f mm; peak %.1f N, %.2f N m)",
                    1e3 * depth, 1e3 * p.depth_m, peak_force_n_, peak_torque_nm_);
      return finish(AlgorithmStatus::Succeeded, Reason::None, buf);
    }
    std::snprintf(buf, sizeof buf, "insert: stuck at depth %.1f mm (target %.1f mm)", 1e3 * depth, 1e3 * p.depth_m);
    return finish(AlgorithmStatus::Failed, Reason::ForceLimit, buf);
  }

  // Force-limited axial advance.
  double k = 1.0 - push / p.contact_force_n;
  k = std::max(-1.0, std::min(1.0, k));
  s_ref_ += p.speed_m_s * k * dt_;
  s_ref_ = std::min(s_ref_, p.depth_m + 0.01);
  const double lateral_k = phase_ == 2 ? p.lateral_stiffness_n_m : p.search_stiffness_n_m;
  out_.admittance.stiffness = {lateral_k, lateral_k, p.axial_stiffness_n_m, p.rotational_stiffness_nm_rad,
                               p.rotational_stiffness_nm_rad, 50.0};
  if (p.lateral_damping_n_s_m > 0.0) out_.admittance.damping[0] = out_.admittance.damping[1] = p.lateral_damping_n_s_m;
  if (p.rotational_damping_nm_s_rad > 0.0)
    out_.admittance.damping[3] = out_.admittance.damping[4] = p.rotational_damping_nm_s_rad;
  out_.base_T_ref.translation() = base_T_start_.translation() +
                                  base_R_task_ * Eigen::Vector3d(lateral_ref_.x(), lateral_ref_.y(), s_ref_);
}

void AlgorithmRunner::step_pull_out(const Pose& tip, const Eigen::Vector3d& f_task) noexcept {
  const auto& p = params_.pull_out;
  const Eigen::Vector3d d_task = base_R_task_.transpose() * (tip.translation() - base_T_start_.translation());
  distance_m_ = -d_task.z();
  char buf[96];
  if (f_task.norm() > p.max_force_n) {
    std::snprintf(buf, sizeof buf, "pull_out: force limit %.1f N > %.1f N after %.1f mm", f_task.norm(),
                  p.max_force_n, 1e3 * distance_m_);
    return finish(AlgorithmStatus::Failed, Reason::ForceLimit, buf);
  }
  if (s_ref_ >= p.distance_m && distance_m_ >= p.distance_m - 0.001) {
    std::snprintf(buf, sizeof buf, "pull_out: %.1f mm out", 1e3 * distance_m_);
    return finish(AlgorithmStatus::Succeeded, Reason::None, buf);
  }
  if (t_ > timeout_s_) {
    std::snprintf(buf, sizeof buf, "pull_out: timeout %.1f s after %.1f mm", timeout_s_, 1e3 * distance_m_);
    return finish(AlgorithmStatus::Failed, Reason::Timeout, buf);
  }
  s_ref_ = std::min(p.distance_m, s_ref_ + p.speed_m_s * dt_);
  out_.admittance.stiffness = {p.lateral_stiffness_n_m, p.lateral_stiffness_n_m, 5000.0, p.rotational_stiffness_nm_rad,
                               p.rotational_stiffness_nm_rad, 50.0};
  out_.base_T_ref.translation() = base_T_start_.translation() + base_R_task_ * Eigen::Vector3d(0.0, 0.0, -s_ref_);
}

}  // namespace foresight::control
