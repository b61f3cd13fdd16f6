#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <type_traits>

#include "foresight/calibration/calibrate.hpp"
#include "synthetic.hpp"

using namespace foresight;
using foresight::testing::random_camera;
using foresight::testing::random_points;
using foresight::testing::with_noise;

namespace {

std::string error_of(const std::vector<calibration::Correspondence>& pts, const camera::Viewport& vp = {}) {
  try {
    calibration::calibrate_camera(pts, vp, "side");
  } catch (const Error& e) {  // EstimationInputError or EstimationError
    return e.what();
  }
  return "(no error)";
}

/// Parameter vector (roll, pitch, yaw, x, y, z, f) of a camera.
Eigen::Matrix<double, 7, 1> params(const camera::Camera& c) {
  Eigen::Matrix<double, 7, 1> p;
  p << rpy_from_rotation(c.base_T_camera.linear()), c.base_T_camera.translation(), c.f_px;
  return p;
}

/// Difference in (roll, pitch, yaw) by the body rotation error mapped
/// through the rpy rate matrix (avoids angle wrap).
Eigen::Matrix<double, 7, 1> param_error(const camera::Camera& est, const camera::Camera& truth) {
  Eigen::Matrix<double, 7, 1> d = params(est) - params(truth);
  const Eigen::AngleAxisd aa(truth.base_T_camera.linear().transpose() * est.base_T_camera.linear());
  const Eigen::Vector3d w = aa.angle() * aa.axis();
  d.head<3>() = calibration::rpy_rate_matrix(rpy_from_rotation(truth.base_T_camera.linear())).inverse() * w;
  return d;
}

}  // namespace

TEST(Calibrate, NoiseFreeRecoversEveryParameter) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 25; ++trial) {
    const Eigen::Vector3d target(0.8, 0.1, 0.5);
    const double f = 400.0 + 100.0 * trial;
    const camera::Camera truth = random_camera(rng, target, 1.5 + 0.1 * trial, f);
    const auto pts = random_points(rng, truth, target, 0.4, 30, 0.0);
    ASSERT_EQ(pts.size(), 30u);
    const calibration::CalibrationResult r = calibration::calibrate_camera(pts, truth.viewport, "cam");
    const auto d = param_error(r.camera, truth);
    for (int i = 0; i < 7; ++i) EXPECT_LT(std::abs(d[i]), 1e-6) << "trial " << trial << " parameter " << i;
    EXPECT_LT(r.rms_px, 1e-6);
    EXPECT_LT(r.linear_rms_px, 1e-6);
    EXPECT_TRUE(r.outliers.empty());
    // The linear stage alone is exact on exact data too.
    const auto dl = param_error(calibration::calibrate_camera_linear(pts, truth.viewport, "cam"), truth);
    EXPECT_LT(dl.head<6>().cwiseAbs().maxCoeff(), 1e-6);
  }
}

TEST(Calibrate, NoisyEstimatesWithinThreeSigmaAndSigmaMatchesSpread) {
  std::mt19937 rng(11);
  const Eigen::Vector3d target(0.8, 0.1, 0.5);
  const camera::Camera truth = random_camera(rng, target, 2.0, 700.0);
  const auto exact = random_points(rng, truth, target, 0.5, 30, 0.0);
  const double noise = 1.0;
  const int trials = 400;
  Eigen::Matrix<double, 7, 1> sum_sq = Eigen::Matrix<double, 7, 1>::Zero();
  Eigen::Matrix<double, 7, 1> sum_sigma = Eigen::Matrix<double, 7, 1>::Zero();
  int within = 0;
  for (int t = 0; t < trials; ++t) {
    calibration::CalibrationOptions opt;
    opt.outliers.enabled = false;  // pure Gaussian noise: compare with the spread
    const calibration::CalibrationResult r = calibration::calibrate_camera(with_noise(rng, exact, noise), truth.viewport, "cam", opt);
    const auto d = param_error(r.camera, truth);
    sum_sq += d.cwiseAbs2();
    sum_sigma += r.sigma;
    if ((d.cwiseAbs().array() < 3.0 * r.sigma.array()).all()) ++within;
  }
  const Eigen::Matrix<double, 7, 1> spread = (sum_sq / trials).cwiseSqrt();
  const Eigen::Matrix<double, 7, 1> reported = sum_sigma / trials;
  for (int i = 0; i < 7; ++i) {
    EXPECT_NEAR(reported[i] / spread[i], 1.0, 0.2) << "parameter " << i << " reported " << reported[i] << " spread "
                                                    << spread[i];
  }
  // All 7 within 3 sigma: 0.9973^7 = 98% for independent parameters.
  EXPECT_GE(within, static_cast<int>(0.95 * trials));
}

TEST(Calibrate, AFitThatHasNotConvergedFailsWithItsIterationCount) {
  // One iteration from the linear start cannot reach the minimum of noisy
  // data: a computation error (exit 1), not a camera presented as converged.
  std::mt19937 rng(12);
  const Eigen::Vector3d target(0.8, 0.1, 0.5);
  const camera::Camera truth = random_camera(rng, target, 2.0, 700.0);
  const auto pts = with_noise(rng, random_points(rng, truth, target, 0.5, 30, 0.0), 1.0);
  calibration::CalibrationOptions opt;
  opt.max_iterations = 1;
  try {
    calibration::calibrate_camera(pts, truth.viewport, "side", opt);
    ADD_FAILURE() << "no error";
  } catch (const calibration::EstimationError& e) {
    EXPECT_EQ(std::string(e.what()), "camera 'side': the nonlinear fit did not converge after 1 iterations (iteration limit)");
  }
  opt.max_iterations = 100;  // the default converges
  EXPECT_LT(calibration::calibrate_camera(pts, truth.viewport, "side", opt).iterations, 100);
}

TEST(Calibrate, BadInputAndFailedComputationAreDistinctErrors) {
  static_assert(std::is_base_of_v<InputError, calibration::EstimationInputError>);
  static_assert(std::is_base_of_v<ComputationError, calibration::EstimationError>);
  static_assert(!std::is_base_of_v<std::invalid_argument, calibration::EstimationError>);
  std::mt19937 rng(13);
  const camera::Camera truth = random_camera(rng, Eigen::Vector3d(1, 0, 0.5), 2.0, 700.0);
  const auto five = random_points(rng, truth, Eigen::Vector3d(1, 0, 0.5), 0.4, 5, 0.0);
  EXPECT_THROW(calibration::calibrate_camera(five, truth.viewport, "side"), calibration::EstimationInputError);
}

TEST(Calibrate, PlantedOutliersFlaggedAndFitUnharmed) {
  std::mt19937 rng(3);
  const Eigen::Vector3d target(0.8, 0.1, 0.5);
  const camera::Camera truth = random_camera(rng, target, 2.2, 800.0);
  auto pts = random_points(rng, truth, target, 0.5, 30, 0.5);
  std::vector<calibration::Correspondence> clean;
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (i != 4 && i != 17 && i != 25) clean.push_back(pts[i]);
  pts[4].uv_px += Eigen::Vector2d(25.0, -10.0);
  pts[17].uv_px += Eigen::Vector2d(-8.0, 12.0);
  pts[25].uv_px += Eigen::Vector2d(40.0, 30.0);
  const calibration::CalibrationResult r = calibration::calibrate_camera(pts, truth.viewport, "cam");
  EXPECT_EQ(r.outliers, (std::vector<int>{pts[4].n, pts[17].n, pts[25].n}));
  EXPECT_TRUE(r.residuals[4].outlier);
  EXPECT_GT(r.residuals[25].px, 40.0);  // named with its residual under the final fit
  EXPECT_LT(r.rms_px, 1.0);
  calibration::CalibrationOptions no_rejection;
  no_rejection.outliers.enabled = false;
  const calibration::CalibrationResult ref = calibration::calibrate_camera(clean, truth.viewport, "cam", no_rejection);
  const auto d = param_error(r.camera, ref.camera);
  for (int i = 0; i < 7; ++i)  // the same fit as without the outliers (to convergence tolerance)
    EXPECT_LT(std::abs(d[i]), 1e-3 * ref.sigma[i]) << "parameter " << i;
  EXPECT_EQ(r.n_points, 30);
}

TEST(Calibrate, FarNearOrthographicView) {
  // 25 m away with a 2.2 degree field of view: nearly orthographic.
  std::mt19937 rng(5);
  const Eigen::Vector3d target(0.8, 0.1, 0.5);
  const camera::Camera truth = random_camera(rng, target, 25.0, 12000.0);
  const auto exact = random_points(rng, truth, target, 0.4, 30, 0.0);
  ASSERT_EQ(exact.size(), 30u);
  const calibration::CalibrationResult r0 = calibration::calibrate_camera(exact, truth.viewport, "cam");
  const auto d0 = param_error(r0.camera, truth);
  for (int i = 0; i < 7; ++i) EXPECT_LT(std::abs(d0[i]), 1e-6 * (i == 6 ? truth.f_px : 1.0)) << i;
  // With noise the linear third row is poor; the cross-product start keeps the
  // fit on the truth, within its (large) reported uncertainty.
  int cross = 0;
  for (int t = 0; t < 20; ++t) {
    const calibration::CalibrationResult r = calibration::calibrate_camera(with_noise(rng, exact, 0.5), truth.viewport, "cam");
    const auto d = param_error(r.camera, truth);
    for (int i = 0; i < 7; ++i) EXPECT_LT(std::abs(d[i]), 4.0 * r.sigma[i]) << "trial " << t << " parameter " << i;
    EXPECT_LT(r.rms_px, 1.0);
    cross += r.linear_cross_product ? 1 : 0;
  }
  EXPECT_GT(cross, 0);
}

TEST(CalibrateBadInput, FewerThanSixPoints) {
  std::mt19937 rng(1);
  const camera::Camera truth = random_camera(rng, Eigen::Vector3d(1, 0, 0.5), 2.0, 700.0);
  auto pts = random_points(rng, truth, Eigen::Vector3d(1, 0, 0.5), 0.4, 5, 0.0);
  EXPECT_EQ(error_of(pts), "camera 'side': 5 points; the linear calibration needs at least 6 (11 unknowns, 2 equations a point)");
  EXPECT_EQ(error_of({}), "camera 'side': 0 points; the linear calibration needs at least 6 (11 unknowns, 2 equations a point)");
}

TEST(CalibrateBadInput, CoplanarAndCollinearPoints) {
  std::mt19937 rng(2);
  const Eigen::Vector3d target(1, 0, 0.5);
  const camera::Camera truth = random_camera(rng, target, 2.0, 700.0);
  auto pts = random_points(rng, truth, target, 0.4, 12, 0.0);
  for (auto& c : pts) {  // flatten onto z = 0.5 and re-project
    c.p_m.z() = 0.5;
    c.uv_px = truth.project(c.p_m);
  }
  EXPECT_EQ(error_of(pts),
            "camera 'side': the 12 points are coplanar: the linear calibration (11 unknowns) is degenerate for points on "
            "one plane; click points off that plane (another arm pose)");
  for (std::size_t i = 0; i < pts.size(); ++i) {
    pts[i].p_m = target + 0.05 * static_cast<double>(i) * Eigen::Vector3d(1, 2, 3).normalized();
    pts[i].uv_px = truth.project(pts[i].p_m);
  }
  EXPECT_EQ(error_of(pts),
            "camera 'side': the 12 points are collinear (or coincide): calibration needs points spread in 3-D");
}

TEST(CalibrateBadInput, PointsBehindTheCamera) {
  // Projection is algebraic: a point behind the camera still "projects", and
  // the fit reproduces it exactly; the fitted camera shows it is behind.
  std::mt19937 rng(4);
  const Eigen::Vector3d target(1, 0, 0.5);
  const camera::Camera truth = random_camera(rng, target, 1.0, 500.0);
  auto pts = random_points(rng, truth, target, 0.3, 12, 0.0);
  const Eigen::Vector3d behind = truth.base_T_camera * Eigen::Vector3d(0.1, 0.05, -0.4);
  calibration::Correspondence c = pts[0];
  c.n = 99;
  c.line = 14;
  c.p_m = behind;
  c.uv_px = truth.project_camera(truth.to_camera(behind));
  pts.push_back(c);
  EXPECT_EQ(error_of(pts), "camera 'side': points behind the camera: n=99 (line 14)");
}

TEST(CalibrateBadInput, NonFiniteNumbers) {
  std::mt19937 rng(6);
  const camera::Camera truth = random_camera(rng, Eigen::Vector3d(1, 0, 0.5), 2.0, 700.0);
  auto pts = random_points(rng, truth, Eigen::Vector3d(1, 0, 0.5), 0.4, 10, 0.0);
  pts[3].uv_px.x() = std::nan("");
  pts[3].line = 6;
  EXPECT_EQ(error_of(pts), "camera 'side': point n=4 (line 6) has a non-finite coordinate");
}

TEST(Calibrate, RpyRateMatrixMatchesFiniteDifferences) {
  const Eigen::Vector3d rpy(0.3, -0.7, 2.1);
  const Eigen::Matrix3d W = calibration::rpy_rate_matrix(rpy);
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    d[k] = 1e-7;
    const Eigen::AngleAxisd aa(rotation_from_rpy(rpy).transpose() * rotation_from_rpy(rpy + d));
    const Eigen::Vector3d w = aa.angle() * aa.axis() / 1e-7;
    EXPECT_NEAR((w - W.col(k)).norm(), 0.0, 1e-6);
  }
}

// The covariance calibrate reports (roll/pitch/yaw, what cameras.yaml keeps)
// in the body-frame rotation increment is s^2 times the inverse of its
// information (J^T J in the body increment): the conversion and the fit
// agree, and the two conversions undo each other.
TEST(Calibrate, CovarianceBetweenRpyAndBodyIncrementAgreesWithTheInformation) {
  std::mt19937 rng(11);
  const Eigen::Vector3d target(0.8, 0.1, 0.5);
  const camera::Camera truth = random_camera(rng, target, 2.0, 800.0);
  const auto pts = random_points(rng, truth, target, 0.4, 40, 1.0);
  const calibration::CalibrationResult r = calibration::calibrate_camera(pts, truth.viewport, "cam");
  const Eigen::Matrix3d R = r.camera.base_T_camera.linear();
  const Eigen::Matrix<double, 7, 7> body = calibration::camera_covariance_body_from_rpy(r.covariance, R);
  const Eigen::Matrix<double, 7, 7> expected = r.residual_variance_px2 * r.information.inverse();
  for (int i = 0; i < 7; ++i)
    for (int j = 0; j < 7; ++j)
      EXPECT_NEAR(body(i, j), expected(i, j), 1e-6 * std::sqrt(expected(i, i) * expected(j, j))) << i << "," << j;
  EXPECT_LT((calibration::camera_covariance_rpy_from_body(body, R) - r.covariance).norm(), 1e-9 * r.covariance.norm());
}
