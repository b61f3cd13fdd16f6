#pragma once
// The simulated work site (config/scene.yaml): where things truly are. Ground
// truth for the synthetic camera, the plant simulator, the accuracy study and
// the demo. Loading allocates and may throw (set-up code, not real-time).
//
// The cameras are given as look-at specifications (position, target, up);
// foresight::Camera::look_at (ground_station/camera) turns one into a camera.
// common/ does not depend on the camera library, so this header only carries
// the numbers.

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "foresight/common/pose.hpp"

namespace foresight {

struct ScenePanel {
  Eigen::Vector3d size_m = Eigen::Vector3d::Zero();  ///< box extents along the panel's x, y, z
  Pose base_T_panel = Pose::Identity();              ///< centre of the box
  Eigen::Vector4d rgba{0.55, 0.57, 0.6, 1.0};
};

struct SceneCamera {
  int width_px = 646;
  int height_px = 486;
  double f_px = 700.0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  ///< base frame
  Eigen::Vector3d look_at_m = Eigen::Vector3d::UnitX();  ///< base frame
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();         ///< base direction that appears up
};

struct Scene {
  Pose base_T_object = Pose::Identity();  ///< the ORU (`object_pose`)
  ScenePanel panel;
  /// By name (sorted); camera_order keeps the file order.
  std::map<std::string, SceneCamera> cameras;
  /// The camera names in the order the file lists them (the paper's view
  /// numbering 1..4 for the accuracy study).
  std::vector<std::string> camera_order;

  /// Throws InputError naming the file, line and key: unreadable file,
  /// malformed YAML, missing or wrongly sized keys, non-finite numbers,
  /// non-positive f_px or viewport, position equal to look_at, up parallel
  /// to the viewing direction.
  static Scene from_file(const std::string& yaml_path);
};

}  // namespace foresight
