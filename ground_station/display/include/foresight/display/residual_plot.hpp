#pragma once
// The residual picture of a fit (`calibrate --plot`, `localize --plot`, the
// fit in `foresight click`): on the image (or a blank of the viewport's size)
// each clicked point, its reprojection through the fitted camera/pose, the
// residual as an arrow from the reprojection to the click, scaled so it can
// be seen, and the outliers marked. Not real-time code (allocates).

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "foresight/calibration/calibrate.hpp"
#include "foresight/calibration/correspondence.hpp"
#include "foresight/camera/camera.hpp"

namespace foresight::display {

struct PlotPoint {
  int n = 0;
  Eigen::Vector2d clicked_px = Eigen::Vector2d::Zero();
  Eigen::Vector2d reprojected_px = Eigen::Vector2d::Zero();
  bool outlier = false;
};

/// Pairs the clicks with the fit's residuals (measured - predicted, matched
/// by point number n and camera): reprojected = clicked - residual. Points
/// of other cameras are skipped. Throws std::invalid_argument when a
/// residual has no click.
std::vector<PlotPoint> plot_points(const std::vector<calibration::Correspondence>& clicks,
                                   const std::vector<calibration::PointResidual>& residuals, const std::string& camera);

/// Arrow magnification: 0 = automatic (the largest inlier residual drawn
/// about 40 px long, a 1-2-5 step between 1 and 500).
double auto_arrow_scale(const std::vector<PlotPoint>& points);

struct ResidualPlotOptions {
  double arrow_scale = 0.0;   ///< 0: auto_arrow_scale
  std::string title;          ///< first line of the legend (e.g. "camera side: rms 0.41 px")
};

/// The picture: `background` (8-bit BGR or grey, any size; empty = a dark
/// blank of `viewport`). Clicks: green crosses numbered; reprojections:
/// small circles; residual arrows (yellow; red and circled for outliers),
/// scaled; legend with the scale. Returns 8-bit BGR.
cv::Mat draw_residual_plot(const cv::Mat& background, const camera::Viewport& viewport, const std::vector<PlotPoint>& points,
                           const ResidualPlotOptions& options = {});

/// Tiles pictures in a grid of up to `columns` (each labelled already), same
/// height per row; one picture is returned as it is.
cv::Mat tile_pictures(const std::vector<cv::Mat>& pictures, int columns = 2);

}  // namespace foresight::display
