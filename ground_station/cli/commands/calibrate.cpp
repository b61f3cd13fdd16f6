// foresight calibrate: camera calibration with the robot arm as the fixture.
//
//   foresight calibrate POINTS.csv --camera NAME [--viewport 646x486]
//                       [--robot config/robot.urdf] [--out cameras.yaml]
//                       [--max-iterations 100] [--json]
//
// Uses the rows of POINTS.csv whose cam column is NAME (base-frame points or
// points on arm links with their joint angles). Exit: 0 ok, 2 bad input
// (file, rows, too few or degenerate points), 1 the fit failed.

#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"
#include "foresight/session/operations.hpp"
#include "residual_plot_option.hpp"

namespace foresight::cli {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct CalibrateArgs {
  session::CalibrateRequest request;
  bool json = false;
  ResidualPlotArgs plot;
};

int run_calibrate(const CalibrateArgs& args) {
  const session::CalibrateRequest& a = args.request;
  const session::Calibrated c = session::calibrate_from_clicks(a);
  const calibration::CalibrationResult& r = c.result;
  const camera::Viewport& vp = c.viewport;
  write_residual_plot(args.plot, c.points, r.residuals, {{a.camera, vp}}, r.rms_px);
  if (!a.out.empty()) session::add_camera(a.out, a.camera, c);
  const Eigen::Vector3d rpy_deg = r.rpy_rad() / kDeg;
  const Eigen::Vector3d pos = r.position_m();
  const double fovy_deg = r.camera.fovy_rad() / kDeg;
  const Eigen::Vector3d sigma_rpy_deg = r.sigma.head<3>() / kDeg;
  const Eigen::Vector3d sigma_pos = r.sigma.segment<3>(3);
  const Eigen::Matrix<double, 7, 1> arm_sigma = r.arm_model_covariance.diagonal().cwiseMax(0.0).cwiseSqrt();

  if (args.json) {
    const nlohmann::json j = session::calibrated_json(a, c);
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  std::printf("camera %s  (%d points, viewport %dx%d, principal point at the centre)\n", a.camera.c_str(), r.n_points,
              vp.width_px, vp.height_px);
  std::printf("  f_px        %10.2f  +- %.2f   (vertical field of view %.2f deg)\n", r.camera.f_px, r.sigma[6], fovy_deg);
  std::printf("  position m  %10.4f %10.4f %10.4f  +- %.4f %.4f %.4f\n", pos.x(), pos.y(), pos.z(), sigma_pos.x(),
              sigma_pos.y(), sigma_pos.z());
  std::printf("  rpy deg     %10.3f %10.3f %10.3f  +- %.3f %.3f %.3f\n", rpy_deg.x(), rpy_deg.y(), rpy_deg.z(),
              sigma_rpy_deg.x(), sigma_rpy_deg.y(), sigma_rpy_deg.z());
  if (a.arm_link_sigma_m > 0.0)
    std::printf("  of which the arm model (links +- %.1f mm): f +- %.2f, position +- %.4f %.4f %.4f, rpy +- %.3f %.3f %.3f\n",
                a.arm_link_sigma_m * 1e3, arm_sigma[6], arm_sigma[3], arm_sigma[4], arm_sigma[5], arm_sigma[0] / kDeg,
                arm_sigma[1] / kDeg, arm_sigma[2] / kDeg);
  std::printf("  base_T_camera\n");
  for (int i = 0; i < 4; ++i)
    std::printf("    %10.6f %10.6f %10.6f %10.6f\n", r.camera.base_T_camera(i, 0), r.camera.base_T_camera(i, 1),
                r.camera.base_T_camera(i, 2), r.camera.base_T_camera(i, 3));
  std::printf("  rms %.3f px, max %.3f px (inliers); linear stage rms %.3f px%s; %d iterations\n", r.rms_px, r.max_px,
              r.linear_rms_px, r.linear_cross_product ? " (r3 = r1 x r2)" : "", r.iterations);
  std::printf("  residuals (px):");
  for (std::size_t i = 0; i < r.residuals.size(); ++i)
    std::printf("%s n%d %.2f%s", i % 8 == 0 ? "\n   " : "", r.residuals[i].n, r.residuals[i].px,
                r.residuals[i].outlier ? "*" : "");
  std::printf("\n");
  if (r.outliers.empty()) {
    std::printf("  outliers: none\n");
  } else {
    for (const auto& p : r.residuals)
      if (p.outlier)
        std::printf("  outlier: point n=%d (line %d) residual %.2f px, left out of the fit\n", p.n, p.line, p.px);
  }
  if (!a.out.empty()) std::printf("  written to %s\n", a.out.c_str());
  return kExitOk;
}

std::function<int()> setup(Command& sub) {
  auto args = std::make_shared<CalibrateArgs>();
  session::CalibrateRequest* a = &args->request;
  sub.add_option("points", a->points, "clicked points CSV (n,cam,x,y,z,u,v or n,cam,link,lx,ly,lz,q1..qN,u,v)")
      ->required();
  sub.add_option("--camera", a->camera, "camera name (the cam column)")->required();
  sub.add_option("--viewport", a->viewport, "viewport WIDTHxHEIGHT in pixels")->capture_default_str();
  sub.add_option("--robot", a->robot, "robot URDF for points on arm links")->capture_default_str();
  sub.add_option("--out", a->out, "cameras.yaml to add this camera to (others are kept)");
  sub.add_option("--arm-link-sigma", a->arm_link_sigma_m,
                 "the arm model's link-length uncertainty (sd per link, m): carried from the arm-link points into "
                 "the camera's covariance (0: the model taken as exact)")
      ->check(check::NonNegativeNumber)
      ->capture_default_str();
  sub.add_option("--max-iterations", a->max_iterations, "Levenberg-Marquardt iteration limit (the fit fails, exit 1, when it "
                 "has not converged by then)")->capture_default_str();
  sub.add_flag("--json", args->json, "print one JSON object");
  add_residual_plot_options(sub, args->plot);
  return [args] { return run_calibrate(*args); };
}

const bool registered = register_command({"calibrate", "calibrate a camera with the robot arm as the fixture", setup});

}  // namespace
}  // namespace foresight::cli
