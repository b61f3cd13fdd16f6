#include <gtest/gtest.h>

#include <cstdio>

#include "foresight/camera/camera.hpp"
#include "foresight/camera/projection.hpp"
#include "foresight/common/error.hpp"

using namespace foresight;

TEST(Camera, LookAtProjectsTargetToPrincipalPoint) {
  const camera::Camera c = camera::Camera::look_at("side", {646, 486}, 700.0, {0, -2, 1}, {0.5, 0, 0.5});
  const Eigen::Vector2d uv = c.project({0.5, 0, 0.5});
  EXPECT_NEAR(uv.x(), 323.0, 1e-9);
  EXPECT_NEAR(uv.y(), 243.0, 1e-9);
  // World up appears up in the image (smaller v).
  EXPECT_LT(c.project({0.5, 0, 0.7}).y(), 243.0);
  EXPECT_TRUE(c.in_front({0.5, 0, 0.5}));
  EXPECT_FALSE(c.in_front({0, -3, 1}));
}

TEST(Camera, GlMatricesAgreeWithProjection) {
  const camera::Camera c = camera::Camera::look_at("oblique", {646, 486}, 640.0, {-0.4, -1.3, 1.5}, {0.8, 0.1, 0.55});
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
  camera::Camera c;
  c.viewport = {646, 486};
  c.f_px = 243.0;  // half height: 90 degrees
  EXPECT_NEAR(c.fovy_rad(), M_PI / 2, 1e-12);
}

TEST(Camera, ViewportParsing) {
  EXPECT_EQ(camera::parse_viewport("646x486"), (camera::Viewport{646, 486}));
  EXPECT_THROW(camera::parse_viewport("646*486"), std::invalid_argument);
  EXPECT_THROW(camera::parse_viewport("0x486"), std::invalid_argument);
  EXPECT_THROW(camera::parse_viewport("646x486px"), std::invalid_argument);
}

TEST(Camera, YamlRoundTrip) {
  std::map<std::string, camera::CameraRecord> cams;
  cams["side"].camera = camera::Camera::look_at("side", {646, 486}, 712.5, {0, -2, 1}, {0.5, 0, 0.5});
  camera::CameraCalibrationInfo info;
  info.rms_px = 0.41;
  info.n_points = 24;
  info.outliers = {7};
  info.covariance(6, 6) = 4.0;
  cams["side"].calibration = info;
  const std::string path = "/tmp/foresight_cameras_test.yaml";
  camera::save_cameras(path, cams);
  const auto back = camera::load_cameras(path);
  ASSERT_EQ(back.size(), 1u);
  const auto& r = back.at("side");
  EXPECT_DOUBLE_EQ(r.camera.f_px, 712.5);
  EXPECT_LT((r.camera.base_T_camera.matrix() - cams["side"].camera.base_T_camera.matrix()).norm(), 1e-9);
  ASSERT_TRUE(r.calibration.has_value());
  EXPECT_EQ(r.calibration->outliers, std::vector<int>{7});
  EXPECT_DOUBLE_EQ(r.calibration->covariance(6, 6), 4.0);
  EXPECT_EQ(r.calibration->arm_link_sensitivity.size(), 0);
  // With the arm model's link sensitivity (7 rows, one column per link).
  cams["side"].calibration->arm_link_sigma_m = 0.002;
  cams["side"].calibration->arm_link_sensitivity = Eigen::MatrixXd::Random(7, 10);
  camera::save_cameras(path, cams);
  const camera::CameraCalibrationInfo k = *camera::load_cameras(path).at("side").calibration;
  EXPECT_EQ(k.arm_link_sigma_m, 0.002);
  ASSERT_EQ(k.arm_link_sensitivity.rows(), 7);
  ASSERT_EQ(k.arm_link_sensitivity.cols(), 10);
  EXPECT_LT((k.arm_link_sensitivity - cams["side"].calibration->arm_link_sensitivity).cwiseAbs().maxCoeff(), 1e-11);
  std::remove(path.c_str());
}

TEST(Camera, LoadRejectsABadArmLinkSensitivity) {
  const std::string path = "/tmp/foresight_cameras_bad_links.yaml";
  auto message = [&](const std::string& calibration) -> std::string {
    std::FILE* f = std::fopen(path.c_str(), "w");
    std::fputs(("side:\n  viewport: [646, 486]\n  f_px: 700\n  base_T_camera: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n"
                "  calibration:\n" + calibration).c_str(), f);
    std::fclose(f);
    try {
      camera::load_cameras(path);
    } catch (const InputError& e) {
      return e.what();
    }
    return "(no error)";
  };
  const std::string rows6 = "    arm_link_sensitivity: [[1,2],[1,2],[1,2],[1,2],[1,2],[1,2]]\n";
  const std::string ragged = "    arm_link_sensitivity: [[1,2],[1,2],[1,2],[1,2],[1,2],[1,2],[1]]\n";
  const std::string good = "    arm_link_sensitivity: [[1,2],[1,2],[1,2],[1,2],[1,2],[1,2],[1,2]]\n";
  EXPECT_EQ(message("    arm_link_sigma_m: 0.002\n" + rows6),
            path + ":7: camera 'side': arm_link_sensitivity must be a list of 7 rows");
  EXPECT_EQ(message("    arm_link_sigma_m: 0.002\n" + ragged),
            path + ":7: camera 'side': arm_link_sensitivity row 7 must have 2 numbers");
  EXPECT_EQ(message(good), path + ":6: camera 'side': arm_link_sigma_m must be a positive number beside arm_link_sensitivity");
  EXPECT_EQ(message("    arm_link_sigma_m: -1\n" + good),
            path + ":6: camera 'side': arm_link_sigma_m must be a positive number beside arm_link_sensitivity");
  EXPECT_EQ(message("    arm_link_sigma_m: 0.002\n" + good), "(no error)");
  // Issue 26: a text where a number belongs was read as 0.
  EXPECT_EQ(message("    n_points: many\n"), path + ":6: camera 'side': calibration.n_points: not an integer: 'many'");
  EXPECT_EQ(message("    rms_px: small\n"), path + ":6: camera 'side': calibration.rms_px: not a number: 'small'");
  EXPECT_EQ(message("    n_points: -4\n"), path + ":6: camera 'side': calibration.n_points -4 is outside 0..100000");
  EXPECT_EQ(message("    rms_px: .nan\n"),
            path + ":6: camera 'side': calibration.rms_px and max_px must be finite and not negative");
  EXPECT_EQ(message("    rms_px: 0.4\n    n_points: 24\n"), "(no error)");
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
    camera::load_cameras(path);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), (path + ":4: camera 'side': base_T_camera rotation is not orthonormal").c_str());
  }
  std::remove(path.c_str());
}

// ---- the projection module: value as Camera::project, Jacobians as finite differences ----

TEST(Projection, ValueAndJacobiansMatchFiniteDifferences) {
  const camera::Camera cam = camera::Camera::look_at("side", camera::Viewport{646, 486}, 812.0, Eigen::Vector3d(2.1, -1.3, 1.4),
                                     Eigen::Vector3d(0.7, 0.1, 0.5));
  const Eigen::Matrix3d R_obj = camera::exp_so3(Eigen::Vector3d(0.3, -0.2, 0.9));
  const Eigen::Vector3d t_obj(0.8, 0.05, 0.45), p_obj(0.1, -0.07, 0.2);
  const Eigen::Vector3d p = R_obj * p_obj + t_obj;
  const camera::Projection pr = camera::project_with_jacobians(cam, p);
  EXPECT_LT((pr.uv_px - cam.project(p)).norm(), 1e-12);
  const double h = 1e-6;
  for (int k = 0; k < 7; ++k) {  // camera: body rotation, position, f
    auto moved = [&](double s) {
      Eigen::Matrix<double, 7, 1> d = Eigen::Matrix<double, 7, 1>::Zero();
      d[k] = s;
      camera::Camera c = cam;
      c.base_T_camera.linear() = cam.base_T_camera.linear() * camera::exp_so3(d.head<3>());
      c.base_T_camera.translation() += d.segment<3>(3);
      c.f_px += d[6];
      return c.project(p);
    };
    const Eigen::Vector2d fd = (moved(h) - moved(-h)) / (2 * h);
    EXPECT_LT((pr.d_camera.col(k) - fd).norm(), 1e-5 * (1.0 + fd.norm())) << "camera parameter " << k;
  }
  const Eigen::Matrix<double, 2, 6> J = camera::object_pose_jacobian(pr, R_obj, p_obj);
  for (int k = 0; k < 6; ++k) {  // object pose: body rotation, origin
    auto moved = [&](double s) {
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d[k] = s;
      return cam.project(R_obj * camera::exp_so3(d.head<3>()) * p_obj + t_obj + d.tail<3>());
    };
    const Eigen::Vector2d fd = (moved(h) - moved(-h)) / (2 * h);
    EXPECT_LT((J.col(k) - fd).norm(), 1e-5 * (1.0 + fd.norm())) << "pose parameter " << k;
  }
  EXPECT_LT((camera::skew(Eigen::Vector3d(1, 2, 3)) * Eigen::Vector3d(-4, 5, 0.5) -
             Eigen::Vector3d(1, 2, 3).cross(Eigen::Vector3d(-4, 5, 0.5)))
                .norm(),
            1e-15);
}

TEST(Projection, InverseRightJacobianMatchesFiniteDifferences) {
  for (const Eigen::Vector3d& phi : {Eigen::Vector3d(0.3, -0.5, 0.2), Eigen::Vector3d(1e-8, 0.0, 2e-8)}) {
    const Eigen::Matrix3d R = camera::exp_so3(phi);
    auto log_of = [](const Eigen::Matrix3d& M) {
      const Eigen::AngleAxisd aa(M);
      return Eigen::Vector3d(aa.angle() * aa.axis());
    };
    const Eigen::Matrix3d Jinv = camera::right_jacobian_inverse_so3(phi);
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d[k] = 1e-6;
      const Eigen::Vector3d fd = (log_of(R * camera::exp_so3(d)) - log_of(R * camera::exp_so3(-d))) / 2e-6;
      EXPECT_LT((Jinv.col(k) - fd).norm(), 1e-6) << k;
    }
  }
}
