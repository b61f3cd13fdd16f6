#include "foresight/align/health.hpp"

#include <algorithm>
#include <cstdio>

namespace foresight::align {

namespace {
double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}
}  // namespace

HealthVerdict HealthMonitor::update(const ModelAligner::FrameScore& s) {
  HealthVerdict v;
  v.frame = frame_++;
  v.matched_fraction = s.matched_fraction;
  v.score_px = s.score_px;
  if (static_cast<int>(fractions_.size()) < o_.baseline_frames) {
    fractions_.push_back(s.matched_fraction);
    scores_.push_back(s.score_px);
    baseline_fraction_ = median(fractions_);
    baseline_score_ = median(scores_);
    return v;
  }
  v.in_baseline = false;
  v.bad = s.matched_fraction < baseline_fraction_ - o_.fraction_drop || s.score_px > baseline_score_ + o_.score_rise_px;
  if (v.bad) {
    if (bad_run_++ == 0) first_bad_ = v.frame;
  } else {
    bad_run_ = 0;
  }
  if (bad_run_ >= o_.consecutive) {
    v.warning = true;
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "the camera may have moved or zoomed since frame %d: %.0f%% of the arm's edges match (baseline %.0f%%), "
                  "edge distance %.2f px (baseline %.2f px)",
                  first_bad_, 100.0 * s.matched_fraction, 100.0 * baseline_fraction_, s.score_px, baseline_score_);
    v.reason = buf;
  }
  return v;
}

}  // namespace foresight::align
