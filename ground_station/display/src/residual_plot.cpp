#include "foresight/display/residual_plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace foresight::display {

std::vector<PlotPoint> plot_points(const std::vector<calibration::Correspondence>& clicks,
                                   const std::vector<calibration::PointResidual>& residuals, const std::string& camera) {
  std::vector<PlotPoint> out;
  for (const auto& r : residuals) {
    if (!r.cam.empty() && r.cam != camera) continue;
    const calibration::Correspondence* match = nullptr;
    for (const auto& c : clicks)
      if (c.n == r.n && c.cam == camera && (r.line == 0 || c.line == 0 || c.line == r.line)) {
        match = &c;
        break;
      }
    if (match == nullptr)
      throw std::invalid_argument("residual plot: no click for point n=" + std::to_string(r.n) + " of camera '" +
                                  camera + "'");
    out.push_back({r.n, match->uv_px, match->uv_px - r.r_px, r.outlier});
  }
  return out;
}

double auto_arrow_scale(const std::vector<PlotPoint>& points) {
  double max_px = 0.0;
  for (const auto& p : points)
    if (!p.outlier) max_px = std::max(max_px, (p.clicked_px - p.reprojected_px).norm());
  if (!(max_px > 0.0)) return 1.0;
  const double raw = std::clamp(40.0 / max_px, 1.0, 500.0);
  // Largest 1-2-5 step not above raw.
  const double decade = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double m : {5.0, 2.0, 1.0})
    if (m * decade <= raw + 1e-9) return m * decade;
  return decade;
}

namespace {

cv::Point2d at(const Eigen::Vector2d& uv) { return {uv.x() - 0.5, uv.y() - 0.5}; }  // pixel centre convention

void label(cv::Mat& img, const std::string& text, cv::Point p, const cv::Scalar& colour, double scale = 0.45) {
  cv::putText(img, text, p + cv::Point(1, 1), cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 2, cv::LINE_AA);
  cv::putText(img, text, p, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv::LINE_AA);
}

}  // namespace

cv::Mat draw_residual_plot(const cv::Mat& background, const camera::Viewport& viewport, const std::vector<PlotPoint>& points,
                           const ResidualPlotOptions& o) {
  cv::Mat img;
  if (background.empty()) {
    img = cv::Mat(viewport.height_px, viewport.width_px, CV_8UC3, cv::Scalar(32, 28, 24));
  } else if (background.channels() == 1) {
    cv::cvtColor(background, img, cv::COLOR_GRAY2BGR);
  } else if (background.channels() == 4) {
    cv::cvtColor(background, img, cv::COLOR_BGRA2BGR);
  } else {
    img = background.clone();
  }
  if (img.depth() != CV_8U) throw std::invalid_argument("residual plot: the background must be an 8-bit image");
  const double scale = o.arrow_scale > 0.0 ? o.arrow_scale : auto_arrow_scale(points);
  constexpr int kShift = 4;  // sub-pixel drawing
  auto fixed = [](const cv::Point2d& p) { return cv::Point(cvRound(p.x * 16), cvRound(p.y * 16)); };
  const cv::Scalar green(80, 230, 80), yellow(0, 220, 255), red(40, 40, 255), white(255, 255, 255);
  double sum2 = 0.0;
  int inliers = 0, outliers = 0;
  for (const auto& p : points) {
    const Eigen::Vector2d r = p.clicked_px - p.reprojected_px;
    if (p.outlier) {
      ++outliers;
    } else {
      sum2 += r.squaredNorm();
      ++inliers;
    }
    const cv::Point2d c = at(p.clicked_px), q = at(p.reprojected_px);
    cv::circle(img, fixed(q), 3 * 16, white, 1, cv::LINE_AA, kShift);
    const cv::Point2d tip = q + cv::Point2d(r.x() * scale, r.y() * scale);
    cv::arrowedLine(img, fixed(q), fixed(tip), p.outlier ? red : yellow, p.outlier ? 2 : 1, cv::LINE_AA, kShift, 0.2);
    cv::drawMarker(img, cv::Point(cvRound(c.x), cvRound(c.y)), green, cv::MARKER_CROSS, 9, 1, cv::LINE_AA);
    if (p.outlier) cv::circle(img, fixed(c), 11 * 16, red, 2, cv::LINE_AA, kShift);
    label(img, std::to_string(p.n), cv::Point(cvRound(c.x) + 6, cvRound(c.y) - 6), p.outlier ? red : green, 0.4);
  }
  char buf[160];
  const double rms = inliers > 0 ? std::sqrt(sum2 / inliers) : 0.0;
  std::snprintf(buf, sizeof buf, "%d points, rms %.2f px (inliers), %d outlier%s; arrows x%g", inliers + outliers, rms,
                outliers, outliers == 1 ? "" : "s", scale);
  int y = 18;
  if (!o.title.empty()) {
    label(img, o.title, cv::Point(8, y), white, 0.5);
    y += 20;
  }
  label(img, buf, cv::Point(8, y), white, 0.45);
  label(img, "+ click   o reprojection   -> residual (scaled)   red: outlier", cv::Point(8, img.rows - 10), white, 0.4);
  return img;
}

cv::Mat tile_pictures(const std::vector<cv::Mat>& pictures, int columns) {
  if (pictures.empty()) throw std::invalid_argument("tile_pictures: nothing to tile");
  if (pictures.size() == 1) return pictures.front();
  columns = std::max(1, std::min<int>(columns, static_cast<int>(pictures.size())));
  int w = 0, h = 0;
  for (const auto& p : pictures) {
    w = std::max(w, p.cols);
    h = std::max(h, p.rows);
  }
  const int rows = (static_cast<int>(pictures.size()) + columns - 1) / columns;
  cv::Mat out(rows * h, columns * w, CV_8UC3, cv::Scalar(0, 0, 0));
  for (std::size_t i = 0; i < pictures.size(); ++i)
    pictures[i].copyTo(out(cv::Rect(static_cast<int>(i % columns) * w, static_cast<int>(i / columns) * h,
                                    pictures[i].cols, pictures[i].rows)));
  return out;
}

}  // namespace foresight::display
