#include "foresight/localization/peers.hpp"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

namespace foresight::localization {

std::optional<Pose> solve_pnp_opencv(const std::vector<calibration::Correspondence>& points, const camera::Camera& camera,
                                     PnpMethod method) {
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (const auto& c : points) {
    object.emplace_back(c.p_m.x(), c.p_m.y(), c.p_m.z());
    image.emplace_back(c.uv_px.x(), c.uv_px.y());
  }
  const Eigen::Vector2d pp = camera.principal_point();
  const cv::Matx33d K(camera.f_px, 0, pp.x(), 0, camera.f_px, pp.y(), 0, 0, 1);
  cv::Mat rvec, tvec;
  bool ok = false;
  try {
    ok = cv::solvePnP(object, image, K, cv::noArray(), rvec, tvec, false,
                      method == PnpMethod::Sqpnp ? cv::SOLVEPNP_SQPNP : cv::SOLVEPNP_ITERATIVE);
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
  if (!ok) return std::nullopt;
  cv::Matx33d Rcv;
  cv::Rodrigues(rvec, Rcv);
  Pose camera_T_object = Pose::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) camera_T_object.linear()(r, c) = Rcv(r, c);
    camera_T_object.translation()[r] = tvec.at<double>(r);
  }
  if (!camera_T_object.matrix().allFinite()) return std::nullopt;
  return camera.base_T_camera * camera_T_object;
}

Eigen::Vector3d triangulate_dlt(const std::vector<const camera::Camera*>& cameras, const std::vector<Eigen::Vector2d>& uv) {
  const int v = static_cast<int>(cameras.size());
  Eigen::MatrixXd A(2 * v, 4);
  for (int k = 0; k < v; ++k) {
    const camera::Camera& c = *cameras[k];
    Eigen::Matrix<double, 3, 4> P;  // K [R | t] with camera_T_base
    Eigen::Matrix3d K;
    K << c.f_px, 0, c.principal_point().x(), 0, c.f_px, c.principal_point().y(), 0, 0, 1;
    const Pose camera_T_base = c.base_T_camera.inverse();
    P.leftCols<3>() = camera_T_base.linear();
    P.col(3) = camera_T_base.translation();
    P = (K * P).eval();
    // Rows scaled to unit norm for conditioning across views.
    const Eigen::RowVector4d r0 = uv[k].x() * P.row(2) - P.row(0), r1 = uv[k].y() * P.row(2) - P.row(1);
    A.row(2 * k) = r0 / r0.norm();
    A.row(2 * k + 1) = r1 / r1.norm();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d X = svd.matrixV().col(3);
  return X.head<3>() / X[3];
}

std::optional<Pose> triangulate_and_align(const std::vector<calibration::Correspondence>& points,
                                          const std::map<std::string, camera::Camera>& cameras) {
  std::vector<Eigen::Vector3d> model;
  std::vector<std::vector<std::size_t>> groups;
  for (std::size_t i = 0; i < points.size(); ++i) {
    bool placed = false;
    for (std::size_t g = 0; g < model.size() && !placed; ++g)
      if ((model[g] - points[i].p_m).norm() < 1e-12) {
        groups[g].push_back(i);
        placed = true;
      }
    if (!placed) {
      model.push_back(points[i].p_m);
      groups.push_back({i});
    }
  }
  std::vector<Eigen::Vector3d> src, dst;
  for (std::size_t g = 0; g < model.size(); ++g) {
    std::vector<const camera::Camera*> cams;
    std::vector<Eigen::Vector2d> uv;
    for (const std::size_t i : groups[g]) {
      const auto it = cameras.find(points[i].cam);
      if (it == cameras.end()) continue;
      cams.push_back(&it->second);
      uv.push_back(points[i].uv_px);
    }
    if (cams.size() < 2) continue;
    src.push_back(model[g]);
    dst.push_back(triangulate_dlt(cams, uv));
  }
  if (src.size() < 3) return std::nullopt;
  Eigen::Matrix3Xd S(3, src.size()), D(3, dst.size());
  for (std::size_t i = 0; i < src.size(); ++i) {
    S.col(static_cast<Eigen::Index>(i)) = src[i];
    D.col(static_cast<Eigen::Index>(i)) = dst[i];
  }
  Pose T = Pose::Identity();
  T.matrix() = Eigen::umeyama(S, D, false);
  if (!T.matrix().allFinite()) return std::nullopt;
  return T;
}

}  // namespace foresight::localization
