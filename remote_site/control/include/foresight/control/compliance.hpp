#pragma once
// Wrist force/torque compliance, in three pieces the Controller chains every
// cycle (each usable alone, e.g. in tests):
//
//  1. WrenchCompensator: the F/T reading (sensor frame, bias already removed
//     by the decoder's tare) -> the contact wrench on the tool, in the tool
//     tip frame and about the tip. Removes the tool's weight for the current
//     sensor orientation (mass, CoM in the sensor frame), adding back the
//     weight that was in the reading when the sensor was tared, and a fixed
//     extra bias; then a first-order low-pass, a deadband (soft: |w| - band)
//     and a clamp (force/torque limits of what the admittance may use).
//  2. Admittance: per axis i of a chosen frame (x y z rx ry rz),
//        M_i x_i'' + D_i x_i' + K_i x_i = w_i
//     discretized exactly for a wrench held over each cycle (zero-order hold:
//     the 2x2 state transition exp(A dt) precomputed at set-up), so the step
//     response equals the analytic mass-spring-damper at the samples. x is the
//     offset of the commanded tool pose from the reference (m, rad), clamped
//     to max_offset.
//  3. dls_step(): damped least-squares inverse of the tip Jacobian,
//        dq = J^T (J J^T + lambda^2 I)^-1 e
//     (lambda grows near singularities: manipulability-based).
//
// Set-up (may allocate/throw std::invalid_argument naming the field):
// constructors and configure(). Real-time (noexcept, no allocation): all the
// rest.

#include <Eigen/Core>
#include <array>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/control/rt_types.hpp"

namespace foresight::control {

using foresight::dls_step;  // common/kinematics.hpp, as Vector6, JointVector, Jacobian
using foresight::Jacobian;
using foresight::JointVector;
using foresight::Vector6;

/// A mass hanging on the sensor: its mass and centre of mass in the sensor frame.
struct PayloadMass {
  double mass_kg = 0.0;
  Vec3 com_sensor_m{};
};
/// Two payloads as one (masses add, centres of mass weighted by mass).
PayloadMass combined(const PayloadMass& a, const PayloadMass& b) noexcept;

/// The tool on the sensor (config/robot.urdf: the LST, 2.6 kg; the daemon
/// sets mass and centre of mass from remote.yaml controller.payload.tool).
struct ToolParams {
  double mass_kg = 2.6;
  Vec3 com_sensor_m{0.015, 0.0, 0.125};  ///< centre of mass in the sensor frame
  Pose sensor_T_tip = Pose(Eigen::Translation3d(0.0, 0.0, 0.295));
  Wrench6 extra_bias_ft{};  ///< subtracted from the reading (sensor frame), beyond the tare
};

struct WrenchFilterParams {
  double cutoff_hz = 30.0;          ///< first-order low-pass; 0 = off
  double force_deadband_n = 1.0;
  double torque_deadband_nm = 0.1;
  double force_clamp_n = 100.0;     ///< what the admittance may see, per axis
  double torque_clamp_nm = 10.0;
};

class WrenchCompensator {
 public:
  /// Throws std::invalid_argument ("tool.mass_kg must be >= 0", ...).
  WrenchCompensator(ToolParams tool, WrenchFilterParams filter, double cycle_rate_hz, Eigen::Vector3d gravity_base);

  /// The reading was tared with the sensor at this orientation: the tool's
  /// weight at that orientation is in the bias and is added back. RT-safe.
  void set_tare_orientation(const Eigen::Matrix3d& base_R_sensor) noexcept;
  /// What hangs on the sensor now (the tool, plus the ORU while it is carried):
  /// the weight removed at every orientation from here on. The tare term is
  /// kept: it is the weight that was on the sensor when it was tared. RT-safe.
  void set_payload(const PayloadMass& payload) noexcept;
  PayloadMass payload() const noexcept { return {tool_.mass_kg, tool_.com_sensor_m}; }
  /// The reading's offset identified with the payload (identify_payload: the
  /// reading = weight + offset): replaces the tare term. RT-safe.
  void set_offset(const Wrench6& offset_ft) noexcept;
  /// Reset the filter to `wrench_tool` (e.g. zero after a tare). RT-safe.
  void reset(const Wrench6& wrench_tool = {}) noexcept;

  struct Output {
    Wrench6 raw_tool{};       ///< compensated, tool frame about the tip, before filtering
    Wrench6 filtered_tool{};  ///< low-passed (what telemetry and limits use)
    Wrench6 shaped_tool{};    ///< deadband + clamp applied (what the admittance uses)
  };
  /// One sample: wrench_ft from hw::FtReading (sensor frame, about the
  /// sensor origin, bias removed). `fresh` false keeps the filter state.
  /// RT-safe.
  const Output& update(const Wrench6& wrench_ft, const Eigen::Matrix3d& base_R_sensor, bool fresh) noexcept;
  const Output& output() const noexcept { return out_; }

  /// The tool's weight as the sensor sees it at this orientation (sensor frame). RT-safe.
  Wrench6 tool_gravity_ft(const Eigen::Matrix3d& base_R_sensor) const noexcept;
  const ToolParams& tool() const noexcept { return tool_; }

 private:
  ToolParams tool_;
  WrenchFilterParams filter_;
  double alpha_ = 1.0;
  Eigen::Vector3d gravity_base_;
  Wrench6 tare_gravity_ft_{};
  Output out_{};
  bool primed_ = false;
};

struct AdmittanceParams {
  TaskFrame frame = TaskFrame::Tool;  ///< Tool: axes of the tip frame; Base: of the base frame
  /// Per axis x y z (kg, N s/m, N/m) and rx ry rz (kg m^2, N m s/rad, N m/rad).
  std::array<double, 6> mass{4.0, 4.0, 4.0, 0.05, 0.05, 0.05};
  /// Damping bounds the contact stiffness the loop stays stable against: for an
  /// overdamped admittance on a position-controlled arm the largest stable
  /// environment stiffness grows with damping / loop delay. SYNC first with
  /// drives that latch at the next SYNC (docs/hardware.md "Cycle") gives a
  /// 3-cycle loop (6 ms at 500 Hz) instead of the earlier 1: twice the damping
  /// keeps the earlier margin (discrete model with the drives' 40 Hz servo and
  /// the 30 Hz wrench filter: lateral 1.0e6 N/m, rotational 2.3e3 -> 2.9e3 N m/rad).
  std::array<double, 6> damping{6000.0, 6000.0, 6000.0, 20.0, 20.0, 20.0};
  std::array<double, 6> stiffness{2000.0, 2000.0, 2000.0, 20.0, 20.0, 20.0};
  std::array<double, 6> max_offset{0.02, 0.02, 0.02, 0.1, 0.1, 0.1};  ///< m, rad
};

class Admittance {
 public:
  Admittance() = default;
  /// Set-up: validates (mass > 0, damping >= 0, stiffness >= 0, max_offset > 0;
  /// std::invalid_argument naming the axis) and precomputes the transitions.
  Admittance(const AdmittanceParams& params, double cycle_rate_hz);
  /// Change parameters keeping the state (real-time: no throw; returns false
  /// and keeps the old parameters when invalid). Six fixed-size 3x3 matrix
  /// exponentials (scaling and squaring, Taylor): a few microseconds.
  bool configure(const AdmittanceParams& params) noexcept;

  /// Advance one cycle with the wrench w (in params().frame, about the tip). RT-safe.
  void step(const Vector6& w) noexcept;
  void reset() noexcept;  ///< offset and velocity to zero. RT-safe.
  /// Anti-windup when the rate limiter cut the command: `achieved` is the
  /// offset from the reference the command carries. Per axis, the last step()
  /// advances the offset at most up to it (never back behind where it was:
  /// a cut caused by the reference's own jump is not the admittance's), and
  /// the velocity is what the offset then moved. RT-safe.
  void take_back(const Vector6& achieved) noexcept;

  const Vector6& offset() const noexcept { return x_; }
  const Vector6& velocity() const noexcept { return v_; }
  const AdmittanceParams& params() const noexcept { return params_; }
  double dt() const noexcept { return dt_; }

 private:
  AdmittanceParams params_{};
  double dt_ = 0.002;
  std::array<Eigen::Matrix2d, 6> phi_{};
  std::array<Eigen::Vector2d, 6> gamma_{};
  Vector6 x_ = Vector6::Zero();
  Vector6 v_ = Vector6::Zero();
  Vector6 x_before_ = Vector6::Zero();  ///< the offset before the last step()
};

/// 6-vector pose error (linear m, rotation vector rad; base frame) taking
/// `from` to `to`. RT-safe.
Vector6 pose_error(const Pose& from, const Pose& to) noexcept;

}  // namespace foresight::control
