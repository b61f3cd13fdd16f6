#pragma once
// `--plot out.png` (and `--plot-image`) for calibrate and localize: the
// residual picture of the fit (foresight/display/residual_plot.hpp). One
// option call and one write call in each command. Include only from
// commands/*.cpp.

#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "command.hpp"
#include "foresight/calibration/calibrate.hpp"
#include "foresight/camera/camera.hpp"
#include "foresight/display/residual_plot.hpp"
#include "foresight/render/video_frame.hpp"

namespace foresight::cli {

struct ResidualPlotArgs {
  std::string out;                  ///< --plot PNG ("" = none)
  std::vector<std::string> images;  ///< --plot-image [CAM=]PATH,...
  double arrow_scale = 0.0;         ///< --plot-scale (0 = automatic)
};

inline void add_residual_plot_options(Command& sub, ResidualPlotArgs& a) {
  sub.add_option("--plot", a.out,
                 "write the residual picture (PNG): each click, its reprojection, the residual arrow scaled, "
                 "outliers marked; on --plot-image or a blank of the viewport size");
  sub.add_option("--plot-image", a.images, "background for --plot: an image, or CAM=IMAGE per view (comma-separated)")
      ->delimiter(',');
  sub.add_option("--plot-scale", a.arrow_scale, "residual arrow magnification for --plot (default: automatic)")
      ->check(check::NonNegativeNumber);
}

/// The background image for `camera`: a CAM=PATH entry, else a bare PATH
/// entry, else none (empty Mat). InputError naming the file when unreadable.
inline cv::Mat residual_plot_background(const ResidualPlotArgs& a, const std::string& camera) {
  std::string bare, named;
  for (const auto& e : a.images) {
    const auto eq = e.find('=');
    if (eq == std::string::npos)
      bare = e;
    else if (e.substr(0, eq) == camera)
      named = e.substr(eq + 1);
  }
  const std::string path = !named.empty() ? named : bare;
  return path.empty() ? cv::Mat() : render::read_video_frame(path);
}

/// (camera, viewport) of each named view.
inline std::vector<std::pair<std::string, camera::Viewport>> plot_views(const std::vector<std::string>& views,
                                                                const std::map<std::string, camera::Camera>& cameras) {
  std::vector<std::pair<std::string, camera::Viewport>> out;
  for (const auto& v : views)
    if (const auto it = cameras.find(v); it != cameras.end()) out.emplace_back(v, it->second.viewport);
  return out;
}

/// One picture per view (tiled when there are several), written to a.out.
/// `views`: (camera, viewport). Does nothing when --plot was not given.
inline void write_residual_plot(const ResidualPlotArgs& a, const std::vector<calibration::Correspondence>& clicks,
                                const std::vector<calibration::PointResidual>& residuals,
                                const std::vector<std::pair<std::string, camera::Viewport>>& views, double rms_px) {
  if (a.out.empty()) return;
  std::vector<cv::Mat> pictures;
  for (const auto& [camera, viewport] : views) {
    display::ResidualPlotOptions o;
    o.arrow_scale = a.arrow_scale;
    char rms[64];
    std::snprintf(rms, sizeof rms, "fit rms %.2f px (all views)", rms_px);
    o.title = "camera " + camera + ": " + rms;
    pictures.push_back(display::draw_residual_plot(residual_plot_background(a, camera), viewport,
                                                   display::plot_points(clicks, residuals, camera), o));
  }
  render::write_image(a.out, display::tile_pictures(pictures, 2), "cannot write the residual plot (--plot)");
}

}  // namespace foresight::cli
