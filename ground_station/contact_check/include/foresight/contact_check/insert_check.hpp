#pragma once
// The go/no-go before the insert (issue 30 items 2 and 4): the probability
// that the insert succeeds is the probability mass of the tip's error
// (tip_error.hpp) inside the insert's capture region (common/insert_capture.hpp):
//
//   p_success = P(tilt in its cone) x P((lateral, axial) in their region)
//
// The lateral and axial errors together (one view's errors along and across
// its line of sight are correlated): within the clearance of the axis the
// approach may end in the hole (the wider axial window), elsewhere in the
// capture disc it must end before the face; the mass by quadrature in the
// whitened lateral plane, the axial error's conditional normal in closed form.
// The tilt's mass (2-D, exact per ray) is taken as independent of them.
// Set-up code.

#include <string>
#include <vector>

#include "foresight/common/insert_capture.hpp"
#include "foresight/contact_check/tip_error.hpp"

namespace foresight::contact_check {

/// The mass of N(mean, covariance) inside the disc |x| <= radius (2-D).
/// Exact up to the angular quadrature (`directions` rays; 1e-6 at the
/// default). A singular covariance is allowed (a point mass is in or out).
double gaussian_mass_in_disc(const Eigen::Vector2d& mean, const Eigen::Matrix2d& covariance, double radius,
                             int directions = 720);

/// The radius of the disc centred at 0 that holds `mass` of N(mean, covariance).
double disc_radius_holding(const Eigen::Vector2d& mean, const Eigen::Matrix2d& covariance, double mass);

/// Default of the go/no-go threshold.
inline constexpr double kDefaultMinPSuccess = 0.99;

struct InsertPrediction {
  double p_success = 0.0;
  double p_lateral = 0.0, p_tilt = 0.0;
  double p_axial = 0.0;  ///< given the lateral is captured: p_success = p_lateral p_axial p_tilt
  // The 95% errors about the planned start (the tip's mean error is the
  // plan's own offset from the hole, e.g. a stand-off):
  double lateral95_m = 0.0;  ///< radius of the disc holding 95% of the lateral error
  double axial95_m = 0.0;    ///< 1.96 sigma_z
  double tilt95_deg = 0.0;   ///< the tilt cone holding 95%
  InsertCapture capture;
  double min_p_success = kDefaultMinPSuccess;
  bool go = false;           ///< p_success >= min_p_success
};

/// The prediction of the error `tip` (at the hole) against `capture`.
/// Throws std::invalid_argument naming the input when min_p_success is not
/// in (0, 1) or the covariance is not symmetric positive semi-definite.
InsertPrediction predict_insert(const LocalCovariance& tip, const InsertCapture& capture, double min_p_success);

const char* verdict(bool go) noexcept;  ///< "go" or "no_go"
inline const char* verdict(const InsertPrediction& p) noexcept { return verdict(p.go); }

}  // namespace foresight::contact_check
