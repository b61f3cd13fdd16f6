// Preview video, contact sheet and predictive frame.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "foresight/common/error.hpp"
#include "foresight/common/kinematics.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/preview/preview.hpp"

using namespace foresight;
using namespace foresight::preview;
using namespace foresight::render;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

std::string temp_path(const std::string& suffix) {
  char tmpl[] = "/tmp/foresight_preview_XXXXXX";
  const int fd = mkstemp(tmpl);
  close(fd);
  std::remove(tmpl);
  return std::string(tmpl) + suffix;
}

struct Fixture : ::testing::Test {
  RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
  ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  Scene scene = Scene::from_file(kConfig + "/scene.yaml");
  std::unique_ptr<GlContext> ctx = GlContext::create(GlBackend::OSMesa);
  camera::Camera camera = scene_camera(scene, "oblique");
  Renderer renderer{*ctx, camera.viewport};
  ArmGeometry arm{renderer, model};
  cv::Mat background = cv::Mat(camera.viewport.height_px, camera.viewport.width_px, CV_8UC3, cv::Scalar(40, 30, 20));

  Eigen::VectorXd approach_q() {
    KinematicsWorkspace ws(model);
    return inverse_kinematics(model, ws, scene.base_T_object * oru.tags.at("approach_20cm"), model.mid_configuration()).q;
  }

  // 2 s: from the middle of the joint ranges to the approach pose.
  Trajectory trajectory() {
    Trajectory t;
    t.time_s = {0.0, 1.0, 2.0};
    const Eigen::VectorXd a = model.mid_configuration(), b = approach_q();
    t.positions_rad.resize(3, model.dof());
    t.positions_rad.row(0) = a.transpose();
    t.positions_rad.row(1) = (0.5 * (a + b)).transpose();
    t.positions_rad.row(2) = b.transpose();
    return t;
  }
};

int video_frames(const std::string& path) {
  cv::VideoCapture cap(path);
  int n = 0;
  cv::Mat f;
  while (n < 10000 && cap.read(f)) ++n;
  return n;
}

}  // namespace

TEST(SampleTrajectory, InterpolatesAndClamps) {
  Trajectory t;
  t.time_s = {1.0, 2.0, 4.0};
  t.positions_rad.resize(3, 2);
  t.positions_rad << 0.0, 1.0, 1.0, 3.0, 3.0, -1.0;
  EXPECT_NEAR(sample_trajectory(t, 1.5)[0], 0.5, 1e-12);
  EXPECT_NEAR(sample_trajectory(t, 1.5)[1], 2.0, 1e-12);
  EXPECT_NEAR(sample_trajectory(t, 3.0)[0], 2.0, 1e-12);
  EXPECT_NEAR(sample_trajectory(t, 3.0)[1], 1.0, 1e-12);
  EXPECT_EQ(sample_trajectory(t, 0.0)[1], 1.0);
  EXPECT_EQ(sample_trajectory(t, 9.0)[1], -1.0);
}

TEST_F(Fixture, PreviewRunsAtTrajectoryTimeAndScaled) {
  const Trajectory tr = trajectory();
  const std::string video = temp_path(".avi"), sheet = temp_path(".png");
  PreviewOptions o;
  o.fps = 10.0;
  OverlayExtras extras;
  extras.object_body = add_object_body(renderer, oru);
  extras.base_T_object = scene.base_T_object;
  PreviewResult r = render_preview(renderer, arm, camera, background, tr, extras, o, video, sheet);
  EXPECT_EQ(r.frames, 21);  // 2 s at 10 frames/s, both ends
  EXPECT_NEAR(r.video_duration_s, 2.1, 1e-9);
  EXPECT_EQ(video_frames(video), 21);
  ASSERT_EQ(r.sheet_times_s.size(), 6u);
  EXPECT_DOUBLE_EQ(r.sheet_times_s.front(), 0.0);
  EXPECT_DOUBLE_EQ(r.sheet_times_s.back(), 2.0);
  const cv::Mat s = cv::imread(sheet);
  ASSERT_FALSE(s.empty());
  EXPECT_EQ(s.cols, 3 * 323);
  EXPECT_EQ(s.rows, 2 * 243);
  // First and last key frames differ: the arm moved.
  cv::Mat first = s(cv::Rect(0, 30, 323, 213)), last = s(cv::Rect(2 * 323, 243 + 30, 323, 213));
  cv::Mat diff;
  cv::absdiff(first, last, diff);
  EXPECT_GT(cv::countNonZero(diff.reshape(1) > 30), 1000);

  o.speed = 2.0;  // twice as fast: half the frames
  r = render_preview(renderer, arm, camera, background, tr, extras, o, video, "");
  EXPECT_EQ(r.frames, 11);
  EXPECT_EQ(video_frames(video), 11);
  o.speed = 0.75;  // 2 s in 2.667 s: 27 frames at t = 0, 0.075, ..., 1.95, then the end pose
  r = render_preview(renderer, arm, camera, background, tr, extras, o, video, "");
  EXPECT_EQ(r.frames, 28);
  std::remove(video.c_str());
  std::remove(sheet.c_str());
}

TEST_F(Fixture, PreviewBadInput) {
  const Trajectory tr = trajectory();
  PreviewOptions o;
  o.speed = 0.0;
  try {
    render_preview(renderer, arm, camera, background, tr, {}, o, "/tmp/x.mp4", "");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "--speed must be a positive number");
  }
  Trajectory six = tr;
  six.positions_rad.conservativeResize(Eigen::NoChange, 6);
  try {
    render_preview(renderer, arm, camera, background, six, {}, {}, "/tmp/x.mp4", "");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "trajectory has 6 joints but the arm has 7");
  }
  try {
    render_preview(renderer, arm, camera, background, tr, {}, {}, "/tmp/foresight_preview.gif", "");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/tmp/foresight_preview.gif: unsupported video extension (use .mp4, .avi or .webm)");
  }
}

// The delayed actual arm is solid, the commanded arm a ghost over the video.
TEST_F(Fixture, PredictiveFrameShowsGhostOverSolid) {
  const Eigen::VectorXd q_actual = model.mid_configuration();
  Eigen::VectorXd q_cmd = q_actual;
  q_cmd[0] += 0.5;  // the commanded arm has turned away from the actual one
  PredictiveOptions o;
  o.label = false;
  const cv::Mat f = predictive_frame(renderer, arm, camera, background, q_cmd, q_actual, 2.5, {}, o);
  // Masks of each arm alone.
  auto mask = [&](const Eigen::VectorXd& q) {
    DrawList l;
    arm.append(q, l);
    cv::Mat layer, a;
    renderer.render(camera, l, {}, layer);
    cv::extractChannel(layer, a, 3);
    return cv::Mat(a > 0);
  };
  const cv::Mat m_act = mask(q_actual), m_cmd = mask(q_cmd);
  cv::Mat only_cmd = m_cmd & ~m_act;
  ASSERT_GT(cv::countNonZero(only_cmd), 500);
  // Where only the commanded arm is: alpha * tinted model + (1 - alpha) * video, so
  // each channel lies between the video and alpha * 255 + (1 - alpha) * video.
  int checked = 0;
  for (int r = 0; r < f.rows; r += 3)
    for (int c = 0; c < f.cols; c += 3) {
      if (!only_cmd.at<std::uint8_t>(r, c)) continue;
      const cv::Vec3b p = f.at<cv::Vec3b>(r, c), bg = background.at<cv::Vec3b>(r, c);
      for (int k = 0; k < 3; ++k) {
        EXPECT_GE(p[k], (1.0 - o.ghost_alpha) * bg[k] - 1.0);
        EXPECT_LE(p[k], o.ghost_alpha * 255.0 + (1.0 - o.ghost_alpha) * bg[k] + 1.0);
      }
      ++checked;
    }
  EXPECT_GT(checked, 30);
  // Where only the actual arm is, the pixels are the solid render (not blended with the video).
  DrawList l;
  arm.append(q_actual, l);
  cv::Mat solid;
  renderer.render(camera, l, {}, solid);
  cv::Mat only_act = m_act & ~m_cmd;
  int same = 0, total = 0;
  for (int r = 0; r < f.rows; r += 3)
    for (int c = 0; c < f.cols; c += 3) {
      if (!only_act.at<std::uint8_t>(r, c)) continue;
      const cv::Vec4b s = solid.at<cv::Vec4b>(r, c);
      const cv::Vec3b p = f.at<cv::Vec3b>(r, c);
      same += (p[0] == s[0] && p[1] == s[1] && p[2] == s[2]);
      ++total;
    }
  ASSERT_GT(total, 30);
  EXPECT_EQ(same, total);
  // With the label, the delay is written in the top-left corner (white text on black).
  const cv::Mat labelled = predictive_frame(renderer, arm, camera, background, q_cmd, q_actual, 2.5, {});
  cv::Mat band;
  cv::cvtColor(labelled(cv::Rect(0, 0, 300, 50)), band, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(band > 200), 100);
}

TEST_F(Fixture, PredictiveBadInput) {
  try {
    predictive_frame(renderer, arm, camera, background, Eigen::VectorXd::Zero(7), Eigen::VectorXd::Zero(5), 1.0, {});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "joint vector has 5 values but the arm has 7 joints");
  }
  try {
    predictive_frame(renderer, arm, camera, background, Eigen::VectorXd::Zero(7), Eigen::VectorXd::Zero(7), -1.0, {});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "delay must be a non-negative number of seconds");
  }
}
