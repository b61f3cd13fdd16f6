#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "foresight/localization/accuracy_study.hpp"
#include "foresight/localization/localize.hpp"
#include "foresight/localization/peers.hpp"

using namespace foresight;

namespace {

/// Arm-like calibration points: 4 "poses" of 8 points in the workspace in
/// front of the ORU (the CLI study uses the URDF arm's FK instead).
std::vector<Eigen::Vector3d> workspace_points() {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> x(0.35, 0.95), y(-0.35, 0.55), z(0.2, 1.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 32; ++i) pts.emplace_back(x(rng), y(rng), z(rng));
  return pts;
}

localization::StudySetup project_setup() {
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  return localization::make_study_setup(scene, oru, workspace_points());
}

}  // namespace

TEST(AccuracyStudy, SceneViewsSeeEnoughPoints) {
  const localization::StudySetup s = project_setup();
  ASSERT_EQ(s.views.size(), 4u);
  for (const auto& v : s.views) {
    EXPECT_GE(v.calibration_points_base.size(), 15u) << v.truth.name;
    EXPECT_GE(v.object_points.size(), 6u) << v.truth.name;  // a single view can localize
  }
}

TEST(AccuracyStudy, CramerRaoBoundIsConsistent) {
  const localization::StudySetup s = project_setup();
  Eigen::Matrix<double, 6, 6> joint, known, joint2, known2;
  localization::cramer_rao_bound(s, {0, 1, 2, 3}, 1.0, joint, known);
  // Knowing the cameras can only help; the bound scales with the noise.
  for (int i = 0; i < 6; ++i) EXPECT_LE(known(i, i), joint(i, i) * (1 + 1e-9));
  localization::cramer_rao_bound(s, {0, 1, 2, 3}, 2.0, joint2, known2);
  EXPECT_NEAR((joint2 - 4.0 * joint).norm() / joint.norm(), 0.0, 1e-6);
  // More views never hurt.
  Eigen::Matrix<double, 6, 6> j1, k1;
  localization::cramer_rao_bound(s, {0}, 1.0, j1, k1);
  EXPECT_LT(joint.trace(), j1.trace());
}

TEST(AccuracyStudy, PeersExactOnExactData) {
  const localization::StudySetup s = project_setup();
  std::map<std::string, camera::Camera> cams;
  std::vector<calibration::Correspondence> all;
  for (const auto& v : s.views) {
    cams[v.truth.name] = v.truth;
    std::vector<calibration::Correspondence> pts;
    for (const auto& p : v.object_points) {
      calibration::Correspondence c;
      c.n = static_cast<int>(pts.size()) + 1;
      c.cam = v.truth.name;
      c.p_m = p;
      c.uv_px = v.truth.project(s.base_T_object * p);
      pts.push_back(c);
      all.push_back(c);
    }
    for (const localization::PnpMethod m : {localization::PnpMethod::Iterative, localization::PnpMethod::Sqpnp}) {
      const auto T = localization::solve_pnp_opencv(pts, v.truth, m);
      ASSERT_TRUE(T.has_value());
      EXPECT_LT((T->matrix() - s.base_T_object.matrix()).norm(), 1e-6) << v.truth.name << " " << static_cast<int>(m);
    }
  }
  const auto T = localization::triangulate_and_align(all, cams);
  ASSERT_TRUE(T.has_value());
  EXPECT_LT((T->matrix() - s.base_T_object.matrix()).norm(), 1e-6);
}

TEST(AccuracyStudy, MonteCarloNearTheBoundAndPeersAgree) {
  const localization::StudySetup s = project_setup();
  localization::StudyOptions opt;
  opt.trials = 150;
  opt.noise_px = 1.0;
  int calls = 0;
  opt.progress = [&](int done, int total) {
    ++calls;
    EXPECT_LE(done, total);
  };
  const localization::StudyResult r = localization::run_accuracy_study(s, opt);
  EXPECT_EQ(calls, 150);
  ASSERT_EQ(r.combos.size(), 15u);
  EXPECT_EQ(r.combos[0].label, "1");
  EXPECT_EQ(r.combos[14].label, "1+2+3+4");
  EXPECT_EQ(r.calibration_failures, 0);
  for (const auto& c : r.combos) {
    EXPECT_EQ(c.failures, 0) << c.label;
    // The estimate is unbiased to within its spread and not better than the bound.
    for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(c.ours.mean[i]), 4.0 * c.ours.sd[i] / std::sqrt(150.0) + 1e-12);
    EXPECT_GT(c.ours.position_rmse_m, 0.8 * c.crlb_position_m) << c.label;
    std::printf("%-8s joint %.3f mm %.4f deg | pos rmse %.3f mm crlb %.3f (known cams %.3f) rot rmse %.4f deg crlb %.4f | pnp %.3f sqpnp %.3f tri %.3f\n",
                c.label.c_str(), 1e3 * c.ours_joint.position_rmse_m, c.ours_joint.rotation_rmse_rad * 180 / M_PI,
                1e3 * c.ours.position_rmse_m, 1e3 * c.crlb_position_m,
                1e3 * c.crlb_known_cameras_sd.head<3>().norm(), c.ours.rotation_rmse_rad * 180 / M_PI,
                c.crlb_rotation_rad * 180 / M_PI, 1e3 * c.pnp_iterative.position_rmse_m, 1e3 * c.pnp_sqpnp.position_rmse_m,
                1e3 * c.triangulation.position_rmse_m);
    if (c.views.size() == 1) {  // a maximum-likelihood PnP: agrees with OpenCV's SQPnP
      EXPECT_EQ(c.pnp_sqpnp.n, 150);
      EXPECT_NEAR(c.pnp_sqpnp.position_rmse_m / c.ours.position_rmse_m, 1.0, 0.1) << c.label;
      EXPECT_NEAR(c.pnp_sqpnp.rotation_rmse_rad / c.ours.rotation_rmse_rad, 1.0, 0.1) << c.label;
    } else {
      EXPECT_GT(c.triangulation.n, 0) << c.label;
    }
  }
  const localization::ComboStats& all = r.combos.back();
  EXPECT_LT(all.ours.position_rmse_m, 1.25 * all.crlb_position_m);
  EXPECT_LT(all.ours.rotation_rmse_rad, 1.25 * all.crlb_rotation_rad);
}

namespace {

/// The CLI's set-up: the URDF arm at four poses as the calibration fixture.
localization::StudySetup arm_setup(const RobotModel& robot) {
  const Scene scene = Scene::from_file(FORESIGHT_CONFIG_DIR "/scene.yaml");
  const ObjectModel oru = ObjectModel::from_file(FORESIGHT_CONFIG_DIR "/oru.yaml");
  localization::StudySetup s = localization::make_study_setup(scene, oru, {});
  localization::choose_calibration_points(s, localization::arm_calibration_poses(robot));
  return s;
}

}  // namespace

TEST(AccuracyStudy, OnTheUrdfArmBothMethodsNearTheBound) {
  const RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  const localization::StudySetup s = arm_setup(robot);
  for (const auto& v : s.views) {
    EXPECT_GE(v.calibration_points_base.size(), 6u) << v.truth.name;
    EXPECT_EQ(v.calibration_features.size(), v.calibration_points_base.size()) << v.truth.name;
  }
  localization::StudyOptions opt;
  opt.trials = 150;
  const localization::StudyResult r = localization::run_accuracy_study(s, opt);
  EXPECT_EQ(r.calibration_failures, 0);
  for (const auto& c : r.combos) {
    EXPECT_EQ(c.failures, 0) << c.label;
    EXPECT_EQ(c.joint_failures, 0) << c.label;
    std::printf("%-8s two-step %.3f mm %.4f deg | joint %.3f mm %.4f deg | bound %.3f mm %.4f deg\n", c.label.c_str(),
                1e3 * c.ours.position_rmse_m, c.ours.rotation_rmse_rad * 180 / M_PI,
                1e3 * c.ours_joint.position_rmse_m, c.ours_joint.rotation_rmse_rad * 180 / M_PI,
                1e3 * c.crlb_position_m, c.crlb_rotation_rad * 180 / M_PI);
    if (c.views.size() < 2) continue;
    // An efficient estimator sits at the bound: 150 trials put the RMSE
    // within about +-12% (3 sigma of a chi with 450 degrees of freedom) of
    // it; the joint method within 20% of the bound, the two-step within 50%.
    EXPECT_GT(c.ours_joint.position_rmse_m, 0.85 * c.crlb_position_m) << c.label;
    EXPECT_LT(c.ours_joint.position_rmse_m, 1.2 * c.crlb_position_m) << c.label;
    EXPECT_GT(c.ours_joint.rotation_rmse_rad, 0.85 * c.crlb_rotation_rad) << c.label;
    EXPECT_LT(c.ours_joint.rotation_rmse_rad, 1.2 * c.crlb_rotation_rad) << c.label;
    EXPECT_LT(c.ours.position_rmse_m, 1.5 * c.crlb_position_m) << c.label;
    EXPECT_GT(c.ours.position_rmse_m, 0.85 * c.crlb_position_m) << c.label;
  }
}

TEST(AccuracyStudy, ArmModelErrorCostsAccuracyOnTheSameClicks) {
  const RobotModel robot = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  const localization::StudySetup s = arm_setup(robot);
  localization::StudyOptions opt;
  opt.trials = 60;
  opt.seed = 5;
  const localization::StudyResult exact = localization::run_accuracy_study(s, opt);
  opt.robot = &robot;
  opt.arm_link_error_m = 0.002;
  const localization::StudyResult wrong = localization::run_accuracy_study(s, opt);
  EXPECT_EQ(wrong.arm_link_error_m, 0.002);
  const localization::ComboStats& a = exact.combos.back();
  const localization::ComboStats& b = wrong.combos.back();
  std::printf("four views: exact arm %.3f mm, 2 mm link-length error %.3f mm (bound %.3f mm)\n",
              1e3 * a.ours.position_rmse_m, 1e3 * b.ours.position_rmse_m, 1e3 * a.crlb_position_m);
  EXPECT_GT(b.ours.position_rmse_m, 1.05 * a.ours.position_rmse_m);
  EXPECT_GT(b.ours.position_rmse_m, 1.1 * b.crlb_position_m);  // beyond the click-noise bound
  EXPECT_LT(b.ours.position_rmse_m, 0.05);                      // but not lost

  localization::StudyOptions no_robot;
  no_robot.trials = 1;
  no_robot.arm_link_error_m = 0.002;
  try {
    localization::run_accuracy_study(s, no_robot);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "accuracy study: an arm-model error needs the robot model");
  }
  no_robot.robot = &robot;
  try {
    localization::run_accuracy_study(project_setup(), no_robot);  // random points: no arm features
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "accuracy study: an arm-model error needs the arm's calibration features (view 'side' has "
                           "none; use choose_calibration_points)");
  }
}

TEST(AccuracyStudy, SeedsGiveTheMonteCarloSpread) {
  const localization::StudySetup s = project_setup();
  localization::StudyOptions opt;
  opt.trials = 20;
  opt.seed = 7;
  int last = 0;
  opt.progress = [&](int done, int total) {
    EXPECT_EQ(total, 60);
    EXPECT_EQ(done, last + 1);
    last = done;
  };
  const std::vector<localization::StudyResult> runs = localization::run_accuracy_study_seeds(s, opt, 3);
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(last, 60);
  std::vector<double> four;
  for (const auto& r : runs) four.push_back(r.combos.back().ours.position_rmse_m);
  EXPECT_NE(four[0], four[1]);  // different seeds, different clicks
  const localization::Spread sp = localization::spread_of(four);
  EXPECT_EQ(sp.n, 3);
  EXPECT_NEAR(sp.mean, (four[0] + four[1] + four[2]) / 3.0, 1e-15);
  EXPECT_GT(sp.sd, 0.0);
  const localization::Spread known = localization::spread_of({1.0, 2.0, 3.0});
  EXPECT_DOUBLE_EQ(known.mean, 2.0);
  EXPECT_DOUBLE_EQ(known.sd, 1.0);
  EXPECT_THROW(localization::run_accuracy_study_seeds(s, opt, 0), InputError);
}
