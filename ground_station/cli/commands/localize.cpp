// foresight localize: the object's pose from its model points clicked in one
// or more calibrated camera views.
//
//   foresight localize POINTS.csv --cameras cameras.yaml [--object config/oru.yaml]
//                      [--views cam1,cam3] [--json]
//
// POINTS.csv rows n,cam,x,y,z,u,v give model points in the object frame; the
// cam column names a camera of cameras.yaml. Exit: 0 ok, 2 bad input, 1 the
// fit failed.

#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/format.hpp"
#include "foresight/session/operations.hpp"
#include "residual_plot_option.hpp"

namespace foresight::cli {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct LocalizeArgs {
  session::LocalizeRequest request;
  bool json = false;
  ResidualPlotArgs plot;
};

int run_localize(const LocalizeArgs& args) {
  const session::Localized l = session::localize_from_clicks(args.request);
  const localization::LocalizationResult& r = l.result;
  const ObjectModel& object = l.object;
  const std::vector<std::string>& held = l.held_cameras;
  write_residual_plot(args.plot, l.points, r.residuals, plot_views(r.views, l.cameras), r.rms_px);
  const Eigen::Vector3d rpy_deg = r.rpy_rad() / kDeg;
  const Eigen::Vector3d pos = r.position_m();
  const Eigen::Vector3d sigma_rpy_deg = r.sigma_rpy_rad / kDeg;
  if (args.json) {
    std::cout << session::localized_json(l).dump(2) << "\n";
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
  if (!held.empty() || l.arm_link_sigma_m > 0.0) {
    std::string what;
    for (const auto& h : held) what += (what.empty() ? "" : ", ") + h;
    std::printf("  sigma includes%s%s%s\n", held.empty() ? "" : (" the held cameras' calibration (" + what + ")").c_str(),
                !held.empty() && l.arm_link_sigma_m > 0.0 ? " and" : "",
                l.arm_link_sigma_m > 0.0 ? (" the arm model's links (" + fixed(l.arm_link_sigma_m * 1e3, 2) + " mm each)").c_str() : "");
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
  auto args = std::make_shared<LocalizeArgs>();
  session::LocalizeRequest* a = &args->request;
  sub.add_option("points", a->points, "clicked model points CSV (n,cam,x,y,z,u,v; x,y,z in the object frame)")->required();
  sub.add_option("--cameras", a->cameras, "calibrated cameras (cameras.yaml)")->required();
  sub.add_option("--object", a->object, "object model")->capture_default_str();
  sub.add_option("--views", a->views, "comma-separated camera names to use (default: all in the file)");
  sub.add_flag("--camera-uncertainty", a->camera_uncertainty,
               "refine the cameras with the pose under their calibration covariance (cameras.yaml); sigma then "
               "includes the calibration error");
  sub.add_flag("--json", args->json, "print one JSON object");
  add_residual_plot_options(sub, args->plot);
  return [args] { return run_localize(*args); };
}

const bool registered = register_command({"localize", "localize the task object from calibrated camera views", setup});

}  // namespace
}  // namespace foresight::cli
