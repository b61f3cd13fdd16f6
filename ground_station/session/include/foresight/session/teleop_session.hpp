#pragma once
// `foresight teleop`'s work: hand-controller teleoperation of the ground's
// simulated arm (Kim 1996's world / tool / camera-view referenced Cartesian
// modes) from a Linux joystick (evdev) or a recorded input file, through the
// remote's own damped-least-squares inverse Jacobian (foresight_teleop); the
// motion checked under the remote's rules and, when valid, recorded as a
// trajectory CSV. Nothing is sent: the operator previews it, then sends it.

#include <atomic>
#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

namespace foresight::session {

struct TeleopRequest {
  std::string device;  ///< a Linux joystick (/dev/input/eventN); or
  std::string input;   ///< a recorded input file (t,x,y,z,rx,ry,rz)
  std::string frame = "world";  ///< world | tool | camera
  std::string camera;           ///< --frame camera: the camera
  std::string cameras;          ///< calibrated cameras.yaml (empty: the work site's layout)
  std::string joints, joints_deg;  ///< the start, one of them
  double position_gain_m_s = 0.05, orientation_gain_deg_s = 10.0, deadband = 0.05, rate_hz = 100.0;
  double duration_s = 0.0;  ///< device: 0 = until a button or the stop flag (at most an hour)
  std::string axes = "X,Y,Z,RX,RY,RZ";
  std::string record;        ///< write the motion as a trajectory CSV (when valid)
  std::string record_input;  ///< device: write the deflections as a recorded input file
  std::string robot, scene;
};

struct TeleopOutcome {
  std::string source;        ///< the device or the input file
  std::string device_name;   ///< the device's own name (device only)
  std::string camera_source; ///< where the camera frame came from (camera frame only)
  std::string ended_by = "end of input";  ///< duration | button | interrupt | end of input
  std::size_t input_samples = 0;
  int samples = 0;
  double duration_s = 0.0;
  Eigen::VectorXd q_start, q_end;
  Eigen::Vector3d tip_start_m, tip_end_m;
  Eigen::Vector3d displacement_base_m, displacement_frame_m;  ///< the frame: as at the start
  Eigen::Vector3d rotation_base_rad;  ///< angle * axis
  double turn_rad = 0.0;
  bool valid = false;
  std::size_t violations = 0;
  std::string first_violation;
  std::string sha256;
  std::string record;  ///< written to (empty: not written)
};

/// Run one teleoperation. `progress` (may be null) gets the device's
/// greeting; `stop` (may be null) ends a device's reading (Ctrl-C).
/// Bad options throw std::invalid_argument, bad files InputError.
TeleopOutcome teleoperate(const TeleopRequest& request, std::ostream* progress, const std::atomic<bool>* stop);

/// `foresight teleop --json`'s object.
nlohmann::json teleop_json(const TeleopRequest& request, const TeleopOutcome& outcome);

}  // namespace foresight::session
