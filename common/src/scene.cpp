#include "foresight/common/scene.hpp"

#include <cmath>

#include "foresight/common/error.hpp"
#include "foresight/common/input_limits.hpp"
#include "foresight/common/yaml_util.hpp"

namespace foresight {

namespace {

using yaml::line_of;

Scene read_scene(const std::string& path) {
  const YAML::Node root = yaml::load_file(path, "cannot open scene file");
  if (!root.IsMap()) throw InputError(path, "expected a map at the top level");
  Scene s;
  s.base_T_object = yaml::read_pose(root["object_pose"], path, "object_pose");

  const YAML::Node panel = root["panel"];
  if (!panel || !panel.IsMap()) throw InputError(path, "missing map 'panel'");
  s.panel.size_m = yaml::read_vector<3>(panel["size_m"], path, "panel.size_m");
  if ((s.panel.size_m.array() <= 0.0).any()) throw InputError(path, line_of(panel["size_m"]), "'panel.size_m' must be positive");
  s.panel.base_T_panel = yaml::read_xyz_rpy(panel, path, "panel");
  if (panel["rgba"]) {
    s.panel.rgba = yaml::read_vector<4>(panel["rgba"], path, "panel.rgba");
    if ((s.panel.rgba.array() < 0.0).any() || (s.panel.rgba.array() > 1.0).any())
      throw InputError(path, line_of(panel["rgba"]), "'panel.rgba' values must lie in [0, 1]");
  }

  const YAML::Node cams = root["cameras"];
  if (!cams || !cams.IsMap() || cams.size() == 0) throw InputError(path, "missing or empty map 'cameras'");
  if (cams.size() > static_cast<std::size_t>(limits::kMaxCameras))
    throw InputError(path, line_of(cams), std::to_string(cams.size()) + " cameras, at most " +
                                               std::to_string(limits::kMaxCameras) + " allowed");
  for (const auto& kv : cams) {
    const std::string name = kv.first.as<std::string>();
    const std::string key = "cameras." + name;
    const YAML::Node c = kv.second;
    if (!c.IsMap()) throw InputError(path, line_of(c), "'" + key + "' must be a map");
    if (s.cameras.count(name)) throw InputError(path, line_of(kv.first), "duplicate camera '" + name + "'");
    SceneCamera cam;
    const Eigen::Vector2d vp = yaml::read_vector<2>(c["viewport"], path, key + ".viewport");
    if (vp.x() < 1.0 || vp.y() < 1.0 || vp.x() > 32768.0 || vp.y() > 32768.0 || vp.x() != std::floor(vp.x()) ||
        vp.y() != std::floor(vp.y()))
      throw InputError(path, line_of(c["viewport"]), "'" + key + ".viewport' must be two integers [W, H] in [1, 32768]");
    cam.width_px = static_cast<int>(vp.x());
    cam.height_px = static_cast<int>(vp.y());
    if (!c["f_px"]) throw InputError(path, line_of(c), "missing key '" + key + ".f_px'");
    cam.f_px = yaml::read_positive(c["f_px"], path, key + ".f_px");
    cam.position_m = yaml::read_vector<3>(c["position_m"], path, key + ".position_m");
    cam.look_at_m = yaml::read_vector<3>(c["look_at_m"], path, key + ".look_at_m");
    cam.up = yaml::read_vector<3>(c["up"], path, key + ".up");
    const Eigen::Vector3d dir = cam.look_at_m - cam.position_m;
    if (dir.norm() < 1e-9) throw InputError(path, line_of(c), "'" + key + "': position_m equals look_at_m");
    if (cam.up.norm() < 1e-9 || dir.normalized().cross(cam.up.normalized()).norm() < 1e-6)
      throw InputError(path, line_of(c), "'" + key + "': up is zero or parallel to the viewing direction");
    s.cameras.emplace(name, cam);
    s.camera_order.push_back(name);
  }
  return s;
}

}  // namespace

/// Any yaml-cpp conversion failure left ("bad conversion") becomes bad input
/// naming the file and line (it escaped as exit 1 with no file named).
Scene Scene::from_file(const std::string& path) {
  try {
    return read_scene(path);
  } catch (const YAML::Exception& e) {
    throw InputError(path, e.mark.line >= 0 ? e.mark.line + 1 : 0, std::string("bad value: ") + e.msg);
  }
}

}  // namespace foresight
