// The tip's error at the hole against known answers: a tag's covariance by
// the rigid-body Jacobian, the estimate's position error seen in the hole's
// frame, the tool's link and encoder sensitivities on the configured arm.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/contact_check/tip_error.hpp"

namespace {

using namespace foresight;
using namespace foresight::contact_check;

Pose translation(double x, double y, double z) { return Pose(Eigen::Translation3d(x, y, z)); }

TEST(TagCovariance, PositionErrorCarriesOverAndYawSwingsTheTag) {
  Matrix6 C = Matrix6::Zero();
  C.bottomRightCorner<3, 3>() = Eigen::Vector3d(1e-6, 4e-6, 9e-6).asDiagonal();
  const double s_yaw = 0.01;
  C(2, 2) = s_yaw * s_yaw;
  const Matrix6 T = tag_covariance_base(translation(0.5, 0.1, 0.3), C, translation(0.2, 0.0, 0.0));
  EXPECT_NEAR(T(3, 3), 1e-6, 1e-12);
  EXPECT_NEAR(T(4, 4), 4e-6 + 0.2 * 0.2 * s_yaw * s_yaw, 1e-12);  // yaw swings a tag 20 cm out sideways
  EXPECT_NEAR(T(5, 5), 9e-6, 1e-12);
  EXPECT_NEAR(T(2, 2), s_yaw * s_yaw, 1e-12);
}

TEST(TipErrorAtHole, TheEstimatesPositionErrorInTheHolesFrame) {
  ObjectEstimate est;
  est.base_T_object = translation(0.6, 0.0, 0.4) * Pose(Eigen::AngleAxisd(0.5 * M_PI, Eigen::Vector3d::UnitY()));
  const Eigen::Matrix3d Cp = Eigen::Vector3d(1e-6, 4e-6, 9e-6).asDiagonal();  // base x, y, z
  est.covariance.bottomRightCorner<3, 3>() = Cp;
  const Pose tag = translation(0, 0, -0.005);
  const LocalCovariance e = tip_error_at_hole(est, Pose::Identity(), tag, ToolTip{}, ArmUncertainty{});
  EXPECT_NEAR(e.mean[5], -0.005, 1e-12);
  EXPECT_NEAR(e.mean.head<5>().norm(), 0.0, 1e-12);
  // The hole's axes in base: x -> -z, y -> y, z -> x.
  const Eigen::Matrix3d R = est.base_T_object.linear();
  const Eigen::Matrix3d expected = R.transpose() * Cp * R;
  EXPECT_LT((e.covariance.bottomRightCorner<3, 3>() - expected).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(e.covariance(5, 5), 1e-6, 1e-12);  // axial = base x
  EXPECT_NEAR(e.covariance(3, 3), 9e-6, 1e-12);  // lateral x = base -z
}

struct Arm : ::testing::Test {
  RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  Pose base_T_oru = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml").base_T_object;
};

TEST_F(Arm, TheToolLinkMovesTheTipAlongItsAxis) {
  const Pose base_T_tag = base_T_oru * oru.tags.at("hole_entrance");
  const ToolTip tip = tool_tip_uncertainty(robot, base_T_tag, {0.002, 0.0});
  KinematicsWorkspace ws{robot};
  EXPECT_LT((forward_kinematics(robot, ws, tip.q).translation() - base_T_tag.translation()).norm(), 2e-4);
  const std::vector<int> links = robot.offset_segments();
  ASSERT_EQ(tip.link_sensitivity.cols(), static_cast<Eigen::Index>(links.size()));
  // The last offset (lst -> lst_tip, 26 cm along the tool axis): 1 m per m along z.
  Vector6 along_z = Vector6::Zero();
  along_z[5] = 1.0;
  EXPECT_LT((tip.link_sensitivity.rightCols<1>() - along_z).norm(), 1e-6);
  EXPECT_NEAR(tip.covariance(5, 5), (0.002 * 0.002 * tip.link_sensitivity.row(5).squaredNorm()), 1e-15);
}

TEST_F(Arm, EncodersMoveTheTipByTheJacobian) {
  const Pose base_T_tag = base_T_oru * oru.tags.at("hole_entrance");
  const double s = 1e-4;
  const ToolTip tip = tool_tip_uncertainty(robot, base_T_tag, {0.0, s});
  KinematicsWorkspace ws{robot};
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, robot.dof());
  jacobian(robot, ws, tip.q, J);
  // The position rows of the base-frame Jacobian, in the tip's frame.
  const Eigen::Matrix3d R = forward_kinematics(robot, ws, tip.q).linear();
  const Eigen::MatrixXd Jp = R.transpose() * J.topRows<3>();
  const Eigen::Matrix3d expected = s * s * Jp * Jp.transpose();
  EXPECT_LT((tip.covariance.bottomRightCorner<3, 3>() - expected).cwiseAbs().maxCoeff(), 1e-6 * expected.cwiseAbs().maxCoeff());
}

TEST_F(Arm, AnUnreachableTagIsRefused) {
  EXPECT_THROW(tool_tip_uncertainty(robot, translation(5.0, 0, 0), {}), std::runtime_error);
}

}  // namespace
