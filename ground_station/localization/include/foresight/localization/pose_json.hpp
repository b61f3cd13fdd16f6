#pragma once
// The object pose file: the one JSON contract for an estimated object pose,
// written by `foresight localize --json` (and `foresight align --object-out`)
// and read by every command that takes --object-pose (overlay, plan, preview,
// goto, run, display, align, health, demo). The one writer and the one
// reader live here, GL-free, so the ground's render and CLI code share them.
//
//   {"base_T_object": [[r11, r12, r13, x], [r21, r22, r23, y],
//                      [r31, r32, r33, z], [0, 0, 0, 1]], ...other keys}
//
// A 4x4 pose is always a list of 4 rows of 4 numbers (metres). Set-up code:
// allocates; the reader throws InputError naming the file and the key.

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>  // callers of pose_json include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "foresight/common/pose.hpp"

namespace foresight::localization {

/// The key of the object pose in the file.
inline constexpr const char* kObjectPoseKey = "base_T_object";

/// A 4x4 pose as 4 rows of 4 numbers (the row form of every pose in the
/// commands' JSON output).
nlohmann::json pose_json(const Pose& T);

/// The writer: {"base_T_object": pose_json(base_T_object)}; callers add
/// their own keys beside it.
nlohmann::json object_pose_json(const Pose& base_T_object);

/// The reader, from JSON text; `source` names it in messages. InputError
/// "<source>: <message>" with the messages "malformed JSON: <reason>" (also
/// a number too large for a double, e.g. 1e400),
/// "no key 'base_T_object'", "base_T_object must be 4 rows of 4 numbers",
/// "base_T_object row R must have 4 numbers", "base_T_object row R has a
/// non-number", "base_T_object is not a rigid transform
/// (rotation not orthonormal or last row not 0 0 0 1)".
Pose parse_object_pose_json(const std::string& text, const std::string& source);

/// The reader, from the file `path` (size bounded as every text input):
/// InputError "<path>: cannot open object pose file" and those of
/// parse_object_pose_json with the path as source.
Pose read_object_pose_json(const std::string& path);

/// The pose and, where the file has it, the uncertainty `localize --json`
/// writes beside it ("covariance": 6 rows of 6 numbers; roll, pitch, yaw,
/// x, y, z).
struct ObjectPoseFile {
  Pose base_T_object;
  std::optional<Eigen::Matrix<double, 6, 6>> covariance;
  /// The arm model's correlated term, where the file has it
  /// ("arm_link_sensitivity": 6 rows of one number per link, with
  /// "arm_link_sigma_m"); empty otherwise.
  Eigen::MatrixXd arm_link_sensitivity;
  double arm_link_sigma_m = 0.0;
  std::vector<std::string> views;  ///< "views": the cameras the pose came from
  bool aligned = false;            ///< "source": "foresight align" (align --object-out)
};

/// read_object_pose_json and the covariance, from one read of `path`; also
/// InputError "<path>: covariance must be 6 rows of 6 numbers" (any
/// non-finite or non-number entry too), "<path>: arm_link_sensitivity must
/// be 6 rows of one number per link", "<path>: arm_link_sensitivity needs
/// arm_link_sigma_m, a number >= 0".
ObjectPoseFile read_object_pose_file(const std::string& path);

}  // namespace foresight::localization
