#include "foresight/contact_check/insert_check.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace foresight::contact_check {

double gaussian_mass_in_disc(const Eigen::Vector2d& mean, const Eigen::Matrix2d& covariance, double radius, int directions) {
  if (!(radius > 0.0)) return 0.0;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (covariance + covariance.transpose()));
  const Eigen::Matrix2d L = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
  const double c = mean.squaredNorm() - radius * radius;
  // In whitened coordinates x = mean + L z, z standard normal: along each
  // direction u the ray z = r u is in the disc for r in [r1, r2], and the
  // standard normal's mass there is (exp(-r1^2/2) - exp(-r2^2/2)) / 2 pi dphi.
  double sum = 0.0;
  for (int i = 0; i < directions; ++i) {
    const double phi = (i + 0.5) * 2.0 * std::numbers::pi / directions;
    const Eigen::Vector2d w = L * Eigen::Vector2d(std::cos(phi), std::sin(phi));
    const double a = w.squaredNorm(), b = mean.dot(w);
    if (a <= 1e-300) {  // no spread this way: the mean is in or out
      sum += c <= 0.0 ? 1.0 : 0.0;
      continue;
    }
    const double disc = b * b - a * c;
    if (disc <= 0.0) continue;
    const double root = std::sqrt(disc);
    const double r2 = (-b + root) / a;
    if (r2 <= 0.0) continue;
    const double r1 = std::max(0.0, (-b - root) / a);
    sum += std::exp(-0.5 * r1 * r1) - std::exp(-0.5 * r2 * r2);
  }
  return sum / directions;
}

double disc_radius_holding(const Eigen::Vector2d& mean, const Eigen::Matrix2d& covariance, double mass) {
  double lo = 0.0, hi = mean.norm() + 10.0 * std::sqrt(std::max(covariance.trace(), 0.0)) + 1e-12;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (gaussian_mass_in_disc(mean, covariance, mid) < mass ? lo : hi) = mid;
  }
  return hi;
}

namespace {

double normal_cdf(double x) { return 0.5 * std::erfc(-x / std::numbers::sqrt2); }

/// P(lo <= N(mean, sd^2) <= hi); sd 0: the mean is in or out.
double mass_in_interval(double mean, double sd, double lo, double hi) {
  if (sd <= 0.0) return mean >= lo && mean <= hi ? 1.0 : 0.0;
  return std::max(0.0, normal_cdf((hi - mean) / sd) - normal_cdf((lo - mean) / sd));
}

void check_covariance(const Matrix6& C) {
  if (!C.allFinite()) throw std::invalid_argument("the tip error's covariance has a non-finite entry");
  const double scale = std::max(C.cwiseAbs().maxCoeff(), 1e-300);
  if (!((C - C.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale))
    throw std::invalid_argument("the tip error's covariance is not symmetric");
  const Eigen::SelfAdjointEigenSolver<Matrix6> eig(C);
  if (eig.eigenvalues().minCoeff() < -1e-9 * scale)
    throw std::invalid_argument("the tip error's covariance is not positive semi-definite");
}

}  // namespace

InsertPrediction predict_insert(const LocalCovariance& tip, const InsertCapture& capture, double min_p_success) {
  if (!(min_p_success > 0.0 && min_p_success < 1.0))
    throw std::invalid_argument("min_p_success must be in (0, 1) (got " + std::to_string(min_p_success) + ")");
  if (!tip.mean.allFinite()) throw std::invalid_argument("the tip error's mean has a non-finite entry");
  check_covariance(tip.covariance);
  InsertPrediction p;
  p.capture = capture;
  p.min_p_success = min_p_success;
  const Eigen::Vector2d lat_mean = tip.mean.segment<2>(3), tilt_mean = tip.mean.head<2>();
  const Eigen::Matrix2d lat_cov = tip.covariance.block<2, 2>(3, 3), tilt_cov = tip.covariance.topLeftCorner<2, 2>();
  const double z = tip.mean[5], sz = std::sqrt(std::max(tip.covariance(5, 5), 0.0));
  p.p_lateral = gaussian_mass_in_disc(lat_mean, lat_cov, capture.lateral_m);
  p.p_tilt = gaussian_mass_in_disc(tilt_mean, tilt_cov, capture.tilt_rad);
  // The axial window is wider for a tip within the clearance (it is in the
  // hole already): the lateral disc splits in two.
  const double p_in_hole = std::min(p.p_lateral, gaussian_mass_in_disc(lat_mean, lat_cov, capture.clearance_m));
  const double p_axial_face = mass_in_interval(z, sz, capture.axial_min_m, capture.axial_max_m);
  const double p_axial_hole = mass_in_interval(z, sz, capture.axial_min_m, std::max(capture.axial_max_m, capture.axial_max_in_hole_m));
  const double p_lateral_and_axial = p_in_hole * p_axial_hole + (p.p_lateral - p_in_hole) * p_axial_face;
  p.p_axial = p.p_lateral > 0.0 ? p_lateral_and_axial / p.p_lateral : p_axial_face;  // given the lateral is captured
  p.p_success = p_lateral_and_axial * p.p_tilt;
  // The 95% errors about the planned start (the mean is the plan's offset).
  p.lateral95_m = disc_radius_holding(Eigen::Vector2d::Zero(), lat_cov, 0.95);
  p.tilt95_deg = disc_radius_holding(Eigen::Vector2d::Zero(), tilt_cov, 0.95) * 180.0 / std::numbers::pi;
  p.axial95_m = 1.959964 * sz;
  p.go = p.p_success >= min_p_success;
  return p;
}

const char* verdict(const InsertPrediction& p) noexcept { return p.go ? "go" : "no_go"; }

}  // namespace foresight::contact_check
