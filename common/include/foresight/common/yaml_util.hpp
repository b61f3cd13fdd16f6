#pragma once
// Reading YAML configuration files (non-real-time code): one loader and one
// set of readers, so that every file reports its errors the same way, as an
// InputError "<file>:<line>: <message>". Configuration sections read key by
// key go through MapReader (below), whose words every config reader shares.

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <initializer_list>
#include <optional>
#include <span>
#include <string>
#include <type_traits>

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

// ---- one configuration map, read key by key ----

/// "a number", "an integer", "a string", "true or false": what a T is, for a message.
template <typename T>
constexpr const char* type_words() {
  if constexpr (std::is_same_v<T, std::string>) return "a string";
  else if constexpr (std::is_same_v<T, bool>) return "true or false";
  else if constexpr (std::is_integral_v<T>) return "an integer";
  else return "a number";
}

/// "not <a_t>: '<text>'" for a scalar node, "not <a_t> (a list)", "(a map)",
/// "(no value)" otherwise: the one wording of a value of the wrong type.
std::string not_a(const YAML::Node& n, const char* a_t);

/// One map of a configuration file, read key by key. Every configuration
/// reader (remote.yaml's sections, the tool, the video switch, ...) says its
/// problems in these words, as InputError "<file>:<line>: <message>":
///   "<path>: expected a map"            (top level: "expected a map at the top level")
///   "<path>.<key>: unknown key (expected one of: a, b)"
///   "<path>: missing '<key>'" + " (<what>)" when the caller says what it is
///   "<path>.<key>: not a number: '<text>'" (not an integer, not a string, ...)
/// <path> names the map ("tool.modbus", "drives[0] (joint1)"); at the top
/// level (empty path) a key is named alone and the map is "top level". The
/// line is the offending key's or value's, else the map's. Set-up code.
class MapReader {
 public:
  /// InputError "<path>: expected a map" when `map` is not a map.
  MapReader(const YAML::Node& map, std::string file, std::string path);

  const YAML::Node& node() const { return map_; }
  const std::string& file() const { return file_; }
  int line() const { return line_of(map_); }
  /// map[key]; an invalid (false) node when absent.
  YAML::Node operator[](const char* key) const { return map_[key]; }
  /// "<path>.<key>", or "<key>" at the top level.
  std::string name(const std::string& key) const;
  /// "<path>", or "top level".
  std::string label() const { return path_.empty() ? "top level" : path_; }

  /// InputError "<file>:<line of at, else of the map>: <message>".
  [[noreturn]] void fail(const YAML::Node& at, const std::string& message) const;
  /// InputError "<file>:<line of the key's value, else of the map>: <path>.<key>: <problem>".
  [[noreturn]] void fail_key(const char* key, const std::string& problem) const;

  /// InputError "<path>.<key>: unknown key (expected one of: a, b)" for the
  /// first key not allowed.
  void check_keys(std::span<const char* const> allowed) const;
  void check_keys(std::initializer_list<const char*> allowed) const {
    check_keys(std::span<const char* const>(allowed.begin(), allowed.size()));
  }

  /// The required value map[key] as a T. InputError "<path>: missing '<key>'
  /// (<what>)" (without the parenthesis when `what` is empty), "<path>.<key>:
  /// not <a T>: '<text>'".
  template <typename T>
  T get(const char* key, const std::string& what = "") const {
    const YAML::Node n = map_[key];
    if (!n) fail(map_, label() + ": missing '" + key + "'" + (what.empty() ? "" : " (" + what + ")"));
    return as<T>(n, key);
  }

  /// map[key] as a T, `fallback` when absent. InputError as get().
  template <typename T>
  T get_or(const char* key, T fallback) const {
    const YAML::Node n = map_[key];
    return n ? as<T>(n, key) : fallback;
  }

  /// The number map[key] (required) within [lo, hi] `unit`. InputError as
  /// get(), and "<path>.<key>: <value> is outside [lo, hi] <unit>" (NaN and
  /// infinities too): the one wording of a configured number's range.
  double get_in(const char* key, double lo, double hi, const char* unit, const std::string& what = "") const {
    return in_range(key, get<double>(key, what), lo, hi, unit);
  }
  /// As get_in, `fallback` when absent.
  double get_or_in(const char* key, double fallback, double lo, double hi, const char* unit) const {
    return map_[key] ? in_range(key, as<double>(map_[key], key), lo, hi, unit) : fallback;
  }

  /// The integer map[key] (required) within [lo, hi] `unit`: InputError as
  /// get<long long>() ("<path>.<key>: not an integer: '5.5'"), and "<path>.<key>:
  /// <value> is outside [lo, hi] <unit>": the one wording of a configured
  /// count, id or code.
  long long get_int_in(const char* key, long long lo, long long hi, const char* unit,
                       const std::string& what = "") const {
    return int_in_range(key, get<long long>(key, what), lo, hi, unit);
  }
  /// As get_int_in, `fallback` when absent.
  long long get_or_int_in(const char* key, long long fallback, long long lo, long long hi, const char* unit) const {
    return map_[key] ? int_in_range(key, as<long long>(map_[key], key), lo, hi, unit) : fallback;
  }

  /// The map at map[key]: InputError "<path>: missing '<key>' (<what>)",
  /// "<path>.<key>: expected a map".
  MapReader map(const char* key, const std::string& what = "") const;

 private:
  double in_range(const char* key, double v, double lo, double hi, const char* unit) const;
  long long int_in_range(const char* key, long long v, long long lo, long long hi, const char* unit) const;
  template <typename T>
  T as(const YAML::Node& n, const char* key) const {
    if constexpr (std::is_same_v<T, std::string>) {
      if (!n.IsScalar()) fail(at(n, key), name(key) + ": " + not_a(n, type_words<T>()));
    }
    try {
      return n.as<T>();
    } catch (const YAML::Exception&) {
      fail(at(n, key), name(key) + ": " + not_a(n, type_words<T>()));
    }
  }

  /// Where to point at a bad value: the value, or its key when it has none
  /// (yaml-cpp marks an empty value at the next token).
  YAML::Node at(const YAML::Node& value, const char* key) const;

  YAML::Node map_;
  std::string file_;
  std::string path_;
};

}  // namespace foresight::yaml
