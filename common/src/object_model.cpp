#include "foresight/common/object_model.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>

#include "foresight/common/error.hpp"

namespace foresight {

namespace {

constexpr double kDeg = M_PI / 180.0;

int line_of(const YAML::Node& n) { return n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }

Eigen::Vector3d vec3(const YAML::Node& n, const std::string& file, const std::string& key) {
  if (!n) throw InputError(file, "missing key '" + key + "'");
  if (!n.IsSequence() || n.size() != 3) throw InputError(file, line_of(n), "'" + key + "' must be a list of 3 numbers");
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    try {
      v[i] = n[i].as<double>();
    } catch (const YAML::Exception&) {
      throw InputError(file, line_of(n), "'" + key + "' element " + std::to_string(i + 1) + " is not a number");
    }
    if (!std::isfinite(v[i])) throw InputError(file, line_of(n), "'" + key + "' has a non-finite number");
  }
  return v;
}

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

Pose pose_node(const YAML::Node& n, const std::string& file, const std::string& key) {
  if (!n || !n.IsMap()) throw InputError(file, line_of(n), "'" + key + "' must be a map {xyz_m, rpy_deg}");
  return make_pose(vec3(n["xyz_m"], file, key + ".xyz_m"), vec3(n["rpy_deg"], file, key + ".rpy_deg") * kDeg);
}

double positive(const YAML::Node& n, const std::string& file, const std::string& key) {
  if (!n) throw InputError(file, "missing key '" + key + "'");
  double v = 0.0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    throw InputError(file, line_of(n), "'" + key + "' is not a number");
  }
  if (!(v > 0.0) || !std::isfinite(v)) throw InputError(file, line_of(n), "'" + key + "' must be a positive number");
  return v;
}

}  // namespace

int ObjectModel::point_index(const std::string& point_name) const {
  for (std::size_t i = 0; i < points.size(); ++i)
    if (points[i].name == point_name) return static_cast<int>(i);
  return -1;
}

ObjectModel ObjectModel::from_file(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw InputError(path, "cannot open object model file");
  } catch (const YAML::Exception& e) {
    throw InputError(path, e.mark.line + 1, std::string("malformed YAML: ") + e.msg);
  }
  if (!root.IsMap()) throw InputError(path, "expected a map at the top level");
  ObjectModel m;
  if (!root["object"]) throw InputError(path, "missing key 'object'");
  m.name = root["object"].as<std::string>();
  m.size_m = vec3(root["size_m"], path, "size_m");
  if ((m.size_m.array() <= 0.0).any()) throw InputError(path, line_of(root["size_m"]), "'size_m' must be positive");
  m.oru_T_box.translation() = root["box_centre_m"] ? vec3(root["box_centre_m"], path, "box_centre_m") : Eigen::Vector3d(0, 0, m.size_m.z() / 2);
  m.rgba = read_rgba(root["rgba"], path, m.rgba);

  const YAML::Node hole = root["hole"];
  if (!hole || !hole.IsMap()) throw InputError(path, "missing map 'hole'");
  m.hole_entrance_m = vec3(hole["entrance_m"], path, "hole.entrance_m");
  const Eigen::Vector3d axis = vec3(hole["axis"], path, "hole.axis");
  if (std::abs(axis.norm() - 1.0) > 1e-6) throw InputError(path, line_of(hole["axis"]), "'hole.axis' must be a unit vector");
  m.hole_axis = axis;
  m.hole_diameter_m = positive(hole["diameter_m"], path, "hole.diameter_m");
  m.hole_depth_m = positive(hole["depth_m"], path, "hole.depth_m");

  const YAML::Node points = root["points"];
  if (!points || !points.IsMap() || points.size() == 0) throw InputError(path, "missing or empty map 'points'");
  for (const auto& kv : points) {
    const std::string name = kv.first.as<std::string>();
    if (m.point_index(name) >= 0) throw InputError(path, line_of(kv.first), "duplicate point '" + name + "'");
    m.points.push_back({name, vec3(kv.second, path, "points." + name)});
  }

  if (const YAML::Node visuals = root["visuals"]) {
    if (!visuals.IsSequence()) throw InputError(path, line_of(visuals), "'visuals' must be a list");
    for (std::size_t i = 0; i < visuals.size(); ++i) {
      const YAML::Node v = visuals[i];
      const std::string key = "visuals[" + std::to_string(i) + "]";
      VisualShape s;
      const std::string type = v["type"] ? v["type"].as<std::string>() : "";
      if (type == "box") {
        s.type = VisualShape::Type::Box;
        s.size_m = vec3(v["size_m"], path, key + ".size_m");
      } else if (type == "cylinder") {
        s.type = VisualShape::Type::Cylinder;
        s.size_m = {positive(v["radius_m"], path, key + ".radius_m"), positive(v["length_m"], path, key + ".length_m"), 0.0};
      } else if (type == "sphere") {
        s.type = VisualShape::Type::Sphere;
        s.size_m = {positive(v["radius_m"], path, key + ".radius_m"), 0.0, 0.0};
      } else {
        throw InputError(path, line_of(v), key + ".type must be box, cylinder or sphere (got '" + type + "')");
      }
      s.link_T_shape = make_pose(vec3(v["xyz_m"], path, key + ".xyz_m"), vec3(v["rpy_deg"], path, key + ".rpy_deg") * kDeg);
      s.rgba = read_rgba(v["rgba"], path, s.rgba);
      m.visuals.push_back(s);
    }
  }

  const YAML::Node tags = root["tags"];
  if (!tags || !tags.IsMap()) throw InputError(path, "missing map 'tags'");
  for (const auto& kv : tags) {
    const std::string name = kv.first.as<std::string>();
    m.tags[name] = pose_node(kv.second, path, "tags." + name);
  }
  return m;
}

}  // namespace foresight
