#pragma once
// Robust outlier flagging shared by calibration and localization (internal).

#include <algorithm>
#include <functional>
#include <vector>

#include "foresight/calibration/calibrate.hpp"

namespace foresight::detail {

/// Iteratively flags the worst inlier while its residual exceeds
/// max(k * robust sigma, floor) and refits without it (fit(inlier mask)
/// returns every point's residual norm under the fit on the inliers); then
/// readmits flagged points that fit the final solution. Returns the mask of
/// inliers; `residual_px` holds the residuals of the final fit.
inline std::vector<bool> flag_outliers(int n, int min_inliers, const OutlierOptions& opt,
                                       const std::function<std::vector<double>(const std::vector<bool>&)>& fit,
                                       std::vector<double>& residual_px) {
  std::vector<bool> inlier(static_cast<std::size_t>(n), true);
  residual_px = fit(inlier);
  if (!opt.enabled) return inlier;
  const int max_flagged = static_cast<int>(opt.max_fraction * n);
  int flagged = 0;
  auto threshold = [&]() {
    std::vector<double> r;
    for (int i = 0; i < n; ++i)
      if (inlier[i]) r.push_back(residual_px[i]);
    return std::max(opt.k_sigma * robust_sigma_px(r), opt.floor_px);
  };
  while (flagged < max_flagged && n - flagged - 1 >= min_inliers) {
    const double thr = threshold();
    int worst = -1;
    for (int i = 0; i < n; ++i)
      if (inlier[i] && residual_px[i] > thr && (worst < 0 || residual_px[i] > residual_px[worst])) worst = i;
    if (worst < 0) break;
    inlier[worst] = false;
    ++flagged;
    residual_px = fit(inlier);
  }
  if (flagged > 0) {  // readmit points the final fit explains
    const double thr = threshold();
    bool changed = false;
    for (int i = 0; i < n; ++i)
      if (!inlier[i] && residual_px[i] <= thr) inlier[i] = changed = true;
    if (changed) residual_px = fit(inlier);
  }
  return inlier;
}

}  // namespace foresight::detail
