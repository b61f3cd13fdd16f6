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
#include "foresight/align/alignment_study.hpp"
#include "foresight/render/overlay_inputs.hpp"
#include "foresight/common/json_text.hpp"
#include "foresight/common/number_list.hpp"
#include "foresight/localization/pose_json.hpp"

namespace foresight::cli {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct EvalAlignmentArgs {
  int trials = 20;
  double noise_px = 1.0;
  unsigned seed = 1;
  double arm_error_mm = 2.0;
  double arm_prior_mm = 2.0;
  double sensor_noise_dn = 2.0;
  double blur_px = 0.6;
  std::string gl = "osmesa";
  std::string scene = default_config("scene.yaml");
  std::string object = default_config("oru.yaml");
  std::string robot = default_config("robot.urdf");
  bool json = false;
};

nlohmann::json summary_json(const ErrorStats& s) {
  return {{"n", s.n},
          {"position_rmse_m", s.position_rmse_m},
          {"rotation_rmse_deg", s.rotation_rmse_rad / kDeg},
          {"alignment95_m", s.alignment95_m},
          {"depth95_m", s.depth95_m},
          {"mean_m", vec_json(s.mean.head<3>())},
          {"sd_m", vec_json(s.sd.head<3>())}};
}

int run_eval_alignment(const EvalAlignmentArgs& a) {
  if (a.trials < 1) throw std::invalid_argument("--trials must be at least 1");
  if (!(a.noise_px > 0.0) || !std::isfinite(a.noise_px)) throw std::invalid_argument("--noise-px must be a positive number");
  if (!(a.arm_error_mm >= 0.0) || !std::isfinite(a.arm_error_mm))
    throw std::invalid_argument("--arm-error-mm must be a non-negative number");
  if (!(a.arm_prior_mm >= 0.0) || !std::isfinite(a.arm_prior_mm))
    throw std::invalid_argument("--arm-prior-mm must be a non-negative number");
  if (!(a.sensor_noise_dn >= 0.0) || !std::isfinite(a.sensor_noise_dn))
    throw std::invalid_argument("--sensor-noise-dn must be a non-negative number");
  if (!(a.blur_px >= 0.0) || !std::isfinite(a.blur_px)) throw std::invalid_argument("--blur-px must be a non-negative number");
  const render::GlBackend backend = render::parse_gl_backend(a.gl);
  const Scene scene = Scene::from_file(a.scene);
  const ObjectModel object = ObjectModel::from_file(a.object);
  const RobotModel robot = RobotModel::from_file(a.robot);
  auto context = render::GlContext::create(backend);

  align::AlignmentStudyOptions o;
  o.trials = a.trials;
  o.noise_px = a.noise_px;
  o.seed = a.seed;
  o.arm_link_error_m = a.arm_error_mm * 1e-3;
  o.arm_link_prior_m = a.arm_prior_mm * 1e-3;
  o.sensor_noise_dn = a.sensor_noise_dn;
  o.blur_px = a.blur_px;
  o.progress = [](int done, int total) {
    const int width = 40, filled = width * done / total;
    std::fprintf(stderr, "\r[%s%s] trial %d/%d", std::string(filled, '#').c_str(),
                 std::string(width - filled, ' ').c_str(), done, total);
    if (done == total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  };
  const align::AlignmentStudyResult r = align::run_alignment_study(*context, robot, object, scene, o);
  const align::AlignmentComboStats& all = r.combos.back();
  double single_clicks_depth = 0.0, single_aligned_depth = 0.0, single_cam_only_depth = 0.0;
  int singles = 0;
  for (const auto& c : r.combos)
    if (c.views.size() == 1) {
      single_clicks_depth += c.clicks.depth95_m;
      single_aligned_depth += c.aligned.depth95_m;
      single_cam_only_depth += c.aligned_cameras_only.depth95_m;
      ++singles;
    }
  single_clicks_depth /= std::max(1, singles);
  single_aligned_depth /= std::max(1, singles);
  single_cam_only_depth /= std::max(1, singles);
  const double four_ratio = all.aligned.alignment95_m > 0 ? all.clicks.alignment95_m / all.aligned.alignment95_m : 0.0;
  const double depth_ratio = single_aligned_depth > 0 ? single_clicks_depth / single_aligned_depth : 0.0;
  const double four_ratio_cam_only = all.aligned_cameras_only.alignment95_m > 0
                                         ? all.clicks.alignment95_m / all.aligned_cameras_only.alignment95_m
                                         : 0.0;
  const double depth_ratio_cam_only = single_cam_only_depth > 0 ? single_clicks_depth / single_cam_only_depth : 0.0;

  if (a.json) {
    nlohmann::json views = nlohmann::json::array();
    for (std::size_t v = 0; v < r.view_names.size(); ++v)
      views.push_back({{"index", v + 1},
                       {"name", r.view_names[v]},
                       {"frames", r.frames[v]},
                       {"camera_clicks_px", r.camera_clicks_px[v]},
                       {"camera_aligned_px", r.camera_aligned_px[v]},
                       {"camera_bundle_px", r.camera_bundle_px[v]},
                       {"camera_refused", r.camera_refused[v]}});
    nlohmann::json combos = nlohmann::json::array();
    for (const auto& c : r.combos)
      combos.push_back({{"views", c.label},
                        {"clicks", summary_json(c.clicks)},
                        {"aligned", summary_json(c.aligned)},
                        {"aligned_held_cameras", summary_json(c.aligned_held_cameras)},
                        {"aligned_cameras_only", summary_json(c.aligned_cameras_only)},
                        {"clicks_failures", c.clicks_failures},
                        {"aligned_refused", c.aligned_refused},
                        {"aligned_refused_disagreement", c.aligned_refused_disagreement},
                        {"aligned_cameras_only_refused", c.aligned_cameras_only_refused},
                        {"aligned_held_cameras_refused", c.aligned_held_cameras_refused},
                        {"aligned_accepted", c.aligned_accepted},
                        {"aligned_within_3_sigma", c.aligned_within_3_sigma},
                        {"aligned_mahalanobis2_mean", c.aligned_mahalanobis2_mean}});
    nlohmann::json links = nlohmann::json::array();
    for (std::size_t j = 0; j < r.link_segments.size(); ++j)
      links.push_back({{"segment", r.link_segments[j]},
                       {"true_rms_m", r.link_true_rms_m[j]},
                       {"estimate_error_rms_m", r.link_estimate_error_rms_m[j]},
                       {"sigma_mean_m", r.link_sigma_mean_m[j]}});
    const nlohmann::json j = {{"study", "alignment"},
                              {"trials", r.trials},
                              {"noise_px", r.noise_px},
                              {"seed", a.seed},
                              {"arm_error_mm", a.arm_error_mm},
                              {"sensor_noise_dn", a.sensor_noise_dn},
                              {"blur_px", a.blur_px},
                              {"calibration_failures", r.calibration_failures},
                              {"elapsed_s", r.elapsed_s},
                              {"frame", "oru (z along the hole axis)"},
                              {"views", views},
                              {"combinations", combos},
                              {"arm_prior_mm", a.arm_prior_mm},
                              {"bundle_refused", r.bundle_refused},
                              {"arm_links", links},
                              {"arm_link_true_rms_m", r.link_true_rms_all_m},
                              {"arm_link_estimate_error_rms_m", r.link_estimate_error_rms_all_m},
                              {"four_view_alignment95_ratio", four_ratio},
                              {"single_view_depth95_ratio", depth_ratio},
                              {"four_view_alignment95_ratio_held_cameras",
                               all.aligned_held_cameras.alignment95_m > 0
                                   ? all.clicks.alignment95_m / all.aligned_held_cameras.alignment95_m
                                   : 0.0},
                              {"four_view_alignment95_ratio_cameras_only", four_ratio_cam_only},
                              {"single_view_depth95_ratio_cameras_only", depth_ratio_cam_only}};
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }

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
              all.aligned_held_cameras.alignment95_m > 0 ? all.clicks.alignment95_m / all.aligned_held_cameras.alignment95_m
                                                         : 0.0);
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
  auto a = std::make_shared<EvalAlignmentArgs>();
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
  sub->add_flag("--json", a->json, "print one JSON object");
  return [a, sub]() -> int { return sub->parsed() ? run_eval_alignment(*a) : -1; };
}

}  // namespace foresight::cli
