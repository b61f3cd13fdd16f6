// `foresight eval insertion` end to end (issue 30 item 5): a small Monte
// Carlo through the executable, the plant's insertions in the child process
// `foresight-remote simulate-insertions`; the --json contract; bad input.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/contact_check/tip_error.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/test/cli.hpp"

namespace {

using foresight::test::CliRun;
CliRun run(const std::string& args) { return foresight::test::run_foresight(args); }

TEST(EvalInsertionCli, SmallStudyEndToEnd) {
  const CliRun r = run("eval insertion --trials 12 --seed 3 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"trials", "bins", "brier", "no_go_precision", "go_failure_rate", "targets", "trial_records"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["trials"].get<int>(), 12);
  int n = 0;
  for (const auto& b : j["bins"]) {
    for (const char* key : {"p_predicted", "observed_success", "n"}) ASSERT_TRUE(b.contains(key)) << key;
    const double p = b["p_predicted"].get<double>(), o = b["observed_success"].get<double>();
    EXPECT_GE(p, 0.0);
    EXPECT_LE(p, 1.0);
    EXPECT_GE(o, 0.0);
    EXPECT_LE(o, 1.0);
    EXPECT_GE(b["n"].get<int>(), 1);
    n += b["n"].get<int>();
  }
  EXPECT_EQ(n, 12);
  const double brier = j["brier"].get<double>();
  EXPECT_GE(brier, 0.0);
  EXPECT_LE(brier, 1.0);
  for (const char* key : {"no_go_precision", "go_failure_rate"}) {
    EXPECT_GE(j[key].get<double>(), 0.0) << key;
    EXPECT_LE(j[key].get<double>(), 1.0) << key;
  }
  ASSERT_EQ(j["trial_records"].size(), 12u);
  for (const auto& t : j["trial_records"]) {
    for (const char* key : {"p_success", "p_lateral", "p_tilt", "p_axial"}) {
      EXPECT_GE(t[key].get<double>(), 0.0) << key;
      EXPECT_LE(t[key].get<double>(), 1.0) << key;
    }
    EXPECT_GE(t["views"].size(), 1u);
    EXPECT_LE(t["views"].size(), 4u);
    EXPECT_TRUE(t["reason"].is_string());
  }
  EXPECT_EQ(j["go"].get<int>() + j["no_go"].get<int>(), 12);
}

TEST(EvalInsertionCli, BadInput) {
  const CliRun zero = run("eval insertion --trials 0 --json");
  EXPECT_EQ(zero.status, 2);
  EXPECT_EQ(zero.out, "");
  EXPECT_EQ(zero.err, "foresight eval: error: --trials must be at least 1\n");
  const CliRun negative = run("eval insertion --seed -1 --json");
  EXPECT_EQ(negative.status, 2);
  EXPECT_EQ(negative.out, "");
  EXPECT_EQ(negative.err, "foresight eval: error: --seed must be a non-negative integer\n");
  const CliRun remote = run("eval insertion --trials 1 --remote /nonexistent/foresight-remote --json");
  EXPECT_EQ(remote.status, 2);
  EXPECT_NE(remote.err.find("/nonexistent/foresight-remote: not found"), std::string::npos) << remote.err;
}

// The arm-model term's sign and size, noise-free: one link 2 mm longer in
// the true arm than in the ground's model; the cameras calibrated on it and
// the ORU localized from four views (the study's code), then the tool sent
// by the nominal model. The estimate's error is the localization's
// arm_link_sensitivity times the link error (signed), the tool's the tool's
// sensitivity, and the tip's error at the hole is the one tip_error_at_hole
// predicts from the two together (its rank-one covariance for that link,
// whose square root is the shift up to its sign; a wrong sign of one of the
// two correlated terms would change the size).
TEST(EvalInsertion, NoiseFreeLinkErrorMatchesTheLinearPrediction) {
  using namespace foresight;
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel object = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  const RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  localization::StudySetup setup = localization::make_study_setup(scene, object, {});
  localization::choose_calibration_points(setup, localization::arm_calibration_poses(robot));
  const auto dp = localization::calibration_link_sensitivities(setup, robot);
  const double s = 0.002;
  calibration::CalibrationOptions co;
  co.arm_link_sigma_m = s;
  const Pose object_T_hole = object.tags.at("hole_entrance");
  const Pose object_T_start = object_T_hole * Pose(Eigen::Translation3d(0.0, 0.0, -0.005));
  const std::vector<int> links = robot.offset_segments();
  ASSERT_FALSE(links.empty());
  int discriminating = 0;  // links whose wrong sign the check would see
  for (std::size_t k = 0; k < links.size(); ++k) {
    std::vector<double> delta(static_cast<std::size_t>(robot.segment_count()), 0.0);
    delta[static_cast<std::size_t>(links[k])] = s;
    const RobotModel true_arm = robot.with_link_lengths_changed(delta);
    const localization::ClickCalibration cc =
        localization::calibrate_from_arm_clicks(setup, {0, 1, 2, 3}, true_arm, dp, co, [] { return 0.0; });
    localization::LocalizationOptions lo;
    lo.camera_link_sensitivity = cc.link_sensitivity;
    lo.arm_link_sigma_m = s;
    const localization::LocalizationResult lr = localization::localize_object(cc.object, cc.cameras, lo);
    ASSERT_EQ(lr.arm_link_sensitivity.cols(), static_cast<Eigen::Index>(links.size()));
    const auto col = static_cast<Eigen::Index>(k);
    // The estimate: (roll, pitch, yaw, x, y, z) of the estimate less the truth's.
    Eigen::Matrix<double, 6, 1> est_err, truth;
    est_err << rpy_from_rotation(lr.base_T_object.linear()), lr.base_T_object.translation();
    truth << rpy_from_rotation(setup.base_T_object.linear()), setup.base_T_object.translation();
    est_err -= truth;
    const Eigen::Matrix<double, 6, 1> est_pred = lr.arm_link_sensitivity.col(col) * s;
    EXPECT_LT((est_err.tail<3>() - est_pred.tail<3>()).norm(), 0.1 * est_pred.tail<3>().norm() + 2e-5)
        << "link " << links[k] << ": estimate off by " << est_err.transpose() << ", predicted " << est_pred.transpose();
    // The tool, sent by the nominal model to the estimated start.
    const contact_check::ArmUncertainty arm{s, 0.0};
    contact_check::ToolTip tool = contact_check::tool_tip_uncertainty(robot, lr.base_T_object * object_T_start, arm);
    KinematicsWorkspace ws(true_arm), wn(robot);
    const Pose tip_true = forward_kinematics(true_arm, ws, tool.q);
    const Eigen::Matrix<double, 6, 1> tool_err =
        contact_check::pose_error_vector(forward_kinematics(robot, wn, tool.q).inverse() * tip_true);
    EXPECT_LT((tool_err - tool.link_sensitivity.col(col) * s).norm(), 0.05 * tool_err.norm() + 1e-6) << "link " << links[k];
    // The two through tip_error_at_hole, this link alone: a rank-one covariance s^2 d d^T.
    contact_check::ObjectEstimate est;
    est.base_T_object = lr.base_T_object;
    est.arm_link_sensitivity = Eigen::MatrixXd::Zero(6, lr.arm_link_sensitivity.cols());
    est.arm_link_sensitivity.col(col) = lr.arm_link_sensitivity.col(col);
    est.covariance = s * s * est.arm_link_sensitivity * est.arm_link_sensitivity.transpose();
    est.arm_link_sigma_m = s;
    const Eigen::MatrixXd tool_col = tool.link_sensitivity.col(col);
    tool.link_sensitivity.setZero();
    tool.link_sensitivity.col(col) = tool_col;
    tool.covariance = s * s * tool.link_sensitivity * tool.link_sensitivity.transpose();
    const contact_check::LocalCovariance tip = contact_check::tip_error_at_hole(est, object_T_hole, object_T_start, tool, arm);
    const Eigen::SelfAdjointEigenSolver<contact_check::Matrix6> eig(tip.covariance);
    const Eigen::Matrix<double, 6, 1> d = eig.eigenvectors().col(5) * std::sqrt(std::max(eig.eigenvalues()[5], 0.0));
    const Eigen::Matrix<double, 6, 1> actual =
        contact_check::pose_error_vector((setup.base_T_object * object_T_hole).inverse() * tip_true) - tip.mean;
    const double off = std::min((actual - d).tail<3>().norm(), (actual + d).tail<3>().norm());
    EXPECT_LT(off, 0.1 * actual.tail<3>().norm() + 2e-5)
        << "link " << links[k] << ": the tip's error at the hole " << actual.transpose() << ", predicted +-" << d.transpose();
    // The same with the tool's term of the wrong sign: the check can tell.
    tool.link_sensitivity.col(col) = -tool_col;
    const contact_check::LocalCovariance flipped =
        contact_check::tip_error_at_hole(est, object_T_hole, object_T_start, tool, arm);
    const Eigen::SelfAdjointEigenSolver<contact_check::Matrix6> feig(flipped.covariance);
    const Eigen::Matrix<double, 6, 1> fd = feig.eigenvectors().col(5) * std::sqrt(std::max(feig.eigenvalues()[5], 0.0));
    const double flipped_off = std::min((actual - fd).tail<3>().norm(), (actual + fd).tail<3>().norm());
    if (flipped_off > 0.1 * actual.tail<3>().norm() + 2e-5) ++discriminating;
    std::printf("link %d: tip error at the hole %.3f mm, predicted %.3f mm (off %.4f mm); with the tool's sign flipped %.3f mm "
                "(off %.3f mm)\n",
                links[k], actual.tail<3>().norm() * 1e3, d.tail<3>().norm() * 1e3, off * 1e3, fd.tail<3>().norm() * 1e3,
                flipped_off * 1e3);
  }
  EXPECT_GT(discriminating, 0);
}

}  // namespace
