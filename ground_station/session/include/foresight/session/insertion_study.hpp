#pragma once
// `foresight eval insertion` (issue 30 item 5): is the go/no-go before the
// insert honest? A Monte Carlo over synthetic work sites: each trial draws a
// view subset (one to four of the scene's cameras), the click noise and the
// arm's true link-length errors; calibrates the cameras from the arm clicks
// (the ground's nominal arm model, its link sigma as belief), localizes the
// ORU, predicts the insert's success (contact_check) at the approach tag,
// and plans the approach (IK on the nominal model to the estimated tag).
// The true arm puts the tip at FK_true(q + encoder noise); that start,
// relative to the true hole, goes to the real insert: the controller's code
// on the simulated plant, `foresight-remote simulate-insertions` as a child
// process, one batch for all trials (the ground links no remote library).
// Not real-time code.

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "foresight/common/insert_capture.hpp"
#include "foresight/session/config_path.hpp"

namespace foresight::session {

struct InsertionStudyRequest {
  int trials = 400;
  std::int64_t seed = 1;
  double noise_px = 1.0;             ///< click noise (sd)
  double arm_error_mm = 0.2;         ///< the true arm's link-length errors (sd; the range's low end)
  double arm_sigma_mm = 2.0;         ///< the ground's belief of them (calibration, prediction) when not drawn
  /// > 0: work sites with arms known better and worse: each trial's link sd
  /// drawn log-uniform in [arm_error_mm, arm_error_max_mm], and the ground
  /// believes the drawn sd (arm_sigma_mm unused). 0: every arm off by
  /// arm_error_mm, believed arm_sigma_mm.
  double arm_error_max_mm = 2.0;
  double encoder_sigma_rad = 2e-5;   ///< the joints' encoder error (drawn, and believed)
  double min_p_success = 0.99;       ///< go when p_success >= this
  int bins = 10;                     ///< equal-width bins of p_predicted over [0, 1]
  double depth_m = 0.065;            ///< the insert's depth_m (from the stand-off; the tip ends 6 cm deep)
  double standoff_m = 0.005;         ///< the insert starts this far out of the hole, along its axis
  std::string hole_tag = "hole_entrance";  ///< the hole's frame (z along its axis; the runner's tag)
  std::string scene = default_config("scene.yaml");
  std::string object = default_config("oru.yaml");
  std::string robot = default_config("robot.urdf");
  std::string remote;                ///< foresight-remote ("": the one beside this executable)
  std::string work_dir;              ///< the batch and its output ("": a fresh directory under /tmp, removed)
};

/// One trial: what the ground predicted, what the plant did.
struct InsertionTrialRecord {
  int id = 0;
  std::vector<int> views;            ///< 0-based scene camera indices
  double arm_error_mm = 0.0;         ///< the arm's link-length sd this trial (true and believed)
  double p_success = 0.0, p_lateral = 0.0, p_tilt = 0.0, p_axial = 0.0;
  double lateral95_m = 0.0, axial95_m = 0.0, tilt95_deg = 0.0;
  bool go = false;
  /// Diagnostics: the same Gaussian's joint mass in the capture region by
  /// sampling (the cross terms kept), and whether the true start is in it.
  double p_joint = 0.0;
  bool in_capture = false;
  /// The true start relative to the true hole: lateral |x, y|, axial z,
  /// tilt of the tool axis to the hole axis.
  double true_lateral_m = 0.0, true_axial_m = 0.0, true_tilt_deg = 0.0;
  /// Mahalanobis^2 of the true start's error about the predicted mean under
  /// the predicted covariance: lateral (x, y), tilt, axial, all six
  /// (2, 2, 1, 6 on average when the covariance is honest).
  double m2_lateral = 0.0, m2_tilt = 0.0, m2_axial = 0.0, m2_all = 0.0;
  double estimate_position_error_m = 0.0;  ///< |ORU position estimate - truth|
  double link_error_rms_m = 0.0;           ///< the trial's true arm
  int redrawn = 0;                         ///< draws discarded before this one (calibration or localization failed)
  // The plant's outcome (simulate-insertions):
  bool success = false, completed = false, in_hole = false, searched = false;
  std::string reason;
  double peak_force_n = 0.0, sim_s = 0.0;
};

struct InsertionBin {
  double lo = 0.0, hi = 0.0;         ///< p_predicted range [lo, hi) (the last bin includes 1)
  int n = 0;
  double p_predicted = 0.0;          ///< mean p_success in the bin
  double observed_success = 0.0;     ///< successes / n
  double se = 0.0;                   ///< the binomial standard error sqrt(p (1 - p) / n) at p_predicted
  double p_joint = 0.0;              ///< mean InsertionTrialRecord::p_joint
  double in_capture = 0.0;           ///< the fraction of true starts in the capture region
};

struct InsertionStudy {
  std::vector<InsertionTrialRecord> records;
  InsertCapture capture;
  std::vector<InsertionBin> bins;    ///< the non-empty ones
  double brier = 0.0;
  int go = 0, go_failures = 0, no_go = 0, no_go_failures = 0;
  double go_failure_rate = 0.0;      ///< go_failures / go (0 without a go)
  double no_go_precision = 0.0;      ///< no_go_failures / no_go (0 without a no-go)
  double success_rate = 0.0, mean_p_success = 0.0;
  int redrawn = 0;
  double ground_s = 0.0, plant_s = 0.0, plant_compute_s = 0.0;
};

/// Runs the study. `progress(done, total)` over the ground's trials; the
/// plant's batch follows. std::invalid_argument naming the option for bad
/// input (--trials below 1 or above 10000, --seed negative, ...);
/// ComputationError when the runner fails or a trial cannot be drawn.
InsertionStudy study_insertion(const InsertionStudyRequest& request,
                               const std::function<void(int done, int total)>& progress = {});

/// `foresight eval insertion --json`'s object: {trials, bins: [{p_predicted,
/// observed_success, n, ...}], brier, no_go_precision, go_failure_rate,
/// targets, ..., trial_records}.
nlohmann::json insertion_study_json(const InsertionStudyRequest& request, const InsertionStudy& study);

}  // namespace foresight::session
