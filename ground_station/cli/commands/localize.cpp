// foresight localize: the object's pose from its model points clicked in one
// or more calibrated camera views.
//
//   foresight localize POINTS.csv --cameras cameras.yaml [--object config/oru.yaml]
//                      [--views cam1,cam3] [--json]
//
// POINTS.csv rows n,cam,x,y,z,u,v give model points in the object frame; the
// cam column names a camera of cameras.yaml. Exit: 0 ok, 2 bad input, 1 the
// fit failed.

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "format.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/localization/localize.hpp"
#include "json_util.hpp"
#include "residual_plot_option.hpp"

namespace foresight::cli {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct LocalizeArgs {
  std::string points;
  std::string cameras;
  std::string object = default_config("oru.yaml");
  std::string views;
  bool camera_uncertainty = false;
  bool json = false;
  ResidualPlotArgs plot;
};

/// The information (J^T J, pixels; body rotation, position, f) of a camera's
/// calibration from what cameras.yaml keeps: covariance C in (roll, pitch,
/// yaw, x, y, z, f) = s^2 (J_rpy^T J_rpy)^-1, with s^2 = rms^2 m / (2 m - 7)
/// over the m inliers; J_rpy = J_body W(rpy).
Eigen::Matrix<double, 7, 7> calibration_information(const std::string& file, const std::string& name,
                                                    const CameraRecord& rec) {
  if (!rec.calibration) throw std::invalid_argument(file + ": camera '" + name + "' has no calibration covariance (--camera-uncertainty)");
  const CameraCalibrationInfo& c = *rec.calibration;
  const int m = c.n_points - static_cast<int>(c.outliers.size());
  if (m < 4 || !(c.rms_px > 0.0))
    throw std::invalid_argument(file + ": camera '" + name + "' calibration has no usable rms_px/n_points (--camera-uncertainty)");
  const double s2 = c.rms_px * c.rms_px * m / std::max(2 * m - 7, 1);
  const Eigen::LDLT<Eigen::Matrix<double, 7, 7>> ldlt(c.covariance);
  if (ldlt.info() != Eigen::Success || !(c.covariance.diagonal().array() > 0.0).all())
    throw std::invalid_argument(file + ": camera '" + name + "' covariance is not positive definite");
  const Eigen::Matrix<double, 7, 7> H_rpy = s2 * ldlt.solve(Eigen::Matrix<double, 7, 7>::Identity());
  Eigen::Matrix<double, 7, 7> T = Eigen::Matrix<double, 7, 7>::Identity();
  T.topLeftCorner<3, 3>() = rpy_rate_matrix(rpy_from_rotation(rec.camera.base_T_camera.linear())).inverse();
  return T.transpose() * H_rpy * T;
}

std::vector<std::string> split_views(const std::string& text) {
  std::vector<std::string> out;
  for (const std::string_view v : split_commas(text)) {
    if (v.empty()) throw std::invalid_argument("--views: empty view name in '" + text + "'");
    out.emplace_back(v);
  }
  return out;
}

int run_localize(const LocalizeArgs& a) {
  const ObjectModel object = ObjectModel::from_file(a.object);
  std::map<std::string, Camera> cameras;
  const auto records = load_cameras(a.cameras);
  for (const auto& [name, rec] : records) cameras[name] = rec.camera;
  const std::vector<Correspondence> pts = read_correspondences_csv(a.points);
  for (const auto& [name, camera] : cameras) check_in_viewport(select_camera(pts, name), camera.viewport, a.points);
  LocalizationOptions opt;
  if (!a.views.empty()) opt.views = split_views(a.views);
  if (a.camera_uncertainty)
    for (const auto& [name, rec] : records) {
      bool used = false;
      for (const auto& c : pts) used = used || c.cam == name;
      if (used && (opt.views.empty() || std::find(opt.views.begin(), opt.views.end(), name) != opt.views.end()))
        opt.camera_information[name] = calibration_information(a.cameras, name, rec);
    }
  // The cameras held as calibrated are not exact, and cameras calibrated on
  // one arm share its link errors (cameras.yaml's arm_link_sensitivity):
  // both enter the pose's covariance; the pose is the same.
  std::vector<std::string> held;
  std::string arm_first;
  for (const auto& [name, rec] : records) {
    const bool used = std::any_of(pts.begin(), pts.end(), [&](const Correspondence& c) { return c.cam == name; }) &&
                      (opt.views.empty() || std::find(opt.views.begin(), opt.views.end(), name) != opt.views.end());
    if (!used || !rec.calibration) continue;
    const CameraCalibrationInfo& c = *rec.calibration;
    const Eigen::Matrix3d R = rec.camera.base_T_camera.linear();
    Eigen::Matrix<double, 7, 7> arm_rpy = Eigen::Matrix<double, 7, 7>::Zero();
    if (c.arm_link_sensitivity.size() > 0) {
      if (!arm_first.empty() && c.arm_link_sigma_m != opt.arm_link_sigma_m)
        throw std::invalid_argument(a.cameras + ": cameras '" + arm_first + "' and '" + name +
                                    "' were calibrated with different arm link sigmas (" + fixed(opt.arm_link_sigma_m * 1e3, 2) +
                                    " and " + fixed(c.arm_link_sigma_m * 1e3, 2) + " mm)");
      if (arm_first.empty()) arm_first = name;
      opt.arm_link_sigma_m = c.arm_link_sigma_m;
      arm_rpy = c.arm_link_sigma_m * c.arm_link_sigma_m * c.arm_link_sensitivity * c.arm_link_sensitivity.transpose();
      Eigen::MatrixXd K = c.arm_link_sensitivity;  // rpy rates -> body increments
      K.topRows<3>() = rpy_rate_matrix(rpy_from_rotation(R)) * c.arm_link_sensitivity.topRows<3>();
      opt.camera_link_sensitivity[name] = K;
    }
    if (opt.camera_information.count(name) || c.covariance.isZero(0.0)) continue;
    // The calibration's own (noise) part, kept positive semi-definite against
    // the file's rounding.
    const Eigen::Matrix<double, 7, 7> body = camera_covariance_body_from_rpy(c.covariance - arm_rpy, R);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 7, 7>> eig(0.5 * (body + body.transpose()));
    opt.camera_covariance[name] =
        eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() * eig.eigenvectors().transpose();
    held.push_back(name);
  }
  const LocalizationResult r = localize_object(pts, cameras, opt);
  write_residual_plot(a.plot, pts, r.residuals, plot_views(r.views, cameras), r.rms_px);
  const Eigen::Vector3d rpy_deg = r.rpy_rad() / kDeg;
  const Eigen::Vector3d pos = r.position_m();
  const Eigen::Vector3d sigma_rpy_deg = r.sigma_rpy_rad / kDeg;

  if (a.json) {
    nlohmann::json tags = nlohmann::json::object();
    for (const auto& [name, oru_T_tag] : object.tags) tags[name] = pose_json(r.base_T_object * oru_T_tag);
    nlohmann::json residuals = nlohmann::json::array();
    nlohmann::json outlier_details = nlohmann::json::array();
    for (const auto& p : r.residuals) {
      residuals.push_back({{"n", p.n}, {"cam", p.cam}, {"px", p.px}, {"outlier", p.outlier}, {"line", p.line}});
      if (p.outlier) outlier_details.push_back({{"n", p.n}, {"cam", p.cam}, {"px", p.px}, {"line", p.line}});
    }
    nlohmann::json j = {{"object", object.name},
                        {"position_m", vec_json(pos)},
                        {"rpy_deg", vec_json(rpy_deg)},
                        {"sigma", {{"position_m", vec_json(r.sigma_position_m)}, {"rpy_deg", vec_json(sigma_rpy_deg)}}},
                        {"covariance", matrix_rows(r.covariance)},
                        {"rms_px", r.rms_px},
                        {"max_px", r.max_px},
                        {"linear_rms_px", r.linear_rms_px},
                        {"iterations", r.iterations},
                        {"n_points", r.n_points},
                        {"residuals_px", residuals},
                        {"outliers", r.outliers},
                        {"outlier_details", outlier_details},
                        {"views", r.views},
                        {"camera_uncertainty", r.camera_uncertainty},
                        {"held_camera_uncertainty", held},
                        {"arm_link_sigma_m", opt.arm_link_sigma_m},
                        {"tags", tags}};
    j.update(object_pose_json(r.base_T_object));  // base_T_object: the object pose file's one writer
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  std::printf("object %s from %zu view(s):", object.name.c_str(), r.views.size());
  for (const auto& v : r.views) std::printf(" %s", v.c_str());
  std::printf("  (%d points)\n", r.n_points);
  std::printf("  position m  %10.4f %10.4f %10.4f  +- %.4f %.4f %.4f\n", pos.x(), pos.y(), pos.z(), r.sigma_position_m.x(),
              r.sigma_position_m.y(), r.sigma_position_m.z());
  std::printf("  rpy deg     %10.3f %10.3f %10.3f  +- %.3f %.3f %.3f\n", rpy_deg.x(), rpy_deg.y(), rpy_deg.z(),
              sigma_rpy_deg.x(), sigma_rpy_deg.y(), sigma_rpy_deg.z());
  std::printf("  base_T_object\n");
  for (int i = 0; i < 4; ++i)
    std::printf("    %10.6f %10.6f %10.6f %10.6f\n", r.base_T_object(i, 0), r.base_T_object(i, 1), r.base_T_object(i, 2),
                r.base_T_object(i, 3));
  std::printf("  rms %.3f px, max %.3f px (inliers); linear stage rms %.3f px; %d iterations%s\n", r.rms_px, r.max_px,
              r.linear_rms_px, r.iterations,
              r.camera_uncertainty ? "; cameras refined under their calibration covariance" : "");
  if (!held.empty() || opt.arm_link_sigma_m > 0.0) {
    std::string what;
    for (const auto& h : held) what += (what.empty() ? "" : ", ") + h;
    std::printf("  sigma includes%s%s%s\n", held.empty() ? "" : (" the held cameras' calibration (" + what + ")").c_str(),
                !held.empty() && opt.arm_link_sigma_m > 0.0 ? " and" : "",
                opt.arm_link_sigma_m > 0.0 ? (" the arm model's links (" + fixed(opt.arm_link_sigma_m * 1e3, 2) + " mm each)").c_str() : "");
  }
  if (r.outliers.empty()) std::printf("  outliers: none\n");
  for (const auto& p : r.residuals)
    if (p.outlier)
      std::printf("  outlier: point n=%d in view %s (line %d) residual %.2f px, left out of the fit\n", p.n, p.cam.c_str(),
                  p.line, p.px);
  std::printf("  tag frames in base (position m, rpy deg):\n");
  for (const auto& [name, oru_T_tag] : object.tags) {
    const Pose T = r.base_T_object * oru_T_tag;
    const Eigen::Vector3d t = T.translation(), e = rpy_from_rotation(T.linear()) / kDeg;
    std::printf("    %-16s %8.4f %8.4f %8.4f   %8.2f %8.2f %8.2f\n", name.c_str(), t.x(), t.y(), t.z(), e.x(), e.y(), e.z());
  }
  return kExitOk;
}

std::function<int()> setup(Command& sub) {
  auto a = std::make_shared<LocalizeArgs>();
  sub.add_option("points", a->points, "clicked model points CSV (n,cam,x,y,z,u,v; x,y,z in the object frame)")->required();
  sub.add_option("--cameras", a->cameras, "calibrated cameras (cameras.yaml)")->required();
  sub.add_option("--object", a->object, "object model")->capture_default_str();
  sub.add_option("--views", a->views, "comma-separated camera names to use (default: all in the file)");
  sub.add_flag("--camera-uncertainty", a->camera_uncertainty,
               "refine the cameras with the pose under their calibration covariance (cameras.yaml); sigma then "
               "includes the calibration error");
  sub.add_flag("--json", a->json, "print one JSON object");
  add_residual_plot_options(sub, a->plot);
  return [a] { return run_localize(*a); };
}

const bool registered = register_command({"localize", "localize the task object from calibrated camera views", setup});

}  // namespace
}  // namespace foresight::cli
