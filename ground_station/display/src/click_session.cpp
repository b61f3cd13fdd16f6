#include "foresight/display/click_session.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace foresight::display {

std::vector<ModelPoint> arm_model_points(const RobotModel& model, const Eigen::VectorXd& q) {
  if (q.size() != model.dof())
    throw std::invalid_argument("joint angles: " + std::to_string(q.size()) + " values for an arm of " +
                                std::to_string(model.dof()) + " joints");
  KinematicsWorkspace ws(model);
  std::vector<ModelPoint> out;
  for (int k = 1; k < static_cast<int>(model.links().size()); ++k) {
    const Pose T = forward_kinematics(model, ws, q, k);
    std::vector<Eigen::Vector3d> local = {Eigen::Vector3d::Zero()};
    for (const auto& v : model.links()[k].visuals) local.push_back(v.link_T_shape.translation());
    int i = 0;
    for (const auto& p : local) {
      const Eigen::Vector3d pb = T * p;
      bool dup = false;
      for (const auto& o : out) dup = dup || (o.p_m - pb).norm() < 0.03;
      if (!dup) out.push_back({model.links()[k].name + (i == 0 ? "" : "." + std::to_string(i)), pb});
      ++i;
    }
  }
  return out;
}

std::vector<ModelPoint> object_model_points(const ObjectModel& object) {
  std::vector<ModelPoint> out;
  for (const auto& p : object.points) out.push_back({p.name, p.p_m});
  return out;
}

camera::Camera model_view_camera(const std::vector<ModelPoint>& points, const camera::Viewport& viewport,
                         const Eigen::Vector3d& view_direction, const Eigen::Vector3d& up) {
  if (points.empty()) throw std::invalid_argument("model view: no model points");
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : points) c += p.p_m;
  c /= static_cast<double>(points.size());
  double radius = 0.05;
  for (const auto& p : points) radius = std::max(radius, (p.p_m - c).norm());
  const double f_px = 0.9 * std::min(viewport.width_px, viewport.height_px);
  // The sphere of `radius` subtends half of 70 % of the smaller side: d = r f / (0.35 side).
  const double distance = radius * f_px / (0.35 * std::min(viewport.width_px, viewport.height_px)) + radius;
  return camera::Camera::look_at("model", viewport, f_px, c + distance * view_direction.normalized(), c, up);
}

camera::Camera default_model_view(const std::vector<ModelPoint>& points, const camera::Viewport& viewport, bool arm) {
  return arm ? model_view_camera(points, viewport, {1.0, -0.8, 0.55}, Eigen::Vector3d::UnitZ())
             : model_view_camera(points, viewport, {-0.35, -0.3, -1.0}, -Eigen::Vector3d::UnitY());
}

int nearest_point(const std::vector<Eigen::Vector2d>& projected_px, const Eigen::Vector2d& uv_px, double radius_px) {
  int best = -1;
  double best_d = radius_px;
  for (int i = 0; i < static_cast<int>(projected_px.size()); ++i) {
    const double d = (projected_px[i] - uv_px).norm();
    if (d <= best_d) {
      best = i;
      best_d = d;
    }
  }
  return best;
}

Eigen::Vector2d ZoomView::to_image(int x, int y) const {
  return origin_ + Eigen::Vector2d(x + 0.5, y + 0.5) / zoom_;
}

Eigen::Vector2d ZoomView::to_window(const Eigen::Vector2d& uv_px) const { return (uv_px - origin_) * zoom_; }

void ZoomView::zoom_at(const Eigen::Vector2d& uv_px, double factor) {
  if (!(factor > 0.0) || !std::isfinite(factor)) return;
  const Eigen::Vector2d w = to_window(uv_px);
  zoom_ = std::clamp(zoom_ * factor, 1.0, max_zoom);
  origin_ = uv_px - w / zoom_;
  clamp();
}

void ZoomView::reset() {
  zoom_ = 1.0;
  origin_.setZero();
}

void ZoomView::clamp() {
  const Eigen::Vector2d shown(size_.width / zoom_, size_.height / zoom_);
  origin_.x() = std::clamp(origin_.x(), 0.0, size_.width - shown.x());
  origin_.y() = std::clamp(origin_.y(), 0.0, size_.height - shown.y());
}

cv::Mat ZoomView::render(const cv::Mat& image) const {
  if (zoom_ == 1.0) return image.clone();
  // Window pixel x shows image coordinate origin + (x + 0.5) / zoom: the
  // affine map from window to image, sampled at pixel centres (warpAffine's
  // convention is pixel index = coordinate - 0.5 on both sides).
  cv::Mat M = (cv::Mat_<double>(2, 3) << 1.0 / zoom_, 0.0, origin_.x() + 0.5 / zoom_ - 0.5, 0.0, 1.0 / zoom_,
               origin_.y() + 0.5 / zoom_ - 0.5);
  cv::Mat out;
  cv::warpAffine(image, out, M, image.size(), cv::INTER_NEAREST | cv::WARP_INVERSE_MAP, cv::BORDER_REPLICATE);
  return out;
}

ClickSession::ClickSession(std::string camera, std::vector<ModelPoint> model_points, cv::Size image_size)
    : camera_(std::move(camera)), model_points_(std::move(model_points)), image_size_(image_size) {
  if (camera_.empty()) throw std::invalid_argument("click session: empty camera name");
  if (model_points_.empty()) throw std::invalid_argument("click session: no model points");
  if (image_size_.width <= 0 || image_size_.height <= 0) throw std::invalid_argument("click session: empty image");
}

void ClickSession::set_existing_rows(std::vector<calibration::Correspondence> rows) {
  existing_ = std::move(rows);
  next_n_ = 1;
  for (const auto& r : existing_) next_n_ = std::max(next_n_, r.n + 1);
  for (auto& r : rows_) r.n = next_n_++;
}

bool ClickSession::select_model_point(int index) {
  if (index < 0 || index >= static_cast<int>(model_points_.size())) return false;
  selected_ = index;
  return true;
}

ClickSession::Outcome ClickSession::click_image(const Eigen::Vector2d& uv) {
  if (!(uv.x() >= 0.0 && uv.x() < image_size_.width && uv.y() >= 0.0 && uv.y() < image_size_.height))
    return Outcome::OutsideImage;
  if (selected_ < 0) return Outcome::NoModelPoint;
  calibration::Correspondence c;
  c.n = next_n_++;
  c.cam = camera_;
  c.p_m = model_points_[selected_].p_m;
  c.uv_px = uv;
  rows_.push_back(c);
  row_point_.push_back(selected_);
  selected_ = -1;
  return Outcome::Added;
}

bool ClickSession::delete_last() {
  if (selected_ >= 0) {
    selected_ = -1;
    return true;
  }
  if (rows_.empty()) return false;
  rows_.pop_back();
  row_point_.pop_back();
  --next_n_;
  return true;
}

void ClickSession::clear() {
  next_n_ -= static_cast<int>(rows_.size());
  rows_.clear();
  row_point_.clear();
  selected_ = -1;
}

std::vector<calibration::Correspondence> ClickSession::rows() const {
  std::vector<calibration::Correspondence> all = existing_;
  all.insert(all.end(), rows_.begin(), rows_.end());
  return all;
}

std::string ClickSession::csv() const { return calibration::to_csv(rows()); }

}  // namespace foresight::display
