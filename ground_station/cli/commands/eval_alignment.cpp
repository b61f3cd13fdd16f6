// foresight eval alignment: the Monte Carlo of clicks alone vs clicks +
// model-to-image alignment (issue 16), beside `eval localization`.
//
//   foresight eval alignment [--trials N] [--noise-px S] [--seed K] [--arm-error-mm E]
//                            [--arm-prior-mm P] [--sensor-noise-dn D] [--blur-px B] [--gl osmesa|egl]
//                            [--scene config/scene.yaml] [--object config/oru.yaml]
//                            [--robot config/robot.urdf] [--json]
//
// Synthetic frames from the synthetic camera (shading, anti-aliasing, blur,
// sensor noise) of the true arm, whose link lengths are off by E mm (sd) from
// the model the ground uses. See foresight/align/alignment_study.hpp. The
// `alignment` subcommand is attached to `eval` by eval.cpp through
// setup_eval_alignment (one registration per top-level command).

#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/session/operations.hpp"

namespace foresight::cli {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct EvalAlignmentArgs {
  session::AlignmentStudyRequest request;
  bool json = false;
};

int run_eval_alignment(const EvalAlignmentArgs& args) {
  const session::AlignmentStudyRequest& a = args.request;
  const auto progress = [](int done, int total) {  // a progress bar on stderr
    const int width = 40, filled = width * done / total;
    std::fprintf(stderr, "\r[%s%s] trial %d/%d", std::string(filled, '#').c_str(),
                 std::string(width - filled, ' ').c_str(), done, total);
    if (done == total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  };
  const session::AlignmentStudySummary s = session::study_alignment(a, progress);
  if (args.json) {
    std::cout << session::alignment_study_json(a, s).dump(2) << "\n";
    return kExitOk;
  }
  const align::AlignmentStudyResult& r = s.result;
  const align::AlignmentComboStats& all = r.combos.back();
  const double four_ratio = s.four_view_ratio, depth_ratio = s.single_view_depth_ratio;
  const double four_ratio_cam_only = s.four_view_ratio_cameras_only;
  const double depth_ratio_cam_only = s.single_view_depth_ratio_cameras_only;
  const double single_clicks_depth = s.single_clicks_depth_m, single_aligned_depth = s.single_aligned_depth_m;
  const double single_cam_only_depth = s.single_cameras_only_depth_m;
  std::printf("Alignment accuracy: %d trials, %.2f px click noise, arm-model error %.1f mm (link lengths, sd) in the "
              "rendered truth, sensor noise %.1f DN, blur %.2f px; errors in the ORU frame\n",
              r.trials, r.noise_px, a.arm_error_mm, a.sensor_noise_dn, a.blur_px);
  for (std::size_t v = 0; v < r.view_names.size(); ++v)
    std::printf("  view %zu %-14s %d frames; camera vs truth %.2f px by clicks, %.2f px aligned (%d refused), %.2f px "
                "with the arm refined\n",
                v + 1, r.view_names[v].c_str(), r.frames[v], r.camera_clicks_px[v], r.camera_aligned_px[v],
                r.camera_refused[v], r.camera_bundle_px[v]);
  std::printf("  arm link lengths (cameras + arm, prior %.1f mm; %d refused): true error %.2f mm rms, estimate's error "
              "%.2f mm rms\n",
              a.arm_prior_mm, r.bundle_refused, r.link_true_rms_all_m * 1e3, r.link_estimate_error_rms_all_m * 1e3);
  if (r.calibration_failures) std::printf("  %d trials skipped: a calibration failed\n", r.calibration_failures);
  std::printf("\n%-9s %28s %28s %9s %s\n", "views", "clicks: mm / deg / 95% cm", "aligned: mm / deg / 95% cm", "refused",
              "(of which the ORU moved beyond the clicks' uncertainty)");
  for (const auto& c : r.combos) {
    char cl[64], al[64];
    std::snprintf(cl, sizeof cl, "%6.2f / %6.3f / %5.3f", c.clicks.position_rmse_m * 1e3, c.clicks.rotation_rmse_rad / kDeg,
                  c.clicks.alignment95_m * 100);
    std::snprintf(al, sizeof al, "%6.2f / %6.3f / %5.3f", c.aligned.position_rmse_m * 1e3,
                  c.aligned.rotation_rmse_rad / kDeg, c.aligned.alignment95_m * 100);
    std::printf("%-9s %28s %28s %9d (%d)\n", c.label.c_str(), cl, al, c.aligned_refused, c.aligned_refused_disagreement);
  }
  std::printf("\nFour views: 95%% alignment %.3f cm by clicks, %.3f cm aligned (%.2fx lower). Single views: mean 95%% "
              "depth %.3f cm by clicks, %.3f cm aligned (%.2fx lower).  (%.1f s)\n",
              all.clicks.alignment95_m * 100, all.aligned.alignment95_m * 100, four_ratio, single_clicks_depth * 100,
              single_aligned_depth * 100, depth_ratio, r.elapsed_s);
  std::printf("Four views with the cameras held (not refined with the ORU): %.3f cm (%.2fx)\n",
              all.aligned_held_cameras.alignment95_m * 100,
              s.four_view_ratio_held_cameras);
  std::printf("Cameras aligned to the nominal arm only: four views %.3f cm (%.2fx), single-view depth %.3f cm (%.2fx)\n",
              all.aligned_cameras_only.alignment95_m * 100, four_ratio_cam_only, single_cam_only_depth * 100,
              depth_ratio_cam_only);
  int accepted = 0, within = 0;
  double z2 = 0.0;
  for (const auto& c : r.combos) {
    accepted += c.aligned_accepted;
    within += c.aligned_within_3_sigma;
    z2 += c.aligned_mahalanobis2_mean * c.aligned_accepted;
  }
  std::printf("Claims: %d of %d accepted ORU alignments within 3 sigma on every axis; mean Mahalanobis^2 of the position "
              "error %.2f (3 when honest)\n",
              within, accepted, accepted > 0 ? z2 / accepted : 0.0);
  return kExitOk;
}

}  // namespace

std::function<int()> setup_eval_alignment(Command& eval) {
  auto args = std::make_shared<EvalAlignmentArgs>();
  session::AlignmentStudyRequest* a = &args->request;
  Command* sub = eval.add_subcommand("alignment", "Monte Carlo: clicks alone vs clicks + model-to-image alignment");
  sub->add_option("--trials", a->trials, "Monte Carlo trials (seconds each)")->capture_default_str();
  sub->add_option("--noise-px", a->noise_px, "click noise standard deviation (px)")->capture_default_str();
  sub->add_option("--seed", a->seed, "random seed")->capture_default_str();
  sub->add_option("--arm-error-mm", a->arm_error_mm, "link-length error of the rendered true arm (mm, sd)")
      ->capture_default_str();
  sub->add_option("--arm-prior-mm", a->arm_prior_mm,
                  "prior sd of the arm's link lengths refined with the cameras (mm; 0: the nominal arm)")
      ->capture_default_str();
  sub->add_option("--sensor-noise-dn", a->sensor_noise_dn, "synthetic camera sensor noise (digital numbers)")
      ->capture_default_str();
  sub->add_option("--blur-px", a->blur_px, "synthetic camera blur (px)")->capture_default_str();
  sub->add_option("--gl", a->gl, "GL back end: osmesa | egl")->capture_default_str();
  sub->add_option("--scene", a->scene, "scene (cameras, ORU pose)")->capture_default_str();
  sub->add_option("--object", a->object, "object model")->capture_default_str();
  sub->add_option("--robot", a->robot, "robot URDF")->capture_default_str();
  sub->add_flag("--json", args->json, "print one JSON object");
  return [args, sub]() -> int { return sub->parsed() ? run_eval_alignment(*args) : -1; };
}

}  // namespace foresight::cli
