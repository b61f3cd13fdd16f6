#include "foresight/localization/pose_json.hpp"

#include <Eigen/Core>
#include <Eigen/LU>
#include <nlohmann/json.hpp>
#include <cmath>

#include "foresight/common/error.hpp"
#include "foresight/common/text_file.hpp"

namespace foresight::localization {

nlohmann::json pose_json(const Pose& T) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (int c = 0; c < 4; ++c) row.push_back(T.matrix()(r, c));
    rows.push_back(row);
  }
  return rows;
}

nlohmann::json object_pose_json(const Pose& base_T_object) {
  return nlohmann::json{{kObjectPoseKey, pose_json(base_T_object)}};
}

namespace {

nlohmann::json parse_json(const std::string& text, const std::string& source) {
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for 1e400
    throw InputError(source, std::string("malformed JSON: ") + e.what());
  }
}

Pose object_pose_of(const nlohmann::json& j, const std::string& source) {
  const std::string key = kObjectPoseKey;
  auto bad = [&](const std::string& message) { return InputError(source, message); };
  if (!j.is_object() || !j.contains(key)) throw bad("no key '" + key + "'");
  const nlohmann::json& m = j[key];
  if (!m.is_array() || m.size() != 4) throw bad(key + " must be 4 rows of 4 numbers");
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r) {
    const std::string row = key + " row " + std::to_string(r + 1);
    if (!m[r].is_array() || m[r].size() != 4) throw bad(row + " must have 4 numbers");
    for (int c = 0; c < 4; ++c) {
      if (!m[r][c].is_number()) throw bad(row + " has a non-number");
      M(r, c) = m[r][c].get<double>();
      if (!std::isfinite(M(r, c))) throw bad(key + " has a non-finite number");
    }
  }
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0.0 ||
      (M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9)
    throw bad(key + " is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)");
  Pose T;
  T.matrix() = M;
  return T;
}

}  // namespace

Pose parse_object_pose_json(const std::string& text, const std::string& source) {
  return object_pose_of(parse_json(text, source), source);
}

Pose read_object_pose_json(const std::string& path) {
  return parse_object_pose_json(read_text_file(path, "cannot open object pose file"), path);  // bounded size
}

namespace {

/// The matrix at j[key]: `rows` rows (0: any number) of `cols` numbers (0:
/// any, the same in every row). InputError "<path>: <key> must be <what>".
Eigen::MatrixXd matrix_at(const nlohmann::json& j, const char* key, int rows, int cols, const std::string& path,
                          const std::string& what) {
  const nlohmann::json& c = j.at(key);
  const InputError bad(path, std::string(key) + " must be " + what);
  if (!c.is_array() || c.empty() || (rows > 0 && c.size() != static_cast<std::size_t>(rows))) throw bad;
  const std::size_t n = cols > 0 ? static_cast<std::size_t>(cols) : (c[0].is_array() ? c[0].size() : 0);
  if (n == 0) throw bad;
  Eigen::MatrixXd M(static_cast<Eigen::Index>(c.size()), static_cast<Eigen::Index>(n));
  for (std::size_t r = 0; r < c.size(); ++r) {
    if (!c[r].is_array() || c[r].size() != n) throw bad;
    for (std::size_t k = 0; k < n; ++k) {
      if (!c[r][k].is_number() || !std::isfinite(c[r][k].get<double>())) throw bad;
      M(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(k)) = c[r][k].get<double>();
    }
  }
  return M;
}

}  // namespace

ObjectPoseFile read_object_pose_file(const std::string& path) {
  const nlohmann::json j = parse_json(read_text_file(path, "cannot open object pose file"), path);
  ObjectPoseFile f;
  f.base_T_object = object_pose_of(j, path);
  if (j.contains("views") && j.at("views").is_array())
    for (const auto& v : j.at("views"))
      if (v.is_string()) f.views.push_back(v.get<std::string>());
  f.aligned = j.contains("source") && j.at("source") == "foresight align";
  if (!j.contains("covariance")) return f;
  f.covariance = matrix_at(j, "covariance", 6, 6, path, "6 rows of 6 numbers");
  if (j.contains("arm_link_sensitivity")) {
    f.arm_link_sensitivity = matrix_at(j, "arm_link_sensitivity", 6, 0, path, "6 rows of one number per link");
    const nlohmann::json& s = j.contains("arm_link_sigma_m") ? j.at("arm_link_sigma_m") : nlohmann::json();
    if (!s.is_number() || !(s.get<double>() >= 0.0) || !std::isfinite(s.get<double>()))
      throw InputError(path, "arm_link_sensitivity needs arm_link_sigma_m, a number >= 0");
    f.arm_link_sigma_m = s.get<double>();
  }
  return f;
}

}  // namespace foresight::localization
