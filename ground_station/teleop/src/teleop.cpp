// Teleoperation model (teleop.hpp).
#include "foresight/teleop/teleop.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight::teleop {

const char* to_string(ReferenceFrame frame) noexcept {
  switch (frame) {
    case ReferenceFrame::World: return "world";
    case ReferenceFrame::Tool: return "tool";
    case ReferenceFrame::Camera: return "camera";
  }
  return "?";
}

ReferenceFrame parse_reference_frame(const std::string& name) {
  if (name == "world") return ReferenceFrame::World;
  if (name == "tool") return ReferenceFrame::Tool;
  if (name == "camera") return ReferenceFrame::Camera;
  throw std::invalid_argument("reference frame '" + name + "' is not world, tool or camera");
}

std::vector<HandSample> read_hand_input_csv(const std::string& path) {
  require_input_file(path, "cannot open hand input");
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot open hand input");
  std::string line;
  int n = 0;
  if (!std::getline(in, line) || line.rfind("t,x,y,z,rx,ry,rz", 0) != 0)
    throw InputError(path, 1, "expected the header t,x,y,z,rx,ry,rz");
  n = 1;
  std::vector<HandSample> out;
  while (std::getline(in, line)) {
    ++n;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    std::vector<std::string> fields;
    std::stringstream ss(line);
    std::string f;
    while (std::getline(ss, f, ',')) fields.push_back(f);
    if (fields.size() != 7)
      throw InputError(path, n, "expected 7 fields (t,x,y,z,rx,ry,rz), got " + std::to_string(fields.size()));
    double v[7];
    for (int i = 0; i < 7; ++i) {
      char* end = nullptr;
      v[i] = std::strtod(fields[i].c_str(), &end);
      if (fields[i].empty() || end != fields[i].c_str() + fields[i].size() || !std::isfinite(v[i]))
        throw InputError(path, n, "field " + std::to_string(i + 1) + " ('" + fields[i] + "') is not a finite number");
      if (i > 0 && std::abs(v[i]) > 1.0)
        throw InputError(path, n, "deflection " + std::to_string(i) + " = " + fields[i] + " is outside [-1, 1]");
    }
    if (!out.empty() && !(v[0] > out.back().t_s)) throw InputError(path, n, "time must increase");
    HandSample s;
    s.t_s = v[0];
    for (int i = 0; i < 6; ++i) s.axes[i] = v[i + 1];
    out.push_back(s);
  }
  return out;
}

TeleopModel::TeleopModel(const RobotModel& model, const Eigen::VectorXd& q0, TeleopOptions options)
    : model_(model), o_(options), ws_(model), q_(q0), qdot_(Eigen::VectorXd::Zero(q0.size())) {
  if (q0.size() != model.dof())
    throw std::invalid_argument("teleop: q0 has " + std::to_string(q0.size()) + " values but the arm has " +
                                std::to_string(model.dof()) + " joints");
  if (!(o_.position_gain_m_s > 0) || !(o_.orientation_gain_rad_s > 0))
    throw std::invalid_argument("teleop: gains must be > 0");
  if (!(o_.linear_accel_m_s2 > 0) || !(o_.angular_accel_rad_s2 > 0))
    throw std::invalid_argument("teleop: accelerations must be > 0");
  if (!(o_.velocity_fraction > 0 && o_.velocity_fraction <= 1))
    throw std::invalid_argument("teleop: velocity_fraction must be in (0, 1]");
  if (!(o_.joint_accel_fraction > 0 && o_.joint_accel_fraction <= 1))
    throw std::invalid_argument("teleop: joint_accel_fraction must be in (0, 1]");
}

Pose TeleopModel::base_T_tip() { return forward_kinematics(model_, ws_, q_); }

Eigen::Matrix<double, 6, 1> TeleopModel::twist_base(const Axes& axes) {
  Eigen::Vector3d v, w;
  for (int i = 0; i < 3; ++i) {
    const double a = std::abs(axes[i]) < o_.deadband ? 0.0 : axes[i];
    const double b = std::abs(axes[i + 3]) < o_.deadband ? 0.0 : axes[i + 3];
    v[i] = a * o_.position_gain_m_s;
    w[i] = b * o_.orientation_gain_rad_s;
  }
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (o_.frame == ReferenceFrame::Tool) R = base_T_tip().linear();
  if (o_.frame == ReferenceFrame::Camera) R = o_.base_T_camera.linear();
  Eigen::Matrix<double, 6, 1> t;
  t << R * v, R * w;
  return t;
}

void TeleopModel::step(const Axes& axes, double dt_s) {
  const Eigen::Matrix<double, 6, 1> target = twist_base(axes);
  Eigen::Vector3d dv = target.head<3>() - twist_.head<3>();
  Eigen::Vector3d dw = target.tail<3>() - twist_.tail<3>();
  if (dv.norm() > o_.linear_accel_m_s2 * dt_s) dv *= o_.linear_accel_m_s2 * dt_s / dv.norm();
  if (dw.norm() > o_.angular_accel_rad_s2 * dt_s) dw *= o_.angular_accel_rad_s2 * dt_s / dw.norm();
  twist_.head<3>() += dv;
  twist_.tail<3>() += dw;
  const Eigen::Matrix<double, 6, 1> twist = twist_;
  Jacobian J(6, model_.dof());
  jacobian(model_, ws_, q_, J);
  JointVector dq;
  dls_step(J, twist * dt_s, dq, o_.lambda_max);
  // Within the velocity limits (scaled together, so the direction holds)...
  double scale = 1.0;
  for (int i = 0; i < model_.dof(); ++i) {
    const double max_step = o_.velocity_fraction * model_.limits()[i].velocity_rad_s * dt_s;
    if (std::abs(dq[i]) > max_step) scale = std::min(scale, max_step / std::abs(dq[i]));
  }
  // ... within the joint accelerations (the change from the last step's
  // velocity scaled together: the motion blends into the new one)...
  double blend = 1.0;
  for (int i = 0; i < model_.dof(); ++i) {
    const double change = std::abs(scale * dq[i] / dt_s - qdot_[i]);
    const double max_change = o_.joint_accel_fraction * model_.limits()[i].acceleration_rad_s2 * dt_s;
    if (change > max_change) blend = std::min(blend, max_change / change);
  }
  // ... and the position limits (a joint at its limit stops). The step is
  // the mean of the two velocities, so the recorded samples lie on the curve
  // of that velocity profile (from rest: a t^2 / 2, not a t (t + dt) / 2), the
  // curve the remote's spline through them executes.
  for (int i = 0; i < model_.dof(); ++i) {
    const auto& l = model_.limits()[i];
    const double v = qdot_[i] + blend * (scale * dq[i] / dt_s - qdot_[i]);
    const double q = q_[i] + 0.5 * (qdot_[i] + v) * dt_s;
    q_[i] = std::clamp(q, l.lower_rad, l.upper_rad);
    qdot_[i] = q_[i] == q ? v : 0.0;
  }
  if (recording_) {
    t_ += dt_s;
    times_.push_back(t_);
    qs_.push_back(q_);
  }
}

void TeleopModel::start_recording() {
  recording_ = true;
  t_ = 0.0;
  times_.assign(1, 0.0);
  qs_.assign(1, q_);
}

void TeleopModel::stop_recording() { recording_ = false; }

Trajectory TeleopModel::recorded() const {
  if (times_.size() < 2) throw std::logic_error("teleop: nothing recorded (start_recording, then step)");
  Trajectory t;
  t.time_s = times_;
  t.positions_rad.resize(static_cast<Eigen::Index>(qs_.size()), model_.dof());
  for (std::size_t i = 0; i < qs_.size(); ++i) t.positions_rad.row(static_cast<Eigen::Index>(i)) = qs_[i].transpose();
  return t;
}

Trajectory play(const RobotModel& model, const Eigen::VectorXd& q0, const std::vector<HandSample>& input,
                const TeleopOptions& options, double rate_hz) {
  if (input.size() < 2) throw std::invalid_argument("teleop: the hand input needs at least 2 samples");
  if (!(rate_hz > 0)) throw std::invalid_argument("teleop: rate_hz must be > 0");
  TeleopModel m(model, q0, options);
  m.start_recording();
  const double dt = 1.0 / rate_hz;
  const double t_end = input.back().t_s - input.front().t_s;
  const long steps = std::lround(t_end * rate_hz);
  std::size_t k = 0;
  for (long i = 0; i < steps; ++i) {
    const double t = input.front().t_s + i * dt;
    while (k + 1 < input.size() && input[k + 1].t_s <= t + 1e-12) ++k;
    m.step(input[k].axes, dt);
  }
  // The hand lets go at the end: the model brakes at its own (positive)
  // accelerations until its twist is zero, so the motion ends at rest (the
  // remote runs a trajectory from rest to rest; validate() refuses one that
  // stops dead, docs/control.md).
  while (!m.at_rest()) m.step(Axes{}, dt);
  return m.recorded();
}

}  // namespace foresight::teleop
