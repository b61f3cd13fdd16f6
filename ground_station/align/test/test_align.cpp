// Model-to-image alignment against the synthetic camera's ground truth: the
// true camera recovered from noise-free frames to 0.05 px reprojection, a
// start 5 px off converging with noise, a start 50 px off refused or
// converged (never silently wrong), the object pose refined over views, and
// the refusals (model not in view, too few edges).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <memory>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "foresight/align/alignment_study.hpp"
#include "foresight/align/model_aligner.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

using namespace foresight;
using namespace foresight::align;
using namespace foresight::render;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

struct World {
  RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  KinematicsWorkspace ws{model};
  std::unique_ptr<GlContext> ctx = GlContext::create(GlBackend::OSMesa);

  Eigen::VectorXd approach_q() {
    const auto ik = inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"),
                                       model.mid_configuration());
    EXPECT_TRUE(ik.success);
    return ik.q;
  }

  // Model points for the reprojection metric: link origins at q and the ORU's corners.
  std::vector<Eigen::Vector3d> points(const Eigen::VectorXd& q) {
    std::vector<Eigen::Vector3d> p;
    for (int link = 0; link < static_cast<int>(model.links().size()); ++link)
      p.push_back(forward_kinematics(model, ws, q, link).translation());
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d h = oru.size_m / 2.0;
      const Eigen::Vector3d c((k & 1) ? h.x() : -h.x(), (k & 2) ? h.y() : -h.y(), (k & 4) ? h.z() : -h.z());
      p.push_back(scene.base_T_object * (oru.oru_T_box * c));
    }
    return p;
  }
};

// The camera rotated by (dx, dy) pixels' worth about its own y and x axes,
// and its focal length scaled.
camera::Camera perturbed(const camera::Camera& c, double dx_px, double dy_px, double f_scale = 1.0, const Eigen::Vector3d& dt = {0, 0, 0}) {
  camera::Camera out = c;
  const Eigen::Vector3d theta(-dy_px / c.f_px, dx_px / c.f_px, 0.0);
  out.base_T_camera.linear() = c.base_T_camera.linear() * camera::exp_so3(theta);
  out.base_T_camera.translation() += dt;
  out.f_px *= f_scale;
  return out;
}

SyntheticOptions options(double noise_dn, unsigned seed = 1) {
  SyntheticOptions o;
  o.noise_sigma_dn = noise_dn;
  o.seed = seed;
  return o;
}

}  // namespace

TEST(Align, NoiseFreeFramesRecoverTheTrueCamera) {
  World w;
  const camera::Camera truth = scene_camera(w.scene, "oblique");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(0.0));
  ModelAligner aligner(*w.ctx, w.model, &w.oru, truth.viewport);
  const Eigen::VectorXd q = w.approach_q();
  AlignView view{perturbed(truth, 2.0, -1.5, 1.01), {{synth.render(truth, q).image_bgr, q}}};
  const auto pts = w.points(q);
  const double start = reprojection_rms_px(view.camera, truth, pts);
  const AlignResult r = aligner.align({view}, w.scene.base_T_object);
  const double end = reprojection_rms_px(r.cameras[0], truth, pts);
  std::printf("noise-free: start %.3f px, end %.4f px, residual %.3f px, score %.3f -> %.3f, %d/%d matched, %d it, %.1f ms\n",
              start, end, r.residual_rms_px, r.start_score_px, r.final_score_px, r.matched_samples, r.visible_samples,
              r.iterations, r.time_ms);
  ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
  // Issue 16 asks 0.05 px. Measured 0.028 px with the edge bias predicted
  // from the model's shaded appearance at the finest level only (0.051 px
  // when predicted at the two fine levels, 0.138 px without: the shading
  // ramps beside the silhouettes pulled the gradient peaks inwards;
  // docs/estimation.md).
  EXPECT_LT(end, 0.05);
  EXPECT_LT(r.final_score_px, r.start_score_px);
}

// The aligner keeps its image buffers from one call to the next (fresh
// pages were over half of an alignment's time): a frame aligned again after
// another gives the same answer to the bit, the earlier frame's gradients
// never leak into a later call, and a grey frame the caller gave is not
// rewritten by the buffers' reuse.
TEST(Align, ReusedBuffersGiveTheSameAnswerAndLeaveTheCallersFrameAlone) {
  World w;
  const camera::Camera truth = scene_camera(w.scene, "oblique");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, 3));
  ModelAligner aligner(*w.ctx, w.model, &w.oru, truth.viewport);
  const Eigen::VectorXd q = w.approach_q();
  const Eigen::VectorXd q2 = q + Eigen::VectorXd::Constant(q.size(), 0.05);
  cv::Mat grey_a;
  cv::cvtColor(synth.render(truth, q).image_bgr, grey_a, cv::COLOR_BGR2GRAY);
  const cv::Mat grey_a_copy = grey_a.clone();
  const AlignView a{perturbed(truth, 3.0, -2.0, 1.005), {{grey_a, q}}};
  const AlignView b{perturbed(truth, -2.0, 1.0), {{synth.render(truth, q2).image_bgr, q2}}};
  const AlignResult first = aligner.align({a}, w.scene.base_T_object);
  const AlignResult other = aligner.align({b}, w.scene.base_T_object);
  const AlignResult again = aligner.align({a}, w.scene.base_T_object);
  ASSERT_EQ(first.status, AlignStatus::Aligned) << first.reason;
  ASSERT_EQ(other.status, AlignStatus::Aligned) << other.reason;
  ASSERT_EQ(again.status, AlignStatus::Aligned) << again.reason;
  EXPECT_EQ(again.iterations, first.iterations);
  EXPECT_EQ(again.matched_samples, first.matched_samples);
  EXPECT_EQ(again.residual_rms_px, first.residual_rms_px);
  EXPECT_TRUE(again.cameras[0].base_T_camera.isApprox(first.cameras[0].base_T_camera, 0.0));
  EXPECT_EQ(again.cameras[0].f_px, first.cameras[0].f_px);
  EXPECT_EQ(again.covariance, first.covariance);
  // b's answer is b's, not a's: the two starts were 5 px apart.
  EXPECT_GT((other.cameras[0].base_T_camera.translation() - first.cameras[0].base_T_camera.translation()).norm() +
                std::abs(other.cameras[0].f_px - first.cameras[0].f_px),
            0.0);
  EXPECT_LT(reprojection_rms_px(other.cameras[0], truth, w.points(q2)), 0.45);
  EXPECT_EQ(cv::norm(grey_a, grey_a_copy, cv::NORM_INF), 0.0);
  // score() (the health check, once a frame) shares the buffers too.
  const auto s1 = aligner.score(truth, a.frames[0], w.scene.base_T_object);
  aligner.score(truth, b.frames[0], w.scene.base_T_object);
  const auto s2 = aligner.score(truth, a.frames[0], w.scene.base_T_object);
  EXPECT_EQ(s1.score_px, s2.score_px);
  EXPECT_EQ(s1.iou, s2.iou);
}

// One AlignmentModel (the primitives and mesh edges, built once) shared by
// two aligners, as by two threads each with its own buffers: each gives the
// answer of an aligner that built its own model.
TEST(Align, SharedModelGivesTheOwnModelsAnswer) {
  World w;
  const camera::Camera truth = scene_camera(w.scene, "oblique");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, 3));
  const Eigen::VectorXd q = w.approach_q();
  const AlignView view{perturbed(truth, 3.0, -2.0, 1.005), {{synth.render(truth, q).image_bgr, q}}};
  ModelAligner own(*w.ctx, w.model, &w.oru, truth.viewport);
  const AlignResult expected = own.align({view}, w.scene.base_T_object);
  ASSERT_EQ(expected.status, AlignStatus::Aligned) << expected.reason;
  const auto model = make_alignment_model(w.model, &w.oru, truth.viewport);
  ModelAligner a(*w.ctx, model), b(*w.ctx, model);
  for (ModelAligner* aligner : {&a, &b}) {
    const AlignResult r = aligner->align({view}, w.scene.base_T_object);
    ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
    EXPECT_EQ(r.iterations, expected.iterations);
    EXPECT_TRUE(r.cameras[0].base_T_camera.isApprox(expected.cameras[0].base_T_camera, 0.0));
    EXPECT_EQ(r.cameras[0].f_px, expected.cameras[0].f_px);
    EXPECT_EQ(r.covariance, expected.covariance);
  }
  EXPECT_THROW(ModelAligner(*w.ctx, nullptr), std::invalid_argument);
}

TEST(Align, FivePixelsOffConvergesWithNoise) {
  World w;
  for (const std::string name : {"side", "oblique"}) {
    const camera::Camera truth = scene_camera(w.scene, name);
    SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, 7));
    ModelAligner aligner(*w.ctx, w.model, &w.oru, truth.viewport);
    const Eigen::VectorXd q = w.approach_q();
    AlignView view{perturbed(truth, 4.0, 3.0, 0.995), {{synth.render(truth, q).image_bgr, q}}};
    const auto pts = w.points(q);
    const double start = reprojection_rms_px(view.camera, truth, pts);
    const AlignResult r = aligner.align({view}, w.scene.base_T_object);
    const double end = reprojection_rms_px(r.cameras[0], truth, pts);
    std::printf("%s 5 px: start %.2f px, end %.3f px, residual %.3f px, %d/%d matched, %.1f ms\n", name.c_str(), start,
                end, r.residual_rms_px, r.matched_samples, r.visible_samples, r.time_ms);
    ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
    EXPECT_GT(start, 4.0);
    EXPECT_LT(end, 0.45);
    ASSERT_EQ(r.covariance.rows(), 7);
    // The reported sigmas are positive; they are optimistic (correlated edge
    // samples): the errors are printed beside them, not asserted within 3 sigma.
    const Eigen::Matrix3d dR = truth.base_T_camera.linear().transpose() * r.cameras[0].base_T_camera.linear();
    const Eigen::AngleAxisd aa(dR);
    const Eigen::Vector3d err = aa.angle() * aa.axis();
    for (int k = 0; k < 3; ++k) EXPECT_GT(std::sqrt(r.covariance(k, k)), 0.0);
    std::printf("  rotation error %.2e %.2e %.2e rad, sigma %.2e %.2e %.2e\n", err[0], err[1], err[2],
                std::sqrt(r.covariance(0, 0)), std::sqrt(r.covariance(1, 1)), std::sqrt(r.covariance(2, 2)));
  }
}

// Monte Carlo of the reported covariance against the truth: seeds (sensor
// noise, start offset) x two cameras x 7 parameters (camera rotation as the
// body rotation vector, centre in base, f_px). The fraction of errors within
// 3 sigma is asserted at >= 85% (measured 50 of 56, 89%; 0 of 28 on the side
// camera before the covariance carried the shared edge offset: worst 5.4
// sigma) and none beyond 4 sigma.
TEST(Align, ErrorsWithinThreeSigmaOfTheCovarianceOverSeeds) {
  World w;
  const Eigen::VectorXd q = w.approach_q();
  int checked = 0, outside = 0, beyond4 = 0;
  double worst = 0.0;
  for (const std::string name : {"side", "oblique"}) {
    const camera::Camera truth = scene_camera(w.scene, name);
    ModelAligner aligner(*w.ctx, w.model, &w.oru, truth.viewport);
    for (unsigned seed = 11; seed < 15; ++seed) {
      SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, seed));
      const double dx = 3.0 * std::cos(seed), dy = 3.0 * std::sin(seed);
      AlignView view{perturbed(truth, dx, dy, 1.0 + 0.002 * std::cos(2.0 * seed)), {{synth.render(truth, q).image_bgr, q}}};
      const AlignResult r = aligner.align({view}, w.scene.base_T_object);
      ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
      ASSERT_EQ(r.covariance.rows(), 7);
      Eigen::Matrix<double, 7, 1> err;
      const Eigen::AngleAxisd aa(r.cameras[0].base_T_camera.linear().transpose() * truth.base_T_camera.linear());
      err.head<3>() = aa.angle() * aa.axis();
      err.segment<3>(3) = r.cameras[0].base_T_camera.translation() - truth.base_T_camera.translation();
      err[6] = r.cameras[0].f_px - truth.f_px;
      std::printf("%s seed %u: |error| / sigma:", name.c_str(), seed);
      for (int k = 0; k < 7; ++k) {
        const double z = std::abs(err[k]) / std::sqrt(r.covariance(k, k));
        std::printf(" %.2f", z);
        worst = std::max(worst, z);
        ++checked;
        if (z > 3.0) ++outside;
        if (z > 4.0) ++beyond4;
      }
      std::printf("\n");
    }
  }
  std::printf("%d of %d parameter errors within 3 sigma (%.0f%%), worst %.2f sigma\n", checked - outside, checked,
              100.0 * (checked - outside) / checked, worst);
  EXPECT_GE(checked - outside, 0.85 * checked);
  EXPECT_EQ(beyond4, 0);
}

TEST(Align, FiftyPixelsOffIsRefusedOrConverges) {
  World w;
  const camera::Camera truth = scene_camera(w.scene, "side");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, 3));
  ModelAligner aligner(*w.ctx, w.model, &w.oru, truth.viewport);
  const Eigen::VectorXd q = w.approach_q();
  const auto pts = w.points(q);
  for (const auto& [dx, dy] : {std::pair{40.0, 30.0}, std::pair{-50.0, 0.0}, std::pair{0.0, 50.0}}) {
    AlignView view{perturbed(truth, dx, dy), {{synth.render(truth, q).image_bgr, q}}};
    const AlignResult r = aligner.align({view}, w.scene.base_T_object);
    const double end = reprojection_rms_px(r.cameras[0], truth, pts);
    std::printf("50 px (%.0f, %.0f): %s %s, end %.2f px\n", dx, dy, to_string(r.status), r.reason.c_str(), end);
    if (r.status == AlignStatus::Aligned) {
      EXPECT_LT(end, 0.5);
    } else {
      EXPECT_EQ(r.status, AlignStatus::Refused);
      EXPECT_FALSE(r.reason.empty());
      EXPECT_EQ(r.cameras[0].base_T_camera.matrix(), view.camera.base_T_camera.matrix());  // not moved
    }
  }
}

TEST(Align, ObjectPoseOverAllViews) {
  World w;
  const Eigen::VectorXd q = w.approach_q();
  std::vector<AlignView> views;
  std::vector<std::unique_ptr<SyntheticCamera>> synths;
  for (const std::string name : {"side", "oblique", "overhead_zoom"}) {
    const camera::Camera truth = scene_camera(w.scene, name);
    synths.push_back(std::make_unique<SyntheticCamera>(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, 5)));
    views.push_back({truth, {{synths.back()->render(truth, q).image_bgr, q}}});
  }
  ModelAligner aligner(*w.ctx, w.model, &w.oru, views[0].camera.viewport);
  Pose start = w.scene.base_T_object;
  start.translation() += Eigen::Vector3d(0.004, -0.003, 0.005);
  start.linear() = start.linear() * camera::exp_so3(Eigen::Vector3d(0.0, 0.008, -0.005));
  AlignOptions o;
  o.refine = Refine::Object;
  const AlignResult r = aligner.align(views, start, o);
  ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
  ASSERT_TRUE(r.base_T_object);
  const double dp = (r.base_T_object->translation() - w.scene.base_T_object.translation()).norm();
  const double da = Eigen::AngleAxisd(w.scene.base_T_object.linear().transpose() * r.base_T_object->linear()).angle();
  std::printf("object over 3 views: %.2f mm, %.3f deg (start 7.1 mm, 0.54 deg), %.1f ms\n", dp * 1e3, da * 180 / M_PI,
              r.time_ms);
  EXPECT_LT(dp, 0.001);
  EXPECT_LT(da, 0.1 * M_PI / 180.0);
  EXPECT_EQ(r.covariance.rows(), 6);
}

// The ORU stands still while the arm moves: its edges are the same image
// edges in every frame of a camera, their errors shared. The covariance's
// clusters say so (one per view and object edge; the arm's are per frame),
// so repeating a frame adds no information: the same pose and the same
// covariance from one copy or three. With a cluster per frame the claimed
// variance fell as 1/frames (seen: a two-view ORU 3.6 mm off claiming
// 0.1 mm, 28 sigma).
TEST(Align, TheStaticObjectsEdgesAreOneClusterOverTheFramesOfAView) {
  World w;
  const Eigen::VectorXd q = w.approach_q();
  const camera::Camera side = scene_camera(w.scene, "side");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, side.viewport, options(2.0, 3));
  const AlignFrame frame{synth.render(side, q).image_bgr, q};
  ModelAligner aligner(*w.ctx, w.model, &w.oru, side.viewport);
  Pose start = w.scene.base_T_object;
  start.translation() += Eigen::Vector3d(0.003, -0.002, 0.004);
  AlignOptions o;
  o.refine = Refine::Object;
  const AlignResult once = aligner.align({AlignView{side, {frame}}}, start, o);
  const AlignResult thrice = aligner.align({AlignView{side, {frame, frame, frame}}}, start, o);
  ASSERT_EQ(once.status, AlignStatus::Aligned) << once.reason;
  ASSERT_EQ(thrice.status, AlignStatus::Aligned) << thrice.reason;
  ASSERT_EQ(once.covariance.rows(), 6);
  ASSERT_EQ(thrice.covariance.rows(), 6);
  EXPECT_EQ(thrice.visible_samples, 3 * once.visible_samples);
  EXPECT_LT((thrice.base_T_object->matrix() - once.base_T_object->matrix()).cwiseAbs().maxCoeff(), 1e-9);
  // The same claim, up to the small-sample correction (n - 1) / (n - 1 - P),
  // which counts samples (a cluster per frame would give 1 / sqrt(3), 0.58).
  for (const int k : {0, 3}) {
    const double sd_once = std::sqrt(once.covariance.block<3, 3>(k, k).trace());
    const double ratio = std::sqrt(thrice.covariance.block<3, 3>(k, k).trace()) / sd_once;
    std::printf("ORU %s sd from one frame %.4g, from three copies x %.3f\n", k ? "position (m)" : "rotation (rad)",
                sd_once, ratio);
    EXPECT_GT(ratio, 0.97);
    EXPECT_LT(ratio, 1.0 + 1e-9);
  }
}

// The satellite's bay (ObjectModel::surroundings) hides all of the ORU but
// its front 5 cm from the side and from above. Without it in the label image
// the hidden edges count as visible and find no edge or another one; with it
// only what the camera sees is sampled. The ORU at its true pose, the true
// cameras: the share of visible ORU samples on an image edge (within 1 px).
TEST(Align, TheBayHidesTheOrusEdgesInsideIt) {
  World w;
  const Eigen::VectorXd q = w.approach_q();
  ObjectModel bare = w.oru;
  bare.surroundings.clear();
  ASSERT_FALSE(w.oru.surroundings.empty());
  for (const std::string name : {"side", "overhead_wide"}) {
    const camera::Camera truth = scene_camera(w.scene, name);
    SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, truth.viewport, options(2.0, 7));
    const AlignView view{truth, {{synth.render(truth, q).image_bgr, q}}};
    AlignOptions o;
    o.refine = Refine::Object;
    ModelAligner with_bay(*w.ctx, w.model, &w.oru, truth.viewport), without(*w.ctx, w.model, &bare, truth.viewport);
    const AlignResult a = with_bay.align({view}, w.scene.base_T_object, o);
    const AlignResult b = without.align({view}, w.scene.base_T_object, o);
    const double fa = static_cast<double>(a.matched_samples) / a.visible_samples;
    const double fb = static_cast<double>(b.matched_samples) / b.visible_samples;
    std::printf("%s: ORU samples on an image edge: with the bay %d of %d (%.0f%%), without %d of %d (%.0f%%)\n",
                name.c_str(), a.matched_samples, a.visible_samples, 100 * fa, b.matched_samples, b.visible_samples,
                100 * fb);
    EXPECT_LT(a.visible_samples, b.visible_samples);
    EXPECT_GT(fa, fb + 0.15);
  }
}

TEST(Align, ModelNotInViewAndBadFrames) {
  World w;
  const camera::Camera truth = scene_camera(w.scene, "side");
  ModelAligner aligner(*w.ctx, w.model, &w.oru, truth.viewport);
  const Eigen::VectorXd q = w.approach_q();
  // Looking away from the work site.
  camera::Camera away = camera::Camera::look_at("away", truth.viewport, truth.f_px, {0.75, -1.9, 0.85}, {0.75, -5.0, 0.85});
  cv::Mat grey(truth.viewport.height_px, truth.viewport.width_px, CV_8UC3, cv::Scalar(30, 30, 30));
  const AlignResult r = aligner.align({{away, {{grey, q}}}}, std::nullopt);
  EXPECT_EQ(r.status, AlignStatus::NotInView);
  EXPECT_NE(r.reason.find("not in view of camera 'away'"), std::string::npos) << r.reason;

  // A blank frame: the model is in view but no edge matches: refused, not moved.
  const AlignResult blank = aligner.align({{truth, {{grey, q}}}}, std::nullopt);
  EXPECT_EQ(blank.status, AlignStatus::Refused);
  std::printf("blank frame: %s\n", blank.reason.c_str());
  EXPECT_EQ(blank.cameras[0].base_T_camera.matrix(), truth.base_T_camera.matrix());

  cv::Mat small(100, 100, CV_8UC3, cv::Scalar(0, 0, 0));
  try {
    aligner.align({{truth, {{small, q}}}}, std::nullopt);
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "frame is 100x100 but the camera viewport is 646x486");
  }
  AlignOptions o;
  o.refine = Refine::Object;
  try {
    aligner.align({{truth, {{grey, q}}}}, std::nullopt, o);
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "refining the object needs its start pose (--object-pose)");
  }
}

// The arm's own model error estimated from the images (a bundle adjustment
// over the cameras and the link lengths): a true arm whose link offsets are
// off by a known +-2-3 mm, three cameras that see it at the four calibration
// poses, cameras started 3 px off. The link lengths come back well inside
// their 2 mm prior and the cameras closer to the truth than an alignment to
// the nominal arm gets them.
TEST(Align, ArmLinkLengthsWithTheCameras) {
  World w;
  const unsigned nseg = w.model.segment_count();
  std::vector<double> truth_delta(nseg, 0.0);
  std::vector<int> segs;
  for (const int k : w.model.offset_segments()) {
    truth_delta[k] = (segs.size() % 2 ? -1.0 : 1.0) * (0.002 + 0.0005 * static_cast<double>(segs.size() % 3));
    segs.push_back(k);
  }
  const RobotModel truth_arm = w.model.with_link_lengths_changed(truth_delta);
  const auto poses = localization::arm_calibration_poses(w.model);
  std::vector<AlignView> views, nominal_only;
  std::vector<camera::Camera> truths;
  std::vector<std::unique_ptr<SyntheticCamera>> synths;
  for (const std::string name : {"side", "oblique", "overhead_zoom"}) {
    const camera::Camera truth = scene_camera(w.scene, name);
    truths.push_back(truth);
    synths.push_back(std::make_unique<SyntheticCamera>(*w.ctx, truth_arm, w.oru, w.scene, truth.viewport, options(2.0, 21)));
    AlignView v{perturbed(truth, 2.5, -1.5, 1.004), {}};
    for (const auto& p : poses) v.frames.push_back({synths.back()->render(truth, p.q).image_bgr, p.q});
    views.push_back(v);
  }
  ModelAligner aligner(*w.ctx, w.model, &w.oru, truths[0].viewport);
  std::vector<Eigen::Vector3d> pts;
  {
    KinematicsWorkspace tws(truth_arm);
    for (const auto& p : poses)
      for (int k = 0; k < static_cast<int>(truth_arm.links().size()); ++k)
        pts.push_back(forward_kinematics(truth_arm, tws, p.q, k).translation());
  }
  AlignOptions nominal;
  const AlignResult r0 = aligner.align(views, w.scene.base_T_object, nominal);
  AlignOptions o;
  o.arm_link_prior_m = 0.002;
  const AlignResult r = aligner.align(views, w.scene.base_T_object, o);
  ASSERT_EQ(r0.status, AlignStatus::Aligned) << r0.reason;
  ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
  ASSERT_EQ(r.arm_link_delta_m.size(), nseg);
  double t2 = 0.0, e2 = 0.0;
  int within3 = 0;
  std::printf("link   truth mm  estimate mm  sigma mm\n");
  for (const int k : segs) {
    const double err = r.arm_link_delta_m[k] - truth_delta[k];
    std::printf("%4d %9.2f %12.2f %9.2f\n", k, truth_delta[k] * 1e3, r.arm_link_delta_m[k] * 1e3,
                r.arm_link_sigma_m[k] * 1e3);
    t2 += truth_delta[k] * truth_delta[k];
    e2 += err * err;
    if (std::abs(err) <= 3.0 * r.arm_link_sigma_m[k]) ++within3;
  }
  const double true_rms = std::sqrt(t2 / segs.size()), est_rms = std::sqrt(e2 / segs.size());
  double cam_nominal = 0.0, cam_bundle = 0.0;
  for (std::size_t v = 0; v < truths.size(); ++v) {
    cam_nominal += reprojection_rms_px(r0.cameras[v], truths[v], pts) / truths.size();
    cam_bundle += reprojection_rms_px(r.cameras[v], truths[v], pts) / truths.size();
  }
  std::printf("links: true error %.2f mm rms, estimate's error %.2f mm rms (%d of %zu within 3 sigma); cameras vs "
              "truth: %.2f px aligned to the nominal arm, %.2f px with the arm refined; %d it, %.0f ms\n",
              true_rms * 1e3, est_rms * 1e3, within3, segs.size(), cam_nominal, cam_bundle, r.iterations, r.time_ms);
  EXPECT_LT(est_rms, 0.5 * true_rms);
  EXPECT_LT(cam_bundle, 0.7 * cam_nominal);
}

// A driver for measurements (not run by ctest: DISABLED_): the alignment
// study with FORESIGHT_STUDY_TRIALS / _SEED / _ARM_ERROR_MM / _PRIOR_MM.
// `eval alignment` seed 2, trial 0, view 2 (oblique) alone: the ORU
// alignment slid ~0.17 m from the clicks, along the oblique view's line of
// sight, onto other edges, reporting a 2.5 mm sd: a silently wrong answer
// (it passed the edge-distance and the 24 px rules; 29-30% matched, at the
// limit). Reproduced from the study's own inputs (the true arm's link
// errors, the synthetic camera's seed, the bundle-adjusted camera and arm,
// the clicks pose and the clicks' position covariance of the time: joint
// estimate plus the arm model's 10 x (2 mm)^2), printed by the study
// (FORESIGHT_STUDY_DUMP); the rotation is left loose here (loose_rotation).
// The same trial's view 4 (overhead_zoom, clicks 22 mm off) is a good
// alignment the rule keeps.
namespace {

Pose pose_from(const std::array<double, 16>& m) {  // column-major 4x4
  Eigen::Matrix4d M = Eigen::Map<const Eigen::Matrix4d>(m.data());
  Pose T = Pose::Identity();
  T.matrix() = M;
  return T;
}

Eigen::Matrix3d matrix3_from(const std::array<double, 9>& m) { return Eigen::Map<const Eigen::Matrix3d>(m.data()); }

// One trial of the study rebuilt: the true arm's link errors (rendered), the
// bundle adjustment's estimate of them (the ground's arm), the synthetic
// camera's seed (seed x 7919 + trial).
struct StudyTrial {
  World w;
  std::vector<std::vector<int>> view_poses;
  std::vector<Eigen::VectorXd> arm_q;
  std::vector<camera::Camera> truth;  // per view
  std::unique_ptr<SyntheticCamera> synth;
  std::vector<double> arm_delta;
  RobotModel truth_arm;

  StudyTrial(const std::vector<double>& true_delta, std::vector<double> estimated_delta, unsigned synth_seed)
      : arm_delta(std::move(estimated_delta)), truth_arm(w.model.with_link_lengths_changed(true_delta)) {
    localization::StudySetup setup = localization::make_study_setup(w.scene, w.oru, {});
    localization::choose_calibration_points(setup, localization::arm_calibration_poses(w.model));
    arm_q = setup.arm_q;
    for (const auto& v : setup.views) {
      truth.push_back(v.truth);
      view_poses.emplace_back();
      for (const auto& f : v.calibration_features)
        if (view_poses.back().empty() || view_poses.back().back() != f.pose) view_poses.back().push_back(f.pose);
    }
    SyntheticOptions so;
    so.noise_sigma_dn = 2.0;
    so.blur_sigma_px = 0.6;
    so.seed = synth_seed;
    synth = std::make_unique<SyntheticCamera>(*w.ctx, truth_arm, w.oru, w.scene, scene_camera(w.scene, "side").viewport, so);
  }

  AlignView view(int v, const camera::Camera& camera,
                 const Eigen::Matrix<double, 7, 7>& covariance = Eigen::Matrix<double, 7, 7>::Zero()) {
    AlignView out{camera, {}, covariance};
    for (const int p : view_poses[v]) out.frames.push_back({synth->render(truth[v], arm_q[p]).image_bgr, arm_q[p]});
    return out;
  }
};

struct Seed2Trial0 : StudyTrial {
  Seed2Trial0()
      : StudyTrial({-0.0022978332227732547, 0.001541391788480648, -0.0027292922779448038, 0.00052054273314506704,
                    0.0018545429158673375, -0.0038486163051447745, 0.0028192859748882113, -0.0017357187934516241,
                    0.00068046599337972407, -0.0019244058186935302},
                   {-0.0022349049783701521, 0.0015114762616777564, -0.0025910361473134871, 0.0004727366285684033,
                    0.0019093552097799668, -0.0038527906936825919, 0.0028479263559763202, -0.00067003283252899267,
                    -0.00032939602041898744, 0},
                   15838) {}  // 2 x 7919 + trial 0
};

camera::Camera camera_from(const camera::Camera& like, double f_px, const std::array<double, 16>& m) {
  camera::Camera c = like;
  c.f_px = f_px;
  c.base_T_camera = pose_from(m);
  return c;
}

double position_error_m(const Pose& est, const Pose& truth) { return (est.translation() - truth.translation()).norm(); }

// A start pose covariance (rpy rad, position m) from a position covariance,
// the rotation left loose (10 deg sd a axis): the position decides.
Eigen::Matrix<double, 6, 6> loose_rotation(const Eigen::Matrix3d& position_cov) {
  Eigen::Matrix<double, 6, 6> c = Eigen::Matrix<double, 6, 6>::Zero();
  c.topLeftCorner<3, 3>() = std::pow(10.0 * M_PI / 180.0, 2) * Eigen::Matrix3d::Identity();
  c.bottomRightCorner<3, 3>() = position_cov;
  return c;
}

// A refusal for the disagreement with the clicks: beyond the limit, the
// reason's exact form with the move (mm) and turn (deg) patterns given, the
// clicks pose kept unchanged.
void expect_refused_keeping_the_clicks(const AlignResult& r, const Pose& clicks, const std::string& moved_mm,
                                       const std::string& turned_deg) {
  ASSERT_EQ(r.status, AlignStatus::Refused);
  EXPECT_GT(r.start_disagreement_sigma, 5.0);
  EXPECT_THAT(r.reason, ::testing::MatchesRegex("the object moved " + moved_mm + " mm and turned " + turned_deg +
                                                " deg from its start pose, [0-9]+\\.[0-9] sigma of the start's and the "
                                                "alignment's pose uncertainty together \\(limit 5\\.0\\): the edges "
                                                "disagree with the start \\(the clicks\\)"));
  ASSERT_TRUE(r.base_T_object);
  EXPECT_TRUE(r.base_T_object->matrix() == clicks.matrix());
}

}  // namespace

// Since the ORU's edges with the bay are sampled and its silhouettes need a
// clear view beyond them (issue 30 item 6), this view no longer slides: it
// lands within a millimetre of the truth, 28 mm from the clicks, and the
// start check keeps it (the refusal itself: SingleViewOruTurnedAwayFrom
// TheClicksIsRefused).
TEST(Align, SingleViewOruThatSlidFromTheClicksNowFindsTheTruth) {
  Seed2Trial0 t;
  const camera::Camera oblique = camera_from(
      scene_camera(t.w.scene, "oblique"), 640.17115357376872,
      {0.75931091569290576, -0.65072800051314528, -5.1553512760573943e-05, 0, -0.29808987380653129,
       -0.34775984303126994, -0.88893504751971186, 0, 0.57843699781705515, 0.6749934525038227, -0.45803327240863467, 0,
       -0.40011049609425764, -1.3005145639218141, 1.5004470496227191, 1});
  const Pose clicks = pose_from({-0.0023515161194228593, -0.9999967971331869, -0.00093599963001425232, 0,
                                 0.0075600088782444876, 0.00091819794524421769, -0.99997100116868076, 0,
                                 0.99996865782768452, -0.0023585240937166073, 0.0075578255072738694, 0,
                                 0.99072633939762289, 0.13023022727093139, 0.56825723482217216, 1});
  const Eigen::Matrix3d clicks_cov = matrix3_from(
      {0.00010665615488197549, 7.6741995012286502e-05, -5.212486850846563e-05, 7.6741995012290527e-05,
       0.00014011456121675747, -6.6928486125283684e-05, -5.2124868508466294e-05, -6.6928486125281475e-05,
       8.7076109359291565e-05});
  const AlignView view = t.view(1, oblique);
  ModelAligner aligner(*t.w.ctx, t.w.model, &t.w.oru, oblique.viewport);
  AlignOptions o;
  o.refine = Refine::Object;
  o.arm_link_delta_m = t.arm_delta;
  const Pose& truth = t.w.scene.base_T_object;
  const double clicks_error = position_error_m(clicks, truth);

  // Without the clicks' covariance, and the matched-fraction limit a little
  // lower (29% matched here before; the study's first run had 30.1% and
  // passed): it was accepted 0.17 m off the truth, the silent wrong answer.
  AlignOptions loose = o;
  loose.min_matched_fraction = 0.25;
  const AlignResult free = aligner.align({view}, clicks, loose);
  ASSERT_EQ(free.status, AlignStatus::Aligned) << free.reason;
  const double error = position_error_m(*free.base_T_object, truth);
  const double sd = std::sqrt(free.covariance.block<3, 3>(3, 3).trace());
  std::printf("seed 2 trial 0 oblique alone: clicks %.1f mm off; the alignment %.1f mm off claiming %.1f mm (sd, 3-D)\n",
              clicks_error * 1e3, error * 1e3, sd * 1e3);
  EXPECT_GT(clicks_error, 0.02);
  EXPECT_LT(error, 0.002);
  EXPECT_LT(error, 3.0 * sd);

  // With the clicks' position covariance: kept, the same pose.
  o.object_start_covariance = loose_rotation(clicks_cov);
  loose.object_start_covariance = loose_rotation(clicks_cov);
  for (const AlignOptions& opt : {o, loose}) {
    const AlignResult r = aligner.align({view}, clicks, opt);
    std::printf("  %s, %.1f sigma from the clicks %s\n", to_string(r.status), r.start_disagreement_sigma, r.reason.c_str());
    ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
    EXPECT_LT(r.start_disagreement_sigma, 5.0);
    EXPECT_LT(position_error_m(*r.base_T_object, truth), 0.002);
  }
}

TEST(Align, SingleViewOruCloseToTheClicksIsKept) {
  Seed2Trial0 t;
  const camera::Camera zoom = camera_from(
      scene_camera(t.w.scene, "overhead_zoom"), 1099.6116647272622,
      {3.4949756288404522e-05, -0.99999999913784554, -2.2423719082050054e-05, 0, -0.97558135062367857,
       -2.9171220651472302e-05, -0.21963840161574605, 0, 0.21963840077225666, 2.9552470755974696e-05,
       -0.97558135080210295, 0, 0.50000024318799152, 0.1499487432395421, 2.5493973084880861, 1});
  const Pose clicks = pose_from({-9.8806025369313545e-05, -0.99998877124391272, -0.0047378923013417238, 0,
                                 0.0025548676019013766, 0.0047376244280254113, -0.99998551367823074, 0,
                                 0.99999673143911116, -0.00011090928157542684, 0.0025543708080768297, 0,
                                 1.0011854805732687, 0.14902589458966148, 0.57201549233889026, 1});
  const Eigen::Matrix3d clicks_cov = matrix3_from(
      {4.2953141175651356e-05, 9.5635387306529097e-08, -1.2657019500421706e-05, 9.5635387306616646e-08,
       4.1907596411619036e-05, -1.2847249616000711e-06, -1.2657019500421932e-05, -1.2847249615993982e-06,
       0.00013722567074472166});
  const AlignView view = t.view(3, zoom);
  ModelAligner aligner(*t.w.ctx, t.w.model, &t.w.oru, zoom.viewport);
  AlignOptions o;
  o.refine = Refine::Object;
  o.arm_link_delta_m = t.arm_delta;
  o.object_start_covariance = loose_rotation(clicks_cov);
  const AlignResult r = aligner.align({view}, clicks, o);
  ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
  const Pose& truth = t.w.scene.base_T_object;
  std::printf("seed 2 trial 0 overhead_zoom alone: clicks %.1f mm off, aligned %.2f mm off, %.1f sigma from the clicks\n",
              position_error_m(clicks, truth) * 1e3, position_error_m(*r.base_T_object, truth) * 1e3,
              r.start_disagreement_sigma);
  EXPECT_GT(position_error_m(clicks, truth), 0.02);
  EXPECT_LT(position_error_m(*r.base_T_object, truth), 0.002);
  EXPECT_LT(r.start_disagreement_sigma, 5.0);
}

// `eval alignment` seed 11, trial 17, the side view alone: the ORU alignment
// turned the ORU 5.6 deg and slid it along its hole axis, 33 mm off the truth
// claiming 1.3 mm; it moved only 4.5 sigma of the clicks' and its own
// position uncertainty, so the position check kept it. The turn is the
// conflict: with the clicks' whole pose covariance (the two-step pose's, the
// held cameras' and the arm's links in it) the check over rotation and
// position refuses it. Rebuilt from the study's inputs (FORESIGHT_STUDY_DUMP=17).
// Since the ORU's edges with the bay are sampled (issue 30 item 6) the
// alignment from these clicks moves 52 mm (39 mm off the truth, turned 5.7
// deg) and its position alone is 5.1 sigma: the turn is still the larger
// conflict (10.8 sigma over the whole pose).
TEST(Align, SingleViewOruTurnedAwayFromTheClicksIsRefused) {
  StudyTrial t({-0.00041637129767616536, -0.0015760898634493599, -0.0029757657020349094, -0.0039120912000619682,
                2.6611863171437961e-05, 0.0032462125011682801, -0.0030708336867237345, -0.0026865029726198266,
                -0.0015477828189939538, 0.0011085610817601389},
               {-0.00041328405992833571, -0.001616728998125709, -0.0028342521801206994, -0.0039403629733717324,
                0.00010035031452190278, 0.0031601634277454763, -0.0028304907427884429, -0.0023458162879468818,
                -0.0020749986401431687, 0},
               87126);  // 11 x 7919 + trial 17
  const camera::Camera side = camera_from(
      scene_camera(t.w.scene, "side"), 700.64477183844542,
      {0.99969128404229424, -0.024846223058172027, -4.2539520190074752e-05, 0,
       -0.0037225894881122352, -0.1480856890241507, -0.98896752779539931, 0,
       0.024565808298735375, 0.98866237609508767, -0.14813246489761697, 0,
       0.75035741279346813, -1.9018533072529529, 0.84997954094166384, 1});
  const Eigen::Matrix<double, 7, 7> side_cov = Eigen::Map<const Eigen::Matrix<double, 7, 7>>(std::array<double, 49>{
      2.6152398135836413e-08, -8.27796627169657e-09, -2.5092465938520652e-09, 5.7923263711015156e-08,
      -2.400294054226403e-07, 4.1549781779258338e-08, 4.4984593571659064e-05,
      -8.2779662716965783e-09, 4.7038554258651561e-08, 1.5146901742408299e-08, -1.6971319431875358e-07,
      6.1796658873998045e-07, -1.4936602252226314e-07, -0.00012663197179364687,
      -2.5092465938520644e-09, 1.5146901742408299e-08, 2.9448907781897915e-08, -2.0213246080273874e-07,
      8.1337264322928609e-07, -2.2141592222008461e-07, -0.00012603572128951944,
      5.7923263711015175e-08, -1.6971319431875361e-07, -2.0213246080273874e-07, 1.6971801176778993e-06,
      -6.6974609497248751e-06, 1.7465526783945452e-06, 0.0011162311520447044,
      -2.400294054226404e-07, 6.1796658873998045e-07, 8.1337264322928609e-07, -6.6974609497248742e-06,
      2.7187799655285286e-05, -7.0536795974008095e-06, -0.0045723365020857399,
      4.1549781779258345e-08, -1.4936602252226314e-07, -2.2141592222008461e-07, 1.746552678394545e-06,
      -7.0536795974008087e-06, 1.8951730322748862e-06, 0.001149122391274232,
      4.4984593571659077e-05, -0.0001266319717936469, -0.00012603572128951944, 0.0011162311520447042,
      -0.0045723365020857391, 0.001149122391274232, 0.83423041285486144}.data());
  const Pose clicks = pose_from({-0.038944130002068221, -0.99906384226061939, 0.018835971592417011, 0,
       0.0081733336046041737, -0.019168129424403681, -0.99978286614252287, 0,
       0.99920796201600104, -0.038781721233303104, 0.0089121681992941366, 0,
       1.019523525245813, 0.11522638100521466, 0.55757290835875872, 1});
  const Eigen::Matrix<double, 6, 6> clicks_cov = Eigen::Map<const Eigen::Matrix<double, 6, 6>>(std::array<double, 36>{
      6.2174580661030846e-05, -6.9810659668765008e-06, -3.9464771027519263e-05, 8.6566326188504816e-07,
      -3.6402441719823345e-05, 1.5642024136091641e-05,
      -6.9810659668764677e-06, 9.6321242912201531e-05, 5.9333020375141044e-05, -1.9173418136456714e-05,
      8.2658457786270595e-05, -1.6280446691667853e-05,
      -3.9464771027518768e-05, 5.9333020375141477e-05, 0.00024379343812255485, -1.9415713294042843e-05,
      0.00019869662320823946, -3.5214747501914979e-05,
      8.6566326188505642e-07, -1.9173418136456711e-05, -1.9415713294042636e-05, 1.7748375419182341e-05,
      -1.7698953514603455e-05, 4.1899115154218909e-06,
      -3.640244171982285e-05, 8.2658457786270948e-05, 0.00019869662320823908, -1.7698953514603245e-05,
      0.00038022751997141945, -7.6577662954574818e-05,
      1.5642024136091604e-05, -1.6280446691667891e-05, -3.5214747501915297e-05, 4.1899115154218468e-06,
      -7.6577662954575225e-05, 3.2349015434683369e-05}.data());
  const AlignView view = t.view(0, side, side_cov);
  ModelAligner aligner(*t.w.ctx, t.w.model, &t.w.oru, side.viewport);
  AlignOptions o;
  o.refine = Refine::Object;
  o.arm_link_delta_m = t.arm_delta;
  const Pose& truth = t.w.scene.base_T_object;
  // Without the start's covariance: accepted, far off, claiming little.
  const AlignResult wrong = aligner.align({view}, clicks, o);
  ASSERT_EQ(wrong.status, AlignStatus::Aligned) << wrong.reason;
  const double wrong_error = position_error_m(*wrong.base_T_object, truth);
  const double wrong_sd = std::sqrt(wrong.covariance.block<3, 3>(3, 3).trace());
  std::printf("seed 11 trial 17 side alone: clicks %.1f mm off; the alignment %.1f mm off claiming %.1f mm (sd, 3-D)\n",
              position_error_m(clicks, truth) * 1e3, wrong_error * 1e3, wrong_sd * 1e3);
  EXPECT_GT(wrong_error, 0.025);
  EXPECT_GT(wrong_error, 5.0 * wrong_sd);  // 36.5 mm off claiming 5.1 mm (3-D sd)
  // With it: refused for the turn, the clicks pose kept. The position alone
  // (the old rule's metric) says less.
  o.object_start_covariance = clicks_cov;
  const AlignResult r = aligner.align({view}, clicks, o);
  std::printf("  refused: %s (position alone %.1f sigma)\n", r.reason.c_str(), r.start_position_disagreement_sigma);
  expect_refused_keeping_the_clicks(r, clicks, "[2-5][0-9]", "[5-7]\\.[0-9]");
  EXPECT_GT(r.start_disagreement_sigma, 8.0);
  EXPECT_LT(r.start_position_disagreement_sigma, 0.6 * r.start_disagreement_sigma);
}

// `eval alignment` seed 4, trial 2, all four views: with the cameras held
// (each aligned to its frames with the arm, step 5) the ORU aligned over the
// four views ended 5.4 mm off; the cameras' small errors, each within its
// own uncertainty, disagree where the ORU is. Refined together (the ORU,
// the four cameras and the arm's link lengths, the ORU's edges in every
// view tying the cameras to each other there) it ends 0.08 mm off, within
// 3 sigma of its covariance, and the start check over the clicks'
// uncertainty passes. Rebuilt from the study's inputs
// (FORESIGHT_STUDY_DUMP=2).
TEST(Align, OruCamerasAndArmRefinedTogetherOverFourViews) {
  StudyTrial t({-0.0025452247983518105, -0.0001058682071186133, 0.0032719496275068361,
                0.0016629685660270162, -0.0009362688918947812, 0.0031713952567213655,
                0.00090838230794526033, -0.0019176890549781503, 0.0040001373191955103,
                3.1939330441835218e-05},
               {-0.0025927952334691587, -0.00010745272568096191, 0.0032481691564702955,
                0.0017347488724451902, -0.00088058662233859281, 0.0031399265096661243,
                0.00096989227636314252, 0.00095352928721785578, 0.0010954088762609527,
                0},
               31678);  // 4 x 7919 + trial 2
  std::vector<AlignView> views;
  views.push_back(t.view(0, camera_from(scene_camera(t.w.scene, "side"), 699.73404637073463,
                                         {0.99968278936346311, -0.025185722036638641, 7.4820969481102713e-06, 0,
                                          -0.0037271354424940049, -0.14823289702956396, -0.9889454568881012, 0,
                                          0.024908414479486742, 0.9886317249834321, -0.14827974657518886, 0,
                                          0.74965099668021995, -1.8993496311049811, 0.84983545379417735, 1})));
  views.push_back(t.view(1, camera_from(scene_camera(t.w.scene, "oblique"), 618.79247875820363,
                                         {0.75574821903765332, -0.65483446281972879, 0.0060378576509871771, 0,
                                          -0.29311190285648159, -0.3464982805720962, -0.8910804419155619, 0,
                                          0.58560228980534923, 0.67166268905171345, -0.45380523389506339, 0,
                                          -0.38233252395926248, -1.2547107994544422, 1.4691895742817744, 1})));
  views.push_back(t.view(2, camera_from(scene_camera(t.w.scene, "overhead_wide"), 420.26978200101763,
                                         {-8.716440530259e-05, -0.99999998565251036, 0.0001452492502308909, 0,
                                          -0.99298892963830232, 6.9383759589161369e-05, -0.11820736356789789, 0,
                                          0.11820735179397994, -0.00015453437206536298, -0.99298892143919848, 0,
                                          0.4498901261264478, 0.10023053560084035, 2.6010642930837564, 1})));
  views.push_back(t.view(3, camera_from(scene_camera(t.w.scene, "overhead_zoom"), 1101.9091755280801,
                                         {-0.00023183552135893194, -0.99999996312820971, 0.00014140674867332985, 0,
                                          -0.9756708169758237, 0.00019519306636075334, -0.21924055008459803, 0,
                                          0.21924051439918971, -0.0001887941852358821, -0.97567082625377999, 0,
                                          0.49985173250032616, 0.15027340652405849, 2.5530265304125752, 1})));
  const Pose clicks = pose_from({-0.0037266814385679427, -0.99999295321284387, 0.0004531777907014721, 0,
                                 -0.011809296837827336, -0.00040913954748618658, -0.99993018411938461, 0,
                                 0.99992332323716282, -0.0037317729680722738, -0.011807688887468703, 0,
                                 0.99110156395673987, 0.15024092935003652, 0.550927777878365, 1});
  const Eigen::Matrix<double, 6, 6> clicks_cov = Eigen::Map<const Eigen::Matrix<double, 6, 6>>(std::array<double, 36>{
      9.4660310160456351e-05, 6.5127451397703416e-06, -4.5620470654292991e-05,
      1.8602754288301706e-05, -1.659185291686614e-05, 5.343462762912739e-06,
      6.5127451397704475e-06, 2.2537326116215431e-05, 2.7123133802075579e-06,
      2.2292198851554799e-06, -8.2880123737793302e-07, -4.0747613673423543e-07,
      -4.5620470654292869e-05, 2.7123133802076295e-06, 7.7062263753092665e-05,
      -2.9387287788149172e-05, 2.6160029287318813e-05, -7.8407703608836466e-07,
      1.8602754288301787e-05, 2.2292198851554782e-06, -2.9387287788149172e-05,
      2.8645708256496451e-05, -1.2405297537207055e-05, 1.8715793781829864e-06,
      -1.6591852916866082e-05, -8.2880123737793207e-07, 2.6160029287318803e-05,
      -1.2405297537207045e-05, 1.2976517051154666e-05, -5.9693142592647238e-07,
      5.3434627629127373e-06, -4.0747613673423855e-07, -7.8407703608840532e-07,
      1.8715793781829845e-06, -5.9693142592647905e-07, 1.2410969890195485e-05}.data());
  ModelAligner aligner(*t.w.ctx, t.w.model, &t.w.oru, views[0].camera.viewport);
  const Pose& truth = t.w.scene.base_T_object;
  AlignOptions o;
  o.refine = Refine::Object;
  o.arm_link_delta_m = t.arm_delta;
  o.object_start_covariance = clicks_cov;
  const AlignResult held = aligner.align(views, clicks, o);
  ASSERT_EQ(held.status, AlignStatus::Aligned) << held.reason;
  o.refine = Refine::Both;
  o.arm_link_prior_m = 0.002;
  const AlignResult joint = aligner.align(views, clicks, o);
  ASSERT_EQ(joint.status, AlignStatus::Aligned) << joint.reason;
  const double clicks_error = position_error_m(clicks, truth), held_error = position_error_m(*held.base_T_object, truth);
  const Eigen::Vector3d e = joint.base_T_object->translation() - truth.translation();
  // The object's block follows the four cameras' (then the links').
  ASSERT_EQ(joint.covariance.rows(), 4 * 7 + 6 + static_cast<int>(t.w.model.offset_segments().size()));
  const Eigen::Matrix3d C = joint.covariance.block<3, 3>(4 * 7 + 3, 4 * 7 + 3);
  const double z = std::sqrt(e.dot(C.ldlt().solve(e)));
  std::printf("seed 4 trial 2, four views: clicks %.1f mm off; cameras held %.2f mm; cameras, arm and ORU together "
              "%.2f mm (%.1f sigma, sd %.2f mm 3-D), %.1f sigma from the clicks, %.0f ms\n",
              clicks_error * 1e3, held_error * 1e3, e.norm() * 1e3, z, 1e3 * std::sqrt(C.trace()),
              joint.start_disagreement_sigma, joint.time_ms);
  EXPECT_GT(clicks_error, 0.008);
  EXPECT_GT(held_error, 0.003);
  EXPECT_LT(e.norm(), 0.0005);
  EXPECT_LT(z, 3.4);  // the 99% point of a 3-D Gaussian's distance
  EXPECT_LT(joint.start_disagreement_sigma, 5.0);
}

// A held camera is not exact: its uncertainty (AlignView::camera_covariance)
// enters the object's covariance. Two known answers on one side view: a
// camera centre uncertain by sd per axis moves the object exactly as much (the
// image depends on the relative pose only), so the object's position
// covariance grows by sd^2 I and its rotation's not at all; an f uncertain by
// 1% trades against depth, so the object's sd along the line of sight grows
// by about 1% of its distance. The solution itself does not change.
TEST(Align, HeldCameraUncertaintyEntersTheObjectCovariance) {
  World w;
  const Eigen::VectorXd q = w.approach_q();
  const camera::Camera side = scene_camera(w.scene, "side");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, side.viewport, options(2.0, 7));
  AlignView view{side, {{synth.render(side, q).image_bgr, q}}};
  ModelAligner aligner(*w.ctx, w.model, &w.oru, side.viewport);
  Pose start = w.scene.base_T_object;
  start.translation() += Eigen::Vector3d(0.003, -0.002, 0.002);
  AlignOptions o;
  o.refine = Refine::Object;
  const AlignResult exact = aligner.align({view}, start, o);
  ASSERT_EQ(exact.status, AlignStatus::Aligned) << exact.reason;
  ASSERT_EQ(exact.covariance.rows(), 6);

  constexpr double kSd = 0.003;
  view.camera_covariance.setZero();
  view.camera_covariance.block<3, 3>(3, 3) = kSd * kSd * Eigen::Matrix3d::Identity();
  const AlignResult centre = aligner.align({view}, start, o);
  ASSERT_EQ(centre.status, AlignStatus::Aligned) << centre.reason;
  EXPECT_LT((centre.base_T_object->matrix() - exact.base_T_object->matrix()).norm(), 1e-12);
  const Eigen::Matrix<double, 6, 6> added = centre.covariance - exact.covariance;
  EXPECT_LT(((added.bottomRightCorner<3, 3>() - kSd * kSd * Eigen::Matrix3d::Identity()).norm()), 0.01 * kSd * kSd)
      << added;
  EXPECT_LT((added.topLeftCorner<3, 3>().norm()), 1e-3 * kSd * kSd) << added;

  view.camera_covariance.setZero();
  view.camera_covariance(6, 6) = std::pow(0.01 * side.f_px, 2);
  const AlignResult focal = aligner.align({view}, start, o);
  ASSERT_EQ(focal.status, AlignStatus::Aligned) << focal.reason;
  const Eigen::Vector3d axis = side.base_T_camera.linear().col(2);  // the optical axis in base
  const double depth_m = side.to_camera(focal.base_T_object->translation()).z();
  const Eigen::Matrix3d added_f = (focal.covariance - exact.covariance).bottomRightCorner<3, 3>();
  const double depth_sd = std::sqrt(axis.dot(added_f * axis));
  std::printf("held side camera: +%.2f mm position sd from a 3 mm centre sd; +%.2f mm depth sd from a 1%% f sd "
              "(1%% of the %.3f m depth: %.2f mm); edges alone %.2f mm\n",
              std::sqrt(added.bottomRightCorner<3, 3>().trace() / 3) * 1e3, depth_sd * 1e3, depth_m, depth_m * 10,
              std::sqrt(axis.dot(exact.covariance.bottomRightCorner<3, 3>() * axis)) * 1e3);
  EXPECT_NEAR(depth_sd, 0.01 * depth_m, 0.2 * 0.01 * depth_m);

  // A covariance that is not one is bad input, named.
  view.camera_covariance(6, 6) = -1.0;
  try {
    aligner.align({view}, start, o);
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "camera 'side': its covariance is not a finite symmetric matrix with a non-negative diagonal");
  }
}

// Issue 30 item 6: from the side the ORU shows a thin sliver of its front
// face and the 5 cm strip of its side in front of the bay. The strip's far
// edge, where the ORU enters the bay, is no edge of the ORU's mesh but its
// intersection with the bay's front face: sampled now (the ORU's label on one
// side, the bay's on the other), it holds the ORU along its hole axis. And
// the front face's far silhouette lies 2 px from the bay's far edge (bay
// against sky, the stronger edge), which the search took: dropped now (an
// object silhouette needs kClear_px of one label beyond it). Before, the
// ORU ended 2.4 mm (image horizontal) and 4.0-4.2 mm (line of sight) off with
// a 0.49-0.50 px inlier residual from every start, the truth included. The
// true camera and arm, a noise-free frame, three starts: the error against
// the truth in the camera's axes (x image horizontal, y vertical, z line of
// sight). Measured 0.01-0.07 mm, 0.18 px.
TEST(Align, TheSideViewsOruIsHeldByItsEdgeWithTheBay) {
  World w;
  const Eigen::VectorXd q = w.approach_q();
  const camera::Camera side = scene_camera(w.scene, "side");
  SyntheticCamera synth(*w.ctx, w.model, w.oru, w.scene, side.viewport, options(0.0));
  const AlignView view{side, {{synth.render(side, q).image_bgr, q}}};
  ModelAligner aligner(*w.ctx, w.model, &w.oru, side.viewport);
  AlignOptions o;
  o.refine = Refine::Object;
  const Pose& truth = w.scene.base_T_object;
  const Eigen::Matrix3d base_R_camera = side.base_T_camera.linear();
  // Starts: 5.4 mm and 5.4 mm off, turned 0.32 deg; the truth itself.
  const std::array<Eigen::Vector3d, 3> offsets{
      Eigen::Vector3d(0.003, -0.002, 0.004), Eigen::Vector3d(-0.004, 0.003, -0.002), Eigen::Vector3d(0.0, 0.0, 0.0)};
  for (std::size_t k = 0; k < offsets.size(); ++k) {
    Pose start = truth;
    start.translation() += offsets[k];
    start.linear() = start.linear() * camera::exp_so3(Eigen::Vector3d(0.004, -0.003, 0.002) * (k < 2 ? 1.0 : 0.0));
    const AlignResult r = aligner.align({view}, start, o);
    ASSERT_EQ(r.status, AlignStatus::Aligned) << r.reason;
    const Eigen::Vector3d err =
        base_R_camera.transpose() * (r.base_T_object->translation() - truth.translation());
    const double turn =
        Eigen::AngleAxisd(truth.linear().transpose() * r.base_T_object->linear()).angle() * 180.0 / M_PI;
    std::printf("side view ORU from start %zu: %.2f mm horizontal, %.2f mm vertical, %.2f mm line of sight, %.3f deg; "
                "inlier residual %.3f px, %d of %d samples within 1 px\n",
                k, err.x() * 1e3, err.y() * 1e3, err.z() * 1e3, turn, r.residual_rms_px, r.matched_samples,
                r.visible_samples);
    EXPECT_LT(err.norm(), 0.001);
    EXPECT_LT(r.residual_rms_px, 0.25);
  }
}

TEST(AlignStudy, DISABLED_Driver) {
  World w;
  AlignmentStudyOptions o;
  auto env = [](const char* k, double d) { const char* v = std::getenv(k); return v ? std::atof(v) : d; };
  o.trials = static_cast<int>(env("FORESIGHT_STUDY_TRIALS", 2));
  o.seed = static_cast<unsigned>(env("FORESIGHT_STUDY_SEED", 1));
  o.arm_link_error_m = env("FORESIGHT_STUDY_ARM_ERROR_MM", 2.0) * 1e-3;
  o.arm_link_prior_m = env("FORESIGHT_STUDY_PRIOR_MM", 2.0) * 1e-3;
  const AlignmentStudyResult r = run_alignment_study(*w.ctx, w.model, w.oru, w.scene, o);
  for (std::size_t v = 0; v < r.view_names.size(); ++v)
    std::printf("view %zu %s: camera %.2f px clicks, %.2f aligned (%d refused), %.2f with arm\n", v + 1,
                r.view_names[v].c_str(), r.camera_clicks_px[v], r.camera_aligned_px[v], r.camera_refused[v],
                r.camera_bundle_px[v]);
  std::printf("links: true %.2f mm rms, estimate error %.2f mm rms, bundle refused %d\n", r.link_true_rms_all_m * 1e3,
              r.link_estimate_error_rms_all_m * 1e3, r.bundle_refused);
  for (std::size_t j = 0; j < r.link_segments.size(); ++j)
    std::printf("  seg %d: true %.2f est err %.2f sigma %.2f mm\n", r.link_segments[j], r.link_true_rms_m[j] * 1e3,
                r.link_estimate_error_rms_m[j] * 1e3, r.link_sigma_mean_m[j] * 1e3);
  for (const auto& c : r.combos)
    std::printf("%-8s clicks %6.2f mm %.3f deg 95%% %.3f depth %.3f | aligned %6.2f mm %.3f deg 95%% %.3f depth %.3f (%d) | "
                "cam-only %6.2f mm 95%% %.3f depth %.3f (%d)\n",
                c.label.c_str(), c.clicks.position_rmse_m * 1e3, c.clicks.rotation_rmse_rad * 180 / M_PI,
                c.clicks.alignment95_m * 100, c.clicks.depth95_m * 100, c.aligned.position_rmse_m * 1e3,
                c.aligned.rotation_rmse_rad * 180 / M_PI, c.aligned.alignment95_m * 100, c.aligned.depth95_m * 100,
                c.aligned_refused, c.aligned_cameras_only.position_rmse_m * 1e3,
                c.aligned_cameras_only.alignment95_m * 100, c.aligned_cameras_only.depth95_m * 100,
                c.aligned_cameras_only_refused);
  std::printf("elapsed %.1f s\n", r.elapsed_s);
}
