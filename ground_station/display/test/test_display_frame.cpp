// The display's picture against the synthetic camera's truth: with the true
// camera, the actual arm's overlay covers the arm the synthetic video shows
// (silhouette IoU), the ghost draws where the commanded arm is, the overlay
// switch leaves the video untouched, and the text says what is wrong.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "foresight/common/kinematics.hpp"
#include "foresight/display/display_frame.hpp"
#include "foresight/render/scene_geometry.hpp"
#include "foresight/render/synthetic_camera.hpp"

using namespace foresight;
using namespace foresight::display;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

double iou(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat i, u;
  cv::bitwise_and(a, b, i);
  cv::bitwise_or(a, b, u);
  return static_cast<double>(cv::countNonZero(i)) / std::max(1, cv::countNonZero(u));
}

cv::Mat changed(const cv::Mat& a, const cv::Mat& b, int threshold) {
  cv::Mat d, g;
  cv::absdiff(a, b, d);
  cv::cvtColor(d, g, cv::COLOR_BGR2GRAY);
  return g > threshold;
}

struct World {
  RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  std::unique_ptr<render::GlContext> gl = render::GlContext::create(render::GlBackend::OSMesa);
};

}  // namespace

TEST(DisplayFrame, ActualArmOverlayCoversTheSyntheticArm) {
  World w;
  const camera::Camera cam = render::scene_camera(w.scene, w.scene.camera_order.front());
  render::SyntheticCamera synth(*w.gl, w.model, w.oru, w.scene, cam.viewport);
  DisplayComposer composer(*w.gl, w.model, &w.oru, w.scene.base_T_object);
  Eigen::VectorXd q = w.model.mid_configuration();
  q[1] += 0.3;
  q[3] -= 0.4;
  const render::SyntheticFrame f = synth.render(cam, q);
  DisplayState s;
  s.q_actual = q;
  s.text = false;
  // The overlay alone (without the ORU): no composer object here.
  DisplayComposer arm_only(*w.gl, w.model, nullptr, std::nullopt);
  const cv::Mat shown = arm_only.compose(cam, f.image_bgr, s);
  const cv::Mat overlay = changed(shown, f.image_bgr, 12);
  // The synthetic arm mask is the visible arm; the overlay draws the whole
  // arm: compare with the part not hidden by the ORU or the panel.
  const double i = iou(overlay, f.arm_mask);
  std::printf("display overlay vs synthetic arm: IoU %.4f (%d vs %d pixels)\n", i, cv::countNonZero(overlay),
              cv::countNonZero(f.arm_mask));
  EXPECT_GT(i, 0.95);
  EXPECT_GT(iou(arm_only.arm_silhouette(cam, q), f.arm_mask), 0.95);

  // Overlay off: the video as it is.
  s.overlay = false;
  EXPECT_EQ(cv::countNonZero(changed(arm_only.compose(cam, f.image_bgr, s), f.image_bgr, 0)), 0);

  // The ghost runs ahead: drawn where the commanded arm's silhouette is.
  Eigen::VectorXd q_cmd = q;
  q_cmd[0] += 0.35;
  s.overlay = true;
  s.q_commanded = q_cmd;
  s.mode = render::RenderMode::Wire;
  const cv::Mat with_ghost = composer.compose(cam, f.image_bgr, s);
  cv::Mat ghost_only = composer.arm_silhouette(cam, q_cmd) & ~composer.arm_silhouette(cam, q);
  cv::Mat ghost_changed = changed(with_ghost, f.image_bgr, 12) & ghost_only;
  EXPECT_GT(cv::countNonZero(ghost_changed), 0.9 * cv::countNonZero(ghost_only));
}

TEST(DisplayFrame, TextSaysTheVideoProblemAndTheFault) {
  World w;
  const camera::Camera cam = render::scene_camera(w.scene, w.scene.camera_order.front());
  DisplayComposer composer(*w.gl, w.model, nullptr, std::nullopt);
  DisplayState s;
  s.q_actual = w.model.mid_configuration();
  s.overlay = false;
  const cv::Mat blank = composer.compose(cam, cv::Mat(), s);
  ASSERT_EQ(blank.size(), cv::Size(cam.viewport.width_px, cam.viewport.height_px));
  s.video_problem = "video source 'nowhere.mp4' cannot be opened (attempt 1); retrying";
  s.fault_text = "drive 3 EMCY";
  const cv::Mat said = composer.compose(cam, cv::Mat(), s);
  // Red text in the middle band (the video problem) and in the header (the fault).
  auto red_pixels = [](const cv::Mat& img, cv::Rect r) {
    int n = 0;
    for (int y = r.y; y < r.y + r.height; ++y)
      for (int x = r.x; x < r.x + r.width; ++x) {
        const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
        n += p[2] > 150 && p[1] < 120;
      }
    return n;
  };
  EXPECT_GT(red_pixels(said, cv::Rect(0, said.rows / 2 - 15, said.cols, 30)), 50);
  EXPECT_GT(red_pixels(said, cv::Rect(0, 0, said.cols, 60)), 30);
  EXPECT_EQ(red_pixels(blank, cv::Rect(0, 0, blank.cols, blank.rows)), 0);
  // The calibration health line: white while healthy, red on a warning.
  DisplayState h;
  h.q_actual = s.q_actual;
  h.overlay = false;
  h.health_text = "calibration: 76% of the arm's edges within 1 px, IoU 0.93";
  const cv::Mat healthy = composer.compose(cam, cv::Mat(), h);
  EXPECT_EQ(red_pixels(healthy, cv::Rect(0, 0, healthy.cols, 80)), 0);
  // White text in the band under the header, where the header alone has none.
  auto white_pixels = [](const cv::Mat& img) {
    return cv::countNonZero(img(cv::Rect(0, 20, img.cols, 30)).reshape(1) > 200);
  };
  std::printf("white in the health line's band: %d with it, %d without\n", white_pixels(healthy), white_pixels(blank));
  EXPECT_GT(white_pixels(healthy), white_pixels(blank) + 100);
  h.health_warning = true;
  h.health_text = "CALIBRATION: the camera may have moved or zoomed";
  const cv::Mat warned = composer.compose(cam, cv::Mat(), h);
  EXPECT_GT(red_pixels(warned, cv::Rect(0, 0, warned.cols, 60)), 30);
  cv::Mat wrong(10, 10, CV_8UC3);
  EXPECT_THROW(composer.compose(cam, wrong, s), std::invalid_argument);
}

// display --check-insert: the composer draws the go/no-go with the overlay
// (draw_go_no_go, the same drawing as `overlay --check-insert`) and not
// without it: green where the hole's 95% ellipse is for a go, red for a no_go.
TEST(DisplayFrame, GoNoGoIsDrawnWithTheOverlay) {
  World w;
  const camera::Camera cam = render::scene_camera(w.scene, "side");
  DisplayComposer composer(*w.gl, w.model, &w.oru, w.scene.base_T_object);
  DisplayState s;
  s.q_actual = w.model.mid_configuration();
  s.text = false;
  s.mode = render::RenderMode::Wire;
  const cv::Mat video(cam.viewport.height_px, cam.viewport.width_px, CV_8UC3, cv::Scalar(40, 40, 40));
  const cv::Mat plain = composer.compose(cam, video, s);
  GoNoGoMarks m;
  m.base_T_hole = w.scene.base_T_object * w.oru.tags.at("hole_entrance");
  m.base_T_tag = w.scene.base_T_object * w.oru.tags.at("insert_start");
  m.hole_position_covariance = Eigen::Vector3d(4e-6, 4e-6, 1e-5).asDiagonal();  // 2 mm across
  m.tip_position_covariance = 2.0 * m.hole_position_covariance;
  const Eigen::Vector2d hole = cam.project(m.base_T_hole.translation());
  for (const bool go : {true, false}) {
    m.go = go;
    m.p_success = go ? 0.999 : 0.4;
    s.go_no_go = m;
    const cv::Mat shown = composer.compose(cam, video, s);
    const ImageEllipse e = project_position_ellipse(cam, m.base_T_hole.translation(), m.hole_position_covariance);
    const int h = static_cast<int>(std::ceil(e.semi_major_px + 12.0));
    int green = 0, red = 0;
    for (int y = static_cast<int>(hole.y()) - h; y <= static_cast<int>(hole.y()) + h; ++y)
      for (int x = static_cast<int>(hole.x()) - h; x <= static_cast<int>(hole.x()) + h; ++x) {
        // Pixels that turned green (red): the tag triads' axes are green and red already.
        const auto is_green = [](const cv::Vec3b& c) { return c[1] >= 150 && c[1] - c[2] >= 80 && c[1] - c[0] >= 80; };
        const auto is_red = [](const cv::Vec3b& c) { return c[2] >= 150 && c[2] - c[1] >= 80 && c[2] - c[0] >= 80; };
        const cv::Vec3b c = shown.at<cv::Vec3b>(y, x), o = plain.at<cv::Vec3b>(y, x);
        green += is_green(c) && !is_green(o);
        red += is_red(c) && !is_red(o);
      }
    std::printf("display go/no-go (%s): hole's ellipse %.2f x %.2f px, %d green, %d red pixels around it\n",
                go ? "go" : "no_go", e.semi_major_px, e.semi_minor_px, green, red);
    EXPECT_GT(go ? green : red, 25);
    EXPECT_EQ(go ? red : green, 0);
    // With the text on, its label is drawn too (beside the marks, in the
    // same colour); off, the marks alone.
    s.text = true;
    const cv::Mat labelled = composer.compose(cam, video, s);
    s.go_no_go.reset();
    const cv::Mat text_only = composer.compose(cam, video, s);
    s.go_no_go = m;
    s.text = false;
    const auto coloured = [&](const cv::Mat& img, const cv::Mat& base) {
      int n = 0;
      for (int y = 0; y < img.rows; ++y)
        for (int x = 0; x < img.cols; ++x) {
          const cv::Vec3b c = img.at<cv::Vec3b>(y, x);
          const bool col = go ? (c[1] >= 150 && c[1] - c[2] >= 80) : (c[2] >= 150 && c[2] - c[1] >= 80);
          n += col && c != base.at<cv::Vec3b>(y, x);
        }
      return n;
    };
    const int with_label = coloured(labelled, text_only), without = coloured(shown, plain);
    std::printf("  %d %s pixels with the text on, %d with it off (the label)\n", with_label, go ? "green" : "red", without);
    EXPECT_GT(with_label, without + 40);
    // Overlay off: nothing of it.
    s.overlay = false;
    EXPECT_EQ(cv::countNonZero(changed(composer.compose(cam, video, s), video, 0)), 0);
    s.overlay = true;
  }
}
