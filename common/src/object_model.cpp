#include "foresight/common/object_model.hpp"

#include <cmath>

#include "foresight/common/error.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight {

namespace {

using yaml::line_of;
using yaml::read_positive;
using yaml::read_vector;

Eigen::Vector4d read_rgba(const YAML::Node& n, const std::string& file, const Eigen::Vector4d& fallback) {
  if (!n) return fallback;
  if (!n.IsSequence() || n.size() != 4) throw InputError(file, line_of(n), "'rgba' must be a list of 4 numbers in [0, 1]");
  Eigen::Vector4d c;
  for (int i = 0; i < 4; ++i) {
    c[i] = n[i].as<double>();
    if (!(c[i] >= 0.0 && c[i] <= 1.0)) throw InputError(file, line_of(n), "'rgba' values must lie in [0, 1]");
  }
  return c;
}

}  // namespace

int ObjectModel::point_index(const std::string& point_name) const {
  for (std::size_t i = 0; i < points.size(); ++i)
    if (points[i].name == point_name) return static_cast<int>(i);
  return -1;
}

namespace {

/// An optional list of shapes (`visuals`, `surroundings`), object frame.
std::vector<VisualShape> read_shapes(const YAML::Node& root, const std::string& name, const std::string& path) {
  std::vector<VisualShape> out;
  const YAML::Node list = root[name];
  if (!list) return out;
  if (!list.IsSequence()) throw InputError(path, line_of(list), "'" + name + "' must be a list");
  for (std::size_t i = 0; i < list.size(); ++i) {
    const YAML::Node v = list[i];
    const std::string key = name + "[" + std::to_string(i) + "]";
    VisualShape s;
    const std::string type = v["type"] ? v["type"].as<std::string>() : "";
    if (type == "box") {
      s.type = VisualShape::Type::Box;
      s.size_m = read_vector<3>(v["size_m"], path, key + ".size_m");
    } else if (type == "cylinder") {
      s.type = VisualShape::Type::Cylinder;
      s.size_m = {read_positive(v["radius_m"], path, key + ".radius_m"),
                  read_positive(v["length_m"], path, key + ".length_m"), 0.0};
    } else if (type == "sphere") {
      s.type = VisualShape::Type::Sphere;
      s.size_m = {read_positive(v["radius_m"], path, key + ".radius_m"), 0.0, 0.0};
    } else {
      throw InputError(path, line_of(v), key + ".type must be box, cylinder or sphere (got '" + type + "')");
    }
    s.link_T_shape = yaml::read_xyz_rpy(v, path, key);
    s.rgba = read_rgba(v["rgba"], path, s.rgba);
    out.push_back(s);
  }
  return out;
}

ObjectModel read_object_model(const std::string& path) {
  const YAML::Node root = yaml::load_file(path, "cannot open object model file");
  if (!root.IsMap()) throw InputError(path, "expected a map at the top level");
  ObjectModel m;
  if (!root["object"]) throw InputError(path, "missing key 'object'");
  m.name = root["object"].as<std::string>();
  m.size_m = read_vector<3>(root["size_m"], path, "size_m");
  if ((m.size_m.array() <= 0.0).any()) throw InputError(path, line_of(root["size_m"]), "'size_m' must be positive");
  m.oru_T_box.translation() = root["box_centre_m"] ? read_vector<3>(root["box_centre_m"], path, "box_centre_m")
                                                   : Eigen::Vector3d(0, 0, m.size_m.z() / 2);
  m.rgba = read_rgba(root["rgba"], path, m.rgba);

  const YAML::Node hole = root["hole"];
  if (!hole || !hole.IsMap()) throw InputError(path, "missing map 'hole'");
  m.hole_entrance_m = read_vector<3>(hole["entrance_m"], path, "hole.entrance_m");
  const Eigen::Vector3d axis = read_vector<3>(hole["axis"], path, "hole.axis");
  if (std::abs(axis.norm() - 1.0) > 1e-6) throw InputError(path, line_of(hole["axis"]), "'hole.axis' must be a unit vector");
  m.hole_axis = axis;
  m.hole_diameter_m = read_positive(hole["diameter_m"], path, "hole.diameter_m");
  m.hole_depth_m = read_positive(hole["depth_m"], path, "hole.depth_m");

  const YAML::Node points = root["points"];
  if (!points || !points.IsMap() || points.size() == 0) throw InputError(path, "missing or empty map 'points'");
  for (const auto& kv : points) {
    const std::string name = kv.first.as<std::string>();
    if (m.point_index(name) >= 0) throw InputError(path, line_of(kv.first), "duplicate point '" + name + "'");
    m.points.push_back({name, read_vector<3>(kv.second, path, "points." + name)});
  }

  m.visuals = read_shapes(root, "visuals", path);
  m.surroundings = read_shapes(root, "surroundings", path);

  const YAML::Node tags = root["tags"];
  if (!tags || !tags.IsMap()) throw InputError(path, "missing map 'tags'");
  for (const auto& kv : tags) {
    const std::string name = kv.first.as<std::string>();
    m.tags[name] = yaml::read_pose(kv.second, path, "tags." + name);
  }
  return m;
}

}  // namespace

/// Any yaml-cpp conversion failure left ("bad conversion") becomes bad input
/// naming the file and line (it escaped as exit 1 with no file named).
ObjectModel ObjectModel::from_file(const std::string& path) {
  try {
    return read_object_model(path);
  } catch (const YAML::Exception& e) {
    throw InputError(path, e.mark.line >= 0 ? e.mark.line + 1 : 0, std::string("bad value: ") + e.msg);
  }
}

}  // namespace foresight
