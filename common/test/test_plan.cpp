// Trajectory generation: goals reached, straight lines straight, limits kept
// (checked by the same validate() the remote runs), min-jerk timing as
// computed by hand, and every failure named.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/plan.hpp"
#include "foresight/common/scene.hpp"

using namespace foresight;

namespace {

struct Site {
  RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
  Goal tag(const std::string& name, SegmentKind kind) const {
    Goal g;
    g.name = name;
    g.kind = kind;
    g.base_T_tip = base_T_oru * oru.tags.at(name);
    return g;
  }
};

const Site& site() {
  static const Site s;
  return s;
}

Eigen::VectorXd start_q() {
  Eigen::VectorXd q(7);
  q << 0.3, 0.4, 0.0, -1.2, 0.0, 0.6, 0.0;
  return q;
}

}  // namespace

TEST(MinJerk, ProfileAndPeaks) {
  EXPECT_DOUBLE_EQ(min_jerk(0.0), 0.0);
  EXPECT_DOUBLE_EQ(min_jerk(1.0), 1.0);
  EXPECT_DOUBLE_EQ(min_jerk(0.5), 0.5);
  EXPECT_DOUBLE_EQ(min_jerk(-1.0), 0.0);
  // Peak slope 1.875 at the middle; peak curvature 10/sqrt(3) at tau = 0.5 -+ sqrt(3)/6.
  const double h = 1e-5;
  EXPECT_NEAR((min_jerk(0.5 + h) - min_jerk(0.5 - h)) / (2 * h), 1.875, 1e-8);
  const double t1 = 0.5 - std::sqrt(3.0) / 6.0;
  EXPECT_NEAR((min_jerk(t1 + h) - 2 * min_jerk(t1) + min_jerk(t1 - h)) / (h * h), 10.0 / std::sqrt(3.0), 1e-3);
}

TEST(Plan, JointMoveIsTimedByTheSlowestJointAndReachesTheGoal) {
  const auto& s = site();
  Goal g;
  g.name = "pose";
  g.is_pose = false;
  g.q = start_q();
  g.q[0] += 0.9;  // joint1: 0.9 rad, limits 0.9 rad/s and 2.0 rad/s^2
  PlanOptions o;
  o.limit_fraction = 0.5;
  const Plan p = plan_motion(s.robot, start_q(), {g}, o);
  // T = max(1.875 * 0.9 / 0.45, sqrt(5.7735 * 0.9 / 1.0)) = 3.75 s, 375 samples after t = 0.
  ASSERT_EQ(p.segments.size(), 1u);
  EXPECT_NEAR(p.segments[0].duration_s, 3.75, 1e-9);
  EXPECT_EQ(p.trajectory.samples(), 376);
  EXPECT_NEAR(p.trajectory.duration_s(), 3.75, 1e-9);
  EXPECT_TRUE((p.trajectory.positions_rad.bottomRows(1).transpose() - g.q).isZero(1e-12));
  EXPECT_NEAR(p.segments[0].peak_velocity_fraction, 0.5, 0.005);
  EXPECT_TRUE(validate(p.trajectory, TrajectoryLimits::from_model(s.robot)).empty());
}

TEST(Plan, InsertionIsAStraightLineAlongTheHoleAxis) {
  const auto& s = site();
  const Plan p = plan_motion(s.robot, start_q(),
                             {s.tag("approach_20cm", SegmentKind::Joint), s.tag("hole_entrance", SegmentKind::Linear),
                              s.tag("tool_inserted", SegmentKind::Linear)});
  ASSERT_EQ(p.segments.size(), 3u);
  for (const auto& seg : p.segments) {
    EXPECT_LT(seg.position_error_m, 2e-5) << seg.goal;
    EXPECT_LT(seg.rotation_error_rad, 2e-5) << seg.goal;
  }
  EXPECT_TRUE(validate(p.trajectory, TrajectoryLimits::from_model(s.robot)).empty());
  // Every sample of the linear segments: the tip on the hole axis (oru x = y = 0),
  // its orientation the tag's, its depth monotonic from -0.20 m to +0.06 m.
  KinematicsWorkspace ws(s.robot);
  const double t_lin = p.segments[1].start_s;
  double last_z = -1.0;
  int checked = 0;
  for (int i = 0; i < p.trajectory.samples(); ++i) {
    if (p.trajectory.time_s[i] < t_lin) continue;
    const Pose oru_T_tip =
        s.base_T_oru.inverse() * forward_kinematics(s.robot, ws, p.trajectory.positions_rad.row(i).transpose());
    EXPECT_NEAR(oru_T_tip.translation().x(), 0.0, 2e-5) << "t " << p.trajectory.time_s[i];
    EXPECT_NEAR(oru_T_tip.translation().y(), 0.0, 2e-5) << "t " << p.trajectory.time_s[i];
    EXPECT_LT(rotation_distance(oru_T_tip.linear(), Eigen::Matrix3d::Identity()), 2e-5);
    EXPECT_GE(oru_T_tip.translation().z(), last_z - 1e-6);
    last_z = oru_T_tip.translation().z();
    ++checked;
  }
  EXPECT_GT(checked, 300);
  EXPECT_NEAR(last_z, 0.06, 2e-5);
  // The 0.20 m approach at 0.05 m/s peak: T = 1.875 * 0.2 / 0.05 = 7.5 s (rounded up to a sample).
  EXPECT_NEAR(p.segments[1].duration_s, 7.5, 0.011);
}

TEST(Plan, DwellHoldsAtEveryGoal) {
  const auto& s = site();
  PlanOptions o;
  o.dwell_s = 0.5;
  const Plan p = plan_motion(s.robot, start_q(), {s.tag("approach_20cm", SegmentKind::Joint)}, o);
  const int n = p.trajectory.samples();
  for (int i = n - 50; i < n; ++i)
    EXPECT_TRUE((p.trajectory.positions_rad.row(i) - p.trajectory.positions_rad.row(n - 51)).isZero(0.0));
  EXPECT_NEAR(p.trajectory.duration_s(), p.segments[0].duration_s + 0.5, 1e-9);
}

TEST(PlanBadInput, EachFailureNamesTheGoal) {
  const auto& s = site();
  Goal far;
  far.name = "far_away";
  far.base_T_tip = make_pose({3.0, 0.0, 0.5}, {0.0, M_PI / 2, 0.0});
  try {
    plan_motion(s.robot, start_q(), {far});
    FAIL() << "no error";
  } catch (const PlanError& e) {
    EXPECT_NE(std::string(e.what()).find("goal 'far_away': inverse kinematics did not reach it (residual "),
              std::string::npos)
        << e.what();
  }
  // A straight line from the approach point through the ORU and far beyond it
  // leaves the arm's reach.
  Goal beyond = s.tag("approach_20cm", SegmentKind::Linear);
  beyond.name = "beyond";
  beyond.base_T_tip.translation() += 2.0 * (s.base_T_oru.linear() * Eigen::Vector3d::UnitZ());
  try {
    plan_motion(s.robot, start_q(), {s.tag("approach_20cm", SegmentKind::Joint), beyond});
    FAIL() << "no error";
  } catch (const PlanError& e) {
    EXPECT_NE(std::string(e.what()).find("goal 'beyond': the straight line leaves the arm's reach at "),
              std::string::npos)
        << e.what();
  }
  Goal joints;
  joints.name = "q";
  joints.is_pose = false;
  joints.q = Eigen::VectorXd::Zero(6);
  EXPECT_THROW(
      {
        try {
          plan_motion(s.robot, start_q(), {joints});
        } catch (const PlanError& e) {
          EXPECT_STREQ(e.what(), "goal 'q': 6 joint values, the arm has 7");
          throw;
        }
      },
      PlanError);
  joints.kind = SegmentKind::Linear;
  joints.q = start_q();
  EXPECT_THROW(plan_motion(s.robot, start_q(), {joints}), PlanError);
  Eigen::VectorXd out_of_limits = start_q();
  out_of_limits[3] = 3.0;
  try {
    plan_motion(s.robot, out_of_limits, {s.tag("approach_20cm", SegmentKind::Joint)});
    FAIL() << "no error";
  } catch (const PlanError& e) {
    EXPECT_STREQ(e.what(), "start joints: joint4 is outside its limits");
  }
  PlanOptions bad;
  bad.limit_fraction = 1.5;
  EXPECT_THROW(plan_motion(s.robot, start_q(), {s.tag("approach_20cm", SegmentKind::Joint)}, bad), InputError);
  EXPECT_THROW(plan_motion(s.robot, start_q(), {}), PlanError);
}
