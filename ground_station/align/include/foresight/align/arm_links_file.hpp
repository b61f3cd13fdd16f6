#pragma once
// The arm model's link-length corrections as a file (arm_links.yaml): what
// `foresight align --arm-prior-mm` estimates from the frames (the cameras and
// the arm's link lengths in one bundle adjustment, issue 16) and writes with
// --arm-out; `align --arm-links` renders, samples and starts from it, and
// `synth --arm-links` renders a true arm that differs from the model by it.
//
//   # foresight align --arm-out: the arm model's link-length corrections
//   robot: config/robot.urdf
//   date: 2026-12-03T04:30:00Z
//   arm_link_delta_m: [0, 0.0012, ...]   # one per chain segment (RobotModel::
//   arm_link_sigma_m: [0, 0.0004, ...]   #   with_link_lengths_changed), m
//
// arm_link_sigma_m is optional on reading (the estimate's sd per segment).

#include <string>
#include <vector>

#include "foresight/common/robot_model.hpp"

namespace foresight::align {

struct ArmLinkCorrections {
  std::vector<double> delta_m;  ///< one per chain segment; 0 where a segment has no offset
  std::vector<double> sigma_m;  ///< the same length, or empty
};

/// Reads and checks against `arm`: one finite value per chain segment, a
/// segment without a length offset corrected by 0, a correction under 0.1 m
/// (a link-length error, not another arm), sds finite and >= 0. Throws
/// InputError naming the file (and the key or segment).
ArmLinkCorrections load_arm_links(const std::string& path, const RobotModel& arm);

/// Writes (atomically: a temporary file renamed). Throws InputError when it
/// cannot be written.
void save_arm_links(const std::string& path, const ArmLinkCorrections& links, const std::string& robot_file,
                    const std::string& date_iso);

}  // namespace foresight::align
