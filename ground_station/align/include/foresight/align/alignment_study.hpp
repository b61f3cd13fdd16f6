#pragma once
// The alignment accuracy study (`foresight eval alignment`, issue 16): a
// Monte Carlo beside the localization study (foresight/localization/
// accuracy_study.hpp) on the same synthetic four-camera ORU scene, comparing
// clicks alone with clicks + model-to-image alignment.
//
// Each trial:
//  1. The true arm: every non-zero link offset of the nominal arm off by a
//     Gaussian of `arm_link_error_m` (the rendered truth); the ground believes
//     the nominal arm (clicks' 3-D points and the aligner's model).
//  2. Clicks: every camera calibrated from noisy clicks on the true arm at the
//     calibration poses (arm_calibration_poses), its covariance carrying the
//     arm model's arm_link_prior_m (CalibrationOptions::arm_link_sigma_m), the
//     ORU localized from noisy clicks for every view combination: the
//     "clicks" result.
//  3. Synthetic frames of the true arm at each calibration pose that a camera
//     sees (SyntheticCamera: shading, anti-aliasing, blur, sensor noise).
//  4. Each camera refined by alignment of the nominal arm to its frames
//     (Refine::Camera, the clicks' camera as the start, the 4-view clicks ORU
//     for occlusion); a refused alignment keeps the clicks camera.
//  5. The arm self-calibration (arm_link_prior_m > 0): one bundle
//     adjustment over every camera whose step-4 alignment held and all their
//     frames, refining the cameras and the arm's link lengths together
//     (AlignOptions::arm_link_prior_m, the prior sd), so the cameras are no
//     longer aligned to the wrong model arm; refused: the step-4 cameras.
//  6. Per view combination the ORU pose refined by alignment over those views
//     at once (the combination's clicks pose as the start), the "aligned"
//     result: a bundle adjustment of the ORU, the combination's cameras and
//     the arm's link lengths together over the views' frames (Refine::Both,
//     from the step-5 cameras and arm, the link prior around step 5's
//     estimate): the ORU's edges tie each camera to where the ORU is, and
//     with several views the cameras to each other. Only the combination's
//     own views and frames enter (the links' start comes from every
//     camera's arm edges, step 5, never from another view's ORU). Beside
//     it, for comparison: the ORU alone with the step-5 cameras held
//     ("aligned_held_cameras") and with the step-4 cameras and the nominal
//     arm held ("aligned_cameras_only"). A refused alignment keeps the
//     clicks pose (and is counted).
// Errors in the ORU frame as the localization study (x, y, z, theta; the
// paper's 95% alignment |mu_xy| + 2 sigma_xy and depth |mu_z| + 2 sigma_z).
//
// Each ORU alignment is given the clicks' pose covariance (the two-step
// pose's: the clicks' noise, the held cameras' calibration noise
// (LocalizationOptions::camera_covariance) and the arm model's error, which
// the cameras share (camera_link_sensitivity, arm_link_prior_m)) and is
// refused when it moves or turns further than 5 sigma from the clicks
// (AlignOptions::object_start_covariance).
// Diagnostics on stderr: FORESIGHT_STUDY_TRACE=1 prints one line per ORU
// alignment (status, reason, errors, scores, the move in sigmas, sds);
// FORESIGHT_STUDY_DUMP=K prints trial K's inputs at full precision (true
// and estimated link errors, the synthetic camera's seed, the cameras, the
// single-view clicks poses and covariances): how test_align's seed-2 and
// seed-11 cases were taken. The trace also prints, per combination, the
// clicks' own error in sigmas of their covariance (HONEST lines).
//
// Not real-time code: renders, allocates; seconds per trial.

#include <functional>
#include <string>
#include <vector>

#include "foresight/common/object_model.hpp"
#include "foresight/common/robot_model.hpp"
#include "foresight/common/scene.hpp"
#include "foresight/localization/accuracy_study.hpp"
#include "foresight/render/gl_context.hpp"

namespace foresight::align {

struct AlignmentStudyOptions {
  int trials = 20;
  double noise_px = 1.0;             ///< click noise sd (px)
  unsigned seed = 1;
  double arm_link_error_m = 0.002;   ///< link-length error sd of the rendered true arm (m)
  double sensor_noise_dn = 2.0;      ///< synthetic camera sensor noise (digital numbers)
  double blur_px = 0.6;              ///< synthetic camera optical blur (px)
  double arm_link_prior_m = 0.002;   ///< step 5's link-length prior sd (m); 0: no arm refinement
  std::function<void(int, int)> progress;  ///< (done, total) after each trial
};

struct AlignmentComboStats {
  std::vector<int> views;  ///< 0-based
  std::string label;       ///< "1+2+3+4"
  localization::ErrorStats clicks;       ///< clicks alone (calibrate, then localize)
  localization::ErrorStats aligned;      ///< clicks + alignment (cameras and arm, then the ORU over the views)
  localization::ErrorStats aligned_held_cameras;  ///< the ORU alone, the step-5 cameras held
  localization::ErrorStats aligned_cameras_only;  ///< the cameras aligned to the nominal arm (no step 5)
  int clicks_failures = 0;
  int aligned_refused = 0;  ///< trials where the ORU alignment refused (clicks pose kept)
  /// of which: the ORU moved or turned from the clicks pose beyond the
  /// clicks' and the alignment's pose uncertainty (AlignOptions::
  /// object_start_covariance, the clicks' covariance)
  int aligned_refused_disagreement = 0;
  int aligned_cameras_only_refused = 0;
  int aligned_held_cameras_refused = 0;
  /// The accepted ORU alignments' claims: how many there were, how many
  /// have their position error within 3 sigma on every base axis, and the
  /// mean of the squared Mahalanobis distance of the position error in the
  /// claimed position covariance (3 when the claims are honest).
  int aligned_accepted = 0;
  int aligned_within_3_sigma = 0;
  double aligned_mahalanobis2_mean = 0.0;
};

struct AlignmentStudyResult {
  std::vector<std::string> view_names;
  std::vector<int> frames;  ///< per view: synthetic frames (arm poses) used
  std::vector<AlignmentComboStats> combos;  ///< all non-empty view subsets, by size then index
  /// Per view: RMS reprojection difference to the true camera over the
  /// ORU's corners and the link origins at the calibration poses (px), mean
  /// over trials, for the clicks camera and the aligned one.
  std::vector<double> camera_clicks_px, camera_aligned_px;
  std::vector<int> camera_refused;  ///< per view, trials where the camera alignment refused
  std::vector<double> camera_bundle_px;  ///< per view, after step 5 (cameras + arm)
  int bundle_refused = 0;                ///< trials where step 5 refused
  /// Step 5's link lengths against the truth, per chain segment with an
  /// offset (`link_segments`, chain indices): RMS over trials of the true
  /// error (what the nominal model is off by) and of the estimate's error
  /// (estimate - truth), and the mean reported sd; all links pooled too.
  std::vector<int> link_segments;
  std::vector<double> link_true_rms_m, link_estimate_error_rms_m, link_sigma_mean_m;
  double link_true_rms_all_m = 0.0, link_estimate_error_rms_all_m = 0.0;
  int trials = 0;
  int calibration_failures = 0;
  double noise_px = 0.0;
  double arm_link_error_m = 0.0;
  double elapsed_s = 0.0;
};

/// Throws InputError on trials < 1 or a non-positive/non-finite noise; the
/// errors of the set-up (IK, GL) propagate.
AlignmentStudyResult run_alignment_study(render::GlContext& context, const RobotModel& robot,
                                         const ObjectModel& object, const Scene& scene,
                                         const AlignmentStudyOptions& options);

}  // namespace foresight::align
