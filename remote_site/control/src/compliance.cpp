// Wrench compensation, admittance and damped least squares (compliance.hpp).
#include "foresight/control/compliance.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace foresight::control {

namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Vector3d head(const Wrench6& w) { return {w[0], w[1], w[2]}; }
Eigen::Vector3d tail(const Wrench6& w) { return {w[3], w[4], w[5]}; }
Wrench6 join(const Eigen::Vector3d& f, const Eigen::Vector3d& t) { return {f(0), f(1), f(2), t(0), t(1), t(2)}; }

/// exp(M) for a 3x3 matrix: scaling and squaring with a 14-term Taylor series.
/// Fixed size: no allocation.
Eigen::Matrix3d expm3(const Eigen::Matrix3d& M) noexcept {
  const double norm = M.cwiseAbs().rowwise().sum().maxCoeff();
  int s = 0;
  if (norm > 0.25) s = std::min(60, static_cast<int>(std::ceil(std::log2(norm / 0.25))));
  const Eigen::Matrix3d A = M / std::ldexp(1.0, s);
  Eigen::Matrix3d term = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d sum = Eigen::Matrix3d::Identity();
  for (int k = 1; k <= 14; ++k) {
    term = (term * A / static_cast<double>(k)).eval();
    sum += term;
  }
  for (int i = 0; i < s; ++i) sum = (sum * sum).eval();
  return sum;
}

bool finite_nonneg(double v) { return std::isfinite(v) && v >= 0.0; }

const char* kAxis[6] = {"x", "y", "z", "rx", "ry", "rz"};

}  // namespace

// ---- WrenchCompensator -------------------------------------------------------------

WrenchCompensator::WrenchCompensator(ToolParams tool, WrenchFilterParams filter, double cycle_rate_hz,
                                     Eigen::Vector3d gravity_base)
    : tool_(tool), filter_(filter), gravity_base_(gravity_base) {
  if (!finite_nonneg(tool_.mass_kg)) throw std::invalid_argument("tool.mass_kg must be >= 0");
  for (double c : tool_.com_sensor_m)
    if (!std::isfinite(c)) throw std::invalid_argument("tool.com_sensor_m must be finite");
  if (!(cycle_rate_hz > 0.0) || !std::isfinite(cycle_rate_hz))
    throw std::invalid_argument("cycle_rate_hz must be > 0");
  if (!finite_nonneg(filter_.cutoff_hz)) throw std::invalid_argument("filter.cutoff_hz must be >= 0");
  if (!finite_nonneg(filter_.force_deadband_n)) throw std::invalid_argument("filter.force_deadband_n must be >= 0");
  if (!finite_nonneg(filter_.torque_deadband_nm))
    throw std::invalid_argument("filter.torque_deadband_nm must be >= 0");
  if (!(filter_.force_clamp_n > 0.0)) throw std::invalid_argument("filter.force_clamp_n must be > 0");
  if (!(filter_.torque_clamp_nm > 0.0)) throw std::invalid_argument("filter.torque_clamp_nm must be > 0");
  const double dt = 1.0 / cycle_rate_hz;
  alpha_ = filter_.cutoff_hz > 0.0 ? 1.0 - std::exp(-2.0 * kPi * filter_.cutoff_hz * dt) : 1.0;
}

Wrench6 WrenchCompensator::tool_gravity_ft(const Eigen::Matrix3d& base_R_sensor) const noexcept {
  const Eigen::Vector3d f = base_R_sensor.transpose() * (tool_.mass_kg * gravity_base_);
  const Eigen::Vector3d c(tool_.com_sensor_m[0], tool_.com_sensor_m[1], tool_.com_sensor_m[2]);
  return join(f, c.cross(f));
}

void WrenchCompensator::set_tare_orientation(const Eigen::Matrix3d& base_R_sensor) noexcept {
  tare_gravity_ft_ = tool_gravity_ft(base_R_sensor);
}

PayloadMass combined(const PayloadMass& a, const PayloadMass& b) noexcept {
  PayloadMass c;
  c.mass_kg = a.mass_kg + b.mass_kg;
  if (c.mass_kg > 0.0)
    for (std::size_t i = 0; i < 3; ++i)
      c.com_sensor_m[i] = (a.mass_kg * a.com_sensor_m[i] + b.mass_kg * b.com_sensor_m[i]) / c.mass_kg;
  return c;
}

void WrenchCompensator::set_payload(const PayloadMass& payload) noexcept {
  tool_.mass_kg = payload.mass_kg;
  tool_.com_sensor_m = payload.com_sensor_m;
}

void WrenchCompensator::set_offset(const Wrench6& offset_ft) noexcept {
  // compensated = reading - extra_bias - weight + tare term; reading = weight + offset.
  for (std::size_t i = 0; i < 6; ++i) tare_gravity_ft_[i] = tool_.extra_bias_ft[i] - offset_ft[i];
}

void WrenchCompensator::reset(const Wrench6& wrench_tool) noexcept {
  out_.filtered_tool = wrench_tool;
  primed_ = true;
}

const WrenchCompensator::Output& WrenchCompensator::update(const Wrench6& wrench_ft,
                                                           const Eigen::Matrix3d& base_R_sensor,
                                                           bool fresh) noexcept {
  if (!fresh && primed_) return out_;
  const Wrench6 g = tool_gravity_ft(base_R_sensor);
  Wrench6 c{};
  for (std::size_t i = 0; i < 6; ++i) c[i] = wrench_ft[i] - tool_.extra_bias_ft[i] - g[i] + tare_gravity_ft_[i];
  // To the tip frame, about the tip.
  const Eigen::Matrix3d R = tool_.sensor_T_tip.linear();
  const Eigen::Vector3d p = tool_.sensor_T_tip.translation();
  const Eigen::Vector3d f_s = head(c);
  const Eigen::Vector3d t_s = tail(c) - p.cross(f_s);
  out_.raw_tool = join(R.transpose() * f_s, R.transpose() * t_s);
  if (!primed_) {
    out_.filtered_tool = out_.raw_tool;
    primed_ = true;
  } else {
    for (std::size_t i = 0; i < 6; ++i)
      out_.filtered_tool[i] += alpha_ * (out_.raw_tool[i] - out_.filtered_tool[i]);
  }
  for (std::size_t i = 0; i < 6; ++i) {
    const double band = i < 3 ? filter_.force_deadband_n : filter_.torque_deadband_nm;
    const double clamp = i < 3 ? filter_.force_clamp_n : filter_.torque_clamp_nm;
    const double v = out_.filtered_tool[i];
    double m = std::abs(v) - band;
    if (!(m > 0.0)) m = 0.0;
    if (m > clamp) m = clamp;
    out_.shaped_tool[i] = v < 0.0 ? -m : m;
  }
  return out_;
}

// ---- Admittance ------------------------------------------------------------------------

namespace {
bool valid(const AdmittanceParams& p, std::string* why) {
  for (std::size_t i = 0; i < 6; ++i) {
    const char* what = nullptr;
    if (!(p.mass[i] > 0.0) || !std::isfinite(p.mass[i]))
      what = "mass must be > 0";
    else if (!finite_nonneg(p.damping[i]))
      what = "damping must be >= 0";
    else if (!finite_nonneg(p.stiffness[i]))
      what = "stiffness must be >= 0";
    else if (!(p.max_offset[i] > 0.0) || !std::isfinite(p.max_offset[i]))
      what = "max_offset must be > 0";
    if (what != nullptr) {
      if (why != nullptr) *why = std::string("admittance ") + kAxis[i] + ": " + what;
      return false;
    }
  }
  return true;
}
}  // namespace

Admittance::Admittance(const AdmittanceParams& params, double cycle_rate_hz) {
  if (!(cycle_rate_hz > 0.0) || !std::isfinite(cycle_rate_hz))
    throw std::invalid_argument("cycle_rate_hz must be > 0");
  dt_ = 1.0 / cycle_rate_hz;
  std::string why;
  if (!valid(params, &why)) throw std::invalid_argument(why);
  configure(params);
}

bool Admittance::configure(const AdmittanceParams& params) noexcept {
  if (!valid(params, nullptr)) return false;
  params_ = params;
  for (std::size_t i = 0; i < 6; ++i) {
    const double m = params.mass[i], d = params.damping[i], k = params.stiffness[i];
    Eigen::Matrix3d aug = Eigen::Matrix3d::Zero();
    aug(0, 1) = 1.0;
    aug(1, 0) = -k / m;
    aug(1, 1) = -d / m;
    aug(1, 2) = 1.0 / m;
    const Eigen::Matrix3d e = expm3(aug * dt_);
    phi_[i] = e.topLeftCorner<2, 2>();
    gamma_[i] = e.topRightCorner<2, 1>();
  }
  return true;
}

void Admittance::step(const Vector6& w) noexcept {
  x_before_ = x_;
  for (int i = 0; i < 6; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const double f = std::isfinite(w(i)) ? w(i) : 0.0;
    const Eigen::Vector2d s(x_(i), v_(i));
    const Eigen::Vector2d n = phi_[k] * s + gamma_[k] * f;
    double x = n(0), v = n(1);
    const double lim = params_.max_offset[k];
    if (x > lim) {
      x = lim;
      if (v > 0.0) v = 0.0;
    } else if (x < -lim) {
      x = -lim;
      if (v < 0.0) v = 0.0;
    }
    x_(i) = x;
    v_(i) = v;
  }
}

void Admittance::reset() noexcept {
  x_.setZero();
  v_.setZero();
  x_before_.setZero();
}

void Admittance::take_back(const Vector6& achieved) noexcept {
  for (int i = 0; i < 6; ++i) {
    const double a = achieved(i), from = x_before_(i);
    if (!std::isfinite(a)) continue;
    double x = x_(i);
    if (x > from)
      x = std::max(from, std::min(x, a));
    else if (x < from)
      x = std::min(from, std::max(x, a));
    if (x != x_(i)) {
      x_(i) = x;
      v_(i) = (x - from) / dt_;
    }
  }
}

// ---- kinematics helpers -----------------------------------------------------------------

Vector6 pose_error(const Pose& from, const Pose& to) noexcept {
  Vector6 e;
  e.head<3>() = to.translation() - from.translation();
  const Eigen::Matrix3d dR = to.linear() * from.linear().transpose();
  const Eigen::AngleAxisd aa(dR);
  e.tail<3>() = aa.axis() * aa.angle();
  if (!std::isfinite(e(3)) || !std::isfinite(e(4)) || !std::isfinite(e(5))) e.tail<3>().setZero();
  return e;
}

}  // namespace foresight::control
