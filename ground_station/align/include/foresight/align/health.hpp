#pragma once
// Calibration health (issue 16): per video frame, how well the reported arm's
// model edges match the image through the calibrated camera
// (ModelAligner::score: the fraction of visible edge samples within 1 px of an
// image edge, and the truncated edge distance), and a warning when the camera
// has moved or zoomed: after a baseline of the first frames (their median),
// `consecutive` frames in a row whose matched fraction falls by more than
// `fraction_drop` below the baseline, or whose edge distance rises by more
// than `score_rise_px` above it. A 0.3 deg bump moves the image ~3.5 px at
// f = 700 px, far outside the 1 px band, so the fraction collapses.
//
// Not real-time code (the scoring renders); update() itself is cheap.

#include <string>
#include <vector>

#include "foresight/align/model_aligner.hpp"

namespace foresight::align {

struct HealthOptions {
  int baseline_frames = 5;
  double fraction_drop = 0.25;
  double score_rise_px = 1.5;
  int consecutive = 2;
};

struct HealthVerdict {
  int frame = 0;
  double matched_fraction = 0.0;
  double score_px = 0.0;
  bool in_baseline = true;  ///< still collecting the baseline
  bool bad = false;         ///< this frame is outside the band
  bool warning = false;     ///< `consecutive` bad frames in a row: the camera moved or zoomed
  std::string reason;
};

class HealthMonitor {
 public:
  explicit HealthMonitor(const HealthOptions& options = {}) : o_(options) {}
  /// The verdict for the next frame's score.
  HealthVerdict update(const ModelAligner::FrameScore& score);
  double baseline_fraction() const { return baseline_fraction_; }
  double baseline_score_px() const { return baseline_score_; }

 private:
  HealthOptions o_;
  std::vector<double> fractions_, scores_;
  double baseline_fraction_ = 0.0, baseline_score_ = 0.0;
  int frame_ = 0, bad_run_ = 0, first_bad_ = -1;
};

}  // namespace foresight::align
