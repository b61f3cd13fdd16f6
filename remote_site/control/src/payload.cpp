// identify_payload: static poses and least squares (payload.hpp).
#include "foresight/control/payload.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <limits>

namespace foresight::control {

namespace {

constexpr double kRestSpeed = 0.01;      // rad/s: a joint slower than this is at rest
constexpr double kRestError = 0.002;     // rad: at its pose
constexpr double kSettleTimeoutS = 5.0;  // beyond settle_s

bool finite_in(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return s;
}

template <int N>
double condition_of(const Eigen::Matrix<double, N, N>& normal) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> es(normal, Eigen::EigenvaluesOnly);
  const double lo = es.eigenvalues().minCoeff(), hi = es.eigenvalues().maxCoeff();
  if (!(lo > 0.0) || !std::isfinite(hi)) return std::numeric_limits<double>::infinity();
  return std::sqrt(hi / lo);  // singular values of the regressor
}

}  // namespace

PayloadFit fit_payload(const PayloadPose* poses, std::size_t n, const Eigen::Vector3d& gravity_base) noexcept {
  PayloadFit r;
  const double gn = gravity_base.norm();
  if (n < 2 || !(gn > 0.0)) {
    r.condition = std::numeric_limits<double>::infinity();
    return r;
  }
  Eigen::Matrix4d nf = Eigen::Matrix4d::Zero();
  Eigen::Vector4d bf = Eigen::Vector4d::Zero();
  Eigen::Matrix<double, 6, 6> nt = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> bt = Eigen::Matrix<double, 6, 1>::Zero();
  // Pose k's regressors and readings.
  struct Rows {
    Eigen::Matrix<double, 3, 4> af;
    Eigen::Matrix<double, 3, 6> at;
    Eigen::Vector3d f, t;
  };
  auto rows = [&](const PayloadPose& p) {
    Rows r;
    const Eigen::Vector3d u = p.base_R_sensor.transpose() * gravity_base / gn;
    r.af.col(0) = u;
    r.af.rightCols<3>().setIdentity();
    r.at.leftCols<3>() = -skew(u);
    r.at.rightCols<3>().setIdentity();
    r.f = Eigen::Vector3d(p.ft[0], p.ft[1], p.ft[2]);
    r.t = Eigen::Vector3d(p.ft[3], p.ft[4], p.ft[5]);
    return r;
  };
  for (std::size_t k = 0; k < n; ++k) {
    const Rows w = rows(poses[k]);
    nf += w.af.transpose() * w.af;
    bf += w.af.transpose() * w.f;
    nt += w.at.transpose() * w.at;
    bt += w.at.transpose() * w.t;
  }
  r.condition = std::max(condition_of<4>(nf), condition_of<6>(nt));
  if (!std::isfinite(r.condition)) return r;
  const Eigen::Vector4d xf = nf.ldlt().solve(bf);
  const Eigen::Matrix<double, 6, 1> xt = nt.ldlt().solve(bt);
  r.payload.mass_kg = xf(0) / gn;
  const Eigen::Vector3d mc = xt.head<3>() / gn;
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    r.payload.com_sensor_m[k] = std::abs(r.payload.mass_kg) > 1e-6 ? mc(i) / r.payload.mass_kg : 0.0;
    r.offset_ft[k] = xf(1 + i);
    r.offset_ft[k + 3] = xt(3 + i);
  }
  double ef2 = 0.0, et2 = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const Rows w = rows(poses[k]);
    ef2 += (w.af * xf - w.f).squaredNorm();
    et2 += (w.at * xt - w.t).squaredNorm();
  }
  r.residual_n = std::sqrt(ef2 / static_cast<double>(n));
  r.residual_nm = std::sqrt(et2 / static_cast<double>(n));
  return r;
}

bool PayloadIdentifier::validate(const IdentifyPayloadParams& p, Reason& code, std::array<char, 96>& text) noexcept {
  const char* bad = nullptr;
  if (!finite_in(p.angle_rad, 1e-4, 0.5))
    bad = "identify_payload: angle_rad must be in [0.0001, 0.5] rad";
  else if (!finite_in(p.move_s, 0.2, 30.0))
    bad = "identify_payload: move_s must be in [0.2, 30] s";
  else if (!finite_in(p.settle_s, 0.0, 10.0))
    bad = "identify_payload: settle_s must be in [0, 10] s";
  else if (!finite_in(p.window_s, 0.01, 10.0))
    bad = "identify_payload: window_s must be in [0.01, 10] s";
  else if (!finite_in(p.max_contact_n, 0.1, 100.0))
    bad = "identify_payload: max_contact_n must be in [0.1, 100] N";
  else if (!finite_in(p.max_condition, 2.0, 1e6))
    bad = "identify_payload: max_condition must be in [2, 1e6]";
  else if (!finite_in(p.max_residual_n, 0.01, 100.0))
    bad = "identify_payload: max_residual_n must be in [0.01, 100] N";
  if (bad == nullptr) return true;
  code = Reason::BadArgument;
  set_text(text, bad);
  return false;
}

bool PayloadIdentifier::start(const IdentifyPayloadParams& p, const JointArray& q_start, std::size_t dof,
                              const JointArray& lower, const JointArray& upper, double contact_n, double max_speed,
                              double dt, Reason& code, std::array<char, 96>& text) noexcept {
  char buf[96];
  if (!validate(p, code, text)) return false;
  if (!(contact_n <= p.max_contact_n)) {
    std::snprintf(buf, sizeof buf, "identify_payload: in contact (%.1f N > %.1f N): move clear first", contact_n,
                  p.max_contact_n);
    code = Reason::ForceLimit;
    set_text(text, buf);
    return false;
  }
  if (!(max_speed <= kRestSpeed)) {
    std::snprintf(buf, sizeof buf, "identify_payload: the arm is not at rest (%.3f rad/s > %.2f rad/s)", max_speed,
                  kRestSpeed);
    code = Reason::Busy;
    set_text(text, buf);
    return false;
  }
  if (dof < 3 || !(dt > 0.0)) {
    code = Reason::BadArgument;
    set_text(text, "identify_payload: needs a wrist of three joints");
    return false;
  }
  // (joint, sign) per pose; joint dof means none (the start).
  const std::size_t w1 = dof - 3, w2 = dof - 2, w3 = dof - 1;
  const std::size_t joint[kPoses] = {dof, w2, w2, w1, w1, w3};
  const double sign[kPoses] = {0.0, 1.0, -1.0, 1.0, -1.0, 1.0};
  for (std::size_t k = 0; k < kPoses; ++k) {
    goals_[k] = q_start;
    if (joint[k] >= dof) continue;
    const auto inside = [&](double v) { return v >= lower[joint[k]] && v <= upper[joint[k]]; };
    double v = q_start[joint[k]] + sign[k] * p.angle_rad;
    if (!inside(v)) v = q_start[joint[k]] - sign[k] * p.angle_rad;  // the other side of the joint
    if (!inside(v)) {
      std::snprintf(buf, sizeof buf, "identify_payload: pose %zu puts joint %zu outside its limits (%.3f rad)", k + 1,
                    joint[k] + 1, v);
      code = Reason::Unreachable;
      set_text(text, buf);
      return false;
    }
    goals_[k][joint[k]] = v;
  }
  p_ = p;
  dof_ = dof;
  dt_ = dt;
  pose_ = 0;
  from_ = to_ = target_ = q_prev_ = q_start;
  t_ = 0.0;
  still_s_ = 0.0;
  samples_ = 0;
  sum_ = {};
  fit_ = PayloadFit{};
  code_ = Reason::None;
  text_[0] = '\0';
  phase_ = Phase::Settle;  // the first pose is where the arm is
  status_ = Status::Running;
  code = Reason::None;
  return true;
}

bool PayloadIdentifier::check_excitation(const PayloadPose* poses, std::size_t n, const Eigen::Vector3d& gravity_base,
                                         Reason& code, std::array<char, 96>& text) const noexcept {
  const double condition = fit_payload(poses, n, gravity_base).condition;
  if (condition <= p_.max_condition) return true;
  char buf[96];
  std::snprintf(buf, sizeof buf, "identify_payload: the poses do not excite the payload (condition %.0f > %.0f)",
                condition, p_.max_condition);
  code = Reason::ValidationFailed;
  set_text(text, buf);
  return false;
}

void PayloadIdentifier::begin_move(const JointArray& to) noexcept {
  from_ = target_;
  to_ = to;
  t_ = 0.0;
  phase_ = Phase::Move;
}

void PayloadIdentifier::fail(Reason code, const char* text) noexcept {
  status_ = Status::Failed;
  code_ = code;
  set_text(text_, text);
}

PayloadIdentifier::Status PayloadIdentifier::step(const JointArray& q, const Eigen::Matrix3d& base_R_sensor,
                                                  const Wrench6& ft, bool fresh,
                                                  const Eigen::Vector3d& gravity_base) noexcept {
  if (status_ != Status::Running) return status_;
  t_ += dt_;
  char buf[96];
  switch (phase_) {
    case Phase::Move:
    case Phase::Return: {
      const double u = std::min(1.0, t_ / p_.move_s);
      const double s = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);  // quintic: rest to rest
      for (std::size_t j = 0; j < dof_; ++j) target_[j] = from_[j] + s * (to_[j] - from_[j]);
      if (u < 1.0) break;
      t_ = 0.0;
      still_s_ = 0.0;
      if (phase_ == Phase::Move) {
        phase_ = Phase::Settle;
        break;
      }
      // Back at the start: the result.
      const PayloadFit& f = fit_;
      Reason code = Reason::None;
      std::array<char, 96> text{};
      if (!check_excitation(poses_.data(), kPoses, gravity_base, code, text)) {
        fail(code, text.data());
      } else if (!(f.residual_n <= p_.max_residual_n)) {
        std::snprintf(buf, sizeof buf, "identify_payload: the readings fit no payload (residual %.2f N > %.2f N): contact?",
                      f.residual_n, p_.max_residual_n);
        fail(Reason::ForceLimit, buf);
      } else if (!(f.payload.mass_kg >= 0.0)) {
        std::snprintf(buf, sizeof buf, "identify_payload: negative mass %.3f kg", f.payload.mass_kg);
        fail(Reason::ValidationFailed, buf);
      } else {
        std::snprintf(buf, sizeof buf, "payload %.3f kg, com [%.4f %.4f %.4f] m, condition %.1f", f.payload.mass_kg,
                      f.payload.com_sensor_m[0], f.payload.com_sensor_m[1], f.payload.com_sensor_m[2], f.condition);
        status_ = Status::Succeeded;
        code_ = Reason::None;
        set_text(text_, buf);
      }
      break;
    }
    case Phase::Settle: {
      target_ = to_;
      bool still = true;
      for (std::size_t j = 0; j < dof_; ++j)
        if (!(std::abs(q[j] - to_[j]) < kRestError) || !(std::abs(q[j] - q_prev_[j]) / dt_ < kRestSpeed)) still = false;
      still_s_ = still ? still_s_ + dt_ : 0.0;
      if (still_s_ >= p_.settle_s) {
        phase_ = Phase::Average;
        t_ = 0.0;
        sum_ = {};
        samples_ = 0;
      } else if (t_ > p_.settle_s + kSettleTimeoutS) {
        std::snprintf(buf, sizeof buf, "identify_payload: not at rest at pose %zu after %.1f s", pose_ + 1, t_);
        fail(Reason::Timeout, buf);
      }
      break;
    }
    case Phase::Average: {
      if (fresh) {
        for (std::size_t i = 0; i < 6; ++i) sum_[i] += ft[i];
        ++samples_;
      }
      if (t_ < p_.window_s) break;
      if (samples_ == 0) {
        std::snprintf(buf, sizeof buf, "identify_payload: no F/T sample at pose %zu", pose_ + 1);
        fail(Reason::Faulted, buf);
        break;
      }
      poses_[pose_].base_R_sensor = base_R_sensor;
      for (std::size_t i = 0; i < 6; ++i) poses_[pose_].ft[i] = sum_[i] / static_cast<double>(samples_);
      if (++pose_ < kPoses) {
        begin_move(goals_[pose_]);
      } else {
        fit_ = fit_payload(poses_.data(), kPoses, gravity_base);
        begin_move(goals_[0]);
        phase_ = Phase::Return;
      }
      break;
    }
  }
  q_prev_ = q;
  return status_;
}

}  // namespace foresight::control
