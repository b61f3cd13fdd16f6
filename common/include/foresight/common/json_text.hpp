#pragma once
// JSON out, whatever bytes the values hold: nlohmann's dump() throws on a
// string that is not UTF-8 (a file name, a key or a reason may hold any
// bytes). Every JSON that carries text from outside is written through this:
// invalid bytes become U+FFFD, the rest is exactly dump()'s.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace foresight {

/// `j` as JSON text (`indent` as nlohmann's dump: -1 one line), never throwing
/// on bytes that are not UTF-8.
inline std::string json_text(const nlohmann::json& j, int indent = -1) {
  return j.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}

/// A matrix as a list of its rows (the --json outputs' covariances).
inline nlohmann::json matrix_rows(const Eigen::MatrixXd& M) {
  nlohmann::json rows = nlohmann::json::array();
  for (Eigen::Index r = 0; r < M.rows(); ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index c = 0; c < M.cols(); ++c) row.push_back(M(r, c));
    rows.push_back(row);
  }
  return rows;
}

/// A vector as a JSON list of numbers.
inline nlohmann::json vec_json(const Eigen::VectorXd& v) {
  return nlohmann::json(std::vector<double>(v.data(), v.data() + v.size()));
}

}  // namespace foresight
