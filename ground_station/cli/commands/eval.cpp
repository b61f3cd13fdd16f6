// foresight eval: accuracy studies.
//
//   foresight eval localization [--trials N] [--noise-px S] [--seed K] [--seeds M]
//                               [--arm-error-mm E]
//                               [--scene config/scene.yaml] [--object config/oru.yaml]
//                               [--robot config/robot.urdf] [--json]
//
// A Monte Carlo reproduction of the paper's Tables 1-3 on the synthetic
// four-camera ORU scene: each trial re-calibrates every camera from noisy
// clicks on the arm (link points at several arm poses, through FK) and then
// localizes the ORU from its visible model points with every combination of
// views; beside it the Cramer-Rao bound and the peers (OpenCV solvePnP,
// triangulate-then-align) on the same clicks. A progress bar on stderr.
// --seeds M repeats the study with seeds K..K+M-1 and reports the spread of
// the RMSEs over the seeds (the tables show seed K). --arm-error-mm E adds the
// arm-model error (every link length off by a Gaussian of E mm in each
// trial, the calibration using that wrong arm) and reports the study both
// without and with it, on the same clicks.

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/session/operations.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {

std::function<int()> setup_eval_alignment(Command& eval);  // eval_alignment.cpp
std::function<int()> setup_eval_insertion(Command& eval);  // eval_insertion.cpp

namespace {

constexpr double kDeg = M_PI / 180.0;

struct EvalArgs {
  session::LocalizationStudyRequest request;
  bool json = false;
};

void print_spread(const std::vector<localization::StudyResult>& runs, const char* title) {
  std::printf("\n%s: RMSE over %zu seeds x %d trials, mean +- sd over the seeds (ratio to the bound)\n", title,
              runs.size(), runs.front().trials);
  std::printf("%-9s %26s %26s %16s\n", "views", "two-step mm / deg", "joint mm / deg", "CRLB mm / deg");
  for (const auto& j : session::localization_spread_json(runs)) {
    const double b = j["crlb_position_mm"].get<double>();
    char two[64], joint[64];
    std::snprintf(two, sizeof two, "%.2f+-%.2f (%.2fx) / %.3f", j["position_rmse_mm"]["mean"].get<double>(),
                  j["position_rmse_mm"]["sd"].get<double>(), j["position_rmse_mm"]["mean"].get<double>() / b,
                  j["rotation_rmse_deg"]["mean"].get<double>());
    std::snprintf(joint, sizeof joint, "%.2f+-%.2f (%.2fx) / %.3f", j["joint_position_rmse_mm"]["mean"].get<double>(),
                  j["joint_position_rmse_mm"]["sd"].get<double>(), j["joint_position_rmse_mm"]["mean"].get<double>() / b,
                  j["joint_rotation_rmse_deg"]["mean"].get<double>());
    std::printf("%-9s %26s %26s %8.2f / %.3f\n", j["views"].get<std::string>().c_str(), two, joint, b,
                j["crlb_rotation_deg"].get<double>());
  }
}

void print_tables(const session::LocalizationStudyRequest& a, const session::LocalizationStudy& study) {
  const std::vector<localization::StudyResult>& runs = study.runs;
  const std::vector<localization::StudyResult>& arm_runs = study.arm_runs;
  const bool arm_error = a.arm_error_mm > 0.0;
  const localization::StudyResult& r = runs.front();
  const double elapsed_s = study.elapsed_s;
  const localization::ComboStats& all = r.combos.back();
  const double pos_ratio = all.ours.position_rmse_m / all.crlb_position_m;
  const double rot_ratio = all.ours.rotation_rmse_rad / all.crlb_rotation_rad;
  const double jpos_ratio = all.ours_joint.position_rmse_m / all.crlb_position_m;
  const double jrot_ratio = all.ours_joint.rotation_rmse_rad / all.crlb_rotation_rad;

  std::printf("Localization accuracy: %d trials, %.2f px click noise, errors in the ORU frame (z along the hole axis)\n",
              r.trials, r.noise_px);
  for (std::size_t v = 0; v < r.view_names.size(); ++v)
    std::printf("  view %zu %-14s %2d arm clicks (calibration rms %.2f px), %2d ORU clicks\n", v + 1,
                r.view_names[v].c_str(), r.calibration_points[v], r.calibration_rms_px[v], r.object_points[v]);
  if (r.calibration_failures) std::printf("  %d trials skipped: a calibration failed\n", r.calibration_failures);

  std::printf("\nTable 1. Error averages (this method: calibrate, then linear + Gauss-Newton localization)\n");
  std::printf("%-9s %8s %8s %8s %8s %8s %8s\n", "views", "mu_x cm", "mu_y cm", "mu_z cm", "mu_thx", "mu_thy", "mu_thz");
  for (const auto& c : r.combos) {
    const auto& s = c.ours;
    std::printf("%-9s %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f\n", c.label.c_str(), s.mean[0] * 100, s.mean[1] * 100,
                s.mean[2] * 100, s.mean[3] / kDeg, s.mean[4] / kDeg, s.mean[5] / kDeg);
  }
  std::printf("\nTable 2. Error standard deviations, and the Cramer-Rao bound [in brackets] (cm, deg)\n");
  std::printf("%-9s %17s %17s %17s %17s %17s %17s\n", "views", "sd_x", "sd_y", "sd_z", "sd_thx", "sd_thy", "sd_thz");
  for (const auto& c : r.combos) {
    std::printf("%-9s", c.label.c_str());
    for (int i = 0; i < 6; ++i) {
      const double k = i < 3 ? 100.0 : 1.0 / kDeg;
      std::printf("  %6.3f [%6.3f]", c.ours.sd[i] * k, c.crlb_sd[i] * k);
    }
    std::printf("\n");
  }
  std::printf("\nTable 3. Maximum positioning errors at 95%% confidence (cm): alignment |mu_xy| + 2 sd_xy, depth |mu_z| + 2 sd_z\n");
  std::printf("%-9s %10s %10s %12s %12s\n", "views", "alignment", "depth", "CRLB align", "CRLB depth");
  for (const auto& c : r.combos)
    std::printf("%-9s %10.3f %10.3f %12.3f %12.3f\n", c.label.c_str(), c.ours.alignment95_m * 100,
                c.ours.depth95_m * 100, c.crlb_alignment95_m * 100, c.crlb_depth95_m * 100);
  std::printf("\nTable 4. RMSE beside the bound and the peers: position (mm) / rotation (deg)\n");
  std::printf("%-9s %15s %15s %15s %15s %15s %15s %15s\n", "views", "paper 2-step", "joint w/ prior", "CRLB",
              "CRLB known cam", "solvePnP SQPNP", "solvePnP ITER", "triang+Umeyama");
  auto pr = [](const localization::ErrorStats& s) {
    char b[40];
    if (s.n == 0) return std::string("              -");
    if (s.position_rmse_m > 10.0) {  // a peer whose failed trials dominate its RMSE
      std::snprintf(b, sizeof b, "  >10 m/%6.1f", s.rotation_rmse_rad / kDeg);
      return std::string(b);
    }
    std::snprintf(b, sizeof b, "%7.3f/%6.3f", s.position_rmse_m * 1e3, s.rotation_rmse_rad / kDeg);
    return std::string(b);
  };
  for (const auto& c : r.combos) {
    char crlb[40], known[40];
    std::snprintf(crlb, sizeof crlb, "%7.3f/%6.3f", c.crlb_position_m * 1e3, c.crlb_rotation_rad / kDeg);
    std::snprintf(known, sizeof known, "%7.3f/%6.3f", c.crlb_known_cameras_sd.head<3>().norm() * 1e3,
                  c.crlb_known_cameras_sd.tail<3>().norm() / kDeg);
    std::printf("%-9s %15s %15s %15s %15s %15s %15s %15s%s\n", c.label.c_str(), pr(c.ours).c_str(),
                pr(c.ours_joint).c_str(), crlb, known,
                pr(c.pnp_sqpnp).c_str(), pr(c.pnp_iterative).c_str(), pr(c.triangulation).c_str(),
                c.failures ? (" (" + std::to_string(c.failures) + " failed)").c_str() : "");
  }
  std::printf("\nFour views, the paper's two steps: position RMSE %.3f mm vs CRLB %.3f mm (ratio %.3f); rotation RMSE "
              "%.4f deg vs CRLB %.4f deg (ratio %.3f): %s 10%% of the bound.\n",
              all.ours.position_rmse_m * 1e3, all.crlb_position_m * 1e3, pos_ratio, all.ours.rotation_rmse_rad / kDeg,
              all.crlb_rotation_rad / kDeg, rot_ratio, pos_ratio <= 1.1 && rot_ratio <= 1.1 ? "within" : "NOT within");
  std::printf("Four views, joint (cameras refined under their calibration prior): position RMSE %.3f mm (ratio %.3f); "
              "rotation RMSE %.4f deg (ratio %.3f): %s 10%% of the bound.  (%.1f s)\n",
              all.ours_joint.position_rmse_m * 1e3, jpos_ratio, all.ours_joint.rotation_rmse_rad / kDeg, jrot_ratio,
              jpos_ratio <= 1.1 && jrot_ratio <= 1.1 ? "within" : "NOT within", elapsed_s);
  std::printf("The arm model is exact in these tables (no link-length error)%s.\n",
              arm_error ? "; with the arm-model error below" : "; --arm-error-mm adds one");
  if (a.seeds > 1) print_spread(runs, "Exact arm model");
  if (arm_error) {
    char title[96];
    std::snprintf(title, sizeof title, "Arm-model error (link lengths off by %.1f mm sd)", a.arm_error_mm);
    print_spread(arm_runs, title);
    const localization::ComboStats& w = arm_runs.front().combos.back();
    std::printf("Four views with the arm-model error (seed %u): position RMSE %.3f mm (bound without it %.3f mm), "
                "95%% alignment %.2f cm, depth %.2f cm.\n",
                a.seed, w.ours.position_rmse_m * 1e3, w.crlb_position_m * 1e3, w.ours.alignment95_m * 100,
                w.ours.depth95_m * 100);
  }
}

int run_eval(const EvalArgs& args) {
  const session::LocalizationStudyRequest& a = args.request;
  int last_shown = -1;
  const auto progress = [&](int done, int total) {  // a progress bar on stderr
    const int pct = 100 * done / total;
    if (pct == last_shown) return;
    last_shown = pct;
    const int width = 40, filled = width * done / total;
    std::fprintf(stderr, "\r[%s%s] %3d%%  trial %d/%d", std::string(filled, '#').c_str(),
                 std::string(width - filled, ' ').c_str(), pct, done, total);
    if (done == total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  };
  const session::LocalizationStudy study = session::study_localization(a, progress);
  if (args.json) {
    std::cout << session::localization_study_json(a, study).dump(2) << "\n";
    return kExitOk;
  }
  print_tables(a, study);
  return kExitOk;
}


std::function<int()> setup(Command& sub) {
  auto args = std::make_shared<EvalArgs>();
  session::LocalizationStudyRequest* a = &args->request;
  sub.require_subcommand(1);
  Command* loc = sub.add_subcommand("localization", "Monte Carlo localization accuracy (the paper's Tables 1-3)");
  loc->add_option("--trials", a->trials, "Monte Carlo trials")->capture_default_str();
  loc->add_option("--noise-px", a->noise_px, "click noise standard deviation (px)")->capture_default_str();
  loc->add_option("--seed", a->seed, "random seed (the first, with --seeds)")->capture_default_str();
  loc->add_option("--seeds", a->seeds, "repeat the study with this many seeds and report the spread")
      ->capture_default_str();
  loc->add_option("--arm-error-mm", a->arm_error_mm,
                  "also run it with an arm-model error: link lengths off by this standard deviation (mm)")
      ->capture_default_str();
  loc->add_option("--scene", a->scene, "scene (cameras, ORU pose)")->capture_default_str();
  loc->add_option("--object", a->object, "object model")->capture_default_str();
  loc->add_option("--robot", a->robot, "robot URDF (the calibration fixture)")->capture_default_str();
  loc->add_flag("--json", args->json, "print one JSON object");
  auto alignment = setup_eval_alignment(sub);
  auto insertion = setup_eval_insertion(sub);
  return [args, loc, alignment, insertion] {
    if (loc->parsed()) return run_eval(*args);
    if (const int rc = alignment(); rc >= 0) return rc;
    if (const int rc = insertion(); rc >= 0) return rc;
    throw std::invalid_argument("eval: choose a study (localization, alignment, insertion)");
  };
}

const bool registered = register_command({"eval", "accuracy studies (eval localization, eval alignment, eval insertion)", setup});

}  // namespace
}  // namespace foresight::cli
