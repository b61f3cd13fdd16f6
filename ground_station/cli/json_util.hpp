#pragma once
// JSON helpers shared by the CLI commands (their --json output is a contract:
// 4x4 poses are lists of 4 rows (pose_json, with the object pose file's writer
// and reader in foresight/localization/pose_json.hpp), angles in degrees only
// where the key says _deg).

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "foresight/common/number_list.hpp"
#include "foresight/common/pose.hpp"
#include "foresight/localization/pose_json.hpp"

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

inline nlohmann::json vec_json(const Eigen::VectorXd& v) {
  return nlohmann::json(std::vector<double>(v.data(), v.data() + v.size()));
}

}  // namespace foresight::cli
