#pragma once
// JSON helpers shared by the CLI commands (their --json output is a contract:
// 4x4 poses are lists of 4 rows, angles in degrees only where the key says _deg).

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "foresight/common/number_list.hpp"
#include "foresight/common/pose.hpp"

namespace foresight::cli {

inline nlohmann::json matrix_rows(const Eigen::MatrixXd& M) {
  nlohmann::json rows = nlohmann::json::array();
  for (Eigen::Index r = 0; r < M.rows(); ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index c = 0; c < M.cols(); ++c) row.push_back(M(r, c));
    rows.push_back(row);
  }
  return rows;
}

inline nlohmann::json pose_json(const Pose& T) { return matrix_rows(T.matrix()); }

inline nlohmann::json vec_json(const Eigen::VectorXd& v) {
  return nlohmann::json(std::vector<double>(v.data(), v.data() + v.size()));
}

/// A 4x4 pose from JSON rows; throws std::invalid_argument naming `what`.
inline Pose pose_from_json(const nlohmann::json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 4) throw std::invalid_argument(what + " must be a 4x4 matrix (list of 4 rows)");
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r) {
    if (!j[r].is_array() || j[r].size() != 4) throw std::invalid_argument(what + " row " + std::to_string(r + 1) + " must have 4 numbers");
    for (int c = 0; c < 4; ++c) {
      if (!j[r][c].is_number()) throw std::invalid_argument(what + " row " + std::to_string(r + 1) + " has a non-number");
      M(r, c) = j[r][c].get<double>();
    }
  }
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0.0)
    throw std::invalid_argument(what + " rotation is not orthonormal");
  Pose T;
  T.matrix() = M;
  return T;
}


}  // namespace foresight::cli
