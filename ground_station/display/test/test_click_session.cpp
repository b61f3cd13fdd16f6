// The click session (foresight click) without a window: model point then
// image point, delete last, clear, clicks outside the image ignored, the zoom
// mapping, and the model points and model view of the arm and the ORU.
#include <gtest/gtest.h>

#include "foresight/calibration/correspondence.hpp"
#include "foresight/display/click_session.hpp"

using namespace foresight;
using namespace foresight::display;

namespace {

const std::string kConfig = FORESIGHT_CONFIG_DIR;

std::vector<ModelPoint> three_points() {
  return {{"a", {0.1, 0.2, 0.3}}, {"b", {-0.4, 0.5, 1.25}}, {"c", {0.0, 0.0, 2.0}}};
}

}  // namespace

TEST(ClickSession, ModelPointThenImagePointMakesARow) {
  ClickSession s("side", three_points(), cv::Size(646, 486));
  EXPECT_EQ(s.state(), ClickSession::State::AwaitModelPoint);
  EXPECT_EQ(s.click_image({100.5, 200.5}), ClickSession::Outcome::NoModelPoint);
  EXPECT_TRUE(s.rows().empty());
  ASSERT_TRUE(s.select_model_point(1));
  EXPECT_EQ(s.state(), ClickSession::State::AwaitImagePoint);
  EXPECT_EQ(s.click_image({100.5, 200.25}), ClickSession::Outcome::Added);
  EXPECT_EQ(s.state(), ClickSession::State::AwaitModelPoint);
  ASSERT_EQ(s.rows().size(), 1u);
  const calibration::Correspondence r = s.rows()[0];
  EXPECT_EQ(r.n, 1);
  EXPECT_EQ(r.cam, "side");
  EXPECT_EQ(r.p_m, Eigen::Vector3d(-0.4, 0.5, 1.25));
  EXPECT_EQ(r.uv_px, Eigen::Vector2d(100.5, 200.25));
  EXPECT_FALSE(s.select_model_point(3));
  EXPECT_FALSE(s.select_model_point(-1));
}

TEST(ClickSession, ClickOutsideTheImageIsIgnored) {
  ClickSession s("side", three_points(), cv::Size(646, 486));
  ASSERT_TRUE(s.select_model_point(0));
  for (const Eigen::Vector2d& uv : {Eigen::Vector2d(-0.5, 10), Eigen::Vector2d(646.0, 10), Eigen::Vector2d(10, 486.0),
                                   Eigen::Vector2d(10, -3)})
    EXPECT_EQ(s.click_image(uv), ClickSession::Outcome::OutsideImage);
  EXPECT_TRUE(s.rows().empty());
  EXPECT_EQ(s.selected(), 0);  // still waiting for the image point
  EXPECT_EQ(s.click_image({645.9, 485.9}), ClickSession::Outcome::Added);
}

TEST(ClickSession, DeleteLastAndClear) {
  ClickSession s("oblique", three_points(), cv::Size(100, 100));
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(s.select_model_point(i));
    ASSERT_EQ(s.click_image({10.0 + i, 20.0}), ClickSession::Outcome::Added);
  }
  EXPECT_TRUE(s.delete_last());
  ASSERT_EQ(s.rows().size(), 2u);
  EXPECT_EQ(s.rows().back().n, 2);
  // A pending selection is cancelled first, rows stay.
  ASSERT_TRUE(s.select_model_point(2));
  EXPECT_TRUE(s.delete_last());
  EXPECT_EQ(s.state(), ClickSession::State::AwaitModelPoint);
  EXPECT_EQ(s.rows().size(), 2u);
  // Numbering continues from the remaining rows.
  ASSERT_TRUE(s.select_model_point(2));
  ASSERT_EQ(s.click_image({50, 50}), ClickSession::Outcome::Added);
  EXPECT_EQ(s.rows().back().n, 3);
  s.clear();
  EXPECT_TRUE(s.rows().empty());
  EXPECT_FALSE(s.delete_last());
  ASSERT_TRUE(s.select_model_point(0));
  ASSERT_EQ(s.click_image({5, 5}), ClickSession::Outcome::Added);
  EXPECT_EQ(s.rows().back().n, 1);
}

TEST(ClickSession, AppendsAfterExistingRowsAndWritesTheCsvCalibrateReads) {
  ClickSession s("side", three_points(), cv::Size(646, 486));
  calibration::Correspondence old;
  old.n = 41;
  old.cam = "top";
  old.p_m = {1, 2, 3};
  old.uv_px = {4, 5};
  s.set_existing_rows({old});
  ASSERT_TRUE(s.select_model_point(2));
  ASSERT_EQ(s.click_image({320.25, 240.75}), ClickSession::Outcome::Added);
  EXPECT_TRUE(s.delete_last());  // only this session's rows can be deleted
  EXPECT_FALSE(s.delete_last());
  ASSERT_TRUE(s.select_model_point(2));
  ASSERT_EQ(s.click_image({320.25, 240.75}), ClickSession::Outcome::Added);
  const auto back = calibration::parse_correspondences_csv(s.csv(), "session");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].n, 41);
  EXPECT_EQ(back[0].cam, "top");
  EXPECT_EQ(back[1].n, 42);
  EXPECT_EQ(back[1].cam, "side");
  EXPECT_EQ(back[1].p_m, Eigen::Vector3d(0.0, 0.0, 2.0));
  EXPECT_EQ(back[1].uv_px, Eigen::Vector2d(320.25, 240.75));
}

TEST(ZoomView, MapsWindowPixelsToImagePixels) {
  ZoomView z(cv::Size(646, 486));
  EXPECT_EQ(z.to_image(10, 20), Eigen::Vector2d(10.5, 20.5));
  const Eigen::Vector2d p(300.5, 200.5);
  const Eigen::Vector2d w = z.to_window(p);
  z.zoom_at(p, 4.0);
  EXPECT_DOUBLE_EQ(z.zoom(), 4.0);
  EXPECT_NEAR((z.to_window(p) - w).norm(), 0.0, 1e-9);  // the point stays under the cursor
  // A window pixel maps to a quarter-pixel step in the image.
  EXPECT_NEAR((z.to_image(101, 50) - z.to_image(100, 50)).x(), 0.25, 1e-12);
  // Near a corner the view is clamped inside the image.
  z.zoom_at({1.0, 1.0}, 2.0);
  EXPECT_DOUBLE_EQ(z.zoom(), 8.0);
  EXPECT_GE(z.origin_px().x(), 0.0);
  EXPECT_GE(z.origin_px().y(), 0.0);
  z.zoom_at({1.0, 1.0}, 100.0);
  EXPECT_DOUBLE_EQ(z.zoom(), ZoomView::max_zoom);
  z.zoom_at({1.0, 1.0}, 1e-3);
  EXPECT_DOUBLE_EQ(z.zoom(), 1.0);
  EXPECT_EQ(z.origin_px(), Eigen::Vector2d::Zero());
}

TEST(ZoomView, RenderShowsTheImagePixelUnderEachWindowPixel) {
  cv::Mat img(120, 160, CV_8UC3);
  for (int v = 0; v < img.rows; ++v)
    for (int u = 0; u < img.cols; ++u) img.at<cv::Vec3b>(v, u) = cv::Vec3b(u, v, (u * 7 + v * 3) % 256);
  ZoomView z(img.size());
  z.zoom_at({77.3, 41.9}, 3.0);
  const cv::Mat shown = z.render(img);
  ASSERT_EQ(shown.size(), img.size());
  int mismatches = 0;
  for (int y = 0; y < shown.rows; y += 7)
    for (int x = 0; x < shown.cols; x += 5) {
      const Eigen::Vector2d uv = z.to_image(x, y);
      const cv::Vec3b expect = img.at<cv::Vec3b>(static_cast<int>(uv.y()), static_cast<int>(uv.x()));
      mismatches += shown.at<cv::Vec3b>(y, x) != expect;
    }
  EXPECT_EQ(mismatches, 0);
}

TEST(ModelPoints, ArmPointsAreLinkFeaturesAndTheModelViewSeesThemAll) {
  const RobotModel model = RobotModel::from_file(kConfig + "/robot.urdf");
  const Eigen::VectorXd q = model.mid_configuration();
  const auto pts = arm_model_points(model, q);
  ASSERT_GE(pts.size(), 8u);
  KinematicsWorkspace ws(model);
  EXPECT_NEAR((pts[0].p_m - forward_kinematics(model, ws, q, 1).translation()).norm(), 0.0, 1e-12);
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (std::size_t j = i + 1; j < pts.size(); ++j) EXPECT_GE((pts[i].p_m - pts[j].p_m).norm(), 0.03);
  const camera::Camera view = model_view_camera(pts, camera::Viewport{646, 486}, {1.0, -0.8, 0.5}, Eigen::Vector3d::UnitZ());
  for (const auto& p : pts) {
    ASSERT_TRUE(view.in_front(p.p_m));
    EXPECT_TRUE(view.in_view(view.project(p.p_m))) << p.label;
  }
  EXPECT_THROW(arm_model_points(model, Eigen::VectorXd::Zero(3)), std::invalid_argument);
}

TEST(ModelPoints, ObjectPointsInFileOrderAndNearestPick) {
  const ObjectModel oru = ObjectModel::from_file(kConfig + "/oru.yaml");
  const auto pts = object_model_points(oru);
  ASSERT_EQ(pts.size(), oru.points.size());
  for (std::size_t i = 0; i < pts.size(); ++i) EXPECT_EQ(pts[i].label, oru.points[i].name);
  const std::vector<Eigen::Vector2d> proj = {{10, 10}, {30, 10}, {20, 40}};
  EXPECT_EQ(nearest_point(proj, {28, 12}, 8.0), 1);
  EXPECT_EQ(nearest_point(proj, {20, 25}, 8.0), -1);
  EXPECT_EQ(nearest_point(proj, {21, 38}, 8.0), 2);
}
