#pragma once
// Trajectory generation for the operator: from the arm's joint angles through
// a list of goals (task-object tag frames for the tool tip, or joint vectors)
// to one time-stamped trajectory (common/trajectory) that the ground previews
// and the remote runs once it has arrived whole. In foresight_common (no GL,
// no OpenCV) so the remote's GOTO_CART / GOTO_JOINT plan exactly the path the
// ground previews.
//
// Segments are minimum-jerk (quintic, zero velocity and acceleration at both
// ends) either in joint space, or along a straight line of the tool tip with
// its orientation interpolated on the geodesic ("linear": the insertion and
// extraction moves along the hole axis), solved by inverse kinematics at every
// sample seeded by the previous one. Durations are the shortest that keep
// every joint within a fraction of its URDF velocity and acceleration limits
// (and a linear move within the tool speed). Not real-time code.

#include <Eigen/Core>
#include <stdexcept>
#include <string>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/trajectory.hpp"

namespace foresight {

/// A goal cannot be planned (IK fails, a linear move leaves the workspace or
/// flips the arm's configuration, bad options). The message names the goal.
class PlanError : public ComputationError {
 public:
  using ComputationError::ComputationError;
};

enum class SegmentKind { Joint, Linear };
const char* to_string(SegmentKind kind);

struct Goal {
  std::string name;                       ///< for messages and the summary
  SegmentKind kind = SegmentKind::Joint;
  bool is_pose = true;                    ///< base_T_tip target; else q
  Pose base_T_tip = Pose::Identity();
  Eigen::VectorXd q;                      ///< joint target (Joint kind only)
};

struct PlanOptions {
  double rate_hz = 100.0;          ///< sample rate of the trajectory
  double limit_fraction = 0.5;     ///< of each joint's URDF velocity and acceleration limit, (0, 1]
  double tool_speed_m_s = 0.05;    ///< peak tip speed of a linear move
  double tool_accel_m_s2 = 0.1;    ///< peak tip acceleration of a linear move
  double tool_rate_rad_s = 0.25;   ///< peak tip rotation rate of a linear move
  double dwell_s = 0.0;            ///< pause at every goal
  double min_segment_s = 0.2;
  /// A linear move may not change any joint by more than this between two
  /// samples (an IK branch flip shows as a jump).
  double max_joint_step_rad = 0.05;
  double position_tolerance_m = 1e-5;
  double rotation_tolerance_rad = 1e-5;
};

struct PlannedSegment {
  std::string goal;
  SegmentKind kind = SegmentKind::Joint;
  double start_s = 0.0;
  double duration_s = 0.0;
  Eigen::VectorXd q_end;
  double position_error_m = 0.0;   ///< tip vs goal at the end (pose goals)
  double rotation_error_rad = 0.0;
  double peak_velocity_fraction = 0.0;  ///< max |qdot| / limit over the segment's samples
};

struct Plan {
  Trajectory trajectory;
  std::vector<PlannedSegment> segments;
};

/// Plans q_start -> goals[0] -> goals[1] -> ... The trajectory starts at t = 0
/// at q_start and passes validate() against the model's limits.
Plan plan_motion(const RobotModel& model, const Eigen::VectorXd& q_start, const std::vector<Goal>& goals,
                 const PlanOptions& options = {});

/// Minimum-jerk profile s(tau) on [0, 1] and its peak factors:
/// max ds/dtau = 1.875, max d2s/dtau2 = 10 / sqrt(3).
double min_jerk(double tau);

}  // namespace foresight
