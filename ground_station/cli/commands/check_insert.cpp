// foresight check-insert: the go/no-go before the insert. The probability
// that the insert, started at the tag from the object pose's estimate,
// ends with the tool in the hole: the tip's error (the pose's covariance
// through the hole, the arm's links and encoders) inside the insert's
// capture region (its spiral radius, the clearance, the tilt the rim takes,
// the axial window). docs/estimation.md "Go/no-go before contact".
//
//   foresight check-insert --object-pose localize.json [--cameras cameras.yaml]
//                          [--tag insert_start] [--hole-tag hole_entrance]
//                          [--min-p 0.99] [--depth-m 0.065] [--spiral-max-radius-m 0.005] [--json]
//
// --json: {p_success, lateral95_m, axial95_m, tilt95_deg, capture, verdict,
// advice, ...}. Exit: 0 go, 1 no_go, 2 bad input (a tag not in the object
// model, a pose without a covariance, a non-positive capture size, a
// threshold outside (0, 1)).

#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>

#include "command.hpp"
#include "foresight/common/format.hpp"
#include "foresight/session/insert_check.hpp"

namespace foresight::cli {
namespace {

struct CheckInsertArgs {
  session::CheckInsertRequest request;
  double min_p = std::nan("");  ///< NaN: ground.yaml's
  bool json = false;
};

int run_check_insert(CheckInsertArgs& args) {
  if (!std::isnan(args.min_p)) args.request.min_p_success = args.min_p;
  const session::InsertCheck c = session::check_insert(args.request);
  const contact_check::InsertPrediction& p = c.prediction;
  if (args.json) {
    std::cout << session::insert_check_json(c).dump(2) << "\n";
    return p.go ? kExitOk : kExitFailure;
  }
  std::printf("insert from '%s' into '%s': %s  P(success) %.4f (threshold %.4f)\n", c.step.tag.c_str(), c.step.hole_tag.c_str(),
              contact_check::verdict(p), p.p_success, p.min_p_success);
  std::printf("  lateral  95%% %6.2f mm  capture %5.2f mm          P %.4f\n", p.lateral95_m * 1e3, p.capture.lateral_m * 1e3,
              p.p_lateral);
  std::printf("  axial    95%% %6.2f mm  window [%.1f, %.1f] mm, start %.1f mm  P %.4f\n", p.axial95_m * 1e3,
              p.capture.axial_min_m * 1e3, p.capture.axial_max_m * 1e3, c.tip_error.mean[5] * 1e3, p.p_axial);
  std::printf("  tilt     95%% %6.2f deg capture %5.2f deg         P %.4f\n", p.tilt95_deg, p.capture.tilt_rad * 180.0 / M_PI,
              p.p_tilt);
  for (const std::string& a : c.advice) std::printf("  advice: %s\n", a.c_str());
  return p.go ? kExitOk : kExitFailure;
}

std::function<int()> setup(Command& sub) {
  auto args = std::make_shared<CheckInsertArgs>();
  session::CheckInsertRequest* r = &args->request;
  sub.add_option("--object-pose", r->object_pose, "the object pose with its covariance (localize --json)")->required();
  sub.add_option("--cameras", r->cameras, "cameras.yaml: the advice names the view that would help most");
  sub.add_option("--tag", r->step.tag, "where the approach ends and the insert starts")->capture_default_str();
  sub.add_option("--hole-tag", r->step.hole_tag, "the hole's frame (z along its axis)")->capture_default_str();
  sub.add_option("--min-p", args->min_p, "go when P(success) is at least this, in (0, 1) (default: ground.yaml's)");
  sub.add_option("--depth-m", r->step.params.depth_m, "the insert's depth_m")->capture_default_str();
  sub.add_option("--spiral-max-radius-m", r->step.params.spiral_max_radius_m, "the insert's spiral_max_radius_m")
      ->capture_default_str();
  sub.add_option("--object", r->object, "object model")->capture_default_str();
  sub.add_option("--robot", r->robot, "robot URDF")->capture_default_str();
  sub.add_option("--ground", r->ground, "ground.yaml (its contact_check section)")->capture_default_str();
  sub.add_flag("--json", args->json, "print one JSON object");
  return [args] { return run_check_insert(*args); };
}

const bool registered = register_command({"check-insert", "go/no-go: will the insert find the hole from this pose estimate?", setup});

}  // namespace
}  // namespace foresight::cli
