#include "foresight/contact_check/insert_check.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <utility>
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

/// Gauss-Legendre, 16 nodes on [-1, 1].
constexpr std::array<double, 8> kGlX = {0.0950125098376374, 0.2816035507792589, 0.4580167776572274, 0.6178762444026438,
                                        0.7554044083550030, 0.8656312023878318, 0.9445750230732326, 0.9894009349916499};
constexpr std::array<double, 8> kGlW = {0.1894506104550685, 0.1826034150449236, 0.1691565193950025, 0.1495959888165767,
                                        0.1246289712555339, 0.0951585116824928, 0.0622535239386479, 0.0271524594117541};

/// Where the ray mean + r w (r >= 0) is within `radius` of 0: [r1, r2]
/// clipped to [0, r_max]; empty (r1 >= r2) when it never is.
std::pair<double, double> ray_in_disc(const Eigen::Vector2d& mean, const Eigen::Vector2d& w, double radius, double r_max) {
  const double a = w.squaredNorm(), b = mean.dot(w), c = mean.squaredNorm() - radius * radius;
  if (a <= 1e-300) return c <= 0.0 ? std::pair{0.0, r_max} : std::pair{0.0, 0.0};
  const double disc = b * b - a * c;
  if (disc <= 0.0) return {0.0, 0.0};
  const double root = std::sqrt(disc);
  return {std::clamp((-b - root) / a, 0.0, r_max), std::clamp((-b + root) / a, 0.0, r_max)};
}

/// The mass of the Gaussian of (x, y, z) = (lateral, axial) in the capture's
/// region: within the clearance of the axis z in [axial_min, axial_max_in_hole],
/// elsewhere in the lateral disc z in [axial_min, axial_max]. The lateral
/// part whitened (x, y) = mean + L w, w standard normal; z given w is
/// normal, mean_z + k.w, variance var_z - |k|^2. Polar in w: per direction
/// the rays' pieces inside the clearance and the rest of the disc,
/// Gauss-Legendre in r against the density r exp(-r^2/2) / 2 pi.
double lateral_axial_mass(const Eigen::Vector3d& mean, const Eigen::Matrix3d& C, const InsertCapture& cap) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(C.topLeftCorner<2, 2>());
  const Eigen::Vector2d sd = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  const Eigen::Matrix2d L = eig.eigenvectors() * sd.asDiagonal();
  Eigen::Vector2d k = Eigen::Vector2d::Zero();  // Cov(w, z) = L^+ Sigma_lz
  const Eigen::Vector2d s_lz = C.block<2, 1>(0, 2);
  for (int i = 0; i < 2; ++i)
    if (sd[i] > 1e-12 * std::max(sd.maxCoeff(), 1e-300)) k[i] = eig.eigenvectors().col(i).dot(s_lz) / sd[i];
  const double sd_z = std::sqrt(std::max(C(2, 2) - k.squaredNorm(), 0.0));
  const Eigen::Vector2d m = mean.head<2>();
  constexpr double kRMax = 9.0;  // exp(-40.5): nothing beyond
  constexpr int kDirections = 360;
  const double zin = std::max(cap.axial_max_m, cap.axial_max_in_hole_m);
  double sum = 0.0;
  for (int i = 0; i < kDirections; ++i) {
    const double phi = (i + 0.5) * 2.0 * std::numbers::pi / kDirections;
    const Eigen::Vector2d u(std::cos(phi), std::sin(phi));
    const Eigen::Vector2d w = L * u;
    const double zu = k.dot(u);
    const auto [r1, r2] = ray_in_disc(m, w, cap.lateral_m, kRMax);
    if (r1 >= r2) continue;
    const auto [c1, c2] = ray_in_disc(m, w, cap.clearance_m, kRMax);
    // Pieces of [r1, r2]: before, inside and after the clearance's [c1, c2].
    const auto gauss_legendre = [&](double lo, double hi, double z_hi) {
      double acc = 0.0;
      const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
      for (std::size_t g = 0; g < kGlX.size(); ++g)
        for (const double sign : {-1.0, 1.0}) {
          const double r = mid + sign * half * kGlX[g];
          acc += kGlW[g] * r * std::exp(-0.5 * r * r) * mass_in_interval(mean[2] + r * zu, sd_z, cap.axial_min_m, z_hi);
        }
      return acc * half;
    };
    // Split where z's conditional mean crosses the window's ends: the
    // integrand turns there (a step when z is fixed by w).
    const auto piece = [&](double lo, double hi, double z_hi) {
      if (hi <= lo) return 0.0;
      std::array<double, 4> at = {lo, hi, hi, hi};  // unused: hi (an empty piece)
      if (std::abs(zu) > 0.0) {
        const double r_min = (cap.axial_min_m - mean[2]) / zu, r_max = (z_hi - mean[2]) / zu;
        if (r_min > lo && r_min < hi) at[2] = r_min;
        if (r_max > lo && r_max < hi) at[3] = r_max;
      }
      std::sort(at.begin(), at.end());
      double acc = 0.0;
      for (std::size_t i = 0; i + 1 < at.size(); ++i)
        if (at[i + 1] > at[i]) acc += gauss_legendre(at[i], at[i + 1], z_hi);
      return acc;
    };
    if (c1 >= c2) {
      sum += piece(r1, r2, cap.axial_max_m);
    } else {
      sum += piece(r1, std::max(r1, c1), cap.axial_max_m) + piece(c1, c2, zin) + piece(std::min(c2, r2), r2, cap.axial_max_m);
    }
  }
  return sum / kDirections;
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
  // Lateral and axial together (one view's errors along and across its line
  // of sight are correlated): the axial window is wider for a tip within the
  // clearance (in the hole already).
  Eigen::Vector3d la_mean;
  la_mean << lat_mean, z;
  Eigen::Matrix3d la_cov;
  la_cov = tip.covariance.bottomRightCorner<3, 3>();
  const double p_lateral_and_axial = std::min(p.p_lateral, lateral_axial_mass(la_mean, la_cov, capture));
  // Given the lateral is captured (p_success = p_lateral p_axial p_tilt).
  p.p_axial = p.p_lateral > 0.0 ? p_lateral_and_axial / p.p_lateral : mass_in_interval(z, sz, capture.axial_min_m, capture.axial_max_m);
  p.p_success = p_lateral_and_axial * p.p_tilt;
  // The 95% errors about the planned start (the mean is the plan's offset).
  p.lateral95_m = disc_radius_holding(Eigen::Vector2d::Zero(), lat_cov, 0.95);
  p.tilt95_deg = disc_radius_holding(Eigen::Vector2d::Zero(), tilt_cov, 0.95) * 180.0 / std::numbers::pi;
  p.axial95_m = 1.959964 * sz;
  p.go = p.p_success >= min_p_success;
  return p;
}

const char* verdict(bool go) noexcept { return go ? "go" : "no_go"; }

}  // namespace foresight::contact_check
