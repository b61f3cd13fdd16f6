// The go/no-go's probability against closed forms: the Gaussian mass in a
// disc (isotropic: the Rayleigh law; rank one: the normal's interval), the
// axial window (erf), the 95% radii, and the bad inputs' exact messages.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "foresight/common/insert_capture.hpp"
#include "foresight/contact_check/insert_check.hpp"

namespace {

using namespace foresight;
using namespace foresight::contact_check;

double normal_cdf(double x) { return 0.5 * std::erfc(-x / std::numbers::sqrt2); }

TEST(GaussianMassInDisc, IsotropicCentredIsTheRayleighLaw) {
  const double s = 1e-3;
  for (double rho : {0.5e-3, 2e-3, 3.5e-3})
    EXPECT_NEAR(gaussian_mass_in_disc({0, 0}, s * s * Eigen::Matrix2d::Identity(), rho), 1.0 - std::exp(-rho * rho / (2 * s * s)), 1e-9);
}

TEST(GaussianMassInDisc, RankOneIsTheNormalsChord) {
  // All spread along x, the mean off both axes (inside and outside the disc):
  // the mass is the normal's on the chord y = mean_y.
  const double s = 2e-3, rho = 5e-3;
  for (const Eigen::Vector2d& mean : {Eigen::Vector2d(1e-3, 3e-3), Eigen::Vector2d(7e-3, -4e-3)}) {
    Eigen::Matrix2d C = Eigen::Matrix2d::Zero();
    C(0, 0) = s * s;
    const double half = std::sqrt(rho * rho - mean.y() * mean.y());
    const double expected = normal_cdf((half - mean.x()) / s) - normal_cdf((-half - mean.x()) / s);
    EXPECT_NEAR(gaussian_mass_in_disc(mean, C, rho), expected, 2e-4) << mean.transpose();
  }
}

TEST(GaussianMassInDisc, PointMassIsInOrOut) {
  EXPECT_DOUBLE_EQ(gaussian_mass_in_disc({1e-3, 1e-3}, Eigen::Matrix2d::Zero(), 2e-3), 1.0);
  EXPECT_DOUBLE_EQ(gaussian_mass_in_disc({3e-3, 1e-3}, Eigen::Matrix2d::Zero(), 2e-3), 0.0);
}

TEST(GaussianMassInDisc, AnisotropicOffCentreMatchesTheRayleighOfItsWhitening) {
  // Rotated anisotropic covariance, mean outside: against a fine polar sum of the density.
  const Eigen::Vector2d mean(4e-3, 1e-3);
  Eigen::Matrix2d C;
  C << 4e-6, 1.5e-6, 1.5e-6, 1e-6;
  const double rho = 3e-3;
  const Eigen::Matrix2d Ci = C.inverse();
  const double norm = 1.0 / (2 * std::numbers::pi * std::sqrt(C.determinant()));
  double sum = 0.0;
  const int nr = 1500, nphi = 1500;
  for (int i = 0; i < nr; ++i)
    for (int j = 0; j < nphi; ++j) {
      const double r = (i + 0.5) * rho / nr, phi = (j + 0.5) * 2 * std::numbers::pi / nphi;
      const Eigen::Vector2d d = Eigen::Vector2d(r * std::cos(phi), r * std::sin(phi)) - mean;
      sum += norm * std::exp(-0.5 * d.dot(Ci * d)) * r * (rho / nr) * (2 * std::numbers::pi / nphi);
    }
  EXPECT_NEAR(gaussian_mass_in_disc(mean, C, rho), sum, 1e-5);
  EXPECT_GT(sum, 0.1);
  EXPECT_LT(sum, 0.9);
}

InsertCapture capture() { return insert_capture(InsertParams{}, InsertGeometry{}); }

TEST(InsertCapture, FromTheInsertsParameters) {
  const InsertCapture c = capture();
  EXPECT_NEAR(c.clearance_m, 0.001, 1e-12);              // 30 mm hole, 28 mm socket
  EXPECT_NEAR(c.lateral_m, 0.005 + 0.001 + 0.0015, 1e-12);  // spiral out to 5 mm + the clearance + the rim's lead-in
  EXPECT_NEAR(c.tilt_rad, std::asin(1.0 / 14.0), 1e-12);
  EXPECT_NEAR(c.axial_min_m, 0.05 - 0.06, 1e-12);        // 6 cm of travel, the latch needs 5 cm
  EXPECT_EQ(c.axial_max_m, 0.0);
  EXPECT_NEAR(c.axial_max_in_hole_m, 0.080 - 0.06 + 0.002, 1e-12);  // in the hole already: on to its bottom
}

TEST(InsertCapture, RefusesNonPositiveSizesNamingThem) {
  InsertParams p;
  p.spiral_max_radius_m = 0.0;
  EXPECT_THROW(
      {
        try {
          insert_capture(p, InsertGeometry{});
        } catch (const std::invalid_argument& e) {
          EXPECT_STREQ(e.what(), "insert.spiral_max_radius_m must be a positive number");
          throw;
        }
      },
      std::invalid_argument);
  InsertGeometry g;
  g.socket_diameter_m = 0.031;
  EXPECT_THROW(
      {
        try {
          insert_capture(InsertParams{}, g);
        } catch (const std::invalid_argument& e) {
          EXPECT_STREQ(e.what(), "capture region: the socket (0.031000 m) must be narrower than the hole (0.030000 m)");
          throw;
        }
      },
      std::invalid_argument);
}

TEST(PredictInsert, IsTheTiltTimesTheLateralAndAxialZones) {
  const InsertCapture c = capture();
  LocalCovariance tip;
  tip.mean[5] = -0.005;  // 5 mm stand-off
  const double sl = 2.5e-3, st = 0.02, sz = 3e-3;
  tip.covariance.diagonal() << st * st, st * st, 1e-4, sl * sl, sl * sl, sz * sz;
  const InsertPrediction p = predict_insert(tip, c, 0.99);
  const double p_lat = 1.0 - std::exp(-c.lateral_m * c.lateral_m / (2 * sl * sl));
  const double p_tilt = 1.0 - std::exp(-c.tilt_rad * c.tilt_rad / (2 * st * st));
  // Within the 1 mm clearance the approach may end in the hole (z up to
  // 22 mm); elsewhere in the disc it must end in front of the face (z <= 0).
  const double p_in = 1.0 - std::exp(-c.clearance_m * c.clearance_m / (2 * sl * sl));
  const double p_face = normal_cdf((0.0 + 0.005) / sz) - normal_cdf((c.axial_min_m + 0.005) / sz);
  const double p_hole = normal_cdf((c.axial_max_in_hole_m + 0.005) / sz) - normal_cdf((c.axial_min_m + 0.005) / sz);
  const double p_lat_ax = p_in * p_hole + (p_lat - p_in) * p_face;
  EXPECT_NEAR(p.p_lateral, p_lat, 1e-9);
  EXPECT_NEAR(p.p_tilt, p_tilt, 1e-9);
  EXPECT_NEAR(p.p_axial, p_lat_ax / p_lat, 1e-9);
  EXPECT_NEAR(p.p_success, p_lat_ax * p_tilt, 1e-9);
  EXPECT_NEAR(p.lateral95_m, sl * std::sqrt(-2.0 * std::log(0.05)), 1e-8);
  EXPECT_NEAR(p.axial95_m, 1.959964 * sz, 1e-12);
  EXPECT_NEAR(p.tilt95_deg, st * std::sqrt(-2.0 * std::log(0.05)) * 180 / std::numbers::pi, 1e-6);
  EXPECT_FALSE(p.go);  // ~0.95 of the axial window
  EXPECT_STREQ(verdict(p), "no_go");
  tip.covariance *= 0.1;
  EXPECT_TRUE(predict_insert(tip, c, 0.99).go);
}

TEST(PredictInsert, LateralAndAxialErrorsThatMoveTogetherAreIntegratedTogether) {
  // One view's error along its line of sight: z = x, all spread along x.
  // The start 5 mm before the face: x in [-5, 5] mm succeeds (beyond 5 mm
  // the tip ends past the face outside the clearance, before -5 mm it starts
  // too far out for 6 cm of travel to reach 5 cm), nothing else counts.
  const InsertCapture c = capture();
  LocalCovariance tip;
  tip.mean[5] = -0.005;
  const double s = 4e-3;
  tip.covariance(3, 3) = tip.covariance(5, 5) = tip.covariance(3, 5) = tip.covariance(5, 3) = s * s;
  tip.covariance(0, 0) = tip.covariance(1, 1) = 1e-8;  // the tilt: captured
  const InsertPrediction p = predict_insert(tip, c, 0.99);
  EXPECT_NEAR(p.p_success, normal_cdf(0.005 / s) - normal_cdf(-0.005 / s), 1e-6);
  // Taken apart, lateral and axial would say less: the product is not it.
  const double product = (normal_cdf(c.lateral_m / s) - normal_cdf(-c.lateral_m / s)) *
                         (normal_cdf(0.005 / s) - normal_cdf(-0.005 / s));
  EXPECT_GT(p.p_success - product, 0.04);
}

TEST(PredictInsert, RefusesAThresholdOutsideTheOpenUnitInterval) {
  for (double bad : {0.0, 1.0, -0.5, std::nan("")}) {
    try {
      predict_insert(LocalCovariance{}, capture(), bad);
      ADD_FAILURE() << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_EQ(std::string(e.what()).rfind("min_p_success must be in (0, 1) (got ", 0), 0u) << e.what();
    }
  }
}

TEST(PredictInsert, RefusesACovarianceThatIsNotOne) {
  LocalCovariance tip;
  tip.covariance(3, 4) = 1e-6;
  EXPECT_THROW(predict_insert(tip, capture(), 0.99), std::invalid_argument);
  tip.covariance(4, 3) = 1e-6;  // symmetric now, but indefinite
  try {
    predict_insert(tip, capture(), 0.99);
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "the tip error's covariance is not positive semi-definite");
  }
}

}  // namespace
