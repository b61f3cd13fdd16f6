#include "foresight/render/overlay_inputs.hpp"

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight::render {

Camera load_camera(const std::string& path, const std::string& name) {
  const auto cams = load_cameras(path);
  const auto it = cams.find(name);
  if (it == cams.end()) {
    std::string known;
    for (const auto& [n, r] : cams) known += (known.empty() ? "" : ", ") + n;
    throw InputError(path, "no camera '" + name + "' (known: " + known + ")");
  }
  return it->second.camera;
}

Pose read_object_pose_json(const std::string& path) {
  const std::string text = read_text_file(path, "cannot open object pose file");  // bounded size
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for 1e400
    throw InputError(path, std::string("malformed JSON: ") + e.what());
  }
  if (!j.is_object() || !j.contains("base_T_object")) throw InputError(path, "no key 'base_T_object'");
  const auto& m = j["base_T_object"];
  if (!m.is_array() || m.size() != 4) throw InputError(path, "base_T_object must be 4 rows of 4 numbers");
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r) {
    if (!m[r].is_array() || m[r].size() != 4)
      throw InputError(path, "base_T_object row " + std::to_string(r + 1) + " must have 4 numbers");
    for (int c = 0; c < 4; ++c) {
      if (!m[r][c].is_number())
        throw InputError(path, "base_T_object row " + std::to_string(r + 1) + " has a non-number");
      M(r, c) = m[r][c].get<double>();
      if (!std::isfinite(M(r, c))) throw InputError(path, "base_T_object has a non-finite number");
    }
  }
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0.0 ||
      (M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9)
    throw InputError(path, "base_T_object is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)");
  Pose T;
  T.matrix() = M;
  return T;
}

}  // namespace foresight::render
