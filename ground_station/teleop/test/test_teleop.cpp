// Teleoperation model: in each reference frame a deflection moves (or turns)
// the simulated tool tip along the commanded direction within 1 deg, at the
// gain's speed; recorded motion is a valid trajectory; bad input files are
// named with their line.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "foresight/common/error.hpp"
#include "foresight/teleop/teleop.hpp"

namespace foresight::teleop {
namespace {

const RobotModel& model() {
  static const RobotModel m = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  return m;
}

/// A well-conditioned configuration in the middle of the workspace.
Eigen::VectorXd q_work() {
  Eigen::VectorXd q(7);
  q << 0.1, 0.5, -0.1, -1.2, 0.2, 0.6, 0.1;
  return q;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

/// The direction the tip moved (or the rotation axis) after 1 s of one axis at 0.6.
struct Moved {
  Eigen::Vector3d displacement;
  Eigen::Vector3d rotation;  ///< rotation vector, base frame
};
Moved drive(TeleopOptions o, int axis) {
  TeleopModel m(model(), q_work(), o);
  const Pose a = m.base_T_tip();
  Axes ax{};
  ax[static_cast<std::size_t>(axis)] = 0.6;
  for (int i = 0; i < 100; ++i) m.step(ax, 0.01);
  const Pose b = m.base_T_tip();
  const Eigen::AngleAxisd r(b.linear() * a.linear().transpose());
  return {b.translation() - a.translation(), r.angle() * r.axis()};
}

Pose camera_pose() {
  // A camera looking along base -y... tilted: an arbitrary but fixed orientation.
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-2.0, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.5, -1.5, 1.2);
  return T;
}

TEST(Teleop, EachFrameMovesTheToolAsCommandedWithin1Deg) {
  TeleopModel probe(model(), q_work(), {});
  const Eigen::Matrix3d R_tool = probe.base_T_tip().linear();
  for (const ReferenceFrame frame : {ReferenceFrame::World, ReferenceFrame::Tool, ReferenceFrame::Camera}) {
    TeleopOptions o;
    o.frame = frame;
    o.base_T_camera = camera_pose();
    const Eigen::Matrix3d R = frame == ReferenceFrame::World  ? Eigen::Matrix3d::Identity()
                              : frame == ReferenceFrame::Tool ? R_tool
                                                              : o.base_T_camera.linear();
    for (int axis = 0; axis < 3; ++axis) {
      const Moved m = drive(o, axis);
      const Eigen::Vector3d expected = R.col(axis);
      EXPECT_LT(angle_deg(m.displacement, expected), 1.0) << to_string(frame) << " axis " << axis;
      // 1 s at 0.6 x 0.05 m/s after a 0.15 s ramp at 0.2 m/s^2: 2.775 cm, within 3%.
      EXPECT_NEAR(m.displacement.norm(), 0.03 - 0.5 * 0.15 * 0.03, 0.0008) << to_string(frame) << " axis " << axis;
      EXPECT_LT(m.rotation.norm(), 1e-3) << "a translation command must not turn the tool";
    }
    for (int axis = 3; axis < 6; ++axis) {
      const Moved m = drive(o, axis);
      // In tool mode the axis turns with the tool, but a rotation about a tool
      // axis leaves that axis fixed, so the start frame's axis is the truth.
      const Eigen::Vector3d expected = R.col(axis - 3);
      EXPECT_LT(angle_deg(m.rotation, expected), 1.0) << to_string(frame) << " axis " << axis;
      // 0.6 x 0.2 rad/s for 1 s after a 0.12 s ramp at 1 rad/s^2, less where
      // a joint's acceleration bound (half its limit) lengthens the ramp
      // (tool axis 3: 0.1096 rad, 2.9% short).
      EXPECT_NEAR(m.rotation.norm(), 0.12 - 0.5 * 0.12 * 0.12, 0.004) << to_string(frame) << " axis " << axis;
      EXPECT_LT(m.displacement.norm(), 1e-3) << "a rotation about the tip must not move it";
    }
  }
}

TEST(Teleop, DeadbandAndVelocityLimits) {
  TeleopOptions o;
  o.deadband = 0.1;
  TeleopModel m(model(), q_work(), o);
  const Eigen::VectorXd q0 = m.q();
  m.step({0.05, -0.09, 0, 0, 0.08, 0}, 0.01);
  EXPECT_EQ((m.q() - q0).norm(), 0.0);
  // A huge gain (and ramp) is slowed to the joint velocity limits.
  o.position_gain_m_s = 50.0;
  o.linear_accel_m_s2 = 1e6;
  TeleopModel fast(model(), q_work(), o);
  fast.step({1, 0, 0, 0, 0, 0}, 0.01);
  const Eigen::VectorXd dq = fast.q() - q_work();
  for (int i = 0; i < 7; ++i)
    EXPECT_LE(std::abs(dq[i]), 0.5 * model().limits()[i].velocity_rad_s * 0.01 + 1e-12) << i;
}

TEST(Teleop, PlayedInputIsAValidTrajectoryFromRestToRest) {
  const std::string path = ::testing::TempDir() + "/hand.csv";
  std::ofstream(path) << "t,x,y,z,rx,ry,rz\n0,0.5,0,0,0,0,0\n1,0,0,-0.5,0,0,0\n2,0,0,0,0,0,0.5\n3,0,0,0,0,0,0\n";
  const auto input = read_hand_input_csv(path);
  ASSERT_EQ(input.size(), 4u);
  const Trajectory t = play(model(), q_work(), input, {}, 100.0);
  // 3 s of input (its last sample only ends it), then the hand lets go: the
  // last twist, 0.5 x 0.2 rad/s about z, brakes at 1 rad/s^2 in 0.1 s
  // (10 steps, or 11 when the steps' rounding leaves a residue).
  EXPECT_GE(t.samples(), 311);
  EXPECT_LE(t.samples(), 312);
  EXPECT_NEAR(t.duration_s(), 0.01 * (t.samples() - 1), 1e-9);
  EXPECT_EQ((t.positions_rad.row(0).transpose() - q_work()).norm(), 0.0);
  // At rest at the end: the last step commands nothing.
  EXPECT_EQ((t.positions_rad.row(t.samples() - 1) - t.positions_rad.row(t.samples() - 2)).norm(), 0.0);
  const auto violations = validate(t, TrajectoryLimits::from_model(model()));
  EXPECT_TRUE(violations.empty()) << violations.front().message;
}

TEST(Teleop, BadHandInputNamesTheLine) {
  const auto error = [](const std::string& text) {
    const std::string path = ::testing::TempDir() + "/bad_hand.csv";
    std::ofstream(path) << text;
    try {
      read_hand_input_csv(path);
    } catch (const InputError& e) {
      return std::string(e.what()).substr(path.size());
    }
    return std::string("(no error)");
  };
  EXPECT_EQ(error("t,x,y\n"), ":1: expected the header t,x,y,z,rx,ry,rz");
  EXPECT_EQ(error("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0\n"), ":2: expected 7 fields (t,x,y,z,rx,ry,rz), got 6");
  EXPECT_EQ(error("t,x,y,z,rx,ry,rz\n0,0,0,0,0,0,0\n1,0,abc,0,0,0,0\n"), ":3: field 3 ('abc') is not a finite number");
  EXPECT_EQ(error("t,x,y,z,rx,ry,rz\n0,0,0,1.5,0,0,0\n"), ":2: deflection 3 = 1.5 is outside [-1, 1]");
  EXPECT_EQ(error("t,x,y,z,rx,ry,rz\n1,0,0,0,0,0,0\n1,0,0,0,0,0,0\n"), ":3: time must increase");
  EXPECT_THROW(parse_reference_frame("screen"), std::invalid_argument);
  EXPECT_EQ(parse_reference_frame("camera"), ReferenceFrame::Camera);
}

}  // namespace
}  // namespace foresight::teleop
