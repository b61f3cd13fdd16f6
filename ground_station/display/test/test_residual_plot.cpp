// The residual picture: reprojections from the fit's residuals, the arrow
// scale, and arrows drawn where the clicks and reprojections are.
#include <gtest/gtest.h>

#include "foresight/display/residual_plot.hpp"

using namespace foresight;
using namespace foresight::display;

namespace {

calibration::Correspondence click(int n, const std::string& cam, double u, double v) {
  calibration::Correspondence c;
  c.n = n;
  c.cam = cam;
  c.uv_px = {u, v};
  return c;
}

calibration::PointResidual residual(int n, const std::string& cam, double du, double dv, bool outlier = false) {
  calibration::PointResidual r;
  r.n = n;
  r.cam = cam;
  r.r_px = {du, dv};
  r.px = r.r_px.norm();
  r.outlier = outlier;
  return r;
}

}  // namespace

TEST(ResidualPlot, ReprojectionIsTheClickMinusTheResidual) {
  const std::vector<calibration::Correspondence> clicks = {click(1, "a", 100.5, 50.5), click(2, "b", 10, 10),
                                              click(3, "a", 300, 200)};
  const auto pts = plot_points(clicks, {residual(1, "a", 2.0, -1.0), residual(3, "a", 0.5, 0.5, true)}, "a");
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_EQ(pts[0].n, 1);
  EXPECT_EQ(pts[0].reprojected_px, Eigen::Vector2d(98.5, 51.5));
  EXPECT_FALSE(pts[0].outlier);
  EXPECT_TRUE(pts[1].outlier);
  try {
    plot_points(clicks, {residual(7, "a", 0, 0)}, "a");
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "residual plot: no click for point n=7 of camera 'a'");
  }
}

TEST(ResidualPlot, AutomaticArrowScaleIsAOneTwoFiveStep) {
  auto one = [](double r_px) { return std::vector<PlotPoint>{{1, {r_px, 0}, {0, 0}, false}}; };
  EXPECT_DOUBLE_EQ(auto_arrow_scale(one(2.0)), 20.0);
  EXPECT_DOUBLE_EQ(auto_arrow_scale(one(0.3)), 100.0);
  EXPECT_DOUBLE_EQ(auto_arrow_scale(one(0.01)), 500.0);
  EXPECT_DOUBLE_EQ(auto_arrow_scale(one(100.0)), 1.0);
  EXPECT_DOUBLE_EQ(auto_arrow_scale({}), 1.0);
}

TEST(ResidualPlot, ArrowsRunFromReprojectionAlongTheScaledResidual) {
  // One inlier with a 2 px residual to the right, drawn x10: a yellow arrow
  // from the reprojection 20 px to the right; an outlier ringed in red.
  const std::vector<PlotPoint> pts = {{1, {202.5, 100.5}, {200.5, 100.5}, false},
                                      {2, {400.5, 300.5}, {396.5, 300.5}, true}};
  ResidualPlotOptions o;
  o.arrow_scale = 10.0;
  const cv::Mat img = draw_residual_plot(cv::Mat(), camera::Viewport{646, 486}, pts, o);
  ASSERT_EQ(img.size(), cv::Size(646, 486));
  auto is_yellow = [&](int x, int y) {
    const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
    return p[2] > 150 && p[1] > 150 && p[0] < 100;
  };
  int yellow_on_shaft = 0;
  for (int x = 206; x <= 216; ++x) yellow_on_shaft += is_yellow(x, 100);
  EXPECT_GE(yellow_on_shaft, 8);
  int yellow_elsewhere = 0;
  for (int x = 230; x <= 260; ++x) yellow_elsewhere += is_yellow(x, 100);
  EXPECT_EQ(yellow_elsewhere, 0);
  int red = 0;  // the outlier's ring, 11 px around the click
  for (int dx = -13; dx <= 13; ++dx) {
    const cv::Vec3b p = img.at<cv::Vec3b>(300, 400 + dx);
    red += p[2] > 200 && p[1] < 100 && p[0] < 100;
  }
  EXPECT_GE(red, 2);
  // A background of another size is used as it is; a grey one becomes BGR.
  const cv::Mat grey(100, 120, CV_8UC1, cv::Scalar(128));
  const cv::Mat on_grey = draw_residual_plot(grey, camera::Viewport{646, 486}, {}, {});
  EXPECT_EQ(on_grey.size(), grey.size());
  EXPECT_EQ(on_grey.type(), CV_8UC3);
}

TEST(ResidualPlot, TilesPicturesInAGrid) {
  const std::vector<cv::Mat> pics(3, cv::Mat(10, 20, CV_8UC3, cv::Scalar(1, 2, 3)));
  const cv::Mat t = tile_pictures(pics, 2);
  EXPECT_EQ(t.size(), cv::Size(40, 20));
  EXPECT_EQ(t.at<cv::Vec3b>(15, 25), cv::Vec3b(0, 0, 0));  // the empty fourth tile
  EXPECT_EQ(t.at<cv::Vec3b>(15, 5), cv::Vec3b(1, 2, 3));
}
