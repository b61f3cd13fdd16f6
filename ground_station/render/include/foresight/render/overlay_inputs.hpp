#pragma once
// Inputs the overlay commands share: a camera by name from cameras.yaml
// (the object pose file is read by foresight/localization/pose_json.hpp). Set-up
// code; throws InputError naming the file (or std::invalid_argument naming
// the option).

#include <Eigen/Core>
#include <string>

#include "foresight/camera/camera.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight::render {

/// Camera `name` of a cameras.yaml file. InputError "no camera 'X' (known: a, b)".
camera::Camera load_camera(const std::string& cameras_yaml, const std::string& name);

}  // namespace foresight::render
