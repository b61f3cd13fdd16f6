#pragma once
// Reading YAML configuration files (non-real-time code): one loader and one
// set of readers, so that every file reports its errors the same way, as an
// InputError "<file>:<line>: <message>".

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <optional>
#include <span>
#include <string>

#include "foresight/common/error.hpp"
#include "foresight/common/pose.hpp"

namespace foresight::yaml {

/// 1-based line of a node in its file; 0 when it has none (absent, or built in code).
int line_of(const YAML::Node& n);

/// Parses the YAML file `path`. InputError "<path>: <cannot_open>" when it
/// cannot be read, "<path>:<line>: malformed YAML: <reason>" when it is not YAML.
YAML::Node load_file(const std::string& path, const std::string& cannot_open);

/// Parses YAML text; `source` names it in messages.
/// InputError "<source>:<line>: malformed YAML: <reason>".
YAML::Node parse(const std::string& text, const std::string& source);

/// The section `root[name]` of a configuration file, a map. InputError
/// "missing section '<name>' (<what>)", "<name>: expected a map".
YAML::Node section(const YAML::Node& root, const std::string& name, const std::string& file, const std::string& what);

// ---- required values; messages quote `key`: "missing key 'K'", "'K' ..." ----

/// A list of N finite numbers. InputError "missing key 'K'",
/// "'K' must be a list of N numbers", "'K' element I is not a number",
/// "'K' has a non-finite number".
template <int N>
Eigen::Matrix<double, N, 1> read_vector(const YAML::Node& n, const std::string& file, const std::string& key) {
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

/// A finite number > 0. InputError "missing key 'K'", "'K' is not a number",
/// "'K' must be a positive number".
double read_positive(const YAML::Node& n, const std::string& file, const std::string& key);

/// The pose given by the entries xyz_m (m) and rpy_deg (deg) of the map `map`
/// (named "K.xyz_m", "K.rpy_deg" in messages).
Pose read_xyz_rpy(const YAML::Node& map, const std::string& file, const std::string& key);

/// A map {xyz_m, rpy_deg}. InputError "missing key 'K'",
/// "'K' must be a map {xyz_m, rpy_deg}", and those of read_xyz_rpy.
Pose read_pose(const YAML::Node& n, const std::string& file, const std::string& key);

// ---- optional settings: `fallback` when map[key] is absent; messages name
// "<prefix><key>" (e.g. prefix "contact.") ----

/// InputError "<prefix><key>: not a number: '<text>'".
double number_or(const YAML::Node& map, const char* key, double fallback, const std::string& file,
                 const std::string& prefix);

/// InputError "<prefix><key>: not an integer: '<text>'".
int integer_or(const YAML::Node& map, const char* key, int fallback, const std::string& file,
               const std::string& prefix);

// ---- keys ----

/// The first key of the map `map` that is not one of `allowed`, if any.
std::optional<YAML::Node> unknown_key(const YAML::Node& map, std::span<const char* const> allowed);

/// "a, b, c": the allowed keys, for a message.
std::string key_list(std::span<const char* const> keys);

}  // namespace foresight::yaml
