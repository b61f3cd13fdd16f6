// The synthetic camera against ground truth, and the overlay against the
// synthetic camera: the arm drawn through a camera calibrated from
// noise-free clicks covers the synthetic video's arm (IoU >= 0.97).
#include <gtest/gtest.h>

#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

using namespace foresight;
using namespace foresight::render;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

struct World {
  RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  KinematicsWorkspace ws{model};

  // The arm 20 cm in front of the ORU hole (the changeout's approach).
  Eigen::VectorXd approach_q() {
    const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"),
                                       model.mid_configuration());
    EXPECT_TRUE(ik.success);
    return ik.q;
  }
};

double iou(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat i, u;
  cv::bitwise_and(a, b, i);
  cv::bitwise_or(a, b, u);
  return static_cast<double>(cv::countNonZero(i)) / std::max(1, cv::countNonZero(u));
}

cv::Mat alpha_mask(const cv::Mat& layer_bgra) {
  cv::Mat a;
  cv::extractChannel(layer_bgra, a, 3);
  return a > 0;
}

// The arm as the calibration fixture: link origins and the tool tip at
// several arm poses, clicked exactly where the true camera sees them.
std::vector<calibration::Correspondence> noise_free_clicks(World& w, const camera::Camera& truth) {
  std::vector<calibration::Correspondence> clicks;
  const Eigen::VectorXd q0 = w.approach_q();
  const double offsets[][3] = {{0, 0, 0}, {0.3, -0.2, 0.2}, {-0.3, 0.25, -0.2}, {0.2, 0.3, 0.3}, {-0.2, -0.3, 0.1}};
  int n = 0;
  for (const auto& o : offsets) {
    Eigen::VectorXd q = q0;
    q[0] += o[0];
    q[1] += o[1];
    q[3] += o[2];
    for (int link = 1; link < static_cast<int>(w.model.links().size()); ++link) {
      const Eigen::Vector3d p = forward_kinematics(w.model, w.ws, q, link).translation();
      if (!truth.in_front(p)) continue;
      const Eigen::Vector2d uv = truth.project(p);
      if (!truth.in_view(uv)) continue;
      calibration::Correspondence c;
      c.n = ++n;
      c.cam = truth.name;
      c.p_m = p;
      c.uv_px = uv;
      clicks.push_back(c);
    }
  }
  return clicks;
}

}  // namespace

TEST(SyntheticCamera, MasksMatchTheScene) {
  World w;
  auto ctx = GlContext::create(GlBackend::OSMesa);
  const camera::Camera cam = scene_camera(w.scene, "oblique");
  SyntheticCamera synth(*ctx, w.model, w.oru, w.scene, cam.viewport);
  const Eigen::VectorXd q = w.approach_q();
  const SyntheticFrame f = synth.render(cam, q);
  ASSERT_EQ(f.image_bgr.type(), CV_8UC3);
  ASSERT_EQ(f.image_bgr.cols, 646);
  ASSERT_EQ(f.image_bgr.rows, 486);
  // The tool tip and the ORU hole are where the camera projects them.
  const Eigen::Vector2d tip_uv = cam.project(forward_kinematics(w.model, w.ws, q, w.model.tip_index()).translation());
  const Eigen::Vector2d face_uv = cam.project(w.scene.base_T_object * Eigen::Vector3d(0.15, -0.1, -0.001));
  EXPECT_EQ(f.object_mask.at<std::uint8_t>(static_cast<int>(face_uv.y()), static_cast<int>(face_uv.x())), 255);
  EXPECT_EQ(f.arm_mask.at<std::uint8_t>(static_cast<int>(face_uv.y()), static_cast<int>(face_uv.x())), 0);
  // The tip is on the arm, give or take a pixel of its rounded end.
  const cv::Rect around(static_cast<int>(tip_uv.x()) - 2, static_cast<int>(tip_uv.y()) - 2, 5, 5);
  EXPECT_GT(cv::countNonZero(f.arm_mask(around)), 0);
  EXPECT_GT(cv::countNonZero(f.arm_mask), 5000);
  // Noise: a flat sky region has a spread near the configured sigma (after blur).
  cv::Mat sky;
  f.image_bgr(cv::Rect(5, 5, 40, 40)).convertTo(sky, CV_32F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(sky, mean, stddev);  // per channel
  EXPECT_GT(stddev[0], 0.3);
  EXPECT_LT(stddev[0], 3.0);
}

TEST(SyntheticCamera, OverlayThroughCalibratedCameraCoversSyntheticArm) {
  World w;
  auto ctx = GlContext::create(GlBackend::OSMesa);
  const Eigen::VectorXd q = w.approach_q();
  SyntheticCamera synth(*ctx, w.model, w.oru, w.scene, {646, 486});
  Renderer overlay(*ctx, {646, 486});
  ArmGeometry arm(overlay, w.model);
  for (const std::string name : {"side", "oblique"}) {
    const camera::Camera truth = scene_camera(w.scene, name);
    const SyntheticFrame frame = synth.render(truth, q);
    const std::vector<calibration::Correspondence> clicks = noise_free_clicks(w, truth);
    ASSERT_GE(clicks.size(), 12u) << name;
    const calibration::CalibrationResult cal = calibration::calibrate_camera(clicks, truth.viewport, name);
    EXPECT_LT(cal.rms_px, 1e-3) << name;

    DrawList list;
    arm.append(q, list);
    cv::Mat layer;
    overlay.render(truth, list, {}, layer);
    const double iou_true = iou(alpha_mask(layer), frame.arm_mask);
    overlay.render(cal.camera, list, {}, layer);
    const double iou_calibrated = iou(alpha_mask(layer), frame.arm_mask);
    std::printf("%s: arm silhouette IoU true camera %.4f, calibrated camera %.4f\n", name.c_str(), iou_true,
                iou_calibrated);
    EXPECT_GE(iou_calibrated, 0.97) << name;
    EXPECT_GE(iou_true, 0.97) << name;
  }
}

TEST(SyntheticCamera, WrongJointCount) {
  World w;
  auto ctx = GlContext::create(GlBackend::OSMesa);
  SyntheticCamera synth(*ctx, w.model, w.oru, w.scene, {646, 486});
  try {
    synth.render(scene_camera(w.scene, "side"), Eigen::VectorXd::Zero(6));
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "joint vector has 6 values but the arm has 7 joints");
  }
}
