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
//     calibration poses (arm_calibration_poses), the ORU localized from noisy
//     clicks for every view combination: the "clicks" result.
//  3. Synthetic frames of the true arm at each calibration pose that a camera
//     sees (SyntheticCamera: shading, anti-aliasing, blur, sensor noise).
//  4. Each camera refined by alignment of the nominal arm to its frames
//     (Refine::Camera, the clicks' camera as the start, the 4-view clicks ORU
//     for occlusion); a refused alignment keeps the clicks camera.
//  5. Per view combination the ORU pose refined by alignment over those views
//     at once (Refine::Object, the arm-refined cameras, the combination's
//     clicks pose as the start): the "aligned" result; a refused alignment
//     keeps the clicks pose (and is counted).
// Errors in the ORU frame as the localization study (x, y, z, theta; the
// paper's 95% alignment |mu_xy| + 2 sigma_xy and depth |mu_z| + 2 sigma_z).
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
  std::function<void(int, int)> progress;  ///< (done, total) after each trial
};

struct AlignmentComboStats {
  std::vector<int> views;  ///< 0-based
  std::string label;       ///< "1+2+3+4"
  ErrorStats clicks;       ///< clicks alone (calibrate, then localize)
  ErrorStats aligned;      ///< clicks + alignment (cameras, then the ORU over the views)
  int clicks_failures = 0;
  int aligned_refused = 0;  ///< trials where the ORU alignment refused (clicks pose kept)
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
