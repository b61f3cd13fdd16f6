#pragma once
// Teleoperation model (Kim 1996's hand-controller mode, on the ground's
// simulated arm): a 6-axis hand controller's deflections, each in [-1, 1], are
// a tool-tip twist in the world (robot base), tool, or camera-view frame,
// scaled by a position and an orientation gain; the twist goes through the
// same damped-least-squares inverse Jacobian as the remote's compliance
// (dls_step, common kinematics) to joint steps, kept within the joint position, velocity and acceleration limits. The motion
// can be recorded as a trajectory (common/trajectory) for preview and sending.
//
// Input for tests and replays: a recorded CSV `t,x,y,z,rx,ry,rz` (s, then the
// six deflections). A Linux joystick (evdev) would feed the same samples.
// Set-up (constructors, readers) may throw; step() does not allocate once
// recording is off (it is not used in the remote's real-time loop).

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"

namespace foresight::teleop {

enum class ReferenceFrame { World, Tool, Camera };
const char* to_string(ReferenceFrame frame) noexcept;
/// "world" | "tool" | "camera"; std::invalid_argument otherwise.
ReferenceFrame parse_reference_frame(const std::string& name);

/// Deflections: x y z (translation), rx ry rz (rotation about those axes).
using Axes = std::array<double, 6>;

struct HandSample {
  double t_s = 0.0;
  Axes axes{};
};

/// Reads `t,x,y,z,rx,ry,rz` with a header. InputError "<file>:<line>: ..."
/// for a missing header, a wrong field count, a non-number, a deflection
/// outside [-1, 1], or time not increasing.
std::vector<HandSample> read_hand_input_csv(const std::string& path);

struct TeleopOptions {
  ReferenceFrame frame = ReferenceFrame::World;
  Pose base_T_camera = Pose::Identity();  ///< camera-view mode: camera x right, y down, z forward
  double position_gain_m_s = 0.05;        ///< tip speed at full deflection
  double orientation_gain_rad_s = 0.2;    ///< tip rotation rate at full deflection
  double deadband = 0.05;                 ///< |deflection| below this is zero
  /// The commanded twist changes at most this fast (so a recorded motion
  /// keeps within the joint acceleration limits the remote checks).
  double linear_accel_m_s2 = 0.2;
  double angular_accel_rad_s2 = 1.0;
  double velocity_fraction = 0.5;         ///< of each joint's URDF velocity limit
  /// Of each joint's URDF acceleration limit: the joint velocities change at
  /// most this fast (the motion the remote executes, the spline through the
  /// record, stays within the limit validate() checks).
  double joint_accel_fraction = 0.5;
  double lambda_max = 0.05;               ///< DLS damping near singularities
};

class TeleopModel {
 public:
  /// std::invalid_argument for a wrong joint count or non-positive gains.
  TeleopModel(const RobotModel& model, const Eigen::VectorXd& q0, TeleopOptions options);

  /// The tip twist in the base frame (v m/s, w rad/s) the deflections command
  /// at the current joints (tool mode rotates with the tool).
  Eigen::Matrix<double, 6, 1> twist_base(const Axes& axes);
  /// Moves the simulated arm by one step of dt seconds: the commanded twist
  /// (ramped within the accelerations) through the DLS inverse Jacobian.
  void step(const Axes& axes, double dt_s);
  const Eigen::VectorXd& q() const noexcept { return q_; }
  /// The commanded twist and the joints' velocity are zero.
  bool at_rest() const noexcept { return twist_.isZero(0.0) && qdot_.isZero(0.0); }
  Pose base_T_tip();

  /// Recording: every step's joints from now (t = 0 at start), until stop.
  void start_recording();
  void stop_recording();
  /// The recorded motion (needs >= 2 steps): starts at the joints where
  /// recording started.
  Trajectory recorded() const;

 private:
  const RobotModel& model_;
  TeleopOptions o_;
  KinematicsWorkspace ws_;
  Eigen::VectorXd q_;
  Eigen::VectorXd qdot_;  ///< the last step's joint velocities
  Eigen::Matrix<double, 6, 1> twist_ = Eigen::Matrix<double, 6, 1>::Zero();  ///< last commanded, base frame
  bool recording_ = false;
  double t_ = 0.0;
  std::vector<double> times_;
  std::vector<Eigen::VectorXd> qs_;
};

/// Plays recorded hand input from q0 at `rate_hz` (the input held between its
/// samples), then lets go of the hand (the twist brakes to zero at the
/// model's accelerations), and returns the whole motion, from rest to rest,
/// as a trajectory.
Trajectory play(const RobotModel& model, const Eigen::VectorXd& q0, const std::vector<HandSample>& input,
                const TeleopOptions& options, double rate_hz = 100.0);

}  // namespace foresight::teleop
