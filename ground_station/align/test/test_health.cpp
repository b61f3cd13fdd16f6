// Calibration health on synthetic video: the arm moving with sensor noise
// through the true camera gives no warning; the camera bumped by 0.3 deg
// (the calibration no longer true) is flagged within a few frames.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "foresight/align/health.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

using namespace foresight;
using namespace foresight::align;
using namespace foresight::render;

TEST(Health, CameraBumpOfPointThreeDegreesIsFlaggedNoFalseAlarm) {
  const std::string cfg = FORESIGHT_CONFIG_DIR;
  const RobotModel model = RobotModel::from_file(cfg + "/robot.urdf");
  const ObjectModel oru = ObjectModel::from_file(cfg + "/oru.yaml");
  const Scene scene = Scene::from_file(cfg + "/scene.yaml");
  KinematicsWorkspace ws(model);
  const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"),
                                     model.mid_configuration());
  ASSERT_TRUE(ik.success);
  auto ctx = GlContext::create(GlBackend::OSMesa);
  for (const std::string name : {"side", "oblique"}) {
    const camera::Camera calibrated = scene_camera(scene, name);
    camera::Camera bumped = calibrated;
    bumped.base_T_camera.linear() =
        calibrated.base_T_camera.linear() * camera::exp_so3(Eigen::Vector3d(0.0, 0.3 * M_PI / 180.0, 0.0));
    SyntheticOptions so;
    so.noise_sigma_dn = 2.0;
    SyntheticCamera synth(*ctx, model, oru, scene, calibrated.viewport, so);
    ModelAligner aligner(*ctx, model, &oru, calibrated.viewport);
    HealthMonitor monitor;
    constexpr int kNormal = 40, kBump = 10;
    int false_alarms = 0, detected_at = -1;
    double min_normal = 1.0, max_bumped = 0.0, min_iou = 1.0, max_bumped_iou = 0.0;
    for (int k = 0; k < kNormal + kBump; ++k) {
      Eigen::VectorXd q = ik.q;
      q[0] += 0.08 * std::sin(0.3 * k);
      q[1] += 0.05 * std::sin(0.21 * k + 1.0);
      q[3] += 0.06 * std::cos(0.17 * k);
      const bool is_bumped = k >= kNormal;
      const SyntheticFrame f = synth.render(is_bumped ? bumped : calibrated, q);
      const auto s = aligner.score(calibrated, {f.image_bgr, q}, scene.base_T_object);
      const HealthVerdict v = monitor.update(s);
      if (!is_bumped) {
        min_normal = std::min(min_normal, s.matched_fraction);
        min_iou = std::min(min_iou, s.iou);
        if (v.warning) ++false_alarms;
      } else {
        max_bumped = std::max(max_bumped, s.matched_fraction);
        max_bumped_iou = std::max(max_bumped_iou, s.iou);
        if (v.warning && detected_at < 0) {
          detected_at = k - kNormal;
          std::printf("%s: %s\n", name.c_str(), v.reason.c_str());
        }
      }
    }
    std::printf("%s: matched fraction normal >= %.2f, bumped <= %.2f; detected %d frames after the bump\n", name.c_str(),
                min_normal, max_bumped, detected_at);
    std::printf("%s: silhouette IoU normal >= %.3f, bumped <= %.3f\n", name.c_str(), min_iou, max_bumped_iou);
    EXPECT_GT(min_iou, 0.9);
    EXPECT_LT(max_bumped_iou, min_iou);
    EXPECT_EQ(false_alarms, 0);
    EXPECT_GE(detected_at, 0);
    EXPECT_LT(detected_at, 30);
  }
}
