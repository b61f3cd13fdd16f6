#include "foresight/common/yaml_util.hpp"

#include <yaml-cpp/eventhandler.h>

#include <cstdio>
#include <numbers>
#include <sstream>
#include <unordered_map>
#include <utility>
#include <vector>

#include "foresight/common/text_file.hpp"

namespace foresight::yaml {

int line_of(const YAML::Node& n) { return n && n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }

namespace {

/// Nodes the duplicate-key walk may visit: linear in the text (a node takes
/// at least a byte or two of it), so only aliases can reach the bound, and
/// yaml-cpp expands them as it iterates: ten nested levels of ten aliases
/// would be 1e10 visits. No configuration of ours uses aliases.
std::size_t node_budget(const std::string& text) { return 2 * text.size() + 1000; }

/// InputError "<source>:<line>: duplicate key 'K' (first on line N)" for the
/// first key given twice in one map, anywhere in `n` (yaml-cpp keeps both and
/// a lookup finds the first: the second would be ignored silently).
void refuse_duplicate_keys(const YAML::Node& n, const std::string& source, std::size_t& budget, int depth = 0) {
  if (budget-- == 0) throw InputError(source, line_of(n), "too many YAML nodes for its size (aliases expanding)");
  if (depth > 64) throw InputError(source, line_of(n), "nested deeper than 64 levels");
  if (n.IsMap()) {
    std::unordered_map<std::string, int> seen;
    for (const auto& kv : n) {
      if (kv.first.IsScalar()) {
        const auto [at, fresh] = seen.emplace(kv.first.Scalar(), line_of(kv.first));
        if (!fresh)
          throw InputError(source, line_of(kv.first),
                           "duplicate key '" + kv.first.Scalar() + "' (first on line " + std::to_string(at->second) + ")");
      }
      refuse_duplicate_keys(kv.second, source, budget, depth + 1);
    }
  } else if (n.IsSequence()) {
    for (const auto& e : n) refuse_duplicate_keys(e, source, budget, depth + 1);
  }
}

}  // namespace

/// Notes where the document it is handed starts; ignores the rest.
class DocumentStart final : public YAML::EventHandler {
 public:
  int line = 0;
  void OnDocumentStart(const YAML::Mark& mark) override { line = mark.line + 1; }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t, const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

YAML::Node parse(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);  // the first document
    // Is there a second one? Asked of the parser twice at most: YAML::LoadAll
    // loops for ever on some inputs (the fuzzer found a stream of NUL bytes
    // after a document that yields empty documents without end).
    std::istringstream in(text);
    YAML::Parser parser(in);
    DocumentStart first, second;
    if (parser.HandleNextDocument(first) && parser.HandleNextDocument(second))
      throw InputError(source, second.line, "a second YAML document (one document per file)");
  } catch (const YAML::Exception& e) {
    throw InputError(source, e.mark.line + 1, std::string("malformed YAML: ") + e.msg);
  }
  std::size_t budget = node_budget(text);
  refuse_duplicate_keys(root, source, budget);
  return root;
}

YAML::Node load_file(const std::string& path, const std::string& cannot_open) {
  return parse(read_text_file(path, cannot_open), path);  // bounded size (input_limits.hpp)
}

YAML::Node section(const YAML::Node& root, const std::string& name, const std::string& file, const std::string& what) {
  const YAML::Node sec = root[name];
  if (!sec) throw InputError(file, "missing section '" + name + "' (" + what + ")");
  if (!sec.IsMap()) throw InputError(file, line_of(sec), name + ": expected a map");
  return sec;
}

double read_positive(const YAML::Node& n, const std::string& file, const std::string& key) {
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

Pose read_xyz_rpy(const YAML::Node& map, const std::string& file, const std::string& key) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  return make_pose(read_vector<3>(map["xyz_m"], file, key + ".xyz_m"),
                   read_vector<3>(map["rpy_deg"], file, key + ".rpy_deg") * kDeg);
}

Pose read_pose(const YAML::Node& n, const std::string& file, const std::string& key) {
  if (!n) throw InputError(file, "missing key '" + key + "'");
  if (!n.IsMap()) throw InputError(file, line_of(n), "'" + key + "' must be a map {xyz_m, rpy_deg}");
  return read_xyz_rpy(n, file, key);
}

namespace {

/// map[key] as a T, `fallback` when absent. InputError "<prefix><key>: not <a_t>: '<text>'".
template <typename T>
T scalar_or(const YAML::Node& map, const char* key, T fallback, const std::string& file, const std::string& prefix,
            const char* a_t) {
  const YAML::Node n = map[key];
  if (!n) return fallback;
  try {
    return n.as<T>();
  } catch (const YAML::Exception&) {
    throw InputError(file, line_of(n), prefix + key + ": " + not_a(n, a_t));
  }
}

}  // namespace

double number_or(const YAML::Node& map, const char* key, double fallback, const std::string& file,
                 const std::string& prefix) {
  return scalar_or(map, key, fallback, file, prefix, type_words<double>());
}

int integer_or(const YAML::Node& map, const char* key, int fallback, const std::string& file,
               const std::string& prefix) {
  return scalar_or(map, key, fallback, file, prefix, type_words<int>());
}

std::optional<YAML::Node> unknown_key(const YAML::Node& map, std::span<const char* const> allowed) {
  for (const auto& kv : map) {
    const std::string key = kv.first.as<std::string>();
    bool known = false;
    for (const char* a : allowed) known = known || key == a;
    if (!known) return kv.first;
  }
  return std::nullopt;
}

std::string key_list(std::span<const char* const> keys) {
  std::string list;
  for (const char* k : keys) list += std::string(list.empty() ? "" : ", ") + k;
  return list;
}

std::string not_a(const YAML::Node& n, const char* a_t) {
  const std::string head = std::string("not ") + a_t;
  if (n.IsScalar()) return head + ": '" + n.Scalar() + "'";
  if (n.IsSequence()) return head + " (a list)";
  if (n.IsMap()) return head + " (a map)";
  return head + " (no value)";
}

MapReader::MapReader(const YAML::Node& map, std::string file, std::string path)
    : map_(map), file_(std::move(file)), path_(std::move(path)) {
  if (!map_.IsMap()) fail(map_, path_.empty() ? "expected a map at the top level" : path_ + ": expected a map");
}

std::string MapReader::name(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

void MapReader::fail(const YAML::Node& at, const std::string& message) const {
  throw InputError(file_, line_of(at) > 0 ? line_of(at) : line_of(map_), message);
}

YAML::Node MapReader::at(const YAML::Node& value, const char* key) const {
  if (value && !value.IsNull()) return value;
  for (const auto& kv : map_)
    if (kv.first.IsScalar() && kv.first.Scalar() == key) return kv.first;
  return value;
}

void MapReader::fail_key(const char* key, const std::string& problem) const {
  fail(at(map_[key], key), name(key) + ": " + problem);
}

double MapReader::in_range(const char* key, double v, double lo, double hi, const char* unit) const {
  if (!(v >= lo && v <= hi)) {  // NaN fails both
    char b[160];
    std::snprintf(b, sizeof b, "%.10g is outside [%.10g, %.10g]%s%s", v, lo, hi, unit[0] != '\0' ? " " : "", unit);
    fail_key(key, b);
  }
  return v;
}

long long MapReader::int_in_range(const char* key, long long v, long long lo, long long hi, const char* unit) const {
  if (v < lo || v > hi) {
    char b[160];
    std::snprintf(b, sizeof b, "%lld is outside [%lld, %lld]%s%s", v, lo, hi, unit[0] != '\0' ? " " : "", unit);
    fail_key(key, b);
  }
  return v;
}

void MapReader::check_keys(std::span<const char* const> allowed) const {
  if (const auto key = unknown_key(map_, allowed))
    fail(*key, name(key->as<std::string>()) + ": unknown key (expected one of: " + key_list(allowed) + ")");
}

MapReader MapReader::map(const char* key, const std::string& what) const {
  const YAML::Node n = map_[key];
  if (!n) fail(map_, label() + ": missing '" + key + "'" + (what.empty() ? "" : " (" + what + ")"));
  return MapReader(n, file_, name(key));
}

}  // namespace foresight::yaml
