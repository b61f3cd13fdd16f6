// foresight eval insertion: is the go/no-go before the insert honest?
// (issue 30 item 5)
//
//   foresight eval insertion [--trials N] [--seed K] [--noise-px S] [--arm-error-mm E] [--arm-error-max-mm M]
//                            [--arm-sigma-mm B] [--encoder-sigma-rad R] [--min-p P] [--bins M]
//                            [--scene F] [--object F] [--robot F] [--remote PATH] [--work-dir DIR] [--json]
//
// Monte Carlo over synthetic work sites (a view subset of one to four
// cameras, click noise, the arm's true link errors): clicks, calibration,
// localization, the prediction (contact_check), then the real insert on the
// simulated plant (`foresight-remote simulate-insertions`, a child process,
// one batch). See foresight/session/insertion_study.hpp. The `insertion`
// subcommand is attached to `eval` by eval.cpp through setup_eval_insertion.

#include <cmath>
#include <cstdio>
#include <iostream>

#include "command.hpp"
#include "foresight/session/insertion_study.hpp"

namespace foresight::cli {
namespace {

struct EvalInsertionArgs {
  session::InsertionStudyRequest request;
  bool json = false;
};

int run_eval_insertion(const EvalInsertionArgs& args) {
  const session::InsertionStudyRequest& a = args.request;
  const auto progress = [](int done, int total) {  // a progress bar on stderr
    const int width = 40, filled = width * done / total;
    std::fprintf(stderr, "\r[%s%s] trial %d/%d", std::string(filled, '#').c_str(),
                 std::string(width - filled, ' ').c_str(), done, total);
    if (done == total) std::fprintf(stderr, "\n  the insertions on the simulated plant (foresight-remote simulate-insertions) ...\n");
    std::fflush(stderr);
  };
  const session::InsertionStudy s = session::study_insertion(a, progress);
  const nlohmann::json j = session::insertion_study_json(a, s);
  if (args.json) {
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  std::printf("Insertion go/no-go: %zu trials (seed %lld), click noise %.2f px, arm links %.1f mm sd (believed %.1f), "
              "insert depth %.3f m from a %.1f mm stand-off; capture: lateral %.2f mm, tilt %.2f deg, axial [%.1f, %.1f] mm\n",
              s.records.size(), static_cast<long long>(a.seed), a.noise_px, a.arm_error_mm, a.arm_sigma_mm, a.depth_m,
              a.standoff_m * 1e3, s.capture.lateral_m * 1e3, s.capture.tilt_rad * 180.0 / M_PI, s.capture.axial_min_m * 1e3,
              s.capture.axial_max_m * 1e3);
  std::printf("\n%-13s %5s %12s %10s %9s\n", "p range", "n", "p_predicted", "observed", "+-1 se");
  for (const auto& b : s.bins)
    std::printf("[%.2f, %.2f%c %5d %12.3f %10.3f %9.3f%s\n", b.lo, b.hi, b.hi >= 1.0 ? ']' : ')', b.n, b.p_predicted,
                b.observed_success, b.se, b.n >= 20 && std::abs(b.p_predicted - b.observed_success) > 0.05 ? "  (off by > 0.05)" : "");
  std::printf("\nBrier %.4f; success %.3f observed, %.3f predicted on average\n", s.brier, s.success_rate, s.mean_p_success);
  std::printf("go (p >= %.2f): %d trials, %d failed (go_failure_rate %.3f; target <= 0.01)\n", a.min_p_success, s.go,
              s.go_failures, s.go_failure_rate);
  std::printf("no_go: %d trials, %d would have failed (no_go_precision %.3f; target >= 0.5)\n", s.no_go, s.no_go_failures,
              s.no_go_precision);
  const auto& t = j["targets"];
  std::printf("targets: bins %s, go %s, no_go %s   (ground %.1f s, plant %.1f s)\n",
              t["bins_within_0_05"]["met"].get<bool>() ? "met" : "NOT met",
              t["go_failure_rate_at_most_0_01"]["met"].get<bool>() ? "met" : "NOT met",
              t["no_go_precision_at_least_0_5"]["met"].get<bool>() ? "met" : "NOT met", s.ground_s, s.plant_s);
  return kExitOk;
}

}  // namespace

std::function<int()> setup_eval_insertion(Command& eval) {
  auto args = std::make_shared<EvalInsertionArgs>();
  session::InsertionStudyRequest* a = &args->request;
  Command* sub = eval.add_subcommand("insertion", "Monte Carlo: the insert's predicted success against the simulated plant");
  sub->add_option("--trials", a->trials, "Monte Carlo trials (one insertion each)")->capture_default_str();
  sub->add_option("--seed", a->seed, "random seed (non-negative)")->capture_default_str();
  sub->add_option("--noise-px", a->noise_px, "click noise standard deviation (px)")->capture_default_str();
  sub->add_option("--arm-error-mm", a->arm_error_mm, "the true arm's link-length errors (mm, sd)")->capture_default_str();
  sub->add_option("--arm-error-max-mm", a->arm_error_max_mm,
                  "> 0: each trial's link sd drawn log-uniform in [--arm-error-mm, this], believed as drawn")
      ->capture_default_str();
  sub->add_option("--arm-sigma-mm", a->arm_sigma_mm, "the ground's belief of them (mm, sd; calibration and prediction)")
      ->capture_default_str();
  sub->add_option("--encoder-sigma-rad", a->encoder_sigma_rad, "the joints' encoder error (rad, sd)")->capture_default_str();
  sub->add_option("--min-p", a->min_p_success, "go when the predicted success is at least this")->capture_default_str();
  sub->add_option("--bins", a->bins, "equal-width bins of the predicted success")->capture_default_str();
  sub->add_option("--scene", a->scene, "scene (cameras, ORU pose)")->capture_default_str();
  sub->add_option("--object", a->object, "object model")->capture_default_str();
  sub->add_option("--robot", a->robot, "robot URDF")->capture_default_str();
  sub->add_option("--remote", a->remote, "foresight-remote (default: beside this executable)");
  sub->add_option("--work-dir", a->work_dir, "keep the batch and the plant's output here (default: a temporary directory)");
  sub->add_flag("--json", args->json, "print one JSON object");
  return [args, sub]() -> int { return sub->parsed() ? run_eval_insertion(*args) : -1; };
}

}  // namespace foresight::cli
