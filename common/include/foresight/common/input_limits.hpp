#pragma once
// The project's rules for untrusted input, in one place (issue 13): every
// parser and validator takes its bounds and range checks from here, so a file
// or message that breaks one is refused the same way everywhere, before any
// computation, with a message naming the file, line and key.
//
//   1. Bounded sizes: a file, a line, rows, cameras, XML nesting depth, and
//      violations listed before "and N more".
//   2. Every number in its physical range: joint angles within the URDF
//      limits (with a margin), pixels inside the viewport, ids that fit an
//      int, masses >= 0, offsets of a sane size, rates and durations whose
//      sample count fits.
//   3. Structure checked (a URDF link tree is a tree).
// Set-up code only (nothing here is for the control loop).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>

namespace foresight::limits {

// ---- sizes ----
inline constexpr std::size_t kMaxTextFileBytes = 64u << 20;  ///< any text input (CSV, YAML, URDF): 64 MiB
inline constexpr std::size_t kMaxLineBytes = 64u << 10;      ///< one CSV line: 64 KiB
inline constexpr std::size_t kMaxScriptBytes = 1u << 20;     ///< a task script: 1 MiB (the changeout's is 3 KiB)
inline constexpr int kMaxTrajectorySamples = 200000;         ///< rows of a trajectory CSV (as TrajectoryLimits)
inline constexpr int kMaxPointRows = 100000;                 ///< data rows of a points CSV
inline constexpr int kMaxCameras = 64;                       ///< cameras in a cameras.yaml
inline constexpr int kMaxXmlDepth = 64;                      ///< element nesting depth of a URDF
inline constexpr std::size_t kMaxListedViolations = 100;     ///< then "... and N more"
inline constexpr int kMaxVideoFrames = 100000;               ///< frames of a preview video (55 min at 30 fps)

// ---- physical ranges ----
inline constexpr double kJointLimitMargin_rad = 0.05;  ///< clicked joints may exceed the URDF limits by this
/// A click may lie this fraction of the viewport's larger side outside it
/// (noisy clicks at the edge), no more.
inline constexpr double kViewportMarginFraction = 0.05;
inline constexpr double kMaxOffset_m = 100.0;          ///< any URDF origin or length
inline constexpr double kMaxMass_kg = 1.0e5;           ///< any URDF link mass
inline constexpr double kMaxPixelNoise_px = 1.0e3;     ///< simulated click noise (sigma)
inline constexpr double kMaxSampleCount = 1.0e7;       ///< a count of samples or frames a rate x duration may give

/// True when `v` is an integer value that fits an int.
inline bool fits_int(double v) {
  return std::isfinite(v) && v == std::floor(v) && v >= static_cast<double>(std::numeric_limits<int>::min()) &&
         v <= static_cast<double>(std::numeric_limits<int>::max());
}

/// The number of samples `duration_s * rate_hz` (rounded up) when it is
/// finite, >= 0 and at most kMaxSampleCount; nullopt otherwise. Use it
/// before any double -> int conversion of a count (float-cast overflow is UB).
inline std::optional<int> sample_count(double duration_s, double rate_hz) {
  const double n = std::ceil(duration_s * rate_hz);
  if (!std::isfinite(n) || n < 0.0 || n > kMaxSampleCount) return std::nullopt;
  return static_cast<int>(n);
}

}  // namespace foresight::limits
