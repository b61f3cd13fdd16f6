#pragma once
// Inputs the overlay commands share: a camera by name from cameras.yaml, the
// object pose from `foresight localize --json` output, joint vectors. Set-up
// code; throws InputError naming the file (or std::invalid_argument naming
// the option).

#include <Eigen/Core>
#include <string>

#include "foresight/camera/camera.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight::render {

/// Camera `name` of a cameras.yaml file. InputError "no camera 'X' (known: a, b)".
Camera load_camera(const std::string& cameras_yaml, const std::string& name);

/// base_T_object from a localize JSON file (key "base_T_object", 4 rows of
/// 4 numbers, orthonormal rotation). InputError naming the file otherwise.
Pose read_object_pose_json(const std::string& path);

/// Joint angles from "q1,...,qN" (radians, or degrees when `degrees`),
/// checked against the arm's joint count. std::invalid_argument:
/// "<option>: element K ('x') is not a finite number",
/// "<option> has N values but the arm has M joints".
Eigen::VectorXd parse_joints(const std::string& text, const std::string& option, const RobotModel& model,
                             bool degrees = false);

}  // namespace foresight::render
