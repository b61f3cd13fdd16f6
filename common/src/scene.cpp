#include "foresight/common/scene.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>

#include "foresight/common/error.hpp"

namespace foresight {

namespace {

constexpr double kDeg = M_PI / 180.0;

int line_of(const YAML::Node& n) { return n && n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }

template <int N>
Eigen::Matrix<double, N, 1> vecn(const YAML::Node& n, const std::string& file, const std::string& key) {
  if (!n) throw InputError(file, "missing key '" + key + "'");
  if (!n.IsSequence() || static_cast<int>(n.size()) != N)
    throw InputError(file, line_of(n), "'" + key + "' must be a list of " + std::to_string(N) + " numbers");
  Eigen::Matrix<double, N, 1> v;
  for (int i = 0; i < N; ++i) {
    try {
      v[i] = n[i].as<double>();
    } catch (const YAML::Exception&) {
      throw InputError(file, line_of(n), "'" + key + "' element " + std::to_string(i + 1) + " is not a number");
    }
    if (!std::isfinite(v[i])) throw InputError(file, line_of(n), "'" + key + "' has a non-finite number");
  }
  return v;
}

Pose pose_of(const YAML::Node& n, const std::string& file, const std::string& key) {
  if (!n) throw InputError(file, "missing key '" + key + "'");
  if (!n.IsMap()) throw InputError(file, line_of(n), "'" + key + "' must be a map {xyz_m, rpy_deg}");
  return make_pose(vecn<3>(n["xyz_m"], file, key + ".xyz_m"), vecn<3>(n["rpy_deg"], file, key + ".rpy_deg") * kDeg);
}

}  // namespace

Scene Scene::from_file(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw InputError(path, "cannot open scene file");
  } catch (const YAML::Exception& e) {
    throw InputError(path, e.mark.line + 1, std::string("malformed YAML: ") + e.msg);
  }
  if (!root.IsMap()) throw InputError(path, "expected a map at the top level");
  Scene s;
  s.base_T_object = pose_of(root["object_pose"], path, "object_pose");

  const YAML::Node panel = root["panel"];
  if (!panel || !panel.IsMap()) throw InputError(path, "missing map 'panel'");
  s.panel.size_m = vecn<3>(panel["size_m"], path, "panel.size_m");
  if ((s.panel.size_m.array() <= 0.0).any()) throw InputError(path, line_of(panel["size_m"]), "'panel.size_m' must be positive");
  s.panel.base_T_panel = make_pose(vecn<3>(panel["xyz_m"], path, "panel.xyz_m"),
                                   vecn<3>(panel["rpy_deg"], path, "panel.rpy_deg") * kDeg);
  if (panel["rgba"]) {
    s.panel.rgba = vecn<4>(panel["rgba"], path, "panel.rgba");
    if ((s.panel.rgba.array() < 0.0).any() || (s.panel.rgba.array() > 1.0).any())
      throw InputError(path, line_of(panel["rgba"]), "'panel.rgba' values must lie in [0, 1]");
  }

  const YAML::Node cams = root["cameras"];
  if (!cams || !cams.IsMap() || cams.size() == 0) throw InputError(path, "missing or empty map 'cameras'");
  for (const auto& kv : cams) {
    const std::string name = kv.first.as<std::string>();
    const std::string key = "cameras." + name;
    const YAML::Node c = kv.second;
    if (!c.IsMap()) throw InputError(path, line_of(c), "'" + key + "' must be a map");
    if (s.cameras.count(name)) throw InputError(path, line_of(kv.first), "duplicate camera '" + name + "'");
    SceneCamera cam;
    const Eigen::Vector2d vp = vecn<2>(c["viewport"], path, key + ".viewport");
    if (vp.x() < 1.0 || vp.y() < 1.0 || vp.x() != std::floor(vp.x()) || vp.y() != std::floor(vp.y()))
      throw InputError(path, line_of(c["viewport"]), "'" + key + ".viewport' must be two positive integers [W, H]");
    cam.width_px = static_cast<int>(vp.x());
    cam.height_px = static_cast<int>(vp.y());
    if (!c["f_px"]) throw InputError(path, line_of(c), "missing key '" + key + ".f_px'");
    try {
      cam.f_px = c["f_px"].as<double>();
    } catch (const YAML::Exception&) {
      throw InputError(path, line_of(c["f_px"]), "'" + key + ".f_px' is not a number");
    }
    if (!(cam.f_px > 0.0) || !std::isfinite(cam.f_px))
      throw InputError(path, line_of(c["f_px"]), "'" + key + ".f_px' must be a positive number");
    cam.position_m = vecn<3>(c["position_m"], path, key + ".position_m");
    cam.look_at_m = vecn<3>(c["look_at_m"], path, key + ".look_at_m");
    cam.up = vecn<3>(c["up"], path, key + ".up");
    const Eigen::Vector3d dir = cam.look_at_m - cam.position_m;
    if (dir.norm() < 1e-9) throw InputError(path, line_of(c), "'" + key + "': position_m equals look_at_m");
    if (cam.up.norm() < 1e-9 || dir.normalized().cross(cam.up.normalized()).norm() < 1e-6)
      throw InputError(path, line_of(c), "'" + key + "': up is zero or parallel to the viewing direction");
    s.cameras.emplace(name, cam);
    s.camera_order.push_back(name);
  }
  return s;
}

}  // namespace foresight
