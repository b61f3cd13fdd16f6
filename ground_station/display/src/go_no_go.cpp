#include "foresight/display/go_no_go.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <vector>

#include "foresight/camera/projection.hpp"
#include "foresight/common/format.hpp"
#include "foresight/display/display_frame.hpp"

namespace foresight::display {

double chi_square_2dof_quantile(double p) {
  if (!(p > 0.0 && p < 1.0)) throw std::invalid_argument("the ellipse's probability must be in (0, 1)");
  return -2.0 * std::log1p(-p);
}

ImageEllipse gaussian_ellipse(const Eigen::Vector2d& centre, const Eigen::Matrix2d& S, double p) {
  const double k2 = chi_square_2dof_quantile(p);
  const double scale = std::max(std::abs(S(0, 0)) + std::abs(S(1, 1)), 1e-300);
  if (!S.allFinite() || std::abs(S(0, 1) - S(1, 0)) > 1e-9 * scale)
    throw std::invalid_argument("an image covariance must be finite and symmetric");
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (S + S.transpose()));
  const Eigen::Vector2d l = eig.eigenvalues();  // ascending
  if (l(0) < -1e-9 * scale) throw std::invalid_argument("an image covariance must be positive semi-definite");
  ImageEllipse e;
  e.centre_px = centre;
  e.covariance_px2 = S;
  e.semi_major_px = std::sqrt(k2 * std::max(l(1), 0.0));
  e.semi_minor_px = std::sqrt(k2 * std::max(l(0), 0.0));
  const Eigen::Vector2d major = eig.eigenvectors().col(1);
  double a = std::atan2(major.y(), major.x());
  if (a <= -std::numbers::pi / 2) a += std::numbers::pi;
  if (a > std::numbers::pi / 2) a -= std::numbers::pi;
  e.angle_rad = a;
  return e;
}

Eigen::Matrix2d project_position_covariance(const camera::Camera& camera, const Eigen::Vector3d& p_base,
                                            const Eigen::Matrix3d& C) {
  if (!camera.in_front(p_base))
    throw std::invalid_argument("the point is behind camera '" + camera.name + "': its covariance has no image");
  const camera::Projection pr = camera::project_with_jacobians(camera, p_base);
  const Eigen::Matrix2d S = pr.d_point * C * pr.d_point.transpose();
  return 0.5 * (S + S.transpose());
}

ImageEllipse project_position_ellipse(const camera::Camera& camera, const Eigen::Vector3d& p_base,
                                      const Eigen::Matrix3d& C, double p) {
  return gaussian_ellipse(camera.project(p_base), project_position_covariance(camera, p_base, C), p);
}

std::string go_no_go_label(bool go, double p) {
  std::string ps;
  if (p < 0.99) ps = fixed(p, 2);
  else if (p < 1.0 && fixed(p, 3) == "1.000") ps = ">0.999";
  else ps = fixed(p, 3);
  return std::string("insert: ") + (go ? "go" : "no_go") + " P=" + ps;
}

cv::Scalar go_no_go_colour(bool go) { return go ? cv::Scalar(60, 220, 60) : cv::Scalar(60, 60, 255); }

namespace {

constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 px
constexpr double kMinSemiAxisPx = 1.5;

cv::Point fixed_point(const Eigen::Vector2d& uv) {
  // Camera pixels cover [i, i+1): the centre of pixel i is i + 0.5, OpenCV's i.
  return {static_cast<int>(std::lround((uv.x() - 0.5) * (1 << kShift))),
          static_cast<int>(std::lround((uv.y() - 0.5) * (1 << kShift)))};
}

void draw_polyline(cv::Mat& img, const std::vector<Eigen::Vector2d>& uv, bool closed, const cv::Scalar& colour,
                   int thickness) {
  std::vector<cv::Point> pts;
  pts.reserve(uv.size());
  for (const auto& p : uv) pts.push_back(fixed_point(p));
  const std::vector<std::vector<cv::Point>> lines{pts};
  cv::polylines(img, lines, closed, colour, thickness, cv::LINE_AA, kShift);
}

void draw_ellipse(cv::Mat& img, const ImageEllipse& e, const cv::Scalar& colour, int thickness) {
  const double a = std::max(e.semi_major_px, kMinSemiAxisPx), b = std::max(e.semi_minor_px, kMinSemiAxisPx);
  const Eigen::Vector2d ax(std::cos(e.angle_rad), std::sin(e.angle_rad)), ay(-ax.y(), ax.x());
  std::vector<Eigen::Vector2d> uv;
  constexpr int n = 96;
  for (int i = 0; i < n; ++i) {
    const double t = 2.0 * std::numbers::pi * i / n;
    uv.push_back(e.centre_px + a * std::cos(t) * ax + b * std::sin(t) * ay);
  }
  draw_polyline(img, uv, true, colour, thickness);
}

/// The image is far larger than anything worth drawing: keep OpenCV's fixed
/// point away from overflow when a point projects far outside.
bool drawable(const Eigen::Vector2d& uv, const cv::Mat& img) {
  const double m = 4.0 * std::max(img.cols, img.rows);
  return uv.allFinite() && uv.x() > -m && uv.y() > -m && uv.x() < img.cols + m && uv.y() < img.rows + m;
}

}  // namespace

GoNoGoDrawn project_go_no_go(const camera::Camera& camera, const GoNoGoMarks& m) {
  GoNoGoDrawn out;
  out.label = go_no_go_label(m.go, m.p_success);
  const Eigen::Vector3d hole = m.base_T_hole.translation(), tip = m.base_T_tag.translation();
  out.hole_in_front = camera.in_front(hole);
  if (out.hole_in_front) {
    out.hole = project_position_ellipse(camera, hole, m.hole_position_covariance);
    out.hole_in_view = camera.in_view(out.hole.centre_px);
  }
  out.tip_in_front = camera.in_front(tip);
  if (out.tip_in_front) {
    out.tip = project_position_ellipse(camera, tip, m.tip_position_covariance);
    out.tip_in_view = camera.in_view(out.tip.centre_px);
  }
  return out;
}

GoNoGoDrawn draw_go_no_go(cv::Mat& img, const camera::Camera& camera, const GoNoGoMarks& m, bool label) {
  if (img.type() != CV_8UC3) throw std::invalid_argument("draw_go_no_go: the picture must be 8-bit BGR");
  const GoNoGoDrawn out = project_go_no_go(camera, m);
  const cv::Scalar colour = go_no_go_colour(m.go);

  // The hole: its 95% ellipse, and a cross-hair outside it so that a small
  // ellipse is still found.
  double reach_px = 0.0;  // how far from the centre the marks go (the label goes beyond)
  Eigen::Vector2d anchor = Eigen::Vector2d::Zero();
  bool anchored = false;
  if (out.hole_in_front) {
    if (drawable(out.hole.centre_px, img) && out.hole.semi_major_px < 4.0 * std::max(img.cols, img.rows)) {
      draw_ellipse(img, out.hole, colour, 2);
      const double r0 = std::max(out.hole.semi_major_px, kMinSemiAxisPx) + 4.0;
      for (const Eigen::Vector2d& d : {Eigen::Vector2d(1, 0), Eigen::Vector2d(-1, 0), Eigen::Vector2d(0, 1), Eigen::Vector2d(0, -1)})
        draw_polyline(img, {out.hole.centre_px + r0 * d, out.hole.centre_px + (r0 + 7.0) * d}, false, colour, 1);
      anchor = out.hole.centre_px;
      anchored = true;
      reach_px = r0 + 7.0;
    }
  }

  // The tool tip at the approach's end: the socket's rim about the tag's z,
  // the tool's axis behind it, and the tip's 95% ellipse.
  if (out.tip_in_front) {
    if (drawable(out.tip.centre_px, img) && out.tip.semi_major_px < 4.0 * std::max(img.cols, img.rows)) {
      draw_ellipse(img, out.tip, colour, 1);
      if (!anchored) anchor = out.tip.centre_px;
      anchored = true;
      const double offset = (out.tip.centre_px - anchor).norm();
      reach_px = std::max(reach_px, offset + std::max(out.tip.semi_major_px, kMinSemiAxisPx));
      std::vector<Eigen::Vector2d> rim;
      bool rim_ok = m.socket_diameter_m > 0.0;
      constexpr int n = 48;
      for (int i = 0; i < n && rim_ok; ++i) {
        const double t = 2.0 * std::numbers::pi * i / n;
        const Eigen::Vector3d p = m.base_T_tag * Eigen::Vector3d(0.5 * m.socket_diameter_m * std::cos(t),
                                                                 0.5 * m.socket_diameter_m * std::sin(t), 0.0);
        rim_ok = camera.in_front(p) && drawable(camera.project(p), img);
        if (rim_ok) rim.push_back(camera.project(p));
      }
      if (rim_ok) {
        draw_polyline(img, rim, true, colour, 1);
        for (const auto& p : rim) reach_px = std::max(reach_px, (p - anchor).norm());
      }
      const Eigen::Vector3d back = m.base_T_tag * Eigen::Vector3d(0.0, 0.0, -0.04);
      // (Left out when it points at the camera: a dot at the centre says nothing.)
      if (camera.in_front(back) && drawable(camera.project(back), img) &&
          (camera.project(back) - out.tip.centre_px).norm() >= 2.0)
        draw_polyline(img, {out.tip.centre_px, camera.project(back)}, false, colour, 1);
    }
  }

  // The label to the right of the marks (to their left near the image's edge).
  if (anchored && label) {
    int base = 0;
    const double scale = 0.5;
    const cv::Size sz = cv::getTextSize(out.label, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &base);
    int x = static_cast<int>(std::lround(anchor.x() + reach_px + 10.0));
    if (x + sz.width + 4 > img.cols) x = static_cast<int>(std::lround(anchor.x() - reach_px - 10.0)) - sz.width;
    x = std::clamp(x, 4, std::max(4, img.cols - sz.width - 4));
    const int y = std::clamp(static_cast<int>(std::lround(anchor.y())) - sz.height / 2 - 3, 4,
                             std::max(4, img.rows - sz.height - base - 8));
    put_text_line(img, out.label, {x, y}, colour, scale);
  }
  return out;
}

}  // namespace foresight::display
