// The go/no-go's drawing (go_no_go.hpp): the projected 95% ellipse against
// hand-computed projections through a known camera, its coverage against
// points sampled in 3-D and projected exactly, and the marks' colour.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <cmath>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <random>

#include "foresight/display/go_no_go.hpp"

using namespace foresight;
using namespace foresight::display;

namespace {

/// Camera frame = base frame (x right, y down, z forward), f 500 px, 640x480:
/// u = 320 + 500 x / z, v = 240 + 500 y / z.
camera::Camera known_camera() {
  camera::Camera c;
  c.name = "known";
  c.viewport = {640, 480};
  c.f_px = 500.0;
  c.base_T_camera = Pose::Identity();
  return c;
}

constexpr double kChi2_95 = 5.991464547107979;  // -2 ln 0.05

}  // namespace

TEST(GoNoGo, ChiSquareTwoDofQuantile) {
  EXPECT_NEAR(chi_square_2dof_quantile(0.95), kChi2_95, 1e-12);
  EXPECT_NEAR(chi_square_2dof_quantile(1.0 - std::exp(-0.5)), 1.0, 1e-12);  // the 1-sigma ellipse holds 39.3%
  EXPECT_THROW(chi_square_2dof_quantile(1.0), std::invalid_argument);
  EXPECT_THROW(chi_square_2dof_quantile(0.0), std::invalid_argument);
}

// On the optical axis at z = 2 m, J = (f / z) [I2 | 0] = 250 px/m [I2 | 0]:
// sigma 2 cm across and 1 cm up-down (and any depth) is 5 px and 2.5 px;
// the 95% semi-axes are sqrt(5.991) * 5 = 12.238 px and 6.119 px, along u.
TEST(GoNoGo, OnAxisEllipseIsTheLateralSigmasScaledByFOverZ) {
  const camera::Camera cam = known_camera();
  Eigen::Matrix3d C = Eigen::Vector3d(0.02 * 0.02, 0.01 * 0.01, 0.05 * 0.05).asDiagonal();
  const ImageEllipse e = project_position_ellipse(cam, {0.0, 0.0, 2.0}, C);
  EXPECT_NEAR(e.centre_px.x(), 320.0, 1e-12);
  EXPECT_NEAR(e.centre_px.y(), 240.0, 1e-12);
  EXPECT_NEAR(e.covariance_px2(0, 0), 25.0, 1e-9);
  EXPECT_NEAR(e.covariance_px2(1, 1), 6.25, 1e-9);
  EXPECT_NEAR(e.covariance_px2(0, 1), 0.0, 1e-12);
  EXPECT_NEAR(e.semi_major_px, std::sqrt(kChi2_95) * 5.0, 1e-9);  // 12.2387
  EXPECT_NEAR(e.semi_minor_px, std::sqrt(kChi2_95) * 2.5, 1e-9);  // 6.1194
  EXPECT_NEAR(e.angle_rad, 0.0, 1e-12);
}

// Off the axis at (0.4, 0.2, 2) (x/z 0.2, y/z 0.1), J = 250 [1 0 -0.2; 0 1 -0.1].
// Depth alone, sigma 1 cm: J C J^T = 6.25 [0.04 0.02; 0.02 0.01] px^2, rank one
// along (2, 1) / sqrt(5) (away from the principal point): eigenvalue 0.3125 px^2,
// semi-major sqrt(5.991 * 0.3125) = 1.368 px at atan2(1, 2) = 26.565 deg, minor 0.
TEST(GoNoGo, DepthUncertaintyProjectsRadially) {
  const camera::Camera cam = known_camera();
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  C(2, 2) = 1e-4;
  const Eigen::Matrix2d S = project_position_covariance(cam, {0.4, 0.2, 2.0}, C);
  EXPECT_NEAR(S(0, 0), 0.25, 1e-12);
  EXPECT_NEAR(S(0, 1), 0.125, 1e-12);
  EXPECT_NEAR(S(1, 0), 0.125, 1e-12);
  EXPECT_NEAR(S(1, 1), 0.0625, 1e-12);
  const ImageEllipse e = project_position_ellipse(cam, {0.4, 0.2, 2.0}, C);
  EXPECT_NEAR(e.centre_px.x(), 420.0, 1e-9);
  EXPECT_NEAR(e.centre_px.y(), 290.0, 1e-9);
  EXPECT_NEAR(e.semi_major_px, std::sqrt(kChi2_95 * 0.3125), 1e-9);  // 1.3683
  EXPECT_NEAR(e.semi_minor_px, 0.0, 1e-6);
  EXPECT_NEAR(e.angle_rad, std::atan2(1.0, 2.0), 1e-9);
}

// A full covariance through a turned camera: J C J^T against the projection's
// finite differences, and the ellipse holds 95% of 3-D samples projected exactly.
TEST(GoNoGo, EllipseHoldsNinetyFivePercentOfProjectedSamples) {
  const camera::Camera cam =
      camera::Camera::look_at("turned", {646, 486}, 700.0, {1.8, -0.9, 1.4}, {0.9, 0.2, 0.5}, Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d p(1.0, 0.15, 0.55);
  Eigen::Matrix3d A;
  A << 3.0, 0.0, 0.0, 1.5, 2.0, 0.0, -1.0, 0.5, 4.0;
  const Eigen::Matrix3d C = 1e-6 * A * A.transpose();  // mm-sized, correlated
  // J by central differences of Camera::project.
  Eigen::Matrix<double, 2, 3> J;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d d = 1e-6 * Eigen::Vector3d::Unit(k);
    J.col(k) = (cam.project(p + d) - cam.project(p - d)) / 2e-6;
  }
  const Eigen::Matrix2d S = project_position_covariance(cam, p, C);
  EXPECT_LT((S - J * C * J.transpose()).norm(), 1e-6 * S.norm());
  const ImageEllipse e = project_position_ellipse(cam, p, C);
  std::mt19937 rng(7);
  std::normal_distribution<double> n01;
  const Eigen::Matrix2d Si = S.inverse();
  int inside = 0;
  constexpr int kN = 40000;
  for (int i = 0; i < kN; ++i) {
    const Eigen::Vector3d q = p + A * 1e-3 * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    const Eigen::Vector2d r = cam.project(q) - e.centre_px;
    if (r.dot(Si * r) <= kChi2_95) ++inside;
  }
  EXPECT_NEAR(static_cast<double>(inside) / kN, 0.95, 0.004);  // binomial sd 0.0011
  // The semi-axes are those of S: sqrt(5.991 * eigenvalues).
  const Eigen::Vector2d l = Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(S).eigenvalues();
  EXPECT_NEAR(e.semi_major_px, std::sqrt(kChi2_95 * l(1)), 1e-9);
  EXPECT_NEAR(e.semi_minor_px, std::sqrt(kChi2_95 * l(0)), 1e-9);
}

TEST(GoNoGo, BadCovarianceAndPointBehindTheCameraAreRefused) {
  const camera::Camera cam = known_camera();
  EXPECT_THROW(project_position_ellipse(cam, {0.0, 0.0, -1.0}, Eigen::Matrix3d::Identity()), std::invalid_argument);
  Eigen::Matrix2d neg;
  neg << 1.0, 0.0, 0.0, -1.0;
  EXPECT_THROW(gaussian_ellipse({0, 0}, neg), std::invalid_argument);
  Eigen::Matrix2d asym;
  asym << 1.0, 0.5, 0.0, 1.0;
  EXPECT_THROW(gaussian_ellipse({0, 0}, asym), std::invalid_argument);
}

TEST(GoNoGo, Label) {
  EXPECT_EQ(go_no_go_label(true, 0.9972), "insert: go P=0.997");
  EXPECT_EQ(go_no_go_label(false, 0.4349), "insert: no_go P=0.43");
  EXPECT_EQ(go_no_go_label(true, 0.99996), "insert: go P=>0.999");
  EXPECT_EQ(go_no_go_label(true, 1.0), "insert: go P=1.000");
}

// The marks in the verdict's colour: the hole's ellipse through its ends on
// the major axis (12.2 px from the centre along u), the label beside them.
TEST(GoNoGo, MarksAreDrawnInTheVerdictsColour) {
  const camera::Camera cam = known_camera();
  for (const bool go : {true, false}) {
    GoNoGoMarks m;
    m.base_T_hole.translation() = Eigen::Vector3d(0.0, 0.0, 2.0);
    m.base_T_tag.translation() = Eigen::Vector3d(0.0, 0.0, 1.995);  // z of the tag along the view: the rim a circle
    m.hole_position_covariance = Eigen::Vector3d(0.02 * 0.02, 0.01 * 0.01, 0.0).asDiagonal();
    m.tip_position_covariance = 4.0 * m.hole_position_covariance;
    m.go = go;
    m.p_success = go ? 0.997 : 0.43;
    cv::Mat img(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
    const GoNoGoDrawn d = draw_go_no_go(img, cam, m);
    EXPECT_TRUE(d.hole_in_view);
    EXPECT_TRUE(d.tip_in_view);
    EXPECT_NEAR(d.hole.semi_major_px, 12.2387, 1e-3);
    EXPECT_NEAR(d.tip.semi_major_px, std::sqrt(kChi2_95) * 0.04 * 500.0 / 1.995, 1e-9);  // 24.539 px: 4 cm at 1.995 m
    EXPECT_EQ(d.label, go ? "insert: go P=0.997" : "insert: no_go P=0.43");
    const cv::Scalar want = go_no_go_colour(go);
    // Pixel (i, j) has its centre at (i + 0.5, j + 0.5): the ellipse's ends
    // at u = 320 -+ 12.24, v = 240 lie on pixels 307/332 of row 239/240.
    for (const int u : {307, 332}) {
      const cv::Vec3b px = img.at<cv::Vec3b>(240, u);
      for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(px[ch], want[ch], 70) << "u " << u << " ch " << ch << " go " << go;
    }
    // The socket's rim: 28 mm at 1.995 m is 3.51 px in radius; the centre is left empty.
    EXPECT_EQ(img.at<cv::Vec3b>(240, 320), cv::Vec3b(0, 0, 0));
    // Nothing in the other verdict's colour.
    cv::Mat mask;
    const cv::Scalar other = go_no_go_colour(!go);
    cv::inRange(img, other - cv::Scalar(30, 30, 30), other + cv::Scalar(30, 30, 30), mask);
    EXPECT_EQ(cv::countNonZero(mask), 0);
    // The label is to the right of the marks.
    cv::inRange(img, want - cv::Scalar(30, 30, 30), want + cv::Scalar(30, 30, 30), mask);
    EXPECT_GT(cv::countNonZero(mask(cv::Rect(360, 220, 200, 40))), 50);
  }
}
