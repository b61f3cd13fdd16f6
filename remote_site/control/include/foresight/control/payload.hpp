#pragma once
// identify_payload: what hangs on the wrist F/T sensor (the tool, plus the
// ORU while it is carried), identified from a few static poses.
//
// Model (sensor frame; u = R^T g / |g| the unit gravity in the sensor frame,
// R = base_R_sensor, g the base-frame gravity):
//     f   = m |g| u + f0                 (force reading)
//     tau = (m |g| c) x u + tau0         (torque reading about the sensor origin)
// linear in x_f = (m |g|, f0) and x_t = (m |g| c, tau0):
//     f   = [u  I] x_f,       tau = [-[u]x  I] x_t
// Every pose adds its averaged reading: two small least-squares problems
// (4 and 6 unknowns) solved from their fixed-size normal equations. The
// condition number (of the regressors, the largest of the two) says whether
// the poses excite the model: the torque's needs two gravity directions, the
// force's separates the weight from the offset only as u changes.
//
// The poses: the start, then the wrist's last three joints turned by
// +-angle_rad (joint n-1 both ways, n-2 both ways, n once; a side beyond the
// joint's limit is replaced by the other side, both beyond: refused): stiff, smooth
// (quintic) moves of move_s, then settle_s at rest (every joint within 2 mrad
// of its pose and slower than 0.01 rad/s), then the reading averaged over
// window_s; at the end back to the start, where the result applies.
//
// Set-up: nothing (lives in the Controller). Real-time (noexcept, no
// allocation, fixed-size Eigen only): everything.

#include <Eigen/Core>
#include <array>
#include <cstddef>

#include "foresight/control/command.hpp"
#include "foresight/control/compliance.hpp"
#include "foresight/control/rt_types.hpp"

namespace foresight::control {

/// One pose: its orientation and the reading averaged there.
struct PayloadPose {
  Eigen::Matrix3d base_R_sensor = Eigen::Matrix3d::Identity();
  Wrench6 ft{};
};

struct PayloadFit {
  PayloadMass payload{};           ///< mass, centre of mass in the sensor frame
  Wrench6 offset_ft{};         ///< the reading with nothing on the sensor (f0, tau0)
  double condition = 0.0;      ///< of the regressors (the larger of force and torque)
  double residual_n = 0.0;     ///< RMS over the poses of |f - model|
  double residual_nm = 0.0;    ///< RMS over the poses of |tau - model|
};

/// Least squares over n poses (n >= 2). RT-safe.
PayloadFit fit_payload(const PayloadPose* poses, std::size_t n, const Eigen::Vector3d& gravity_base) noexcept;

class PayloadIdentifier {
 public:
  static constexpr std::size_t kPoses = 6;
  enum class Status : std::uint8_t { Idle = 0, Running, Succeeded, Failed };

  /// The parameters' ranges (BadArgument with text naming the parameter).
  static bool validate(const IdentifyPayloadParams& p, Reason& code, std::array<char, 96>& text) noexcept;

  /// Begin at q_start (the held command). Refused (false, code, text): bad
  /// parameters, the arm in contact (contact_n, the compensated force, above
  /// max_contact_n), not at rest (max_speed = the fastest joint, rad/s, above
  /// 0.01), a pose outside the joint limits.
  bool start(const IdentifyPayloadParams& p, const JointArray& q_start, std::size_t dof, const JointArray& lower,
             const JointArray& upper, double contact_n, double max_speed, double dt, Reason& code,
             std::array<char, 96>& text) noexcept;
  /// One cycle: the measured joints, the sensor's orientation, the reading
  /// (bias removed by the decoder's tare; `fresh` a new sample). target() is
  /// the joint command to send.
  Status step(const JointArray& q, const Eigen::Matrix3d& base_R_sensor, const Wrench6& ft, bool fresh,
              const Eigen::Vector3d& gravity_base) noexcept;
  void cancel() noexcept { status_ = Status::Idle; }

  /// The k-th pose's joints (k < kPoses), from start().
  const JointArray& goal(std::size_t k) const noexcept { return goals_[k]; }
  /// The refusal when the poses' orientations do not excite the model
  /// (condition above max_condition): false with code and text. RT-safe.
  bool check_excitation(const PayloadPose* poses, std::size_t n, const Eigen::Vector3d& gravity_base, Reason& code,
                        std::array<char, 96>& text) const noexcept;
  Status status() const noexcept { return status_; }
  const JointArray& target() const noexcept { return target_; }
  const PayloadFit& fit() const noexcept { return fit_; }
  Reason code() const noexcept { return code_; }
  const std::array<char, 96>& text() const noexcept { return text_; }

 private:
  enum class Phase : std::uint8_t { Move, Settle, Average, Return };
  void begin_move(const JointArray& to) noexcept;
  void fail(Reason code, const char* text) noexcept;

  IdentifyPayloadParams p_{};
  std::size_t dof_ = 0;
  double dt_ = 0.002;
  Status status_ = Status::Idle;
  Phase phase_ = Phase::Move;
  std::array<JointArray, kPoses> goals_{};
  std::size_t pose_ = 0;
  JointArray from_{}, to_{}, target_{}, q_prev_{};
  double t_ = 0.0;          // in the phase
  double move_s_ = 0.0;     // of the current move
  double still_s_ = 0.0;    // at rest so far (Settle)
  std::array<PayloadPose, kPoses> poses_{};
  Wrench6 sum_{};
  int samples_ = 0;
  PayloadFit fit_{};
  Reason code_ = Reason::None;
  std::array<char, 96> text_{};
};

}  // namespace foresight::control
