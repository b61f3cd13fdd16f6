// The per-cycle control logic (controller.hpp).
#include "foresight/control/controller.hpp"

#include "foresight/hw/drive_system.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace foresight::control {

namespace {

int severity(StopCategory c) {
  switch (c) {
    case StopCategory::Cat0: return 3;
    case StopCategory::Cat1: return 2;
    case StopCategory::Cat2: return 1;
    case StopCategory::None: return 0;
  }
  return 0;
}

bool finite_pos(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

Controller::Controller(const RobotModel& model, const ControllerConfig& config)
    : model_(model),
      config_(config),
      ws_(model),
      comp_(config.tool, config.filter, config.cycle_rate_hz, model.gravity()),
      adm_(config.admittance, config.cycle_rate_hz),
      algo_(config.admittance) {
  if (model.dof() < 1 || static_cast<std::size_t>(model.dof()) > kMaxJoints)
    throw std::invalid_argument("controller: " + std::to_string(model.dof()) + " joints (at most " +
                                std::to_string(kMaxJoints) + ")");
  dof_ = static_cast<std::size_t>(model.dof());
  ft_link_ = model.link_index("ft_sensor");
  if (ft_link_ < 0) throw std::invalid_argument("controller: the robot model has no link 'ft_sensor'");
  tip_link_ = model.tip_index();
  if (!finite_pos(config.start_tolerance_rad) || config.start_tolerance_rad > kMaxStartToleranceRad)
    throw std::invalid_argument("start_tolerance_rad must be in (0, 0.02] rad");
  if (!(config.position_margin_rad >= 0.0)) throw std::invalid_argument("position_margin_rad must be >= 0");
  if (!finite_pos(config.velocity_limit_fraction) || config.velocity_limit_fraction > 1.0)
    throw std::invalid_argument("velocity_limit_fraction must be in (0, 1]");
  if (!finite_pos(config.following_error_rad)) throw std::invalid_argument("following_error_rad must be > 0");
  if (config.following_error_delay_cycles < 1 ||
      config.following_error_delay_cycles > static_cast<int>(kFollowingErrorHistory))
    throw std::invalid_argument("following_error_delay_cycles must be in [1, " +
                                std::to_string(kFollowingErrorHistory) + "]");
  if (!finite_pos(config.force_limit_n)) throw std::invalid_argument("force_limit_n must be > 0");
  if (!finite_pos(config.torque_limit_nm)) throw std::invalid_argument("torque_limit_nm must be > 0");
  if (!finite_pos(config.stop_decel_fraction)) throw std::invalid_argument("stop_decel_fraction must be > 0");
  if (!finite_pos(config.stop_cart_decel_m_s2)) throw std::invalid_argument("stop_cart_decel_m_s2 must be > 0");
  if (!finite_pos(config.stop_cart_decel_rad_s2)) throw std::invalid_argument("stop_cart_decel_rad_s2 must be > 0");
  if (config.estop_category == StopCategory::None) throw std::invalid_argument("estop_category must be 0, 1 or 2");
  if (config.sensor_fault_cycles < 1) throw std::invalid_argument("sensor_fault_cycles must be >= 1");
  if (!finite_pos(config.velocity_filter_hz)) throw std::invalid_argument("velocity_filter_hz must be > 0");
  if (config.drive_velocity_max_age_cycles < 0) throw std::invalid_argument("drive_velocity_max_age_cycles must be >= 0");
  if (!(config.oru.mass_kg >= 0.0) || !std::isfinite(config.oru.mass_kg))
    throw std::invalid_argument("oru.mass_kg must be >= 0");
  for (double c : config.oru.com_sensor_m)
    if (!std::isfinite(c)) throw std::invalid_argument("oru.com_sensor_m must be finite");
  if (!finite_pos(config.tare_max_force_n)) throw std::invalid_argument("tare_max_force_n must be > 0");
  tool_payload_ = PayloadMass{config.tool.mass_kg, config.tool.com_sensor_m};
  oru_payload_ = config.oru;
  if (!finite_pos(config.rate_limit_acceleration_fraction) || config.rate_limit_acceleration_fraction < 1.0 ||
      config.rate_limit_acceleration_fraction > 10.0)
    throw std::invalid_argument("rate_limit_acceleration_fraction must be in [1, 10]");
  if (!finite_pos(config.rate_limit_jerk_per_s) || config.rate_limit_jerk_per_s < 10.0 ||
      config.rate_limit_jerk_per_s > 100000.0)
    throw std::invalid_argument("rate_limit_jerk_per_s must be in [10, 100000] 1/s");
  if (!(config.rate_limit_compliant_acceleration_fraction >= config.rate_limit_acceleration_fraction) ||
      !(config.rate_limit_compliant_acceleration_fraction <= 100.0))
    throw std::invalid_argument(
        "rate_limit_compliant_acceleration_fraction must be in [rate_limit_acceleration_fraction, 100]");
  dt_ = 1.0 / config.cycle_rate_hz;
  RateLimits rl;
  for (std::size_t j = 0; j < dof_; ++j) {
    const JointLimits& l = model.limits()[j];
    lower_[j] = l.lower_rad + config.position_margin_rad;
    upper_[j] = l.upper_rad - config.position_margin_rad;
    vmax_[j] = l.velocity_rad_s * config.velocity_limit_fraction;
    amax_[j] = l.acceleration_rad_s2 * config.stop_decel_fraction;
    const double fe = config.following_error_joint_rad[j];
    if (!(fe >= 0.0) || !std::isfinite(fe))
      throw std::invalid_argument("following_error_joint_rad of joint " + std::to_string(j + 1) + " must be >= 0");
    fe_limit_[j] = fe > 0.0 ? fe : config.following_error_rad;
    rl.velocity[j] = vmax_[j];
    rl.acceleration[j] = l.acceleration_rad_s2 * config.rate_limit_acceleration_fraction;
    rl.jerk[j] = l.acceleration_rad_s2 * config.rate_limit_jerk_per_s;
  }
  limiter_.configure(dof_, rl, dt_);
  compliant_scale_ = config.rate_limit_compliant_acceleration_fraction / config.rate_limit_acceleration_fraction;
  qv_.resize(static_cast<Eigen::Index>(dof_));
  qv2_.resize(static_cast<Eigen::Index>(dof_));
  dqv_.resize(static_cast<Eigen::Index>(dof_));
  J_.resize(6, static_cast<Eigen::Index>(dof_));
  qv_.setZero();
  qv2_.setZero();
  {
    const Eigen::VectorXd mid = model.mid_configuration();
    KinematicsWorkspace ws(model);
    sensor_T_tip_ = forward_kinematics(model, ws, mid, ft_link_).inverse() * forward_kinematics(model, ws, mid, tip_link_);
  }
  dqv_.setZero();
  J_.setZero();
}

// ---- events ------------------------------------------------------------------------------

void Controller::emit(std::uint64_t id, MotionCommandKind cmd, MotionEventKind kind, Reason code,
                      const char* text) noexcept {
  if (pending_event_count_ >= pending_events_.size()) return;
  MotionEvent& e = pending_events_[pending_event_count_++];
  e = MotionEvent{};
  e.command_id = id;
  e.command = cmd;
  e.kind = kind;
  e.code = code;
  e.cycle = cycle_;
  e.stamp_ns = stamp_ns_;
  e.joints = dof_;
  e.final_q = q_;
  const PayloadMass now = comp_.payload();
  e.payload_mass_kg = now.mass_kg;
  e.payload_com_m = now.com_sensor_m;
  if (cmd == MotionCommandKind::RunAlgorithm && identifying_) e.payload_condition = ident_.fit().condition;
  if (cmd == MotionCommandKind::RunAlgorithm) {
    e.distance_m = algo_.distance_m();
    e.peak_force_n = algo_.peak_force_n();
    e.spiral_radius_m = algo_.spiral_radius_m();
  }
  set_text(e.text, text);
}

void Controller::finish_active(MotionEventKind kind, Reason code, const char* text) noexcept {
  if (active_ == Active::Trajectory || active_ == Active::Algorithm) {
    emit(active_id_, active_cmd_, kind, code, text);
    if (active_ == Active::Algorithm) {
      algo_.cancel();
      ident_.cancel();
      identifying_ = false;
    }
    traj_ = nullptr;
    active_ = Active::None;
    active_id_ = 0;
  }
}

// ---- commands -------------------------------------------------------------------------------

void Controller::command(const MotionCommand& cmd) noexcept {
  const auto reject = [&](Reason code, const char* text) {
    emit(cmd.command_id, cmd.kind, MotionEventKind::Rejected, code, text);
  };
  const bool stopped = mode_ == ControllerMode::Stopped || mode_ == ControllerMode::Fault ||
                       mode_ == ControllerMode::Stopping;
  const bool moving = active_ == Active::Trajectory || active_ == Active::Algorithm;
  char buf[96];
  switch (cmd.kind) {
    case MotionCommandKind::RunTrajectory:
    case MotionCommandKind::RunAlgorithm: {
      if (stopped) return reject(Reason::Faulted, "stopped: send Recover first");
      if (mode_ == ControllerMode::Disabled) return reject(Reason::Faulted, "drives disabled: send Enable first");
      if (drive_request_pending_) return reject(Reason::Busy, "drive power change in progress");
      if (link_lost_) return reject(Reason::NotInControl, "link lost: no new motion");
      if (moving) return reject(Reason::Busy, "a motion is running: send Hold first");
      if (!have_q_) return reject(Reason::Internal, "no joint feedback yet");
      if (cmd.kind == MotionCommandKind::RunTrajectory) {
        const PreparedTrajectory* t = cmd.trajectory;
        if (t == nullptr) return reject(Reason::UnknownTrajectory, "no trajectory");
        if (t->joints() != dof_) {
          std::snprintf(buf, sizeof buf, "trajectory has %zu joints, the arm %zu", t->joints(), dof_);
          return reject(Reason::JointCount, buf);
        }
        const double tol = cmd.start_tolerance_rad > 0.0 ? cmd.start_tolerance_rad : config_.start_tolerance_rad;
        int joint = -1;
        const double err = t->start_error(q_cmd_, &joint);
        if (!(err <= tol)) {
          std::snprintf(buf, sizeof buf, "start: joint %d is %.4f rad from the first sample (tolerance %.4f)",
                        joint + 1, err, tol);
          return reject(Reason::StartMismatch, buf);
        }
        traj_ = t;
        traj_t_ = 0.0;
        traj_hint_ = 0;
        for (std::size_t j = 0; j < dof_; ++j) traj_offset_[j] = q_cmd_[j] - t->start()[j];
        traj_fade_s_ = std::min(1.0, std::max(t->duration_s(), dt_));
        traj_compliant_ = cmd.compliant;
        if (traj_compliant_) {
          adm_.configure(config_.admittance);
          adm_.reset();
        }
        active_ = Active::Trajectory;
        mode_ = ControllerMode::Trajectory;
      } else if (cmd.algorithm.kind == AlgorithmKind::IdentifyPayload) {
        Reason code = Reason::None;
        std::array<char, 96> text{};
        double speed = 0.0;
        for (std::size_t j = 0; j < dof_; ++j) speed = std::max(speed, std::abs(dq_[j]));
        if (mode_ != ControllerMode::Idle || hold_compliant_)
          return reject(Reason::Busy, "identify_payload: needs a stiff hold (send Hold first)");
        if (!ident_.start(cmd.algorithm.identify_payload, q_cmd_, dof_, lower_, upper_, force_norm(), speed, dt_, code,
                          text))
          return reject(code, text.data());
        // The poses' orientations must excite the model: known before anything moves.
        std::array<PayloadPose, PayloadIdentifier::kPoses> planned{};
        for (std::size_t k = 0; k < planned.size(); ++k) {
          for (std::size_t j = 0; j < dof_; ++j) qv2_(static_cast<Eigen::Index>(j)) = ident_.goal(k)[j];
          planned[k].base_R_sensor = forward_kinematics(model_, ws_, qv2_, ft_link_).linear();
        }
        if (!ident_.check_excitation(planned.data(), planned.size(), model_.gravity(), code, text)) {
          ident_.cancel();
          return reject(code, text.data());
        }
        identifying_ = true;
        active_ = Active::Algorithm;
        mode_ = ControllerMode::Algorithm;
      } else {
        Reason code = Reason::None;
        std::array<char, 96> text{};
        if (!algo_.start(cmd.algorithm, commanded_tip_now(), config_.cycle_rate_hz, code, text))
          return reject(code, text.data());
        adm_.configure(algo_.last().admittance);
        adm_.reset();
        base_T_hold_ = commanded_tip_now();
        algo_ref_ = algo_ref_prev_ = base_T_hold_;
        active_ = Active::Algorithm;
        mode_ = ControllerMode::Algorithm;
      }
      active_id_ = cmd.command_id;
      active_cmd_ = cmd.kind;
      emit(cmd.command_id, cmd.kind, MotionEventKind::Started, Reason::None, "");
      return;
    }
    case MotionCommandKind::Hold: {
      if (mode_ == ControllerMode::Disabled) return reject(Reason::Faulted, "drives disabled");
      if (stopped) return reject(Reason::Faulted, "stopped: send Recover first");
      finish_active(MotionEventKind::Canceled, Reason::Aborted, "canceled by hold");
      hold_here();
      hold_compliant_ = cmd.compliant;
      if (hold_compliant_) {
        adm_.configure(config_.admittance);
        adm_.reset();
      }
      emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, "holding");
      return;
    }
    case MotionCommandKind::Stop: {
      StopCategory cat = cmd.category == StopCategory::None ? StopCategory::Cat2 : cmd.category;
      if (mode_ == ControllerMode::Disabled || mode_ == ControllerMode::Fault) {
        emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, "already stopped");
        return;
      }
      std::snprintf(buf, sizeof buf, "stop commanded (%s)", to_string(cat));
      begin_stop(StopCause::Command, cat, -1, 0.0, 0.0, buf);
      emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, buf);
      return;
    }
    case MotionCommandKind::Recover:
    case MotionCommandKind::Enable: {
      if (drive_request_pending_) return reject(Reason::Busy, "drive power change in progress");
      if (mode_ == ControllerMode::Stopping || moving) return reject(Reason::Busy, "motion or stop in progress");
      if (cmd.kind == MotionCommandKind::Enable && mode_ == ControllerMode::Fault)
        return reject(Reason::Faulted, "stopped: send Recover");
      if (mode_ == ControllerMode::Idle) {
        emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, "already enabled");
        return;
      }
      if (mode_ == ControllerMode::Stopped) {  // Cat2: powered, just leave the stop
        stop_.category = StopCategory::None;
        stop_.cause = StopCause::None;
        hold_here();
        emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, "recovered: holding");
        return;
      }
      // Disabled or Fault: power up.
      drive_request_pending_ = true;
      pending_request_ = DriveRequest::Enable;
      active_ = cmd.kind == MotionCommandKind::Enable ? Active::Enable : Active::Recover;
      active_id_ = cmd.command_id;
      active_cmd_ = cmd.kind;
      emit(cmd.command_id, cmd.kind, MotionEventKind::Started, Reason::None, "enabling drives");
      return;
    }
    case MotionCommandKind::Disable: {
      if (mode_ == ControllerMode::Disabled || (mode_ == ControllerMode::Fault && !drives_enabled_)) {
        emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, "already disabled");
        return;
      }
      if (drive_request_pending_) return reject(Reason::Busy, "drive power change in progress");
      if (moving || mode_ == ControllerMode::Stopping) return reject(Reason::Busy, "motion or stop in progress");
      drive_request_pending_ = true;
      pending_request_ = DriveRequest::Disable;
      active_ = Active::Disable;
      active_id_ = cmd.command_id;
      active_cmd_ = cmd.kind;
      emit(cmd.command_id, cmd.kind, MotionEventKind::Started, Reason::None, "disabling drives");
      return;
    }
    case MotionCommandKind::Tare: {
      // Only in a stiff hold (Idle, or Stopped after a category 2 stop) out
      // of contact: a tare in contact would call the contact "zero".
      if (moving || mode_ == ControllerMode::Stopping) return reject(Reason::Busy, "tare needs the arm still");
      if (tare_id_ != 0) return reject(Reason::Busy, "tare in progress");
      if (cmd.tare_samples < 1 || cmd.tare_samples > 10000) return reject(Reason::BadArgument, "tare_samples must be 1..10000");
      if (!((mode_ == ControllerMode::Idle && !hold_compliant_) || mode_ == ControllerMode::Stopped))
        return reject(Reason::Busy, "tare needs a stiff hold (send Hold first)");
      if (zeroed_ && !(force_norm() <= config_.tare_max_force_n)) {
        std::snprintf(buf, sizeof buf, "tare refused: contact force %.1f N > %.1f N (tare only out of contact)",
                      force_norm(), config_.tare_max_force_n);
        return reject(Reason::ForceLimit, buf);
      }
      tare_id_ = cmd.command_id;
      tare_request_ = cmd.tare_samples;
      tare_wait_cycles_ = 0;
      tare_seen_ = false;
      emit(cmd.command_id, cmd.kind, MotionEventKind::Started, Reason::None, "taring");
      return;
    }
    case MotionCommandKind::SetPayload: {
      if (identifying_) return reject(Reason::Busy, "identify_payload is running");
      oru_latched_ = cmd.oru_latched;
      apply_payload();
      std::snprintf(buf, sizeof buf, "payload %.3f kg (%s)", comp_.payload().mass_kg,
                    oru_latched_ ? "tool + ORU" : "tool");
      emit(cmd.command_id, cmd.kind, MotionEventKind::Completed, Reason::None, buf);
      return;
    }
  }
  reject(Reason::BadArgument, "unknown command kind");
}

const Pose& Controller::commanded_tip_now() noexcept {
  if (!tip_cmd_valid_) {
    for (std::size_t j = 0; j < dof_; ++j) qv2_(static_cast<Eigen::Index>(j)) = q_cmd_[j];
    base_T_tip_cmd_ = forward_kinematics(model_, ws_, qv2_, tip_link_);
    tip_cmd_valid_ = true;
  }
  return base_T_tip_cmd_;
}

void Controller::hold_here() noexcept {
  q_hold_ = q_cmd_;
  tip_cmd_valid_ = false;
  base_T_hold_ = commanded_tip_now();
  hold_compliant_ = false;
  adm_.reset();
  mode_ = ControllerMode::Idle;
}

void Controller::drive_request_done(DriveRequest request, bool ok, const char* text,
                                    const JointArray& held) noexcept {
  if (!drive_request_pending_ || request != pending_request_) return;
  drive_request_pending_ = false;
  drive_request_issued_ = false;  // a request made before the next step (RECOVER) is issued then
  pending_request_ = DriveRequest::None;
  if (enable_aborted_ && request == DriveRequest::Enable) {
    enable_aborted_ = false;
    ok = false;
    text = enable_abort_text_.data();
  }
  const bool command_owned = active_ == Active::Enable || active_ == Active::Recover || active_ == Active::Disable;
  if (request == DriveRequest::Enable) {
    if (ok) {
      drives_enabled_ = true;
      q_cmd_ = held;
      q_cmd_prev_ = held;
      limiter_.reset(held);  // at rest on what the drives hold
      v_cmd_ = JointArray{};
      for (std::size_t j = 0; j < dof_; ++j) qv_(static_cast<Eigen::Index>(j)) = held[j];
      tip_cmd_valid_ = false;
      stop_.category = StopCategory::None;
      stop_.cause = StopCause::None;
      sensor_bad_cycles_ = 0;
      hold_here();
    }
  } else {  // Disable
    if (ok) drives_enabled_ = false;
    if (active_ == Active::Disable) {
      mode_ = ok ? ControllerMode::Disabled : ControllerMode::Fault;
    } else {
      mode_ = ControllerMode::Fault;  // the end of a Cat0/Cat1 stop
    }
  }
  if (command_owned) {
    emit(active_id_, active_cmd_, ok ? MotionEventKind::Completed : MotionEventKind::Failed,
         ok ? Reason::None : Reason::Faulted, ok ? (request == DriveRequest::Enable ? "enabled: holding" : "disabled")
                                                 : text);
    active_ = Active::None;
    active_id_ = 0;
  }
}

// ---- stops ----------------------------------------------------------------------------------

void Controller::begin_stop(StopCause cause, StopCategory cat, int joint, double value, double limit,
                            const char* text) noexcept {
  const bool already = mode_ == ControllerMode::Stopping || mode_ == ControllerMode::Stopped ||
                       mode_ == ControllerMode::Fault;
  if (already && severity(cat) <= severity(pending_stop_category_)) return;  // nothing more severe
  const Reason code = cause == StopCause::Command ? Reason::Aborted : Reason::Faulted;
  const std::uint64_t running_id =
      (active_ == Active::Trajectory || active_ == Active::Algorithm) ? active_id_ : 0;
  // A controlled stop of a trajectory stays on its path (path_stop_step), and
  // one of an algorithm on its reference's line (cartesian_stop_step), unless
  // the motion's own command is what broke a limit.
  const bool controlled = cat != StopCategory::Cat0 && cause != StopCause::JointPositionLimit &&
                          cause != StopCause::JointVelocityLimit;
  const bool on_path = controlled && active_ == Active::Trajectory && traj_ != nullptr;
  // (identify_payload moves stiffly between joint poses: a joint-wise stop.)
  const bool on_reference = controlled && active_ == Active::Algorithm && !identifying_;
  if (on_path || on_reference) {
    if (!stop_on_path_ && !stop_cartesian_) {
      path_scale_ = 1.0;
      if (on_reference) {
        stop_twist_ = pose_error(algo_ref_prev_, algo_ref_) / dt_;
        stop_dq_ = v_cmd_;
      }
    }
    stop_on_path_ = on_path;
    stop_cartesian_ = on_reference;
    path_cancel_code_ = code;
    set_text(path_cancel_text_, text);
  } else {
    stop_on_path_ = stop_cartesian_ = false;
    finish_active(MotionEventKind::Canceled, code, text);
  }
  if (active_ == Active::Disable || active_ == Active::Enable || active_ == Active::Recover) {
    // a power change in progress keeps its own outcome
  }
  stop_ = StopEvent{};
  stop_.cause = cause;
  stop_.category = cat;
  stop_.cycle = cycle_;
  stop_.stamp_ns = stamp_ns_;
  stop_.command_id = running_id;
  stop_.joint = static_cast<std::int8_t>(joint);
  stop_.value = value;
  stop_.limit = limit;
  stop_.joints = dof_;
  const std::size_t n = evidence_count_;
  stop_.evidence_count = n;
  for (std::size_t i = 0; i < n; ++i)
    stop_.evidence[i] = evidence_[(evidence_head_ + StopEvent::kEvidence - n + i) % StopEvent::kEvidence];
  set_text(stop_.text, text);
  stop_new_ = true;
  pending_stop_category_ = cat;
  hold_compliant_ = false;
  if (cat == StopCategory::Cat0) {
    q_cmd_ = q_;  // power is off: the targets follow the arm
    v_cmd_ = JointArray{};
    power_off();
  } else {
    mode_ = ControllerMode::Stopping;
  }
}

void Controller::follow_trajectory_at(double t) noexcept {
  JointArray q_ref{}, dq_ref{};
  traj_->evaluate(t, traj_hint_, q_ref, dq_ref);
  if (t < traj_fade_s_) {  // fade out the start offset (smoothstep): C1, no jump
    const double u = t / traj_fade_s_;
    const double keep = 1.0 - u * u * (3.0 - 2.0 * u);
    for (std::size_t j = 0; j < dof_; ++j) q_ref[j] += keep * traj_offset_[j];
  }
  if (traj_compliant_) {
    for (std::size_t j = 0; j < dof_; ++j) qv2_(static_cast<Eigen::Index>(j)) = q_ref[j];
    const Pose ref = forward_kinematics(model_, ws_, qv2_, tip_link_);
    compliant_offset_to_joints(ref, q_ref, false);
  } else {
    q_cmd_ = q_ref;
  }
}

void Controller::path_stop_step() noexcept {
  // The path velocity the joints have now (ds/dt = path_scale_): the scaling
  // may fall as fast as the joint closest to its acceleration limit allows
  // (|dq_ref_j| x d(scale)/dt <= amax_j), so all decelerate together.
  JointArray q_ref{}, dq_ref{};
  traj_->evaluate(traj_t_, traj_hint_, q_ref, dq_ref);
  double rate = 1.0 / dt_;  // at most to zero in one cycle (a path at rest)
  for (std::size_t j = 0; j < dof_; ++j) {
    const double v = std::abs(dq_ref[j]);
    if (v > 1e-9) rate = std::min(rate, amax_[j] / v);
  }
  path_scale_ = std::max(0.0, path_scale_ - rate * dt_);
  traj_t_ = std::min(traj_t_ + path_scale_ * dt_, traj_->duration_s());
  follow_trajectory_at(traj_t_);
  for (std::size_t j = 0; j < dof_; ++j) v_cmd_[j] = (q_cmd_[j] - q_cmd_prev_[j]) / dt_;
  if (path_scale_ == 0.0 || traj_t_ >= traj_->duration_s()) cancel_at_rest();
}

void Controller::cartesian_stop_step() noexcept {
  // The reference keeps moving along the twist it had, scaled by path_scale_,
  // which falls as fast as the Cartesian limits and the joint nearest its
  // acceleration limit allow (the joints' velocities scale with the twist).
  const double v = stop_twist_.head<3>().norm(), w = stop_twist_.tail<3>().norm();
  double rate = 1.0 / dt_;
  if (v > 1e-12) rate = std::min(rate, config_.stop_cart_decel_m_s2 / v);
  if (w > 1e-12) rate = std::min(rate, config_.stop_cart_decel_rad_s2 / w);
  for (std::size_t j = 0; j < dof_; ++j) {
    const double dq = std::abs(stop_dq_[j]);
    if (dq > 1e-9) rate = std::min(rate, amax_[j] / dq);
  }
  path_scale_ = std::max(0.0, path_scale_ - rate * dt_);
  algo_ref_prev_ = algo_ref_;
  algo_ref_.translation() += path_scale_ * dt_ * stop_twist_.head<3>();
  const double angle = path_scale_ * dt_ * w;
  if (angle > 0.0)
    algo_ref_.linear() =
        Eigen::AngleAxisd(angle, stop_twist_.tail<3>() / w).toRotationMatrix() * algo_ref_prev_.linear();
  compliant_offset_to_joints(algo_ref_, q_cmd_prev_, true);
  for (std::size_t j = 0; j < dof_; ++j) v_cmd_[j] = (q_cmd_[j] - q_cmd_prev_[j]) / dt_;
  if (path_scale_ == 0.0) cancel_at_rest();
}

void Controller::cancel_at_rest() noexcept {
  stop_on_path_ = stop_cartesian_ = false;
  const std::array<char, 96> text = path_cancel_text_;
  finish_active(MotionEventKind::Canceled, path_cancel_code_, text.data());  // at rest, on the path
  v_cmd_ = JointArray{};
  stop_at_rest();
}

void Controller::power_off() noexcept {
  power_off_now_ = true;  // Disable Voltage to every drive this cycle
  mode_ = ControllerMode::Fault;
  if (drives_enabled_ && !drive_request_pending_) {  // then disable() confirms it
    drive_request_pending_ = true;
    pending_request_ = DriveRequest::Disable;
  }
}

void Controller::stop_at_rest() noexcept {
  if (pending_stop_category_ == StopCategory::Cat1) {
    power_off();  // then power off, as for Cat0
  } else {
    mode_ = ControllerMode::Stopped;
  }
  q_hold_ = q_cmd_;
}

void Controller::controlled_stop_step() noexcept {
  bool rest = true;
  for (std::size_t j = 0; j < dof_; ++j) {
    double v = v_cmd_[j];
    const double dv = amax_[j] * dt_;
    if (std::abs(v) <= dv)
      v = 0.0;
    else
      v -= v > 0.0 ? dv : -dv;
    v_cmd_[j] = v;
    q_cmd_[j] = q_cmd_prev_[j] + v * dt_;
    if (v != 0.0) rest = false;
  }
  if (rest) stop_at_rest();
}

void Controller::back_off(const char* text) noexcept {
  char why[160];
  std::snprintf(why, sizeof why, "%s: backing off into a compliant hold", text);
  finish_active(MotionEventKind::Failed, Reason::ForceLimit, why);
  // The compliant hold anchored where the tip is measured, not where it was
  // commanded: the admittance gives way to the contact and the force falls.
  mode_ = ControllerMode::Idle;
  hold_compliant_ = true;
  base_T_hold_ = base_T_tip_;
  adm_.configure(config_.admittance);
  adm_.reset();
  compliant_offset_to_joints(base_T_hold_, q_cmd_prev_, true);
  q_hold_ = q_cmd_;
  backoff_active_ = true;
  backoff_cycles_ = 0;
}

void Controller::record_evidence(const CycleInputs& in) noexcept {
  EvidenceSample& s = evidence_[evidence_head_];
  s.cycle = in.cycle;
  s.q = q_;
  s.q_cmd = q_cmd_;
  s.wrench_tool = wrench_tool_;
  evidence_head_ = (evidence_head_ + 1) % StopEvent::kEvidence;
  if (evidence_count_ < StopEvent::kEvidence) ++evidence_count_;
}

void Controller::compliant_offset_to_joints(const Pose& base_T_ref_tip, const JointArray& q_seed,
                                            bool tracking) noexcept {
  compliant_ref_ = base_T_ref_tip;
  const Eigen::Matrix3d R_ref = base_T_ref_tip.linear();
  const Eigen::Matrix3d R_frame = adm_.params().frame == TaskFrame::Tool ? R_ref : Eigen::Matrix3d::Identity();
  // Wrench into the admittance frame (from the measured tip frame).
  const Eigen::Matrix3d R_meas = base_T_tip_.linear();
  const Eigen::Vector3d f_base = R_meas * Eigen::Vector3d(shaped_[0], shaped_[1], shaped_[2]);
  const Eigen::Vector3d t_base = R_meas * Eigen::Vector3d(shaped_[3], shaped_[4], shaped_[5]);
  Vector6 w;
  w.head<3>() = R_frame.transpose() * f_base;
  w.tail<3>() = R_frame.transpose() * t_base;
  adm_.step(w);
  const Vector6& x = adm_.offset();
  Vector6 e;
  e.head<3>() = R_frame * x.head<3>();
  e.tail<3>() = R_frame * x.tail<3>();
  if (tracking) {
    Pose target = base_T_ref_tip;
    target.translation() += e.head<3>();
    const double angle = e.tail<3>().norm();
    if (angle > 1e-12)
      target.linear() = Eigen::AngleAxisd(angle, e.tail<3>() / angle).toRotationMatrix() * R_ref;
    for (std::size_t j = 0; j < dof_; ++j) qv2_(static_cast<Eigen::Index>(j)) = q_cmd_prev_[j];
    const Pose cur = forward_kinematics(model_, ws_, qv2_, tip_link_);
    jacobian(model_, ws_, qv2_, J_, tip_link_);
    const Vector6 err = pose_error(cur, target);
    dls_step(J_, err, dqv_);
    // Cartesian tracking never asks for more than 90% of a joint's speed
    // limit: a large correction becomes a fast motion, not a safety stop.
    double scale = 1.0;
    for (std::size_t j = 0; j < dof_; ++j) {
      const double step = std::abs(dqv_(static_cast<Eigen::Index>(j)));
      const double cap = 0.9 * vmax_[j] * dt_;
      if (step > cap && step * scale > cap) scale = cap / step;
    }
    for (std::size_t j = 0; j < dof_; ++j) q_cmd_[j] = q_cmd_prev_[j] + scale * dqv_(static_cast<Eigen::Index>(j));
  } else {
    for (std::size_t j = 0; j < dof_; ++j) qv2_(static_cast<Eigen::Index>(j)) = q_seed[j];
    jacobian(model_, ws_, qv2_, J_, tip_link_);
    dls_step(J_, e, dqv_);
    for (std::size_t j = 0; j < dof_; ++j) q_cmd_[j] = q_seed[j] + dqv_(static_cast<Eigen::Index>(j));
  }
}

bool Controller::check_safety(const CycleInputs& in) noexcept {
  char buf[96];
  // The E-stop circuit as the drives report it (safe torque off) comes
  // first: the drives' own reaction (torque off, leaving Operation enabled)
  // would otherwise be named as the cause.
  if (in.safe_torque_off) {
    std::snprintf(buf, sizeof buf, "E-stop: safe torque off reported by the drive of joint %d",
                  static_cast<int>(in.sto_joint) + 1);
    begin_stop(StopCause::EStop, config_.estop_category, in.sto_joint, 1.0, 0.0, buf);
    return false;
  }
  // Hardware first: the drives (or the F/T sensor) said stop.
  if (in.hw_stop_required) {
    std::snprintf(buf, sizeof buf, "hw: %s node %u joint %d code 0x%04x",
                  hw::to_string(static_cast<hw::HwFault>(in.hw_fault)), static_cast<unsigned>(in.hw_node),
                  static_cast<int>(in.hw_joint) + 1, static_cast<unsigned>(in.hw_code));
    const StopCause cause = in.hw_drive_fault ? StopCause::DriveFault : StopCause::SensorFault;
    begin_stop(cause, in.hw_drive_fault ? StopCategory::Cat0 : StopCategory::Cat1, in.hw_joint,
               static_cast<double>(in.hw_code), 0.0, buf);
    stop_.hw_fault = in.hw_fault;
    stop_.hw_node = in.hw_node;
    stop_.hw_code = in.hw_code;
    return false;
  }
  if (!in.drives_enabled && !drive_request_pending_) {
    begin_stop(StopCause::DriveFault, StopCategory::Cat0, -1, 0.0, 0.0, "hw: a drive left operation enabled");
    return false;
  }
  if (in.estop) {
    begin_stop(StopCause::EStop, config_.estop_category, -1, 1.0, 0.0, "E-stop pressed");
    return false;
  }
  if (in.missed_cycles_limit > 0 && in.missed_cycles >= in.missed_cycles_limit) {
    std::snprintf(buf, sizeof buf, "control loop overrun: %u periods missed in a row (limit %u)",
                  static_cast<unsigned>(in.missed_cycles), static_cast<unsigned>(in.missed_cycles_limit));
    begin_stop(StopCause::Overrun, StopCategory::Cat1, -1, static_cast<double>(in.missed_cycles),
               static_cast<double>(in.missed_cycles_limit), buf);
    return false;
  }
  if (in.ft_fault || in.ft_saturated_mask != 0) {
    if (++sensor_bad_cycles_ >= config_.sensor_fault_cycles) {
      std::snprintf(buf, sizeof buf, "F/T sensor %s (mask 0x%02x) for %d cycles", in.ft_fault ? "fault" : "saturated",
                    static_cast<unsigned>(in.ft_saturated_mask), sensor_bad_cycles_);
      begin_stop(StopCause::SensorFault, StopCategory::Cat1, -1, static_cast<double>(in.ft_saturated_mask), 0.0, buf);
      return false;
    }
  } else {
    sensor_bad_cycles_ = 0;
  }
  if (in.link_lost && !link_lost_ && config_.link_loss == LinkLossPolicy::Stop) {
    link_lost_ = true;
    begin_stop(StopCause::LinkLoss, StopCategory::Cat2, -1, 0.0, 0.0, "link lost (policy: stop)");
    return false;
  }
  // The command the measurement now shows: sent the loop's latency ago.
  const JointArray& shown =
      cmd_history_[(cmd_head_ + kFollowingErrorHistory + 1 - static_cast<std::size_t>(config_.following_error_delay_cycles)) %
                   kFollowingErrorHistory];
  for (std::size_t j = 0; j < dof_; ++j) {
    const double fe = std::abs(shown[j] - q_[j]);
    if (!(fe <= fe_limit_[j])) {
      std::snprintf(buf, sizeof buf, "following error joint %zu: %.4f rad > %.4f rad", j + 1, fe, fe_limit_[j]);
      begin_stop(StopCause::FollowingError, StopCategory::Cat1, static_cast<int>(j), fe, fe_limit_[j], buf);
      return false;
    }
  }
  const double f = force_norm();
  const double t = std::sqrt(wrench_tool_[3] * wrench_tool_[3] + wrench_tool_[4] * wrench_tool_[4] +
                             wrench_tool_[5] * wrench_tool_[5]);
  const bool over_f = !(f <= config_.force_limit_n);
  if (over_f || !(t <= config_.torque_limit_nm)) {
    const StopCause cause = over_f ? StopCause::ForceLimit : StopCause::TorqueLimit;
    const double value = over_f ? f : t, limit = over_f ? config_.force_limit_n : config_.torque_limit_nm;
    if (over_f)
      std::snprintf(buf, sizeof buf, "contact force %.1f N > %.1f N", f, config_.force_limit_n);
    else
      std::snprintf(buf, sizeof buf, "contact torque %.2f N m > %.2f N m", t, config_.torque_limit_nm);
    if (backoff_active_) {
      // Backing off did not bring the contact below the limit in time: Cat1.
      if (static_cast<double>(++backoff_cycles_) * dt_ >= kBackoffTimeS) {
        backoff_active_ = false;
        char why[160];
        std::snprintf(why, sizeof why, "%s %.0f ms after backing off", buf, 1e3 * kBackoffTimeS);
        begin_stop(cause, StopCategory::Cat1, -1, value, limit, why);
      }
      return false;
    }
    const bool compliant = (active_ == Active::Algorithm && !identifying_) ||
                           (active_ == Active::Trajectory && traj_compliant_) ||
                           (mode_ == ControllerMode::Idle && hold_compliant_);
    if (compliant && mode_ != ControllerMode::Stopping) {
      back_off(buf);
      return false;
    }
    begin_stop(cause, StopCategory::Cat2, -1, value, limit, buf);
    return false;
  }
  backoff_active_ = false;
  // Braking distance: every joint must be able to stop inside its limits at
  // the controlled stop's deceleration from the velocity commanded now
  // (q + v|v| / 2a; controlled_stop_step's discrete ramp travels v dt / 2 less), so
  // reaching a limit is a planned deceleration (a Cat2 stop begun early
  // enough), not a one-cycle stop at the limit. The check of the command
  // itself below stays as the last resort.
  if (mode_ != ControllerMode::Stopping) {
    for (std::size_t j = 0; j < dof_; ++j) {
      const double v = (q_cmd_[j] - q_cmd_prev_[j]) / dt_;
      const double stop_at = q_cmd_[j] + v * std::abs(v) / (2.0 * amax_[j]);
      if (stop_at > upper_[j] || stop_at < lower_[j]) {
        const double limit = stop_at > upper_[j] ? upper_[j] : lower_[j];
        std::snprintf(buf, sizeof buf, "joint %zu would stop at %.4f rad, beyond its limit %.4f: braking", j + 1,
                      stop_at, limit);
        for (std::size_t k = 0; k < dof_; ++k) v_cmd_[k] = (q_cmd_[k] - q_cmd_prev_[k]) / dt_;
        begin_stop(StopCause::JointPositionLimit, StopCategory::Cat2, static_cast<int>(j), stop_at, limit, buf);
        return false;
      }
    }
  }
  // The new command itself.
  for (std::size_t j = 0; j < dof_; ++j) {
    const double q = q_cmd_[j];
    if (!(q >= lower_[j] && q <= upper_[j])) {
      std::snprintf(buf, sizeof buf, "joint %zu command %.4f rad outside [%.4f, %.4f]", j + 1, q, lower_[j], upper_[j]);
      const double bad = q;
      q_cmd_ = q_cmd_prev_;  // drop the command
      v_cmd_ = JointArray{};
      begin_stop(StopCause::JointPositionLimit, StopCategory::Cat2, static_cast<int>(j), bad,
                 q < lower_[j] ? lower_[j] : upper_[j], buf);
      return false;
    }
    const double v = (q - q_cmd_prev_[j]) / dt_;
    if (!(std::abs(v) <= vmax_[j] * (1.0 + 1e-9))) {
      std::snprintf(buf, sizeof buf, "joint %zu command speed %.3f rad/s > %.3f rad/s", j + 1, std::abs(v), vmax_[j]);
      q_cmd_ = q_cmd_prev_;
      begin_stop(StopCause::JointVelocityLimit, StopCategory::Cat2, static_cast<int>(j), std::abs(v), vmax_[j], buf);
      return false;
    }
  }
  return true;
}

// ---- the cycle ------------------------------------------------------------------------------

void Controller::step(const CycleInputs& in, CycleOutputs& out) noexcept {
  cycle_ = in.cycle;
  stamp_ns_ = in.stamp_ns;
  estop_ = in.estop;
  out.power_off = false;
  out.tare_samples = 0;
  out.drive_request = DriveRequest::None;
  out.stop = nullptr;

  const bool joints_ok = in.joints == dof_;
  const Pose base_T_sensor = measure(in, joints_ok);
  refuse_enable_in_estop(in);
  watch_power_change(in);
  step_tare(in, out, base_T_sensor);
  const WrenchCompensator::Output& w = comp_.update(in.wrench_ft, base_T_sensor.linear(), in.ft_fresh);
  wrench_tool_ = w.filtered_tool;
  shaped_ = w.shaped_tool;
  if (in.link_lost != link_lost_ && !(in.link_lost && config_.link_loss == LinkLossPolicy::Stop))
    link_lost_ = in.link_lost;

  // Motion generation.
  const bool powered = mode_ != ControllerMode::Disabled && mode_ != ControllerMode::Fault;
  if (!joints_ok && powered) {
    begin_stop(StopCause::DriveFault, StopCategory::Cat0, -1, static_cast<double>(in.joints),
               static_cast<double>(dof_), "joint feedback count differs from the model");
  }
  generate_motion();
  const std::uint32_t limited = limit_rate(in);
  if (powered && mode_ != ControllerMode::Fault && mode_ != ControllerMode::Disabled) check_safety(in);
  write_outputs(in, out, joints_ok, limited);
}

Pose Controller::measure(const CycleInputs& in, bool joints_ok) noexcept {
  q_prev_ = q_;
  for (std::size_t j = 0; j < dof_; ++j) q_[j] = joints_ok ? in.q[j] : q_cmd_prev_[j];
  if (!have_q_) {
    q_prev_ = q_;
    q_cmd_ = q_;
    q_cmd_prev_ = q_;
    cmd_history_.fill(q_);
  }
  const double a = 1.0 - std::exp(-6.283185307179586 * config_.velocity_filter_hz * dt_);
  for (std::size_t j = 0; j < dof_; ++j) dq_[j] += a * ((q_[j] - q_prev_[j]) / dt_ - dq_[j]);
  for (std::size_t j = 0; j < dof_; ++j) qv_(static_cast<Eigen::Index>(j)) = q_[j];
  const Pose base_T_sensor = forward_kinematics(model_, ws_, qv_, ft_link_);
  base_T_tip_ = base_T_sensor * sensor_T_tip_;  // fixed joints: one FK for both
  base_R_sensor_ = base_T_sensor.linear();
  ft_reading_ = in.wrench_ft;
  ft_fresh_ = in.ft_fresh;
  if (!have_q_) {
    comp_.set_tare_orientation(base_T_sensor.linear());
    have_q_ = true;
  }
  return base_T_sensor;
}

void Controller::refuse_enable_in_estop(const CycleInputs& in) noexcept {
  if ((in.estop || in.safe_torque_off) && drive_request_pending_ && pending_request_ == DriveRequest::Enable &&
      !drive_request_issued_) {
    drive_request_pending_ = false;
    pending_request_ = DriveRequest::None;
    emit(active_id_, active_cmd_, MotionEventKind::Rejected, Reason::Faulted,
         in.estop ? "E-stop pressed" : "E-stop: safe torque off reported by the drives");
    active_ = Active::None;
    active_id_ = 0;
  }
}

void Controller::watch_power_change(const CycleInputs& in) noexcept {
  // The drives' enable runs in the cycle (the loop steps it): the E-stop, the
  // drives' safe torque off and the link are checked every cycle meanwhile.
  if (!drive_request_pending_ || !drive_request_issued_ || pending_request_ != DriveRequest::Enable ||
      enable_aborted_)
    return;
  const bool link = in.link_lost && config_.link_loss == LinkLossPolicy::Stop;
  if (!in.estop && !in.safe_torque_off && !link) return;
  enable_aborted_ = true;
  if (link) {
    set_text(enable_abort_text_, "link lost during the enable (policy stop): drives left off");
    power_off_now_ = true;  // Disable Voltage to every drive this cycle; the enable then fails
    return;
  }
  set_text(enable_abort_text_, in.estop ? "E-stop pressed during the enable: drives powered off (category 0)"
                                        : "E-stop: safe torque off reported during the enable: drives powered off "
                                          "(category 0)");
  // Category 0 whatever the mode: nothing moved yet, and whatever had
  // switched on is powered off in this cycle's RPDOs.
  pending_stop_category_ = StopCategory::None;
  begin_stop(StopCause::EStop, StopCategory::Cat0, in.estop ? -1 : in.sto_joint, 1.0, 0.0,
             in.estop ? "E-stop pressed during the enable" : "E-stop: safe torque off reported during the enable");
  power_off_now_ = true;
}

void Controller::step_tare(const CycleInputs& in, CycleOutputs& out, const Pose& base_T_sensor) noexcept {
  if (tare_id_ == 0) return;
  if (tare_request_ > 0) {
    out.tare_samples = tare_request_;
    tare_request_ = 0;
    comp_.set_tare_orientation(base_T_sensor.linear());
    return;
  }
  ++tare_wait_cycles_;
  if (in.ft_tare_in_progress) tare_seen_ = true;
  if ((tare_seen_ || tare_wait_cycles_ > 3) && !in.ft_tare_in_progress) {
    comp_.reset();
    adm_.reset();  // nothing the admittance integrated before the new zero survives it
    backoff_active_ = false;
    zeroed_ = true;
    emit(tare_id_, MotionCommandKind::Tare, MotionEventKind::Completed, Reason::None, "tared");
    tare_id_ = 0;
  } else if (tare_wait_cycles_ > 20000) {
    emit(tare_id_, MotionCommandKind::Tare, MotionEventKind::Failed, Reason::Timeout, "tare did not finish");
    tare_id_ = 0;
  }
}

void Controller::generate_motion() noexcept {
  switch (mode_) {
    case ControllerMode::Disabled:
    case ControllerMode::Fault:
      q_cmd_ = q_;  // follow the arm: nothing jumps at enable
      v_cmd_ = JointArray{};
      break;
    case ControllerMode::Idle:
    case ControllerMode::Goto:
      if (hold_compliant_)
        compliant_offset_to_joints(base_T_hold_, q_hold_, true);
      else
        q_cmd_ = q_hold_;
      break;
    case ControllerMode::Trajectory: step_trajectory(); break;
    case ControllerMode::Algorithm: step_algorithm(); break;
    case ControllerMode::Stopping:
      if (stop_on_path_ && traj_ != nullptr)
        path_stop_step();
      else if (stop_cartesian_)
        cartesian_stop_step();
      else
        controlled_stop_step();
      break;
    case ControllerMode::Stopped: q_cmd_ = q_hold_; break;
  }
}

void Controller::step_trajectory() noexcept {
  traj_t_ += dt_;
  follow_trajectory_at(traj_t_);
  if (traj_t_ >= traj_->duration_s()) {
    const bool compliant = traj_compliant_;
    const JointArray end = traj_->end();
    finish_active(MotionEventKind::Completed, Reason::None, "trajectory done");
    hold_here();
    q_hold_ = compliant ? q_cmd_ : end;
    hold_compliant_ = false;
  }
}

void Controller::apply_payload() noexcept {
  comp_.set_payload(oru_latched_ ? combined(tool_payload_, oru_payload_) : tool_payload_);
}

double Controller::force_norm() const noexcept {
  return std::sqrt(wrench_tool_[0] * wrench_tool_[0] + wrench_tool_[1] * wrench_tool_[1] +
                   wrench_tool_[2] * wrench_tool_[2]);
}

void Controller::step_identify() noexcept {
  const PayloadIdentifier::Status st = ident_.step(q_, base_R_sensor_, ft_reading_, ft_fresh_, model_.gravity());
  for (std::size_t j = 0; j < dof_; ++j) q_cmd_[j] = ident_.target()[j];
  if (st == PayloadIdentifier::Status::Running) return;
  if (st == PayloadIdentifier::Status::Succeeded) {
    // The identified total is what hangs on the sensor now: the ORU's part
    // while it is latched (the total less the tool), else the tool's.
    const PayloadMass total = ident_.fit().payload;
    if (oru_latched_) {
      PayloadMass oru;
      oru.mass_kg = total.mass_kg - tool_payload_.mass_kg;
      if (oru.mass_kg > 1e-3)
        for (std::size_t i = 0; i < 3; ++i)
          oru.com_sensor_m[i] =
              (total.mass_kg * total.com_sensor_m[i] - tool_payload_.mass_kg * tool_payload_.com_sensor_m[i]) /
              oru.mass_kg;
      else
        oru = PayloadMass{};
      oru_payload_ = oru;
    } else {
      tool_payload_ = total;
    }
    comp_.set_payload(total);
    comp_.set_offset(ident_.fit().offset_ft);
    comp_.reset();
    adm_.reset();
    zeroed_ = true;
    const std::array<char, 96> text = ident_.text();
    finish_active(MotionEventKind::Completed, Reason::None, text.data());
  } else {
    const Reason code = ident_.code();
    const std::array<char, 96> text = ident_.text();
    finish_active(MotionEventKind::Failed, code, text.data());
  }
  hold_here();  // stiff, where the identifier left the arm
}

void Controller::step_algorithm() noexcept {
  if (identifying_) return step_identify();
  const AlgorithmStep& s = algo_.step(base_T_tip_, wrench_tool_);
  algo_ref_prev_ = algo_ref_;
  if (s.status == AlgorithmStatus::Running || s.status == AlgorithmStatus::Succeeded) {
    algo_ref_ = s.base_T_ref;
    const AdmittanceParams& now = adm_.params();
    if (s.admittance.stiffness != now.stiffness || s.admittance.damping != now.damping) adm_.configure(s.admittance);
    compliant_offset_to_joints(s.base_T_ref, q_cmd_prev_, true);
  }
  if (s.status == AlgorithmStatus::Succeeded) {
    finish_active(MotionEventKind::Completed, Reason::None, s.text.data());
    q_hold_ = q_cmd_;
    base_T_hold_ = s.base_T_ref;
    mode_ = ControllerMode::Idle;
    hold_compliant_ = true;  // keep the algorithm's compliance while the tool works
  } else if (s.status == AlgorithmStatus::Failed) {
    const Reason code = s.code;
    std::array<char, 96> text = s.text;
    finish_active(MotionEventKind::Failed, code, text.data());
    // Hold compliantly where the tip is (a failed push must not keep pushing).
    mode_ = ControllerMode::Idle;
    base_T_hold_ = base_T_tip_;
    hold_compliant_ = true;
    adm_.reset();
    compliant_offset_to_joints(base_T_hold_, q_cmd_prev_, true);
    q_hold_ = q_cmd_;
  }
}

// The rate limiter: every powered motion's command, limited in acceleration
// and jerk. Inside the force loop (an algorithm, a compliant trajectory or
// hold) at the looser compliant limits, with anti-windup: a limiter there at
// the stiff limits, lagging behind the admittance at the bus's 3-cycle loop
// delay, made the contact unstable (docs/control.md, "The rate limiter").
// Controlled stops shape their own ramp.
std::uint32_t Controller::limit_rate(const CycleInputs& in) noexcept {
  limiter_applied_ = false;
  std::uint32_t limited = 0;
  const bool stiff_motion = ((mode_ == ControllerMode::Idle || mode_ == ControllerMode::Goto) && !hold_compliant_) ||
                            (mode_ == ControllerMode::Trajectory && !traj_compliant_) ||
                            (mode_ == ControllerMode::Algorithm && identifying_);
  const bool compliant_motion = ((mode_ == ControllerMode::Idle || mode_ == ControllerMode::Goto) && hold_compliant_) ||
                                (mode_ == ControllerMode::Algorithm && !identifying_) ||
                                (mode_ == ControllerMode::Trajectory && traj_compliant_);
  if (stiff_motion) {
    limited = limiter_.apply(q_cmd_, q_cmd_);
    limiter_applied_ = true;
  } else if (compliant_motion) {
    limited = limiter_.apply(q_cmd_, q_cmd_, compliant_scale_);
    limiter_applied_ = true;
    if (limited != 0 && limiter_.too_fast() == 0) take_back_limited();
  }

  record_evidence(in);
  if (const std::uint32_t fast = limiter_applied_ ? limiter_.too_fast() : 0u; fast != 0) {
    // The motion itself asks for more than the velocity limit: a broken
    // command (validated trajectories and the compliance's capped steps
    // never do). Cat2, the command dropped (the evidence shows it).
    std::size_t j = 0;
    while (((fast >> j) & 1u) == 0) ++j;
    char buf[96];
    std::snprintf(buf, sizeof buf, "joint %zu command speed %.3f rad/s > %.3f rad/s", j + 1,
                  limiter_.target_speed()[j], vmax_[j]);
    q_cmd_ = q_cmd_prev_;
    limited = 0;
    begin_stop(StopCause::JointVelocityLimit, StopCategory::Cat2, static_cast<int>(j), limiter_.target_speed()[j],
               vmax_[j], buf);
  }
  if (limited != 0) {
    ++rate_limited_cycles_;
    for (std::size_t j = 0; j < dof_; ++j)
      if ((limited >> j) & 1u) ++rate_limited_joint_cycles_[j];
  }
  return limited;
}

void Controller::take_back_limited() noexcept {
  // The admittance does not run ahead of what the arm is commanded, so it
  // has nothing to snap back when the limiter lets go.
  for (std::size_t j = 0; j < dof_; ++j) qv2_(static_cast<Eigen::Index>(j)) = q_cmd_[j];
  const Vector6 e = pose_error(compliant_ref_, forward_kinematics(model_, ws_, qv2_, tip_link_));
  const Eigen::Matrix3d R_frame = adm_.params().frame == TaskFrame::Tool ? Eigen::Matrix3d(compliant_ref_.linear())
                                                                       : Eigen::Matrix3d::Identity();
  Vector6 achieved;
  achieved.head<3>() = R_frame.transpose() * e.head<3>();
  achieved.tail<3>() = R_frame.transpose() * e.tail<3>();
  adm_.take_back(achieved);
}

void Controller::write_outputs(const CycleInputs& in, CycleOutputs& out, bool joints_ok, std::uint32_t limited) noexcept {
  if (power_off_now_) {
    out.power_off = true;
    power_off_now_ = false;
  }
  if (drive_request_pending_ && !drive_request_issued_) {
    out.drive_request = pending_request_;
    drive_request_issued_ = true;
  }
  if (!drive_request_pending_) drive_request_issued_ = false;
  for (std::size_t j = 0; j < dof_; ++j) {
    if (mode_ != ControllerMode::Stopping) v_cmd_[j] = (q_cmd_[j] - q_cmd_prev_[j]) / dt_;
  }
  if (mode_ != ControllerMode::Stopping)
    for (std::size_t j = 0; j < dof_; ++j)
      if (std::abs(v_cmd_[j]) > vmax_[j]) v_cmd_[j] = v_cmd_[j] > 0 ? vmax_[j] : -vmax_[j];
  q_cmd_prev_ = q_cmd_;
  cmd_head_ = (cmd_head_ + 1) % kFollowingErrorHistory;
  cmd_history_[cmd_head_] = q_cmd_;
  // The limiter's state is what was sent: it follows the stops' own ramps and
  // rests with the arm while the drives are off.
  if (mode_ == ControllerMode::Disabled || mode_ == ControllerMode::Fault)
    limiter_.reset(q_cmd_);
  else if (!limiter_applied_)
    limiter_.follow(q_cmd_);
  tip_cmd_valid_ = false;  // computed on demand (commanded_tip_now)
  out.q_cmd = q_cmd_;
  if (stop_new_) out.stop = &stop_;
  stop_new_ = false;

  TelemetrySample& t = out.telemetry;
  t.stamp_ns = in.stamp_ns;
  t.cycle = in.cycle;
  t.joints = dof_;
  t.q = q_;
  t.dq = dq_;
  t.dq_drive_mask = 0;
  if (config_.drive_velocity_max_age_cycles > 0 && joints_ok) {
    const auto max_age = static_cast<std::uint64_t>(config_.drive_velocity_max_age_cycles);
    for (std::size_t j = 0; j < dof_; ++j) {
      const std::uint64_t at = in.dq_drive_cycle[j];
      if (at == 0 || at > in.cycle || in.cycle - at > max_age || !std::isfinite(in.dq_drive[j])) continue;
      t.dq[j] = in.dq_drive[j];
      t.dq_drive_mask |= std::uint32_t{1} << j;
    }
  }
  t.torque = in.torque;
  t.q_cmd = q_cmd_;
  t.wrench_tool = wrench_tool_;
  t.ft_saturated = in.ft_saturated_mask != 0;
  t.drives_enabled = in.drives_enabled;
  t.drive_state = in.drive_state;
  t.mode = mode_;
  t.active_command_id = active_id_;
  t.algorithm = active_ != Active::Algorithm ? AlgorithmKind::None
                : identifying_              ? AlgorithmKind::IdentifyPayload
                                            : algo_.kind();
  t.stop_category = stop_.category;
  t.stop_cause = stop_.cause;
  t.rate_limited_mask = limited;
  t.rate_limited_cycles = rate_limited_cycles_;
  t.rate_limited_joint_cycles = rate_limited_joint_cycles_;
  t.rate_limit_lag = limiter_.lag();

  out.event_count = pending_event_count_;
  for (std::size_t i = 0; i < pending_event_count_; ++i) out.events[i] = pending_events_[i];
  pending_event_count_ = 0;
}

}  // namespace foresight::control
