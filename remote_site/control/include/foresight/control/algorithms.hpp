#pragma once
// The changeout's contact steps as real-time state machines. Each cycle the
// Controller gives the runner the measured tip pose and the compensated
// contact wrench; the runner returns the reference tip pose and the
// admittance to use on top of it. The Controller turns reference + admittance
// offset into joints (damped least squares) and applies the safety checks.
// Parameters and defaults: rt_types.hpp (GuardedMoveParams, InsertParams,
// PullOutParams); docs/control.md has the same in prose.
//
// Task frame: the tool tip frame (lst_tip: z along the tool axis, out of the
// tool) frozen at the algorithm's start, unless a parameter says Base.
//
// guarded_move  Reference moves along `direction` at speed_m_s (stiff
//               admittance, 2000 N/m per axis, so contact builds force
//               gently). Success: the contact force component against the
//               motion >= force_threshold_n; the reference stays where it
//               was, so the compliant hold that follows keeps about that
//               force on the contact. Failure: Unreachable when the reference
//               travelled max_distance_m without contact; Timeout; ForceLimit
//               when |F| > 4 x force_threshold_n (a hard hit).
// insert        Force-guided along +z of the tool with lateral (x, y) and
//               tilt (rx, ry) compliance. Axial: the reference advances at
//               speed_m_s x clamp(1 - F_push / contact_force_n, -1, 1), so it
//               pushes with at most ~contact_force_n. When it pushes (F_push >
//               0.7 x contact_force_n) but the tip progresses less than
//               stall_progress_m in stall_time_s, the tip is on the face
//               beside the hole: an Archimedean spiral search of the lateral
//               reference, r = spiral_pitch_m x theta / 2 pi, at
//               spiral_speed_m_s tangential, until the tip drops
//               entered_progress_m deeper than where it stalled (entered: the
//               lateral reference stays there, insertion continues).
//               Success: advanced depth_m from the start (or stalled in the
//               hole within depth_tolerance_m of it: bottomed out).
//               Failure: ForceLimit when |F| > max_force_n; Unreachable when
//               the spiral passes spiral_max_radius_m; Timeout after
//               timeout_s; ForceLimit ("stuck at depth") when it stalls
//               inside the hole short of depth_m - depth_tolerance_m.
//               Lateral admittance: search_stiffness_n_m until entered (the
//               spiral must not be dragged by friction), then
//               lateral_stiffness_n_m.
// pull_out      Reference moves along -z of the tool distance_m at speed_m_s,
//               compliant across the axis and in tilt (the hole guides the
//               tool). Success: the measured tip moved distance_m (within
//               1 mm). Failure: ForceLimit when |F| > max_force_n (jammed),
//               Timeout.
//
// Set-up: nothing (the runner lives inside the Controller, preallocated).
// Real-time (noexcept, no allocation): start(), step().

#include <cstdint>

#include "foresight/common/pose.hpp"
#include "foresight/control/command.hpp"
#include "foresight/control/compliance.hpp"
#include "foresight/control/rt_types.hpp"

namespace foresight::control {

enum class AlgorithmStatus : std::uint8_t { Idle = 0, Running, Succeeded, Failed };

struct AlgorithmStep {
  AlgorithmStatus status = AlgorithmStatus::Idle;
  Pose base_T_ref = Pose::Identity();  ///< reference tip pose this cycle
  AdmittanceParams admittance{};       ///< compliance about the reference (frame Tool = start tip frame)
  Reason code = Reason::None;          ///< on Failed
  std::array<char, 96> text{};         ///< on Succeeded/Failed
};

class AlgorithmRunner {
 public:
  /// `base_admittance` is the configured default (masses, damping ratios);
  /// algorithms set stiffness per axis on top of it.
  explicit AlgorithmRunner(const AdmittanceParams& base_admittance = {}) : base_(base_admittance) {}

  /// Validate the parameters and begin at the current (measured) tip pose.
  /// False (with code BadArgument and text) when a parameter is out of range:
  /// non-finite, speed <= 0, distance/depth <= 0, a zero direction. RT-safe.
  bool start(const AlgorithmParams& params, const Pose& base_T_tip, double cycle_rate_hz,
             Reason& code, std::array<char, 96>& text) noexcept;

  /// One cycle. base_T_tip = measured tip pose; wrench_tool = compensated,
  /// filtered contact wrench in the current tip frame about the tip. RT-safe.
  const AlgorithmStep& step(const Pose& base_T_tip, const Wrench6& wrench_tool) noexcept;

  void cancel() noexcept { out_.status = AlgorithmStatus::Idle; }
  AlgorithmKind kind() const noexcept { return params_.kind; }
  const AlgorithmStep& last() const noexcept { return out_; }
  /// Outcome numbers for the final event.
  double distance_m() const noexcept { return distance_m_; }
  double peak_force_n() const noexcept { return peak_force_n_; }
  /// |T| about the tip, the largest seen since start (what the controller's torque limit checks).
  double peak_torque_nm() const noexcept { return peak_torque_nm_; }
  double spiral_radius_m() const noexcept { return spiral_r_; }
  /// Insert phase, for telemetry/tests: 0 approach/push, 1 spiral search, 2 entered.
  int phase() const noexcept { return phase_; }

 private:
  void finish(AlgorithmStatus status, Reason code, const char* text) noexcept;
  void step_guarded(const Pose& tip, const Eigen::Vector3d& f_task) noexcept;
  void step_insert(const Pose& tip, const Eigen::Vector3d& f_task) noexcept;
  void step_pull_out(const Pose& tip, const Eigen::Vector3d& f_task) noexcept;

  AdmittanceParams base_;
  AlgorithmParams params_{};
  AlgorithmStep out_{};
  Pose base_T_start_ = Pose::Identity();
  Eigen::Vector3d dir_task_ = Eigen::Vector3d::UnitZ();  // guarded move, in the task frame
  Eigen::Matrix3d base_R_task_ = Eigen::Matrix3d::Identity();
  double dt_ = 0.002;
  double t_ = 0.0;
  double timeout_s_ = 0.0;
  double s_ref_ = 0.0;          // reference travel along the axis
  Eigen::Vector2d lateral_ref_ = Eigen::Vector2d::Zero();
  int phase_ = 0;
  double stall_timer_ = 0.0;
  double stall_depth_ = 0.0;    // measured depth at the start of the current stall window
  double contact_depth_ = 0.0;  // depth where the search began
  double theta_ = 0.0;
  double spiral_r_ = 0.0;
  double distance_m_ = 0.0;
  double peak_force_n_ = 0.0;
  double peak_torque_nm_ = 0.0;
};

}  // namespace foresight::control
