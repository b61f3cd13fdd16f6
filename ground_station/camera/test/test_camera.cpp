#include <gtest/gtest.h>

#include <cstdio>

#include "foresight/camera/camera.hpp"
#include "foresight/common/error.hpp"

using namespace foresight;

TEST(Camera, LookAtProjectsTargetToPrincipalPoint) {
  const Camera c = Camera::look_at("side", {646, 486}, 700.0, {0, -2, 1}, {0.5, 0, 0.5});
  const Eigen::Vector2d uv = c.project({0.5, 0, 0.5});
  EXPECT_NEAR(uv.x(), 323.0, 1e-9);
  EXPECT_NEAR(uv.y(), 243.0, 1e-9);
  // World up appears up in the image (smaller v).
  EXPECT_LT(c.project({0.5, 0, 0.7}).y(), 243.0);
  EXPECT_TRUE(c.in_front({0.5, 0, 0.5}));
  EXPECT_FALSE(c.in_front({0, -3, 1}));
}

TEST(Camera, GlMatricesAgreeWithProjection) {
  const Camera c = Camera::look_at("oblique", {646, 486}, 640.0, {-0.4, -1.3, 1.5}, {0.8, 0.1, 0.55});
  const Eigen::Matrix4d PV = c.gl_projection(0.05, 20.0) * c.gl_view();
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.8, 0.1, 0.55), Eigen::Vector3d(1.0, 0.3, 0.2), Eigen::Vector3d(0.2, -0.3, 0.9)}) {
    const Eigen::Vector4d clip = PV * p.homogeneous();
    const double xw = (clip.x() / clip.w() + 1.0) * 0.5 * 646;
    const double yw = (clip.y() / clip.w() + 1.0) * 0.5 * 486;  // GL window, from the bottom
    const Eigen::Vector2d uv = c.project(p);
    EXPECT_NEAR(xw, uv.x(), 1e-9);
    EXPECT_NEAR(486 - yw, uv.y(), 1e-9);
  }
}

TEST(Camera, FovyFromFocalLength) {
  Camera c;
  c.viewport = {646, 486};
  c.f_px = 243.0;  // half height: 90 degrees
  EXPECT_NEAR(c.fovy_rad(), M_PI / 2, 1e-12);
}

TEST(Camera, ViewportParsing) {
  EXPECT_EQ(parse_viewport("646x486"), (Viewport{646, 486}));
  EXPECT_THROW(parse_viewport("646*486"), std::invalid_argument);
  EXPECT_THROW(parse_viewport("0x486"), std::invalid_argument);
  EXPECT_THROW(parse_viewport("646x486px"), std::invalid_argument);
}

TEST(Camera, YamlRoundTrip) {
  std::map<std::string, CameraRecord> cams;
  cams["side"].camera = Camera::look_at("side", {646, 486}, 712.5, {0, -2, 1}, {0.5, 0, 0.5});
  CameraCalibrationInfo info;
  info.rms_px = 0.41;
  info.n_points = 24;
  info.outliers = {7};
  info.covariance(6, 6) = 4.0;
  cams["side"].calibration = info;
  const std::string path = "/tmp/foresight_cameras_test.yaml";
  save_cameras(path, cams);
  const auto back = load_cameras(path);
  ASSERT_EQ(back.size(), 1u);
  const auto& r = back.at("side");
  EXPECT_DOUBLE_EQ(r.camera.f_px, 712.5);
  EXPECT_LT((r.camera.base_T_camera.matrix() - cams["side"].camera.base_T_camera.matrix()).norm(), 1e-9);
  ASSERT_TRUE(r.calibration.has_value());
  EXPECT_EQ(r.calibration->outliers, std::vector<int>{7});
  EXPECT_DOUBLE_EQ(r.calibration->covariance(6, 6), 4.0);
  std::remove(path.c_str());
}

TEST(Camera, LoadRejectsNonOrthonormalRotation) {
  const std::string path = "/tmp/foresight_cameras_bad.yaml";
  {
    std::FILE* f = std::fopen(path.c_str(), "w");
    std::fputs("side:\n  viewport: [646, 486]\n  f_px: 700\n  base_T_camera: [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n", f);
    std::fclose(f);
  }
  try {
    load_cameras(path);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), (path + ": camera 'side': base_T_camera rotation is not orthonormal").c_str());
  }
  std::remove(path.c_str());
}
