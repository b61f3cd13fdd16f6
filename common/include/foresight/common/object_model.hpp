#pragma once
// The task object (the ORU) as the ground sees it: its box, the model points
// the operator clicks for localization, the hole axis, and the tag frames the
// changeout moves to (the paper's fig. 6 target frames), all in the object
// frame `oru`. Loaded from config/oru.yaml.
//
// Object frame `oru`: origin at the hole entrance on the front face; z along
// the hole axis, pointing into the ORU (the insertion direction); x along the
// face's width, y completing a right-handed frame (down when the ORU sits
// upright facing the arm).

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "foresight/common/pose.hpp"
#include "foresight/common/robot_model.hpp"

namespace foresight {

struct ObjectModel {
  std::string name;                        ///< e.g. "oru"
  Eigen::Vector3d size_m;                  ///< box extents along x, y, z
  Pose oru_T_box = Pose::Identity();       ///< centre of the box in the object frame
  Eigen::Vector4d rgba{0.8, 0.75, 0.3, 1.0};
  struct Point {
    std::string name;
    Eigen::Vector3d p_m;                   ///< in the object frame
  };
  std::vector<Point> points;               ///< model points for localization
  Eigen::Vector3d hole_entrance_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d hole_axis = Eigen::Vector3d::UnitZ();  ///< unit, into the ORU
  double hole_diameter_m = 0.03;
  double hole_depth_m = 0.08;
  std::map<std::string, Pose> tags;        ///< oru_T_tag, by tag name
  /// Extra visual primitives (e.g. the hole, a handle), object frame.
  std::vector<VisualShape> visuals;
  /// The structure around the object as installed (the satellite's bay,
  /// object frame): not part of the object and never drawn as it, but it
  /// hides the object's parts inside it (from the side, all of the ORU but
  /// its front 5 cm), so the model-to-image alignment's visibility needs it.
  /// Optional key `surroundings`, the same shapes as `visuals`.
  std::vector<VisualShape> surroundings;

  /// Index of a model point by name, -1 when absent.
  int point_index(const std::string& name) const;

  /// Throws InputError naming the file and key: missing/unreadable file,
  /// malformed YAML, missing or wrongly sized keys, non-unit hole axis.
  static ObjectModel from_file(const std::string& yaml_path);
};

}  // namespace foresight
